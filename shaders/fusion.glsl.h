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
 *   addresses the device addresses (uvec2 each) of hash, nodes, sign, conf
 *             and the frame rings, FUSION_ADDR_*: a reader that binds this one
 *             buffer reads them through it (render_raycast.comp,
 *             fusion_colour.comp; on lavapipe a storage-buffer load at a
 *             per-lane index is a scalar loop over the lanes, one through an
 *             address a gather: gpu_buffer_address).
 */
#ifndef BF_FUSION_GLSL_H
#define BF_FUSION_GLSL_H

#include "bf_common.glsl.h"

#define FUSION_MAX_LEVEL 8u
#define FUSION_ADDR_HASH 0u
#define FUSION_ADDR_NODES 1u
#define FUSION_ADDR_SIGN 2u
#define FUSION_ADDR_CONF 3u
#define FUSION_ADDR_DEPTH_RING 4u
#define FUSION_ADDR_COLOUR_RING 5u
#define FUSION_ADDRS 6u
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
/* The size the level rule asks of a voxel for a sample at depth z: ratio
 * times the pixel footprint z / fx, and with voxel_sigmas > 0 at least
 * voxel_sigmas times the sensor's sigma(z) (Kinect v1's grows as z^2, the
 * footprint as z: far samples get voxels as coarse as their noise). */
BF_FN bf_f32 fusion_level_size(bf_f32 z, bf_f32 inv_abs_fx, bf_f32 ratio, bf_f32 voxel_sigmas, bf_f32 sigma_z)
{
    BF_PRECISE bf_f32 f = ratio * z * inv_abs_fx;
    BF_PRECISE bf_f32 n = voxel_sigmas * sigma_z;
    return n > f ? n : f;
}

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
    bf_u32 has_colour;      /* 1: the colour ring's slot holds its colour image */
    bf_u32 pad[3];
};
#define FUSION_FRAME_WORDS 24u
#ifndef BF_GLSL
typedef struct fusion_frame fusion_frame;
_Static_assert(sizeof(fusion_frame) == FUSION_FRAME_WORDS * 4, "fusion_frame must match std430");
#endif

/* ------------------------------------------------------------ work lists */
/* A list of brick slots (new bricks of a frame, a window's bricks): word
 * FUSION_LIST_COUNT holds the count, words FUSION_LIST_ARGS .. + 2 the
 * indirect dispatch arguments a prepare pass writes, entries start at
 * FUSION_LIST_HEADER. */
#define FUSION_LIST_COUNT 0u
#define FUSION_LIST_ARGS 1u
#define FUSION_LIST_HEADER 4u

/* ------------------------------------------------------------ allocation */
/* The retry queues of the allocation passes live in one buffer: two queues,
 * each a 4-word header {count, groups x, y, z} at word 4 * q, entries from
 * FUSION_QUEUE_ENTRIES + q * queue_cap. An entry is pixel * 4 + band point. */
#define FUSION_QUEUE_ENTRIES 8u
/* Workgroup size of the allocation passes (1-D: pixel columns in pass 0,
 * queue entries after it). llvmpipe pays about a microsecond per workgroup:
 * 64 rather than 16 saves several ms on the ~100k queued points of a
 * 640x480 frame. (The former pass 0, 4x4 pixel tiles per invocation, lost
 * a 160x120 frame's last tile row with 64; the column segments pass the
 * same test with 64.) */
#define FUSION_ALLOC_LOCAL 64u
/* Pass 0 gives each invocation a column segment of this many rows. */
#define FUSION_ALLOC_ROWS 16u

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
    bf_f32 voxel_sigmas;  /* the level rule's voxel is at least this many sigma(z) (0: the footprint alone) */
    bf_u32 max_groups_x;  /* args pass: workgroups per row of the retry pass's grid */
};
#ifndef BF_GLSL
typedef struct fusion_alloc_push fusion_alloc_push;
_Static_assert(sizeof(fusion_alloc_push) == 68, "fusion_alloc_push must match std430");
#endif

/* Push constants of fusion_window_list.comp. */
struct fusion_window_list_push {
    bf_u32 brick_cap;
    bf_u32 n_entries;  /* hash entries: a brick record's chunk below it is live */
    bf_u32 first, last; /* frame indices of the window, inclusive */
    bf_u32 n_buckets;  /* the window's slices times FUSION_SLICE_BUCKETS, <= FUSION_MAX_BUCKETS */
    bf_u32 pass;       /* FUSION_GATHER_COUNT, _PREFIX or _SCATTER */
    /* The COUNT pass also lists in the trim list the bricks stamped last
     * by frames [trim_first, trim_last] (none when trim_first > trim_last):
     * those no window integrates again, whose colour the trim pass takes
     * off where it lies past the surface (docs/colour.md). With trim_only
     * the pass does that alone. */
    bf_u32 trim_first, trim_last;
    bf_u32 trim_only;
    bf_u32 pad[3];
};
#ifndef BF_GLSL
typedef struct fusion_window_list_push fusion_window_list_push;
_Static_assert(sizeof(fusion_window_list_push) == 48, "fusion_window_list_push must match std430");
#endif

