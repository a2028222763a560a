/* Binning particles into bricks on the host (render/particles.c's helper;
 * internal to render/). */
#ifndef BF_RENDER_PARTICLES_BIN_H
#define BF_RENDER_PARTICLES_BIN_H

#include "core/core.h"
#include "hostmap/hostmap.h"

/* Global brick coordinates are below 2^PARTICLES_AXIS_BITS per axis (the
 * origin sits below the set's box, so they are never negative): a brick's
 * Morton code and its cell's place in it fit one 64-bit sort key. */
#define PARTICLES_AXIS_BITS 18
#define PARTICLES_MAX_CELLS ((int64_t)1 << (PARTICLES_AXIS_BITS + 3))

/* The binning's buffers, kept from one binning to the next (a moving set
 * re-binned per step touches no new memory). NULL when out of memory. */
typedef struct particles_binner particles_binner;
particles_binner *particles_binner_create(void);
void particles_binner_destroy(particles_binner *w);

typedef struct particles_binned {
    hostmap_brick *bricks; /* the binner's: key, cell, level and both planes filled; until its next binning */
    uint32_t n_bricks;
    uint32_t n_occupied;   /* bricks holding set bits */
    uint64_t n_cells;      /* set bits */
    uint64_t n_nodes, n_chunks; /* what the octrees of these bricks need (fusion_load) */
    bool too_many;         /* failed: more than max_bricks */
} particles_binned;

/* Bins xyz (n particles, world metres) into cells of cell_m from origin
 * (every cell within the grid: set_frame checked) on octree level `level`:
 * each particle sets its cell's bit (sign plane); each cell a sphere of
 * radius_m at a set cell's middle overlaps gets a reach bit (confidence
 * plane), in bricks allocated (empty) where need be. BF_NO_MEMORY when
 * out of memory or past max_bricks (out->too_many: it stops early there,
 * so a grid too fine costs little to try). */
bf_status particles_bin(particles_binner *w, const float *xyz, uint64_t n, bf_vec3 origin, double cell_m,
                        double radius_m, uint32_t level, uint64_t max_bricks, particles_binned *out);

#endif
