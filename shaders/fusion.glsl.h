/* The sign-bit map, as both C and GLSL see it (DESIGN.md sections 3 and 4;
 * Reichl, Weiss, Westermann 2016 and Reichl's dissertation, ch. 8).
 *
 * World chunks (2 m cubes by default) live in a hash table; each holds an
 * octree whose nodes may each own one 8x8x8 brick at the node's level:
 * level 0 is the whole chunk as one brick (25 cm voxels for 2 m chunks),
 * every level halves the voxel, level 8 gives ~1 mm. Positions on the GPU
 * are relative to the map origin (a double on the CPU), in float; a chunk's
 * corner is key * chunk_m, so precision does not decay with the distance of
 * the map origin from the world origin (DESIGN.md section 10).
 *
 * Buffers (all uint32 words):
 *   hash      FUSION_ENTRY_WORDS per entry; entries [0, n_buckets *
 *             FUSION_BUCKET_SLOTS) are the buckets' slots, the rest is the
 *             overflow pool, linked through `next` (Niessner et al. 2013).
 *   locks     one word per bucket: a pass's single inserter (cleared before
 *             every allocation pass, so no unlock and no spinning).
 *   nodes     FUSION_NODE_WORDS per node; children come in groups of 8
 *             consecutive nodes. The pool is filled with FUSION_NONE at
 *             create, so a fresh group needs no initialisation.
 *   bricks    FUSION_BRICK_INFO_WORDS per brick slot (where it lives).
 *   sign      BRICK_WORDS per brick slot: bit = voxel centre in front.
 *   conf      BRICK_WORDS per brick slot: bit = voxel is confident.
 *   counters  fusion_counters (allocation cursors, free stack, statistics).
 */
#ifndef BF_FUSION_GLSL_H
#define BF_FUSION_GLSL_H

#include "bf_common.glsl.h"

#define FUSION_MAX_LEVEL 8u
#define FUSION_NONE 0xFFFFFFFFu   /* no child / no brick / end of list */
#define FUSION_LOCKED 0xFFFFFFFEu /* being created in this pass */

/* ------------------------------------------------------------ hash */
#define FUSION_BUCKET_SLOTS 4u
#define FUSION_ENTRY_WORDS 8u
/* Entry word offsets. */
#define FUSION_ENTRY_X 0u
#define FUSION_ENTRY_Y 1u
#define FUSION_ENTRY_Z 2u
#define FUSION_ENTRY_ROOT 3u  /* root node index */
#define FUSION_ENTRY_NEXT 4u  /* next overflow entry or FUSION_NONE */
#define FUSION_ENTRY_STATE 5u /* FUSION_ENTRY_FREE / _VALID, written last */
#define FUSION_ENTRY_FREE 0u
#define FUSION_ENTRY_VALID 1u

/* Niessner et al. 2013's spatial hash (Teschner's primes). */
BF_FN bf_u32 fusion_hash(bf_i32 x, bf_i32 y, bf_i32 z, bf_u32 n_buckets)
{
    bf_u32 h = (BF_U32(x) * 73856093u) ^ (BF_U32(y) * 19349669u) ^ (BF_U32(z) * 83492791u);
    return h % n_buckets;
}

/* ------------------------------------------------------------ nodes */
#define FUSION_NODE_WORDS 2u
#define FUSION_NODE_CHILD 0u /* first of 8 children, FUSION_NONE or FUSION_LOCKED */
#define FUSION_NODE_BRICK 1u /* brick slot, FUSION_NONE or FUSION_LOCKED */

/* Child octant of a cell at level+1 inside its parent: bit 0 = x, 1 = y, 2 = z. */
BF_FN bf_u32 fusion_octant(bf_u32 x, bf_u32 y, bf_u32 z) { return (x & 1u) | ((y & 1u) << 1) | ((z & 1u) << 2); }

/* ------------------------------------------------------------ bricks */
#define FUSION_BRICK_INFO_WORDS 4u
#define FUSION_INFO_CHUNK 0u     /* hash entry index of its chunk */
#define FUSION_INFO_POS 1u       /* fusion_pack_pos(cell x, y, z, level) */
#define FUSION_INFO_NODE 2u      /* node that owns it */
#define FUSION_INFO_ERROR 3u     /* float bits: average sigma of the window that set it */

/* A cell at level L has integer coordinates in [0, 2^L) inside its chunk;
 * L <= 8 so each fits in 8 bits (0..255). */
BF_FN bf_u32 fusion_pack_pos(bf_u32 x, bf_u32 y, bf_u32 z, bf_u32 level)
{
    return x | (y << 8) | (z << 16) | (level << 24);
}
BF_FN bf_u32 fusion_pos_x(bf_u32 p) { return p & 255u; }
BF_FN bf_u32 fusion_pos_y(bf_u32 p) { return (p >> 8) & 255u; }
BF_FN bf_u32 fusion_pos_z(bf_u32 p) { return (p >> 16) & 255u; }
BF_FN bf_u32 fusion_pos_level(bf_u32 p) { return p >> 24; }

/* Voxel edge at a level: chunk_m / 8 / 2^level (exact: powers of two). */
BF_FN bf_f32 fusion_voxel_m(bf_f32 chunk_m, bf_u32 level)
{
    return chunk_m * (0.125f / BF_F32(1u << level));
}

