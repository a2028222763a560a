/* The chunk and octree walk of the ray-caster (DESIGN.md section 5;
 * Reichl, Weiss, Westermann 2016, section 5), shared by every renderer:
 * shaders/render_raycast.comp (the `surface` traverser on a fused map) and
 * shaders/render_particles.comp (the `particles` traverser on binned
 * particles) include it with their own brick traverser
 * (shaders/render_traverse.glsl.h says what one must do).
 *
 * The ray walks the map hierarchically, always from the current depth s to
 * the exit of the largest region whose content it knows:
 *   - chunk level: the chunk of the point just past s is looked up in the
 *     hash as fusion does (fusion_hash, the bucket's slots, then the
 *     overflow chain; only VALID entries count); a chunk that does not exist
 *     is skipped whole (a DDA over chunks, Amanatides & Woo 1987, one cell
 *     size, re-located at each step);
 *   - octree level: from the chunk's root down to the deepest existing node
 *     containing the point, remembering the finest brick on the way. The
 *     deepest node's cell holds no finer data, so the ray crosses it in one
 *     step: through the finest brick's voxels when there is one, else as
 *     unknown space. Children come in groups of 8, so empty space is skipped
 *     at the coarsest cell without data. The path is kept in a short stack
 *     of RENDER_STACK entries; the next cell pops to the deepest common
 *     ancestor (the highest differing bit of the integer cell coordinates,
 *     Laine & Karras 2010's trick) and restarts from the root on underflow.
 *   - brick level: render_traverse.
 *
 * The including shader defines, before including this file, the map's word
 * accessors
 *   uint fusion_hash_word(uint i);   (the hash, shaders/fusion_hash.glsl.h)
 *   uint render_node_word(uint i);   (the node pool)
 * and, anywhere, the traverser render_traverse (prototype below).
 *
 * This file is GLSL only.
 */
#ifndef BF_RENDER_WALK_GLSL_H
#define BF_RENDER_WALK_GLSL_H

#include "fusion.glsl.h"
#include "render.glsl.h"
#include "fusion_hash.glsl.h"

/* A ray in the map frame: o + s dir, s = camera depth (dir has camera z 1). */
struct render_ray {
    vec3 o;
    vec3 dir;
    vec3 inv_dir; /* 1 / dir, components of dir kept away from 0 */
    vec3 zc;      /* the camera's optical axis in the map frame: depth(p) = dot(p - o, zc) */
    float inv_len; /* 1 / |dir| (the particles' sphere test: no division per sphere) */
};

/* State carried along the ray from brick to brick. */
struct render_trace {
    uint has_front;    /* surface: a front voxel seen since the last unknown space */
    float front_depth; /* surface: camera depth of its centre */
    float hit_depth;
    uint hit_level;
    uint hit_slot;     /* surface: brick of the first behind voxel (the sub-voxel refinement starts there) */
    ivec3 hit_brick;   /* surface: its brick coordinate on its level's grid (brick units from the map origin) */
    vec3 hit_normal;   /* particles: unit normal of the sphere hit, map frame */
    float hit_s_exit;  /* surface: ray parameter where the ray leaves the first behind voxel */
};

/* The map a walk reads: what of the push constants the walk needs. */
struct render_walk_map {
    float chunk_m;
    uint max_level;
    uint n_buckets;  /* fusion_hash's modulus */
    uint n_overflow; /* overflow entries after the buckets' slots */
    uint max_cells;  /* cells a ray may visit (RENDER_MAX_CELLS, RENDER_PARTICLES_MAX_CELLS) */
};

/* Nudge into a cell past its entry face before locating the voxel there
 * (metres of camera depth: 10 um, a hundredth of the finest voxel). */
#define RENDER_NUDGE 1.0e-5

/* Depth s nudged: s + RENDER_NUDGE, and at least the next float above s.
 * From 256 m on a float's step is over twice the nudge, which then rounded
 * away: a ray walking toward lower coordinates stayed on its cell's face
 * until its cells ran out and missed a mesh seen from 300 m. Below 256 m
 * the two are the same. */
float render_nudged(float s)
{
    return max(s + RENDER_NUDGE, uintBitsToFloat(floatBitsToUint(max(s, 0.0)) + 1u));
}

