/* Test oracles of fusion/ (STYLE.md section 1: a CPU version of a kernel
 * is a test oracle, not a product path): the CPU integration of one brick
 * (integrate_ref.c) and the host brick inserter (insert_ref.c). They reach
 * into fusion/'s internals (fusion/fusion_int.h). */
#ifndef BF_TESTS_FUSION_REF_H
#define BF_TESTS_FUSION_REF_H

#include "fusion/fusion_int.h"

/* insert_ref.c: inserts one brick from the host, creating its chunk and
 * octree path (tests build maps with it). Must not run while GPU work is
 * pending. *slot receives the brick slot. */
bf_status fusion_ref_insert_brick(fusion_map *map, const int32_t key[3], uint32_t level, const uint32_t cell[3],
                                  uint32_t *slot);

/* One brick as the integration sees it: its chunk key, packed position,
 * stored error (float bits of FUSION_INFO_ERROR) and bit planes. */
typedef struct fusion_ref_brick {
    int32_t key[3];
    uint32_t pos;                 /* fusion_pack_pos(cell, level) */
    float error;
    uint32_t sign[BRICK_WORDS], conf[BRICK_WORDS];
} fusion_ref_brick;

/* What the oracle saw, for tests: how far the inputs kept from the
 * boundaries where a last-bit difference in a GPU division (2.5 ulp allowed
 * by Vulkan) could flip a bit. Only divisions can differ: adds, multiplies
 * and conversions are correctly rounded on both sides, and BF_PRECISE
 * forbids contraction. A voxel is fragile when one of its projections lies
 * within FUSION_REF_TOL px of a pixel edge whose other side holds another
 * depth (or the image border), or when its decision sums hold a divided
 * term and its numerator or its confidence test is within a relative
 * FUSION_REF_TOL of the boundary. Elsewhere GPU == CPU bit for bit is a
 * fair requirement. */
#define FUSION_REF_TOL 1e-4
typedef struct fusion_ref_margins {
    double pixel;        /* smallest distance of u + 1/2 or v + 1/2 to an integer (pixel edge, image border), px */
    double sign;         /* smallest |numerator| / (|psi phi| + sum |W_i D_i|) of a voxel with a divided term */
    double conf;         /* smallest |denominator - conf_weight| / conf_weight of such a voxel */
    uint32_t n_pairs;    /* (voxel, frame) pairs with W > 0 */
    uint32_t n_observed; /* voxels with at least one such pair */
    uint32_t n_divided;  /* voxels whose sums hold a ramp weight or a scaled psi */
    uint32_t n_fragile;  /* voxels set in fragile */
    uint32_t fragile[BRICK_WORDS]; /* bit planes' layout */
    float window_err;    /* fusion_window_error of the brick */
    double error_gap;    /* |window_err - brick error| / brick error when the rule compares them, else inf */
    bool error_written;  /* the pass stored window_err as the brick's error */
} fusion_ref_margins;

/* integrate_ref.c: the CPU oracle of one brick's integration. Runs the shared functions of
 * shaders/fusion.glsl.h in the kernel's order on brick b in place, against
 * the frame ring as the GPU holds it: frames[pc->ring_slots] records and
 * depth_ring (pc->ring_slots images of pc->depth_words words). No culling:
 * the kernel's culling must not change a bit, and the comparison checks it.
 * margins may be NULL. */
void fusion_ref_integrate(const fusion_integrate_push *pc, const fusion_frame *frames, const uint32_t *depth_ring,
                          fusion_ref_brick *b, fusion_ref_margins *margins);

#endif
