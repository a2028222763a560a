#version 450
/* Brick allocation (DESIGN.md section 3). Each depth sample has three points
 * along its ray, at -band, 0 and +band sigma(z) around the measured depth,
 * so the voxels on both sides of the surface get bricks. Pass 0 computes
 * every point's cell (chunk, cell at the level matching the sample's pixel
 * footprint) and queues only the points whose cell differs from those of
 * the neighbours before it; the later passes, one invocation per queued
 * point, do the chunk hash lookup / insertion, the octree descent (creating
 * nodes) and the brick allocation. Split so, every lane of a SIMD group does
 * the same work (llvmpipe runs 8 lanes in lockstep; a descent done for any
 * lane costs all of them), and there are about four descents per brick
 * instead of three per pixel (about 120k points instead of 920k for a
 * 640x480 frame of 28k bricks).
 *
 * Contention never spins (no forward-progress guarantee; lavapipe runs
 * subgroups of 8): whoever wins a lock (bucket word, or CAS of a node field
 * from NONE to LOCKED) does the work; losers queue the point for the next
 * pass, which sees the finished result. Bucket locks are cleared by the host
 * before every pass. A point that loses at most once per level finishes
 * within max_level + 2 insertion passes. */
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_shuffle_relative : require
#include "fusion.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

layout(std430, binding = 0) coherent buffer Hash { uint w[]; } hash;
layout(std430, binding = 1) coherent buffer Locks { uint w[]; } locks;
layout(std430, binding = 2) buffer Nodes { uint w[]; } nodes;
layout(std430, binding = 3) buffer Info { uint w[]; } info;
layout(std430, binding = 4) coherent buffer Counters { uint w[]; } cnt;
layout(std430, binding = 5) buffer FreeStack { uint w[]; } free_stack;
layout(std430, binding = 6) buffer Stamp { uint w[]; } stamp;
layout(std430, binding = 7) readonly buffer Frames { fusion_frame f[]; } frames;
layout(std430, binding = 8) readonly buffer DepthRing { uint w[]; } depth;
layout(std430, binding = 9) buffer Queue { uint w[]; } queue;
layout(std430, binding = 10) buffer NewList { uint w[]; } new_list;

layout(push_constant) uniform Push { fusion_alloc_push pc; };

/* Queues the point for the next pass. */
void retry(uint item)
{
    uint q = pc.pass % 2u; /* pass p reads queue (p - 1) % 2 and writes p % 2 */
    uint i = atomicAdd(queue.w[4u * q], 1u);
    if (i < pc.queue_cap) queue.w[FUSION_QUEUE_ENTRIES + q * pc.queue_cap + i] = item;
}

uint fusion_hash_word(uint i) { return hash.w[i]; }
#include "fusion_hash.glsl.h"

/* Inserts the chunk; the caller holds the bucket's lock for this pass, so
 * nobody else writes this bucket's slots or chain. FUSION_NONE if a pool
 * is full (counted). */