/* The brick traverser: true when the ray hits inside [s_in, s_out) of the
 * brick (slot, level) whose corner is brick_lo (map frame), then
 * tr.hit_depth and tr.hit_level are set. node is the brick's octree node
 * where the walk's stack holds it (the brick is on the deepest node
 * reached), parent the node above that where the stack holds it too; else
 * FUSION_NONE. */
bool render_traverse(uint slot, uint node, uint parent, uint level, vec3 brick_lo, float voxel_m, render_ray ray,
                     float s_in, float s_out, uint flags, inout render_trace tr);

/* The ray of pixel px of a camera at (R, t) in the map frame (render.glsl.h
 * says why dir has camera z 1). */
render_ray render_pixel_ray(uvec2 px, float R[9], float t[3], float fx, float fy, float cx, float cy)
{
    float xc = (float(px.x) - cx) / fx, yc = (float(px.y) - cy) / fy;
    render_ray ray;
    ray.o = vec3(t[0], t[1], t[2]);
    ray.dir = vec3(R[0] * xc + R[1] * yc + R[2], R[3] * xc + R[4] * yc + R[5], R[6] * xc + R[7] * yc + R[8]);
    /* Keep every component away from 0 so 1/dir is finite: a ray parallel
     * to a face then never crosses it within any range we walk. */
    for (int a = 0; a < 3; a++)
        if (abs(ray.dir[a]) < 1.0e-12) ray.dir[a] = 1.0e-12;
    ray.inv_dir = 1.0 / ray.dir;
    ray.zc = vec3(R[2], R[5], R[8]);
    ray.inv_len = inversesqrt(dot(ray.dir, ray.dir));
    return ray;
}

/* Hash entry of the chunk, FUSION_NONE if absent (fusion's lookup). */
uint render_find_chunk(render_walk_map m, ivec3 key)
{
    return fusion_find_chunk(key.x, key.y, key.z, m.n_buckets, m.n_overflow);
}

/* Depth at which the ray leaves the axis-aligned cube [lo, lo + size]. */
float render_cell_exit(render_ray ray, vec3 lo, float size)
{
    vec3 bound = lo + vec3(greaterThan(ray.dir, vec3(0.0))) * size;
    vec3 s = (bound - ray.o) * ray.inv_dir;
    return min(s.x, min(s.y, s.z));
}

/* Slot of the brick at `level` with brick coordinate b (brick units from the
 * map origin on that level's grid), FUSION_NONE when the node or its brick
 * does not exist. Only this level counts. */
uint render_brick_at(render_walk_map m, ivec3 b, uint level)
{
    ivec3 key = b >> int(level);
    uint e = render_find_chunk(m, key);
    if (e == FUSION_NONE) return FUSION_NONE;
    uvec3 cell = uvec3(b - (key << int(level)));
    uint node = fusion_hash_word(e * FUSION_ENTRY_WORDS + FUSION_ENTRY_ROOT);
    for (uint l = 1u; l <= level; l++) {
        uint child = render_node_word(node * FUSION_NODE_WORDS + FUSION_NODE_CHILD);
        if (child >= FUSION_LOCKED) return FUSION_NONE;
        uvec3 c = cell >> (level - l);
        node = child + fusion_octant(c.x, c.y, c.z);
    }
    uint slot = render_node_word(node * FUSION_NODE_WORDS + FUSION_NODE_BRICK);
    return slot < FUSION_LOCKED ? slot : FUSION_NONE;
}

/* Walks the ray from depth s to s_far through map m, handing each brick it
 * crosses to render_traverse; true at the first hit (tr holds it). At most
 * m.max_cells cells: false with s < s_far when the walk stopped there (s is
 * where a later walk resumes). */