/* A window's bricks are integrated in n/2 slices, one per frame, and the
 * map the tracker sees between them holds the slices done so far: which
 * slice a brick falls in must not depend on the order in which atomics
 * hand out list places (nor on its slot, which allocation atomics choose),
 * or two runs of the same input part (docs/determinism.md). A brick's bucket
 * is a hash of what it is, its chunk and its cell; the list is gathered
 * bucket by bucket, in three passes: count per bucket, prefix sums, scatter,
 * and fusion/ cuts it into slices at bucket boundaries.
 * The bucket buffer: counts at FUSION_SLICE_COUNTS, bucket s's first list
 * place at FUSION_SLICE_STARTS + s (s = 0..n_buckets, the last is the total),
 * the scatter's cursors at FUSION_SLICE_CURSORS. */
#define FUSION_MAX_SLICES 128u
#define FUSION_SLICE_BUCKETS 64u /* hash buckets per slice: fusion/ cuts the list into slices of nearly equal size at
                                    bucket boundaries (a frame's share of the window's work stays even) */
#define FUSION_MAX_BUCKETS (FUSION_MAX_SLICES * FUSION_SLICE_BUCKETS)
#define FUSION_SLICE_COUNTS 0u
#define FUSION_SLICE_STARTS FUSION_MAX_BUCKETS
#define FUSION_SLICE_CURSORS (2u * FUSION_MAX_BUCKETS + 1u)
#define FUSION_SLICE_WORDS (3u * FUSION_MAX_BUCKETS + 1u)
#define FUSION_GATHER_COUNT 0u
#define FUSION_GATHER_PREFIX 1u
#define FUSION_GATHER_SCATTER 2u

/* The slice of the brick at pos in chunk (x, y, z): its chunk, level and
 * cell / 4 (a group of up to 4 x 4 x 4 neighbouring bricks of one level)
 * mixed by MurmurHash3's finaliser (Appleby), so the groups spread evenly.
 * Groups rather than single bricks: a region of the map becomes confident
 * together, as it did when slices were runs of the allocation order (real
 * dev frames: ATE 22.0 mm with a slice per brick, 21.4 with groups, 20.1-20.3
 * with the old racy order; docs/determinism.md). */
BF_FN bf_u32 fusion_bucket_of(bf_i32 x, bf_i32 y, bf_i32 z, bf_u32 pos, bf_u32 n_buckets)
{
    bf_u32 g = (pos & 0xFF000000u) | ((pos >> 2) & 0x003F3F3Fu); /* the level and the cell / 4 */
    bf_u32 h = (BF_U32(x) * 73856093u) ^ (BF_U32(y) * 19349669u) ^ (BF_U32(z) * 83492791u) ^ (g * 2654435761u);
    h ^= h >> 16;
    h *= 0x85ebca6bu;
    h ^= h >> 13;
    h *= 0xc2b2ae35u;
    h ^= h >> 16;
    return h % n_buckets;
}

/* Push constants of fusion_remove.comp. */
struct fusion_remove_push {
    bf_u32 first, max_count; /* the window slice just integrated */
    bf_u32 last_frame;       /* last frame of its window */
    bf_u32 has_colour;       /* 1: give a removed brick's colour units back */
};
#ifndef BF_GLSL
typedef struct fusion_remove_push fusion_remove_push;
_Static_assert(sizeof(fusion_remove_push) == 16, "fusion_remove_push must match std430");
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
#define FUSION_CNT_REMOVED 10u     /* bricks removed as empty, in all */
#define FUSION_CNT_COLOUR_TOP 11u  /* colour units on their free stack */
#define FUSION_CNT_DISPATCH 12u    /* 3 words: indirect group counts */
#define FUSION_CNT_FAIL_COLOUR 15u /* bricks whose new colours found the colour pool empty */
#define FUSION_CNT_WORDS 16u