/* The level whose voxel edge is closest (in ratio) to the sample's footprint
 * ratio * z / f, i.e. voxel / sqrt(2) < footprint <= voxel * sqrt(2),
 * clamped to [0, max_level] (DESIGN.md section 3: model only what the
 * sensor resolves). A loop of exact halvings, so C and GLSL agree. */
BF_FN bf_u32 fusion_level_for_footprint(bf_f32 footprint_m, bf_f32 chunk_m, bf_u32 max_level)
{
    bf_f32 voxel = chunk_m * 0.125f;
    bf_u32 level = 0u;
    while (level < max_level && footprint_m * 1.41421356f <= voxel) {
        voxel *= 0.5f;
        level++;
    }
    return level;
}

/* ------------------------------------------------------------ frames */
/* The frame ring: 2n slots (DESIGN.md section 4). Each slot has a record in
 * the frames buffer and a depth image in the depth ring (raw 16-bit depth,
 * two pixels per word, pixel i in word i / 2, low half first). The record
 * holds the map-to-camera transform T_cm (camera point = R p + t, p relative
 * to the map origin) and the intrinsics. Scalars only: std430 and C agree. */
struct fusion_frame {
    bf_f32 R[9];            /* row-major */
    bf_f32 t[3];
    bf_f32 fx, fy, cx, cy;  /* pixels */
    bf_f32 depth_unit_m;    /* metres per raw depth unit */
    bf_u32 width, height;
    bf_u32 index;           /* sequence index of the frame in the slot, FUSION_NONE if empty */
    bf_u32 pad[4];
};
#define FUSION_FRAME_WORDS 24u
#ifndef BF_GLSL
typedef struct fusion_frame fusion_frame;
_Static_assert(sizeof(fusion_frame) == FUSION_FRAME_WORDS * 4, "fusion_frame must match std430");
#endif

/* Depth sensor uncertainty sigma(z) = a + b (z - c)^2 [m] (Kinect v1:
 * Nguyen, Izadi, Lovell 2012: a = 0.0012, b = 0.0019, c = 0.4). */
BF_FN bf_f32 fusion_sigma(bf_f32 z, bf_f32 a, bf_f32 b, bf_f32 c)
{
    BF_PRECISE bf_f32 d = z - c;
    BF_PRECISE bf_f32 s = a + b * d * d;
    return s;
}

/* ------------------------------------------------------------ allocation */
/* The retry queues of the allocation passes live in one buffer: two queues,
 * each a 4-word header {count, groups x, y, z} at word 4 * q, entries from
 * FUSION_QUEUE_ENTRIES + q * queue_cap. An entry is pixel * 4 + band point. */
#define FUSION_QUEUE_ENTRIES 8u
/* Workgroup size of the allocation passes (1-D: pixels or queue entries). */
#define FUSION_ALLOC_LOCAL 64u

/* Push constants of fusion_alloc.comp and fusion_alloc_args.comp. */
struct fusion_alloc_push {
    bf_u32 slot;          /* ring slot of the frame */
    bf_u32 frame_index;   /* its sequence index (brick stamps) */
    bf_u32 pass;          /* 0: every pixel; > 0: the retry queue (pass - 1) % 2 */
    bf_u32 queue_cap;     /* entries per retry queue */
    bf_u32 max_level;
    bf_u32 n_buckets;
    bf_u32 n_overflow;
    bf_u32 node_cap;
    bf_f32 chunk_m;
    bf_f32 voxel_ratio;
    bf_f32 band_sigmas;
    bf_f32 max_depth_m;
    bf_f32 sigma_a, sigma_b, sigma_c;
    bf_u32 pad;
};
#ifndef BF_GLSL
typedef struct fusion_alloc_push fusion_alloc_push;
_Static_assert(sizeof(fusion_alloc_push) == 64, "fusion_alloc_push must match std430");
#endif

/* Push constants of fusion_window_list.comp. */
struct fusion_window_list_push {
    bf_u32 brick_cap;
    bf_u32 n_entries;  /* hash entries: a brick record's chunk below it is live */
    bf_u32 first, last; /* frame indices of the window, inclusive */
};
#ifndef BF_GLSL
typedef struct fusion_window_list_push fusion_window_list_push;
_Static_assert(sizeof(fusion_window_list_push) == 16, "fusion_window_list_push must match std430");
#endif

/* ------------------------------------------------------------ counters */
/* Word offsets in the counters buffer. */
#define FUSION_CNT_NODES 0u        /* nodes handed out (bump allocator) */
#define FUSION_CNT_OVERFLOW 1u     /* overflow hash entries handed out */
#define FUSION_CNT_FREE_TOP 2u     /* bricks on the free stack */
#define FUSION_CNT_BRICKS 3u       /* live bricks */
#define FUSION_CNT_RETRY 4u        /* samples queued for the next pass */
#define FUSION_CNT_NEW 5u          /* bricks created this frame */
#define FUSION_CNT_FAIL_NODES 6u   /* requests refused: node pool full */
#define FUSION_CNT_FAIL_BRICKS 7u  /* requests refused: brick pool full */
#define FUSION_CNT_FAIL_HASH 8u    /* requests refused: hash overflow full */
#define FUSION_CNT_LIST 9u         /* entries in the work list being built */
#define FUSION_CNT_DISPATCH 12u    /* 3 words: indirect group counts */
#define FUSION_CNT_WORDS 16u

#endif