uint insert_chunk(uint bucket, ivec3 key)
{
    uint first = bucket * FUSION_BUCKET_SLOTS, e = FUSION_NONE;
    for (uint k = 0u; k < FUSION_BUCKET_SLOTS && e == FUSION_NONE; k++)
        if (hash.w[(first + k) * FUSION_ENTRY_WORDS + FUSION_ENTRY_STATE] == FUSION_ENTRY_FREE) e = first + k;
    uint root = atomicAdd(cnt.w[FUSION_CNT_NODES], 1u);
    if (root >= pc.node_cap) {
        atomicAdd(cnt.w[FUSION_CNT_FAIL_NODES], 1u);
        return FUSION_NONE;
    }
    if (e == FUSION_NONE) {
        uint idx = atomicAdd(cnt.w[FUSION_CNT_OVERFLOW], 1u);
        if (idx >= pc.n_overflow) {
            atomicAdd(cnt.w[FUSION_CNT_FAIL_HASH], 1u);
            return FUSION_NONE; /* the root node stays unused: counted in nodes, harmless */
        }
        e = pc.n_buckets * FUSION_BUCKET_SLOTS + idx;
        hash.w[e * FUSION_ENTRY_WORDS + FUSION_ENTRY_NEXT] = FUSION_NONE;
    }
    uint base = e * FUSION_ENTRY_WORDS;
    hash.w[base + FUSION_ENTRY_X] = uint(key.x);
    hash.w[base + FUSION_ENTRY_Y] = uint(key.y);
    hash.w[base + FUSION_ENTRY_Z] = uint(key.z);
    hash.w[base + FUSION_ENTRY_ROOT] = root;
    if (e >= pc.n_buckets * FUSION_BUCKET_SLOTS) { /* link at the end of the bucket's chain */
        uint link = (first + FUSION_BUCKET_SLOTS - 1u) * FUSION_ENTRY_WORDS + FUSION_ENTRY_NEXT;
        while (hash.w[link] != FUSION_NONE) link = hash.w[link] * FUSION_ENTRY_WORDS + FUSION_ENTRY_NEXT;
        memoryBarrierBuffer(); /* publish the entry before it becomes reachable */
        hash.w[link] = e;
    }
    memoryBarrierBuffer(); /* key and root before the state that makes them valid */
    atomicExchange(hash.w[base + FUSION_ENTRY_STATE], FUSION_ENTRY_VALID);
    return e;
}

/* Takes a brick slot off the free stack; FUSION_NONE when empty. */
uint pop_brick()
{
    int old = int(atomicAdd(cnt.w[FUSION_CNT_FREE_TOP], 0xFFFFFFFFu));
    if (old <= 0) {
        atomicAdd(cnt.w[FUSION_CNT_FREE_TOP], 1u);
        return FUSION_NONE;
    }
    return free_stack.w[old - 1];
}

/* Creates the brick of node (owner of cell at level) or stamps the existing one. */
void touch_brick(uint node, uint entry, uvec3 cell, uint level)
{
    uint f = node * FUSION_NODE_WORDS + FUSION_NODE_BRICK;
    uint b = nodes.w[f];
    if (b == FUSION_LOCKED) return; /* being created in this pass: its creator stamps it */
    if (b != FUSION_NONE) {
        stamp.w[b] = pc.frame_index;
        return;
    }
    if (atomicCompSwap(nodes.w[f], FUSION_NONE, FUSION_LOCKED) != FUSION_NONE) return;
    b = pop_brick();
    if (b == FUSION_NONE) {
        atomicAdd(cnt.w[FUSION_CNT_FAIL_BRICKS], 1u);
        atomicExchange(nodes.w[f], FUSION_NONE);
        return;
    }
    uint base = b * FUSION_BRICK_INFO_WORDS;
    info.w[base + FUSION_INFO_CHUNK] = entry;
    info.w[base + FUSION_INFO_POS] = fusion_pack_pos(cell.x, cell.y, cell.z, level);
    info.w[base + FUSION_INFO_NODE] = node;
    info.w[base + FUSION_INFO_ERROR] = floatBitsToUint(1.0 / 0.0); /* no window has set it yet */
    stamp.w[b] = pc.frame_index;
    atomicAdd(cnt.w[FUSION_CNT_BRICKS], 1u);
    atomicAdd(cnt.w[FUSION_CNT_NEW], 1u);
    uint i = atomicAdd(new_list.w[0], 1u);
    new_list.w[4u + i] = b; /* the list holds brick_cap entries: never overflows */
    memoryBarrierBuffer(); /* the record before the node points at it */
    atomicExchange(nodes.w[f], b);
}