/* ============================================================ integration
 * Windowed integration of one brick (DESIGN.md section 4; Reichl, Weiss,
 * Westermann 2016, section 4; the host side is fusion/integrate.c, the
 * kernel shaders/fusion_integrate.comp, the CPU oracle
 * tests/fusion/integrate_ref.c). The per-voxel math lives here once, so GPU and
 * CPU round every float operation the same way (BF_PRECISE: no contraction
 * or reassociation in GLSL; C builds with -ffp-contract=off by -std=c17).
 *
 * For voxel centre p (relative to the map origin) and each frame i of the
 * window still in the ring: p_c = R p + t, nearest pixel of (fx x/z + cx,
 * fy y/z + cy), d_i = raw depth * depth_unit_m (0: no sample),
 * D_i = d_i - p_c.z (positive in front of the surface), sigma_i =
 * bf_sensor_sigma(d_i), and
 *   W_i = 1,                         D_i > -2 sigma_i,
 *   W_i = (3 sigma_i + D_i)/sigma_i, -3 sigma_i < D_i <= -2 sigma_i (fade-out),
 *   W_i = 0,                         D_i <= -3 sigma_i (occluded),
 * and D_i enters the sum clamped to [-sigma_i, +sigma_i] (free space in front
 * counts as +sigma and carves).
 * Why symmetric: the depth noise is symmetric around the surface, so the
 * clamp must be too. DESIGN.md's ramp over (-sigma, 0] (whichever way it is
 * read) weighs noisy observations behind the surface less than those in
 * front and moves the sign change behind the true surface by a fraction of
 * sigma: on the synthetic room (100 frames, Kinect v1 noise) surface voxels
 * sat 5 mm below the floor and the median surface error was 9 mm; with
 * this rule the floor bias is 0.2 mm and the median error 1.95 mm
 * (docs/fusion_integrate.md). The fade-out starts at -2 sigma, where the
 * noise has 2.3% of its mass, so the bias it leaves is small.
 * D = (Psi Phi + sum W_i D_i) / (Psi + sum W_i); sign bit = D > 0, decided
 * on the numerator (the denominator is positive) without dividing. */


/* Frames one pass may look at (fusion_config.window <= 256): a workgroup
 * keeps one visibility bit per frame, and the window error's fixed-point
 * sum of 512 voxels x 256 frames x FUSION_SIGMA_UM_MAX stays below 2^32. */
#define FUSION_INTEGRATE_MAX_FRAMES 256u
#define FUSION_SIGMA_UM_MAX 32767u
/* Default prior weight Psi of a confident voxel at equal errors. */
#define FUSION_PRIOR_WEIGHT 2.0f
/* Prior distance when the sweep finds no confident voxel of the other sign
 * within FUSION_PRIOR_STEPS voxels: the bound, (steps + 1) - 1/2 voxels. */
#define FUSION_PRIOR_STEPS 3u

/* Push constants of fusion_integrate.comp and fusion_integrate_args.comp. */
struct fusion_integrate_push {
    bf_u32 first;          /* first list entry of this pass */
    bf_u32 max_count;      /* entries at most, clamped to the list's count on the GPU */
    bf_u32 frame_first;    /* sequence index of the window's first frame */
    bf_u32 n_frames;       /* frames of the window, <= FUSION_INTEGRATE_MAX_FRAMES */
    bf_u32 ring_slots;     /* frame ring slots (2n) */
    bf_u32 depth_words;    /* words per depth image in the ring: (width * height + 1) / 2 */
    bf_u32 set_confidence; /* 1: window rule; 0: sub-cache (signs of non-confident voxels only) */
    bf_u32 max_groups_x;   /* args pass: workgroups per row of the indirect grid */
    bf_f32 chunk_m;
    bf_f32 conf_weight;    /* Psi + sum W_i that makes a voxel confident */
    bf_f32 sigma_a, sigma_b, sigma_c;
    bf_f32 prior_weight;   /* Psi of a confident voxel when window and brick errors agree */
    bf_u32 bricks_per_group; /* consecutive list entries one workgroup integrates */
    bf_u32 pad;
    /* The depth ring's device address, low and high words: read through it,
     * not its binding (gpu_buffer_address; on lavapipe a load at a per-lane
     * address through a binding is a scalar loop over the lanes). */
    bf_u32 depth_addr_lo, depth_addr_hi;
    bf_u32 pad2, pad3;
};
#ifndef BF_GLSL
typedef struct fusion_integrate_push fusion_integrate_push;
_Static_assert(sizeof(fusion_integrate_push) == 80, "fusion_integrate_push must match std430");
#endif

/* One axis of a voxel centre relative to the map origin: chunk corner
 * key * chunk_m plus (cell * 8 + xyz + 1/2) voxels (fusion.h's
 * hostmap_voxel_center_w in float). */
BF_FN bf_f32 fusion_voxel_centre(bf_i32 key, bf_u32 cell, bf_u32 xyz, bf_f32 chunk_m, bf_f32 voxel_m)
{
    BF_PRECISE bf_f32 corner = BF_F32(key) * chunk_m;
    BF_PRECISE bf_f32 offset = (BF_F32(cell * 8u + xyz) + 0.5f) * voxel_m;
    BF_PRECISE bf_f32 p = corner + offset;
    return p;
}

/* A point in camera coordinates. */
struct fusion_point {
    bf_f32 x, y, z;
};
#ifndef BF_GLSL
typedef struct fusion_point fusion_point;
#endif