bool render_walk_from(render_walk_map m, render_ray ray, inout float s, float s_far, uint flags, inout render_trace tr)
{
    float inv_chunk = 1.0 / m.chunk_m;
    float grid_per_m = float(RENDER_GRID) * inv_chunk;
    ivec3 cur_key = ivec3(0);
    uint entry = FUSION_NONE;
    bool have_key = false;
    /* The short stack: the path's nodes at levels [lo, deep], entry of level
     * l at index l % RENDER_STACK, each with the finest brick on the path
     * down to it (slot, level). deep < 0: empty. uvec4s, not arrays
     * (RENDER_STACK is 4): llvmpipe keeps a private array in memory and
     * reads and writes it lane by lane; a vector's component is selected in
     * registers (docs/particles.md, "One loop over the search box's words"). */
    uvec4 st_node = uvec4(0u), st_brick = uvec4(0u), st_blevel = uvec4(0u);
    int deep = -1, lo = 0;
    uvec3 g_prev = uvec3(0u);
    for (uint iter = 0u; iter < m.max_cells && s < s_far; iter++) {
        float sp = render_nudged(s);
        vec3 p = ray.o + sp * ray.dir;
        ivec3 key = BF_TRUNC_I32(floor(p * inv_chunk));
        if (!have_key || key != cur_key) {
            have_key = true;
            cur_key = key;
            entry = render_find_chunk(m, key);
            deep = -1;
        }
        vec3 chunk_lo = vec3(key) * m.chunk_m;
        if (entry == FUSION_NONE) {
            tr.has_front = 0u; /* unknown space */
            s = max(render_cell_exit(ray, chunk_lo, m.chunk_m), sp);
            continue;
        }
        uvec3 g = uvec3(clamp(BF_TRUNC_I32(floor((p - chunk_lo) * grid_per_m)), ivec3(0), ivec3(int(RENDER_GRID) - 1)));
        if (deep >= 0) {
            /* Pop to the deepest ancestor that also holds the new point. */
            uint diff = (g.x ^ g_prev.x) | (g.y ^ g_prev.y) | (g.z ^ g_prev.z);
            int shared_level = diff == 0u ? deep : int(RENDER_GRID_BITS) - 1 - findMSB(diff);
            if (shared_level < deep) deep = shared_level < lo ? -1 : shared_level;
        }
        if (deep < 0) { /* (re)start at the root */
            uint root = fusion_hash_word(entry * FUSION_ENTRY_WORDS + FUSION_ENTRY_ROOT);
            uint b = render_node_word(root * FUSION_NODE_WORDS + FUSION_NODE_BRICK);
            deep = 0;
            lo = 0;
            st_node[0] = root;
            st_brick[0] = b < FUSION_LOCKED ? b : FUSION_NONE;
            st_blevel[0] = 0u;
        }
        /* Descend to the deepest existing node holding the point. */
        while (uint(deep) < m.max_level) {
            uint top = uint(deep) % RENDER_STACK;
            uint child = render_node_word(st_node[top] * FUSION_NODE_WORDS + FUSION_NODE_CHILD);
            if (child >= FUSION_LOCKED) break; /* none (or, never while we read, being made) */
            uint l = uint(deep) + 1u;
            uvec3 c = g >> (RENDER_GRID_BITS - l);
            uint node = child + fusion_octant(c.x, c.y, c.z);
            uint b = render_node_word(node * FUSION_NODE_WORDS + FUSION_NODE_BRICK);
            uint k = l % RENDER_STACK;
            st_node[k] = node;
            st_brick[k] = b < FUSION_LOCKED ? b : st_brick[top];
            st_blevel[k] = b < FUSION_LOCKED ? l : st_blevel[top];
            deep = int(l);
            if (deep - lo >= int(RENDER_STACK)) lo = deep - int(RENDER_STACK) + 1;
        }
        g_prev = g;
        uint top = uint(deep) % RENDER_STACK;
        float cell_m = m.chunk_m / float(1u << uint(deep));
        float s_exit = render_cell_exit(ray, chunk_lo + vec3(g >> (RENDER_GRID_BITS - uint(deep))) * cell_m, cell_m);
        uint slot = st_brick[top];
        if (slot == FUSION_NONE) {
            tr.has_front = 0u; /* unknown space */
        } else {
            uint bl = st_blevel[top];
            float brick_m = m.chunk_m / float(1u << bl);
            vec3 brick_lo = chunk_lo + vec3(g >> (RENDER_GRID_BITS - bl)) * brick_m;
            uint node = bl == uint(deep) ? st_node[top] : FUSION_NONE;
            uint parent = node != FUSION_NONE && deep > lo ? st_node[uint(deep - 1) % RENDER_STACK] : FUSION_NONE;
            if (render_traverse(slot, node, parent, bl, brick_lo, brick_m * 0.125, ray, s, min(s_exit, s_far), flags,
                                tr))
                return true;
        }
        s = max(s_exit, sp);
    }
    return false;
}

/* render_walk_from from depth s, for a caller that does not resume. */
bool render_walk(render_walk_map m, render_ray ray, float s, float s_far, uint flags, inout render_trace tr)
{
    return render_walk_from(m, ray, s, s_far, flags, tr);
}

#endif