/* The chunk of map point p and its cell at level inside the chunk. */
void locate(vec3 p, uint level, out ivec3 key, out uvec3 cell)
{
    key = BF_TRUNC_I32(floor(p * (1.0 / pc.chunk_m)));
    vec3 q = p - vec3(key) * pc.chunk_m; /* chunk-local, in [0, chunk_m) up to rounding */
    float cells_per_m = float(1u << level) / pc.chunk_m; /* level-`level` cells per metre */
    cell = uvec3(clamp(BF_TRUNC_I32(floor(q * cells_per_m)), ivec3(0), ivec3((1 << level) - 1)));
}

/* Inserts the brick of cell at level in chunk key; false if it must be
 * retried. */
bool insert_cell(ivec3 key, uvec3 cell, uint level)
{
    uint bucket = fusion_hash(key.x, key.y, key.z, pc.n_buckets);
    uint entry = fusion_find_in_bucket(bucket, key.x, key.y, key.z, pc.n_overflow);
    if (entry == FUSION_NONE) {
        if (atomicCompSwap(locks.w[bucket], 0u, 1u) != 0u) return false;
        entry = insert_chunk(bucket, key);
        if (entry == FUSION_NONE) return true; /* pool full: dropped and counted */
    }
    uint node = hash.w[entry * FUSION_ENTRY_WORDS + FUSION_ENTRY_ROOT];
    for (uint l = 1u; l <= level; l++) {
        uint f = node * FUSION_NODE_WORDS + FUSION_NODE_CHILD;
        uint child = nodes.w[f];
        if (child == FUSION_LOCKED) return false;
        if (child == FUSION_NONE) {
            if (atomicCompSwap(nodes.w[f], FUSION_NONE, FUSION_LOCKED) != FUSION_NONE) return false;
            child = atomicAdd(cnt.w[FUSION_CNT_NODES], 8u);
            if (child + 8u > pc.node_cap) {
                atomicAdd(cnt.w[FUSION_CNT_FAIL_NODES], 1u);
                atomicExchange(nodes.w[f], FUSION_NONE);
                return true;
            }
            /* The pool is pre-filled with FUSION_NONE: the 8 children need no
             * initialisation before they become reachable. */
            atomicExchange(nodes.w[f], child);
        }
        uint sh = level - l;
        node = child + fusion_octant(cell.x >> sh, cell.y >> sh, cell.z >> sh);
    }
    touch_brick(node, entry, cell, level);
    return true;
}

uint depth_raw(uint slot, uint pixel, uint n_pixels)
{
    uint words = (n_pixels + 1u) / 2u;
    uint w = depth.w[slot * words + pixel / 2u];
    return (pixel & 1u) == 0u ? (w & 0xFFFFu) : (w >> 16);
}

/* The frame's camera, read once per invocation. */
uint g_width, g_n_pixels;
float g_unit, g_cx, g_cy, g_inv_fx, g_inv_fy, g_inv_abs_fx;

void load_camera(fusion_frame fr)
{
    g_width = fr.width;
    g_n_pixels = fr.width * fr.height;
    g_unit = fr.depth_unit_m;
    g_cx = fr.cx;
    g_cy = fr.cy;
    g_inv_fx = 1.0 / fr.fx;
    g_inv_fy = 1.0 / fr.fy;
    g_inv_abs_fx = 1.0 / abs(fr.fx);
}

/* A depth sample as the allocation sees it: the map point at depth 1 along
 * its ray is o + d, band point k sits at o + z_k d. */
struct sample_ray {
    vec3 d;       /* ray direction in the map frame, scaled to unit camera z */
    float z;      /* measured depth [m] */
    float band;   /* band_sigmas * sigma(z) */
    uint level;   /* octree level of the sample */
};

/* The sample of pixel (x, y); false when the pixel has no usable depth. Rt
 * is R^T of the frame's map-to-camera transform. */