/* p_c = R p + t of the frame record (map to camera), summed left to right. */
BF_FN fusion_point fusion_to_camera(fusion_frame f, bf_f32 px, bf_f32 py, bf_f32 pz)
{
    BF_PRECISE bf_f32 x = f.R[0] * px + f.R[1] * py + f.R[2] * pz + f.t[0];
    BF_PRECISE bf_f32 y = f.R[3] * px + f.R[4] * py + f.R[5] * pz + f.t[1];
    BF_PRECISE bf_f32 z = f.R[6] * px + f.R[7] * py + f.R[8] * pz + f.t[2];
    fusion_point c;
    c.x = x;
    c.y = y;
    c.z = z;
    return c;
}

/* Row-major index of the pixel nearest to the projection of camera point c
 * (pixel centres at integers: floor(u + 1/2)), or FUSION_NONE when c is not
 * in front of the camera (z <= 0) or falls outside the image. NaN
 * coordinates fail every comparison and give FUSION_NONE. */
BF_FN bf_u32 fusion_project_pixel(fusion_frame f, fusion_point c)
{
    if (!(c.z > 0.0f)) return FUSION_NONE;
    BF_PRECISE bf_f32 u = f.fx * c.x / c.z + f.cx + 0.5f;
    BF_PRECISE bf_f32 v = f.fy * c.y / c.z + f.cy + 0.5f;
    if (!(u >= 0.0f && v >= 0.0f && u < BF_F32(f.width) && v < BF_F32(f.height))) return FUSION_NONE;
    return BF_TRUNC_U32(v) * f.width + BF_TRUNC_U32(u); /* truncation is floor for u, v >= 0 */
}

/* Incremental voxel stepping (the integration kernel and its oracle). For a
 * (brick, frame) pair the voxel centres are p0 + (x, y, z) voxel_m, so their
 * pixel-scaled camera points h = (fx X + (cx + 1/2) Z, fy Y + (cy + 1/2) Z, Z)
 * (X, Y, Z = R p + t) are affine in (x, y, z): h = h0 + x sx + y sy + z sz.
 * fusion_step_make computes h0 (fusion_to_camera of the first voxel centre,
 * then K) and the steps (K times R's columns times voxel_m) once per pair;
 * fusion_step_point then costs 3 multiplies and 3 adds per axis term, and
 * fusion_project_step divides h.x and h.y by h.z (u and v already include
 * the + 1/2 of the nearest pixel). Both sides evaluate exactly these
 * expressions in this order, so they round identically; against the direct
 * R p + t of each centre the point moves by a few float ulps of the
 * coordinates (~1e-6 m, ~1e-4 px), far below the sensor noise. */
struct fusion_step {
    fusion_point h0, sx, sy, sz;
};
#ifndef BF_GLSL
typedef struct fusion_step fusion_step;
#endif

BF_FN fusion_point fusion_step_axis(fusion_frame f, bf_f32 rx, bf_f32 ry, bf_f32 rz)
{
    BF_PRECISE bf_f32 ku = f.cx + 0.5f;
    BF_PRECISE bf_f32 kv = f.cy + 0.5f;
    BF_PRECISE bf_f32 hx = f.fx * rx + ku * rz;
    BF_PRECISE bf_f32 hy = f.fy * ry + kv * rz;
    fusion_point h;
    h.x = hx;
    h.y = hy;
    h.z = rz;
    return h;
}

BF_FN fusion_step fusion_step_make(fusion_frame f, bf_f32 p0x, bf_f32 p0y, bf_f32 p0z, bf_f32 voxel_m)
{
    fusion_point c0 = fusion_to_camera(f, p0x, p0y, p0z);
    fusion_step s;
    s.h0 = fusion_step_axis(f, c0.x, c0.y, c0.z);
    BF_PRECISE bf_f32 r0x = f.R[0] * voxel_m, r0y = f.R[3] * voxel_m, r0z = f.R[6] * voxel_m;
    BF_PRECISE bf_f32 r1x = f.R[1] * voxel_m, r1y = f.R[4] * voxel_m, r1z = f.R[7] * voxel_m;
    BF_PRECISE bf_f32 r2x = f.R[2] * voxel_m, r2y = f.R[5] * voxel_m, r2z = f.R[8] * voxel_m;
    s.sx = fusion_step_axis(f, r0x, r0y, r0z);
    s.sy = fusion_step_axis(f, r1x, r1y, r1z);
    s.sz = fusion_step_axis(f, r2x, r2y, r2z);
    return s;
}

/* h of voxel (x, y, z): ((h0 + x sx) + z sz) + y sy, per axis. */
BF_FN bf_f32 fusion_step_coord(bf_f32 h0, bf_f32 sx, bf_f32 sy, bf_f32 sz, bf_u32 x, bf_u32 y, bf_u32 z)
{
    BF_PRECISE bf_f32 a = h0 + BF_F32(x) * sx;
    BF_PRECISE bf_f32 b = a + BF_F32(z) * sz;
    BF_PRECISE bf_f32 h = b + BF_F32(y) * sy;
    return h;
}

