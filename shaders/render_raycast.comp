#version 450
/* Ray-casting of the sign-bit map, one invocation per pixel (DESIGN.md
 * section 5; Reichl, Weiss, Westermann 2016, section 5).
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
 *   - brick level: render_traverse (shaders/render_traverse.glsl.h).
 * Outputs: camera depth of the hit (0: none) and the level of its brick
 * (FUSION_NONE: none); render_shade.comp derives normals and colour.
 */
#extension GL_GOOGLE_include_directive : require
#include "fusion.glsl.h"
#include "render.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

layout(std430, binding = 0) readonly buffer Hash { uint w[]; } hash;
layout(std430, binding = 1) readonly buffer Nodes { uint w[]; } nodes;
layout(std430, binding = 2) readonly buffer Sign { uint w[]; } sign_pool;
layout(std430, binding = 3) readonly buffer Conf { uint w[]; } conf_pool;
layout(std430, binding = 4) writeonly buffer Depth { float v[]; } depth_out;
layout(std430, binding = 5) writeonly buffer Level { uint v[]; } level_out;

layout(push_constant) uniform Push { render_push pc; };

uint render_sign_word(uint slot, uint w) { return sign_pool.w[slot * BRICK_WORDS + w]; }
uint render_conf_word(uint slot, uint w) { return conf_pool.w[slot * BRICK_WORDS + w]; }

#include "render_traverse.glsl.h"

bool entry_has(uint e, ivec3 key)
{
    uint base = e * FUSION_ENTRY_WORDS;
    return hash.w[base + FUSION_ENTRY_STATE] == FUSION_ENTRY_VALID && int(hash.w[base + FUSION_ENTRY_X]) == key.x &&
           int(hash.w[base + FUSION_ENTRY_Y]) == key.y && int(hash.w[base + FUSION_ENTRY_Z]) == key.z;
}

/* Hash entry of the chunk, FUSION_NONE if absent (fusion_alloc.comp's
 * lookup, read-only). */
uint find_chunk(ivec3 key)
{
    uint first = fusion_hash(key.x, key.y, key.z, pc.n_buckets) * FUSION_BUCKET_SLOTS;
    for (uint k = 0u; k < FUSION_BUCKET_SLOTS; k++)
        if (entry_has(first + k, key)) return first + k;
    uint e = hash.w[(first + FUSION_BUCKET_SLOTS - 1u) * FUSION_ENTRY_WORDS + FUSION_ENTRY_NEXT];
    for (uint guard = 0u; e != FUSION_NONE && guard < pc.n_overflow; guard++) {
        if (entry_has(e, key)) return e;
        e = hash.w[e * FUSION_ENTRY_WORDS + FUSION_ENTRY_NEXT];
    }
    return FUSION_NONE;
}

/* Depth at which the ray leaves the axis-aligned cube [lo, lo + size]. */
float cell_exit(render_ray ray, vec3 lo, float size)
{
    vec3 bound = lo + vec3(greaterThan(ray.dir, vec3(0.0))) * size;
    vec3 s = (bound - ray.o) * ray.inv_dir;
    return min(s.x, min(s.y, s.z));
}