bool sample_at(mat3 Rt, uint x, uint y, out sample_ray s)
{
    s.z = float(depth_raw(pc.slot, y * g_width + x, g_n_pixels)) * g_unit;
    s.d = vec3(0.0);
    s.band = 0.0;
    s.level = 0u;
    if (!(s.z > 0.0) || s.z > pc.max_depth_m) return false;
    float sigma = bf_sensor_sigma(s.z, pc.sigma_a, pc.sigma_b, pc.sigma_c);
    s.band = pc.band_sigmas * sigma;
    s.level = fusion_level_for_footprint(fusion_level_size(s.z, g_inv_abs_fx, pc.voxel_ratio, pc.voxel_sigmas, sigma),
                                         pc.chunk_m, pc.max_level);
    s.d = Rt * vec3((float(x) - g_cx) * g_inv_fx, (float(y) - g_cy) * g_inv_fy, 1.0);
    return true;
}

/* Band point k (0, 1, 2: -band, 0, +band) of a sample; false when it lies
 * behind the camera. */
bool band_point(sample_ray sr, uint k, out float zk)
{
    zk = sr.z + (float(k) - 1.0) * sr.band;
    return zk > 0.0;
}

/* A band point's brick: its chunk key and fusion_pack_pos(cell, level);
 * pos = FUSION_NONE when there is no point (no depth, or behind the
 * camera). No real pos equals FUSION_NONE (level <= 8). */
struct cell_id {
    ivec3 key;
    uint pos;
};

cell_id point_cell(vec3 o, sample_ray sr, bool ok, uint k)
{
    cell_id c;
    c.key = ivec3(0);
    c.pos = FUSION_NONE;
    float zk;
    if (!ok || !band_point(sr, k, zk)) return c;
    uvec3 cell;
    locate(o + zk * sr.d, sr.level, c.key, cell);
    c.pos = fusion_pack_pos(cell.x, cell.y, cell.z, sr.level);
    return c;
}

bool same_cell(cell_id a, cell_id b) { return a.pos == b.pos && all(equal(a.key, b.key)); }

/* The three band cells of pixel (x, y). */
void pixel_cells(mat3 Rt, vec3 o, uint x, uint y, out cell_id c0, out cell_id c1, out cell_id c2)
{
    sample_ray sr;
    bool ok = sample_at(Rt, x, y, sr);
    c0 = point_cell(o, sr, ok, 0u);
    c1 = point_cell(o, sr, ok, 1u);
    c2 = point_cell(o, sr, ok, 2u);
}

/* Is the point c a repeat of one of the three cells a0..a2 (a neighbour's)? */
bool in3(cell_id c, cell_id a0, cell_id a1, cell_id a2)
{
    return same_cell(c, a0) || same_cell(c, a1) || same_cell(c, a2);
}

/* The cell of the lane to the left in the subgroup (undefined in lane 0). */
cell_id from_left(cell_id c)
{
    cell_id l;
    l.key = subgroupShuffleUp(c.key, 1u);
    l.pos = subgroupShuffleUp(c.pos, 1u);
    return l;
}

/* Pass 0 queues band point k of pixel unless it repeats an earlier point:
 * one of the same pixel (repeat: a smaller k), of the left, upper or upper
 * left pixel. */
void queue_new(cell_id c, bool repeat, uint pixel, uint k, cell_id l0, cell_id l1, cell_id l2, cell_id u0, cell_id u1,
               cell_id u2, cell_id ul0, cell_id ul1, cell_id ul2)
{
    if (c.pos == FUSION_NONE || repeat || in3(c, l0, l1, l2) || in3(c, u0, u1, u2) || in3(c, ul0, ul1, ul2)) return;
    retry(pixel * 4u + k);
}

/* T_cm maps map points to the camera, so p_m = R^T (p_c - t): the origin of
 * the rays is -R^T t. GLSL's mat3(...) is column-major, so these columns
 * are R's rows: the matrix is R^T. */
mat3 frame_Rt(fusion_frame fr)
{
    return mat3(fr.R[0], fr.R[1], fr.R[2], fr.R[3], fr.R[4], fr.R[5], fr.R[6], fr.R[7], fr.R[8]);
}