BF_FN fusion_point fusion_step_point(fusion_step s, bf_u32 x, bf_u32 y, bf_u32 z)
{
    fusion_point h;
    h.x = fusion_step_coord(s.h0.x, s.sx.x, s.sy.x, s.sz.x, x, y, z);
    h.y = fusion_step_coord(s.h0.y, s.sx.y, s.sy.y, s.sz.y, x, y, z);
    h.z = fusion_step_coord(s.h0.z, s.sx.z, s.sy.z, s.sz.z, x, y, z);
    return h;
}

/* Row-major index of the pixel nearest to the pixel-scaled point h (u =
 * h.x / h.z, v = h.y / h.z, floor), or FUSION_NONE when h.z <= 0, outside
 * the image, or NaN: fusion_project_pixel's rule on stepped points. */
BF_FN bf_u32 fusion_project_step(fusion_point h, bf_u32 width, bf_u32 height)
{
    if (!(h.z > 0.0f)) return FUSION_NONE;
    BF_PRECISE bf_f32 u = h.x / h.z;
    BF_PRECISE bf_f32 v = h.y / h.z;
    if (!(u >= 0.0f && v >= 0.0f && u < BF_F32(width) && v < BF_F32(height))) return FUSION_NONE;
    return BF_TRUNC_U32(v) * width + BF_TRUNC_U32(u);
}

/* Raw 16-bit depth of pixel i of a ring image, from its word (two pixels
 * per word, low half first). */
BF_FN bf_u32 fusion_depth_raw(bf_u32 word, bf_u32 pixel) { return (pixel & 1u) != 0u ? word >> 16 : word & 0xFFFFu; }

/* One frame's observation of one voxel: weight W_i, W_i * D_i (D_i clamped
 * to +sigma in front) and sigma_i; all 0 when the sample is invalid or the
 * voxel is occluded (W_i = 0). */
struct fusion_obs {
    bf_f32 w, wd, sigma;
};
#ifndef BF_GLSL
typedef struct fusion_obs fusion_obs;
#endif

BF_FN fusion_obs fusion_observe(bf_u32 raw, bf_f32 depth_unit_m, bf_f32 z, bf_f32 a, bf_f32 b, bf_f32 c)
{
    fusion_obs o;
    o.w = 0.0f;
    o.wd = 0.0f;
    o.sigma = 0.0f;
    if (raw == 0u) return o;
    BF_PRECISE bf_f32 d = BF_F32(raw) * depth_unit_m;
    BF_PRECISE bf_f32 sigma = bf_sensor_sigma(d, a, b, c);
    BF_PRECISE bf_f32 dist = d - z;
    if (!(sigma > 0.0f) || !(dist > -3.0f * sigma)) return o; /* occluded (or NaN) */
    BF_PRECISE bf_f32 dc = dist < sigma ? (dist > -sigma ? dist : -sigma) : sigma;
    if (dist > -2.0f * sigma) {
        o.w = 1.0f;
        o.wd = dc;
    } else {
        /* Fade-out of the occluded side: 1 at -2 sigma, 0 at -3 sigma. */
        BF_PRECISE bf_f32 w = (3.0f * sigma + dist) / sigma;
        BF_PRECISE bf_f32 wd = w * dc;
        o.w = w;
        o.wd = wd;
    }
    o.sigma = sigma;
    return o;
}

/* A voxel's sums over the window, in frame order: sum W_i, sum W_i D_i,
 * the number of frames with W_i > 0 and their sigma_i in micrometres (an
 * integer, so the per-brick error sums the same in any order). */
struct fusion_acc {
    bf_f32 sum_w, sum_wd;
    bf_u32 n, sigma_um;
};
#ifndef BF_GLSL
typedef struct fusion_acc fusion_acc;
#endif

BF_FN fusion_acc fusion_acc_zero(void)
{
    fusion_acc a;
    a.sum_w = 0.0f;
    a.sum_wd = 0.0f;
    a.n = 0u;
    a.sigma_um = 0u;
    return a;
}

/* sigma in whole micrometres, capped at FUSION_SIGMA_UM_MAX (33 mm: the
 * Kinect v1 sigma at 4.4 m). */
BF_FN bf_u32 fusion_sigma_um(bf_f32 sigma)
{
    BF_PRECISE bf_f32 um = sigma * 1.0e6f + 0.5f;
    return um < BF_F32(FUSION_SIGMA_UM_MAX) ? BF_TRUNC_U32(um) : FUSION_SIGMA_UM_MAX;
}

BF_FN fusion_acc fusion_acc_add(fusion_acc a, fusion_obs o)
{
    if (!(o.w > 0.0f)) return a;
    BF_PRECISE bf_f32 sw = a.sum_w + o.w;
    BF_PRECISE bf_f32 swd = a.sum_wd + o.wd;
    a.sum_w = sw;
    a.sum_wd = swd;
    a.n += 1u;
    a.sigma_um += fusion_sigma_um(o.sigma);
    return a;
}

