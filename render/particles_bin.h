/* Binning particles into bricks on the host (render/particles.c's helper;
 * internal to render/). */
#ifndef BF_RENDER_PARTICLES_BIN_H
#define BF_RENDER_PARTICLES_BIN_H

#include "core/core.h"
#include "hostmap/hostmap.h"
#include "shaders/render.glsl.h"

#define PARTICLES_COARSE_LEVELS ((int)RENDER_PARTICLES_COARSE_LEVELS)

/* Global brick coordinates are below 2^PARTICLES_AXIS_BITS per axis (the
 * origin sits below the set's box, so they are never negative): a brick's
 * Morton code and its cell's place in it fit one 64-bit sort key. */
#define PARTICLES_AXIS_BITS 18
#define PARTICLES_MAX_CELLS ((int64_t)1 << (PARTICLES_AXIS_BITS + 3))
#define PARTICLES_INDEX_HEADER RENDER_PARTICLES_INDEX_HEADER
#define PARTICLES_INDEX_ONE RENDER_PARTICLES_INDEX_ONE

/* The binning's buffers, kept from one binning to the next (a moving set
 * re-binned per step touches no new memory). NULL when out of memory. */
typedef struct particles_binner particles_binner;
particles_binner *particles_binner_create(void);
void particles_binner_destroy(particles_binner *w);

typedef struct particles_binned {
    hostmap_brick *bricks; /* the binner's: key, cell, level and both planes filled; until its next binning */
    uint32_t n_bricks;     /* both levels' */
    uint32_t n_occupied;   /* bricks of centres (the first n_bricks - n_coarse) */
    uint32_t n_coarse;     /* bricks of the coarse level (the last n_coarse) */
    uint64_t n_cells;      /* set bits */
    uint64_t n_nodes, n_chunks; /* what the octrees of these bricks need (fusion_load) */
    /* The centres' index: each brick of centres found from its coarse cell
     * without the octree's three levels between (the child pointer and
     * mask of Laine & Karras's sparse voxel octrees, per coarse word):
     *   [0] the first coarse brick's slot (the bricks of centres fill the
     *       slots before it), [1] where the slots below start (S);
     *   [2 + 16 j + w] the entry of coarse brick j's (slot [0] + j) first
     *       set cell in sign word w (the cells in word order, then bit order);
     *   [S + e] the slot of entry e's brick of centres, or where it holds one
     *       centre, PARTICLES_INDEX_ONE | its cell (sign word << 5 | bit).
     * The binner's, until its next binning. */
    const uint32_t *index;
    uint64_t n_index;      /* words */
    bool too_many;         /* failed: more than max_bricks */
} particles_binned;

/* Bins xyz (n particles, world metres) into cells of cell_m from origin
 * (every cell within the grid: set_frame checked) on two octree levels:
 *   - `level`, the centres: each particle sets its cell's sign bit; only
 *     bricks holding centres are made; the confidence plane's word 0 says
 *     which sign words hold centres (bit w), its other words are 0;
 *   - level - PARTICLES_COARSE_LEVELS, the coarse level, whose cells are
 *     the centres' bricks: a cell's sign bit says its brick holds centres,
 *     its confidence bit that a sphere of radius_m centred anywhere in a
 *     set cell overlaps it (the reach), in bricks made (empty) where need
 *     be.
 * BF_NO_MEMORY when out of memory or past max_bricks (out->too_many: it
 * stops early there, so a grid too fine costs little to try);
 * BF_INVALID_ARG for a level below PARTICLES_COARSE_LEVELS. */
bf_status particles_bin(particles_binner *w, const float *xyz, uint64_t n, bf_vec3 origin, double cell_m,
                        double radius_m, uint32_t level, uint64_t max_bricks, particles_binned *out);

#endif