void main()
{
    fusion_frame fr = frames.f[pc.slot];
    uint n_pixels = fr.width * fr.height;
    load_camera(fr);
    if (pc.pass > 0u) {
        uint q = (pc.pass - 1u) % 2u;
        uint i = BF_LINEAR_INDEX;
        if (i >= min(queue.w[4u * q], pc.queue_cap)) return;
        uint item = queue.w[FUSION_QUEUE_ENTRIES + q * pc.queue_cap + i];
        uint pixel = item / 4u, k = item % 4u;
        mat3 Rt = frame_Rt(fr);
        vec3 o = -(Rt * vec3(fr.t[0], fr.t[1], fr.t[2]));
        sample_ray sr;
        if (pixel >= n_pixels || k > 2u || !sample_at(Rt, pixel % g_width, pixel / g_width, sr)) return;
        float zk;
        if (!band_point(sr, k, zk)) return;
        ivec3 key;
        uvec3 cell;
        locate(o + zk * sr.d, sr.level, key, cell);
        if (!insert_cell(key, cell, sr.level)) retry(item);
        return;
    }
    /* Pass 0 inserts nothing: it queues, for the insertion passes, every
     * band point whose cell differs from the band cells of the pixels to its
     * left, above and above left, and from the same pixel's earlier points.
     * Every cell a frame touches is queued at least once (a point left out
     * repeats one earlier in (row, column, k) order, which by induction
     * leads to a queued one), a few times per brick instead of three times
     * per pixel. One invocation per column segment of FUSION_ALLOC_ROWS
     * rows: every lane does the same work, the cells of the pixel above are
     * carried from the previous row, those of the left column come from the
     * lane to the left when it holds column x - 1 (checked, so any lane
     * order is exact); the first lane of a subgroup compares with the pixel
     * above only (more points queued, no column computed twice). */
    uint x = gl_GlobalInvocationID.x, y0 = gl_WorkGroupID.y * FUSION_ALLOC_ROWS;
    if (y0 >= fr.height) return; /* uniform in the workgroup */
    bool inside = x < fr.width;
    bool has_left = gl_SubgroupInvocationID > 0u && subgroupShuffleUp(x, 1u) + 1u == x && inside;
    uint y1 = min(y0 + FUSION_ALLOC_ROWS, fr.height);
    mat3 Rt = frame_Rt(fr);
    vec3 o = -(Rt * vec3(fr.t[0], fr.t[1], fr.t[2]));
    cell_id none;
    none.key = ivec3(0);
    none.pos = FUSION_NONE;
    cell_id u0 = none, u1 = none, u2 = none;
    if (y0 > 0u && inside) pixel_cells(Rt, o, x, y0 - 1u, u0, u1, u2);
    cell_id ul0 = from_left(u0), ul1 = from_left(u1), ul2 = from_left(u2);
    if (!has_left) {
        ul0 = none;
        ul1 = none;
        ul2 = none;
    }
    for (uint y = y0; y < y1; y++) {
        cell_id c0 = none, c1 = none, c2 = none;
        if (inside) pixel_cells(Rt, o, x, y, c0, c1, c2);
        cell_id l0 = from_left(c0), l1 = from_left(c1), l2 = from_left(c2);
        if (!has_left) {
            l0 = none;
            l1 = none;
            l2 = none;
        }
        uint pixel = y * fr.width + x;
        queue_new(c0, false, pixel, 0u, l0, l1, l2, u0, u1, u2, ul0, ul1, ul2);
        queue_new(c1, same_cell(c1, c0), pixel, 1u, l0, l1, l2, u0, u1, u2, ul0, ul1, ul2);
        queue_new(c2, same_cell(c2, c0) || same_cell(c2, c1), pixel, 2u, l0, l1, l2, u0, u1, u2, ul0, ul1, ul2);
        u0 = c0;
        u1 = c1;
        u2 = c2;
        ul0 = l0;
        ul1 = l1;
        ul2 = l2;
    }
}