/* The window's error for a brick: mean sigma over its (voxel, frame) pairs
 * with W > 0 [m], by integer division of the fixed-point sum (exact on both
 * sides); 0 when there is none. */
BF_FN bf_f32 fusion_window_error(bf_u32 n_pairs, bf_u32 sigma_um_sum)
{
    if (n_pairs == 0u) return 0.0f;
    BF_PRECISE bf_f32 e = BF_F32(sigma_um_sum / n_pairs) * 1.0e-6f;
    return e;
}

/* The prior's sweep. row_x holds the bits of voxels (0..7, y, z) that are
 * confident and of the other sign than voxel (x, y, z), row_y those of
 * (x, 0..7, z), row_z those of (x, y, 0..7). Returns the fewest steps
 * (1..FUSION_PRIOR_STEPS) along +-x, +-y, +-z to such a voxel, or
 * FUSION_PRIOR_STEPS + 1 when there is none within the brick. */
BF_FN bf_u32 fusion_prior_steps(bf_u32 row_x, bf_u32 row_y, bf_u32 row_z, bf_u32 x, bf_u32 y, bf_u32 z)
{
    for (bf_u32 k = 1u; k <= FUSION_PRIOR_STEPS; k++) {
        bf_u32 hit = 0u;
        if (x + k < 8u) hit |= (row_x >> (x + k)) & 1u;
        if (x >= k) hit |= (row_x >> (x - k)) & 1u;
        if (y + k < 8u) hit |= (row_y >> (y + k)) & 1u;
        if (y >= k) hit |= (row_y >> (y - k)) & 1u;
        if (z + k < 8u) hit |= (row_z >> (z + k)) & 1u;
        if (z >= k) hit |= (row_z >> (z - k)) & 1u;
        if (hit != 0u) return k;
    }
    return FUSION_PRIOR_STEPS + 1u;
}

/* Prior distance Phi of a confident voxel: its sign (front +, behind -)
 * times the distance to the sign change, which lies halfway between its
 * centre and the nearest confident voxel of the other sign: (steps - 1/2)
 * voxels; with none in reach, the bound (FUSION_PRIOR_STEPS + 1/2).
 * Truncated at band_m (the window's error, when known): observations count
 * at most +sigma in front, so an untruncated prior of 3.5 voxels, many
 * sigmas at fine levels, would outvote any window. */
BF_FN bf_f32 fusion_prior_phi(bf_u32 is_front, bf_u32 steps, bf_f32 voxel_m, bf_f32 band_m)
{
    BF_PRECISE bf_f32 dist = (BF_F32(steps) - 0.5f) * voxel_m;
    if (band_m > 0.0f && dist > band_m) dist = band_m;
    return is_front != 0u ? dist : -dist;
}

/* Prior weight Psi of a confident voxel: prior_weight scaled by how much
 * better the brick's stored error is than this window's,
 * clamp(window_err / brick_err, 1/4, 4); unscaled when either error is
 * unknown (0, infinite or NaN on the brick's side). */
BF_FN bf_f32 fusion_prior_psi(bf_f32 prior_weight, bf_f32 window_err, bf_f32 brick_err)
{
    BF_PRECISE bf_f32 ratio = 1.0f;
    if (window_err > 0.0f && brick_err > 0.0f && brick_err < 3.0e38f) {
        BF_PRECISE bf_f32 r = window_err / brick_err;
        ratio = r < 0.25f ? 0.25f : (r > 4.0f ? 4.0f : r);
    }
    BF_PRECISE bf_f32 psi = prior_weight * ratio;
    return psi;
}

/* May this window overwrite the brick's confident voxels? Only when it is
 * the window rule (set_confidence), and the brick has no confident voxel or
 * the window's error is not above the brick's stored one (Reichl 2016: a
 * confident voxel is replaced only by a confident one from a window with a
 * lower average error). */
BF_FN bf_u32 fusion_may_replace(bf_u32 set_confidence, bf_u32 has_confident, bf_f32 window_err, bf_f32 brick_err)
{
    if (set_confidence == 0u) return 0u;
    return (has_confident == 0u || !(window_err > brick_err)) ? 1u : 0u;
}

/* Bits of fusion_decide's result. */
#define FUSION_DECIDE_SIGN 1u     /* the voxel's sign bit */
#define FUSION_DECIDE_CONF 2u     /* its confidence bit */
#define FUSION_DECIDE_SET 4u      /* this window set the confidence (the brick's error follows it) */