void main()
{
    uvec2 px = gl_GlobalInvocationID.xy;
    if (px.x >= pc.width || px.y >= pc.height) return;
    uint pixel = px.y * pc.width + px.x;

    float xc = (float(px.x) - pc.cx) / pc.fx, yc = (float(px.y) - pc.cy) / pc.fy;
    render_ray ray;
    ray.o = vec3(pc.t[0], pc.t[1], pc.t[2]);
    ray.dir = vec3(pc.R[0] * xc + pc.R[1] * yc + pc.R[2], pc.R[3] * xc + pc.R[4] * yc + pc.R[5],
                   pc.R[6] * xc + pc.R[7] * yc + pc.R[8]);
    /* Keep every component away from 0 so 1/dir is finite: a ray parallel
     * to a face then never crosses it within any range we walk. */
    for (int a = 0; a < 3; a++)
        if (abs(ray.dir[a]) < 1.0e-12) ray.dir[a] = 1.0e-12;
    ray.inv_dir = 1.0 / ray.dir;
    ray.zc = vec3(pc.R[2], pc.R[5], pc.R[8]);

    render_trace tr;
    tr.has_front = 0u;
    tr.front_depth = 0.0;
    tr.hit_depth = 0.0;
    tr.hit_level = FUSION_NONE;

    float inv_chunk = 1.0 / pc.chunk_m;
    float grid_per_m = float(RENDER_GRID) * inv_chunk;
    ivec3 cur_key = ivec3(0);
    uint entry = FUSION_NONE;
    bool have_key = false;
    /* The short stack: the path's nodes at levels [lo, deep], entry of level
     * l at index l % RENDER_STACK, each with the finest brick on the path
     * down to it (slot, level). deep < 0: empty. */
    uint st_node[RENDER_STACK], st_brick[RENDER_STACK], st_blevel[RENDER_STACK];
    int deep = -1, lo = 0;
    uvec3 g_prev = uvec3(0u);
    bool hit = false;

    float s = pc.near_m;
    for (uint iter = 0u; iter < RENDER_MAX_CELLS && s < pc.far_m; iter++) {
        float sp = s + RENDER_NUDGE;
        vec3 p = ray.o + sp * ray.dir;
        ivec3 key = ivec3(floor(p * inv_chunk));
        if (!have_key || key != cur_key) {
            have_key = true;
            cur_key = key;
            entry = find_chunk(key);
            deep = -1;
        }
        vec3 chunk_lo = vec3(key) * pc.chunk_m;
        if (entry == FUSION_NONE) {
            tr.has_front = 0u; /* unknown space */
            s = max(cell_exit(ray, chunk_lo, pc.chunk_m), sp);
            continue;
        }
        uvec3 g = uvec3(clamp(ivec3(floor((p - chunk_lo) * grid_per_m)), ivec3(0), ivec3(int(RENDER_GRID) - 1)));
        if (deep >= 0) {
            /* Pop to the deepest ancestor that also holds the new point. */
            uint diff = (g.x ^ g_prev.x) | (g.y ^ g_prev.y) | (g.z ^ g_prev.z);
            int shared_level = diff == 0u ? deep : int(RENDER_GRID_BITS) - 1 - findMSB(diff);
            if (shared_level < deep) deep = shared_level < lo ? -1 : shared_level;
        }
        if (deep < 0) { /* (re)start at the root */
            uint root = hash.w[entry * FUSION_ENTRY_WORDS + FUSION_ENTRY_ROOT];
            uint b = nodes.w[root * FUSION_NODE_WORDS + FUSION_NODE_BRICK];
            deep = 0;
            lo = 0;
            st_node[0] = root;
            st_brick[0] = b < FUSION_LOCKED ? b : FUSION_NONE;
            st_blevel[0] = 0u;
        }
        /* Descend to the deepest existing node holding the point. */
        while (uint(deep) < pc.max_level) {
            uint top = uint(deep) % RENDER_STACK;
            uint child = nodes.w[st_node[top] * FUSION_NODE_WORDS + FUSION_NODE_CHILD];
            if (child >= FUSION_LOCKED) break; /* none (or, never while we read, being made) */
            uint l = uint(deep) + 1u;
            uvec3 c = g >> (RENDER_GRID_BITS - l);
            uint node = child + fusion_octant(c.x, c.y, c.z);
            uint b = nodes.w[node * FUSION_NODE_WORDS + FUSION_NODE_BRICK];
            uint k = l % RENDER_STACK;
            st_node[k] = node;
            st_brick[k] = b < FUSION_LOCKED ? b : st_brick[top];
            st_blevel[k] = b < FUSION_LOCKED ? l : st_blevel[top];
            deep = int(l);
            if (deep - lo >= int(RENDER_STACK)) lo = deep - int(RENDER_STACK) + 1;
        }
        g_prev = g;
        uint top = uint(deep) % RENDER_STACK;
        float cell_m = pc.chunk_m / float(1u << uint(deep));
        float s_exit = cell_exit(ray, chunk_lo + vec3(g >> (RENDER_GRID_BITS - uint(deep))) * cell_m, cell_m);
        uint slot = st_brick[top];
        if (slot == FUSION_NONE) {
            tr.has_front = 0u; /* unknown space */
        } else {
            uint bl = st_blevel[top];
            float brick_m = pc.chunk_m / float(1u << bl);
            vec3 brick_lo = chunk_lo + vec3(g >> (RENDER_GRID_BITS - bl)) * brick_m;
            if (render_traverse(slot, bl, brick_lo, brick_m * 0.125, ray, s, min(s_exit, pc.far_m), pc.flags, tr)) {
                hit = true;
                break;
            }
        }
        s = max(s_exit, sp);
    }
    depth_out.v[pixel] = hit ? tr.hit_depth : 0.0;
    level_out.v[pixel] = hit ? tr.hit_level : FUSION_NONE;
}