/* The voxel's new bits from its old ones and its window sums.
 * - Confident voxel: replaced (sign, stays confident) only when may_replace
 *   and the result is itself confident, psi + sum W >= conf_weight; kept
 *   otherwise, and always in the sub-cache pass.
 * - Other voxels: unchanged without an observation (sum W = 0); else the
 *   sign of the numerator, confident when set_confidence and
 *   psi + sum W >= conf_weight.
 * psi and phi are 0 for a voxel that is not confident. */
BF_FN bf_u32 fusion_decide(bf_u32 old_sign, bf_u32 old_conf, fusion_acc a, bf_f32 psi, bf_f32 phi,
                           bf_f32 conf_weight, bf_u32 set_confidence, bf_u32 may_replace)
{
    BF_PRECISE bf_f32 num = psi * phi + a.sum_wd;
    BF_PRECISE bf_f32 den = psi + a.sum_w;
    bf_u32 sign = num > 0.0f ? FUSION_DECIDE_SIGN : 0u;
    bf_u32 confident = (set_confidence != 0u && a.n > 0u && den >= conf_weight) ? 1u : 0u;
    if (old_conf != 0u) {
        if (may_replace != 0u && confident != 0u) return sign | FUSION_DECIDE_CONF | FUSION_DECIDE_SET;
        return (old_sign != 0u ? FUSION_DECIDE_SIGN : 0u) | FUSION_DECIDE_CONF;
    }
    if (a.n == 0u) return old_sign != 0u ? FUSION_DECIDE_SIGN : 0u;
    return confident != 0u ? sign | FUSION_DECIDE_CONF | FUSION_DECIDE_SET : sign;
}

/* Culling of a (brick, frame) pair (DESIGN.md section 11), before the
 * per-voxel loop: 1 when no voxel centre of the box [lo, hi] (the centres of
 * the brick's first and last voxels) can land on a pixel: all 8 corners
 * behind the camera plane, or all beyond one image edge by more than a
 * pixel. The tests are half-spaces in camera coordinates (u < -1.5 is
 * fx x + (cx + 1.5) z < 0 for z > 0), so every centre, a convex combination
 * of the corners, is on the same side: a culled frame would have given each
 * voxel W = 0, and culling changes no bit. The pixel of margin covers the
 * rounding of corners against centres. */
BF_FN bf_u32 fusion_box_culled(fusion_frame f, bf_f32 lo_x, bf_f32 lo_y, bf_f32 lo_z, bf_f32 hi_x, bf_f32 hi_y,
                               bf_f32 hi_z)
{
    bf_u32 outside = 31u; /* bit per half-space: behind, left, right, top, bottom */
    for (bf_u32 k = 0u; k < 8u; k++) {
        fusion_point c = fusion_to_camera(f, (k & 1u) != 0u ? hi_x : lo_x, (k & 2u) != 0u ? hi_y : lo_y,
                                          (k & 4u) != 0u ? hi_z : lo_z);
        BF_PRECISE bf_f32 left = f.fx * c.x + (f.cx + 1.5f) * c.z;
        BF_PRECISE bf_f32 right = f.fx * c.x + (f.cx - BF_F32(f.width) - 0.5f) * c.z;
        BF_PRECISE bf_f32 top = f.fy * c.y + (f.cy + 1.5f) * c.z;
        BF_PRECISE bf_f32 bottom = f.fy * c.y + (f.cy - BF_F32(f.height) - 0.5f) * c.z;
        bf_u32 o = (c.z <= 0.0f ? 1u : 0u) | (left < 0.0f ? 2u : 0u) | (right > 0.0f ? 4u : 0u) |
                   (top < 0.0f ? 8u : 0u) | (bottom > 0.0f ? 16u : 0u);
        outside &= o;
    }
    return outside != 0u ? 1u : 0u;
}

/* ============================================================ colour
 * Colour of the confident voxels at the surface (DESIGN.md section 3;
 * Reichl's dissertation, ch. 8), addressed by popcount:
 * - colour masks: per 32-bit sub-brick (a word of the bit planes) one word,
 *   bit i set when voxel bit i of the sub-brick has a colour; one word per
 *   32 voxels, the method's one bit per voxel for the pointer;
 * - colour head: per brick slot the first unit of its colours, or
 *   FUSION_NONE;
 * - colour units: 8 words, word 0 the next unit of the brick (FUSION_NONE
 *   ends the chain), words 1..7 fourteen RGB565 colours, two per word, the
 *   low half first. The brick's coloured voxels, in the order (sub-brick,
 *   bit), take consecutive colours along the chain: colour r of the brick
 *   is colour r % 14 of its unit r / 14.
 * So colour costs 16 bits only where a voxel has one (plus an eighth for
 * the links and half a unit per brick), not a 32-colour block per touched
 * sub-brick (8.5 bits per allocated voxel before, on the room test).
 * RGB565 0 means "no colour"; black is stored as 0x0001.
 *
 * Units come off a free stack (FUSION_CNT_COLOUR_TOP): the colour pass
 * pops, the removal pass and eviction push, never in the same dispatch, so
 * neither spins (the dissertation's page allocation spins on lockstep
 * warps, which Vulkan does not promise). A brick's chain only grows while
 * the brick lives (a unit it no longer needs stays linked for later). */
#define FUSION_COLOUR_UNIT_WORDS 8u
#define FUSION_COLOUR_UNIT_COLOURS 14u
/* Units of a brick whose 512 voxels all have colour: ceil(512 / 14). */
#define FUSION_COLOUR_MAX_UNITS 37u
#define FUSION_COLOUR_NONE 0u
/* Frames of a window the colour pass reads at most. */
#define FUSION_COLOUR_MAX_FRAMES 32u
/* Half-thickness of the coloured shell around the surface, in voxels:
 * the mean of D over the colour samples (weighted as they are) must be
 * below it. 0.5 keeps about one voxel across a surface (docs/colour.md). */
#define FUSION_COLOUR_SHELL 0.5f
/* The colour pass's modes (fusion_colour_push.mode): a window slice's
 * colours, or the trim of bricks no window integrates again. */
#define FUSION_COLOUR_MODE_FRAMES 0u
#define FUSION_COLOUR_MODE_TRIM 1u
/* Workgroup of the colour pass: 64 invocations, 8 voxels each (the trim's
 * surface_mask maps them onto a face's 8 x 8 voxels). */
#define FUSION_COLOUR_LOCAL 64u
#ifndef BF_GLSL
_Static_assert(FUSION_COLOUR_LOCAL == 64u, "fusion_colour.comp's trim reads a brick face with one invocation a voxel");
#endif

/* RGB565 of a colour in [0, 255] per channel (rounded; black -> 0x0001). */
BF_FN bf_u32 fusion_rgb565(bf_f32 r, bf_f32 g, bf_f32 b)
{
    BF_PRECISE bf_f32 rr = r * (31.0f / 255.0f) + 0.5f;
    BF_PRECISE bf_f32 gg = g * (63.0f / 255.0f) + 0.5f;
    BF_PRECISE bf_f32 bb = b * (31.0f / 255.0f) + 0.5f;
    bf_u32 ri = rr < 31.0f ? (rr > 0.0f ? BF_TRUNC_U32(rr) : 0u) : 31u;
    bf_u32 gi = gg < 63.0f ? (gg > 0.0f ? BF_TRUNC_U32(gg) : 0u) : 63u;
    bf_u32 bi = bb < 31.0f ? (bb > 0.0f ? BF_TRUNC_U32(bb) : 0u) : 31u;
    bf_u32 c = (ri << 11) | (gi << 5) | bi;
    return c != 0u ? c : 1u;
}
/* Push constants of fusion_colour.comp. The colour camera: intrinsics,
 * Brown-Conrady distortion and T_colour_depth (rotation as a unit
 * quaternion, t), or registered != 0 when colour pixel i shows what depth
 * pixel i measured (TUM, registered Kinect modes). */
struct fusion_colour_push {
    bf_u32 first, max_count;  /* the window slice's list entries */
    bf_u32 frame_first;       /* first frame the pass reads */
    bf_u32 n_frames;          /* frames it reads, <= FUSION_COLOUR_MAX_FRAMES */
    bf_u32 frame_stride;      /* frames frame_first + k * stride */
    bf_u32 ring_slots;
    bf_u32 depth_words;       /* words per image in the depth and colour rings */
    bf_u32 registered;
    bf_f32 chunk_m;
    bf_f32 sigma_a, sigma_b, sigma_c;
    bf_f32 cfx, cfy, ccx, ccy;
    bf_f32 q[4];              /* x y z w */
    bf_f32 t[3];
    bf_f32 dist[5];           /* k1 k2 p1 p2 k3, OpenCV's order */
    bf_u32 bricks_per_group;  /* consecutive list entries one workgroup colours */
    bf_u32 n_buckets;         /* the hash's modulus and overflow (the trim's neighbouring bricks) */
    bf_u32 n_overflow;
    bf_u32 mode;              /* FUSION_COLOUR_MODE_* | reach << 8: the trim keeps colour within L1
                               * distance `reach` (1 or 2) of a confident voxel of the other sign */
};
#ifndef BF_GLSL
typedef struct fusion_colour_push fusion_colour_push;
_Static_assert(sizeof(fusion_colour_push) == 128, "fusion_colour_push must match std430");
#endif

/* Weight of one frame's colour sample of a voxel: the cosine between the
 * viewing ray and the surface normal (from the depth image) over the
 * squared depth (grazing views smear texture, far ones blur it);
 * InfiniTAM and ElasticFusion weigh colour by the same two factors. */
BF_FN bf_f32 fusion_colour_weight(bf_f32 cos_view, bf_f32 depth_m)
{
    BF_PRECISE bf_f32 w = cos_view / (depth_m * depth_m);
    return w;
}

#endif
