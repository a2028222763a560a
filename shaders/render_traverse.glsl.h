/* The brick traversers of the ray-caster (DESIGN.md section 5).
 *
 * The chunk and octree walk (shaders/render_walk.glsl.h) hands every brick
 * the ray crosses, with the ray's segment inside the part of the brick that
 * is the finest data at those points, to one function:
 *
 *   bool render_traverse(uint slot, uint level, vec3 brick_lo, float voxel_m,
 *                        render_ray ray, float s_in, float s_out, uint flags,
 *                        inout render_trace tr)
 *
 * which returns true when the ray hits inside [s_in, s_out) and then fills
 * tr.hit_depth and tr.hit_level. tr carries what a traverser must remember
 * from one brick to the next (the `surface` traverser: the last front voxel
 * seen); the walk clears tr.has_front where the ray crosses space without a
 * brick (unknown space: a sign change across it means nothing).
 *
 * Two traversers live here; a shader takes `particles` by defining
 * RENDER_TRAVERSE_PARTICLES before including this file, else `surface`.
 * The brick's bits come through accessors the including shader defines, so
 * a brick loads only the words the ray touches:
 *   uint render_sign_word(uint slot, uint w);
 *   uint render_conf_word(uint slot, uint w);             (surface)
 *   float render_particle_radius_m();                     (particles)
 *   uint render_conf_word(uint slot, uint w);             (particles: the reach bits)
 *   render_walk_map render_particle_map();                (particles: neighbour bricks)
 *
 * This file is GLSL only.
 */
#ifndef BF_RENDER_TRAVERSE_GLSL_H
#define BF_RENDER_TRAVERSE_GLSL_H

#include "fusion.glsl.h"
#include "render.glsl.h"
#include "render_walk.glsl.h"

#ifndef RENDER_TRAVERSE_PARTICLES

/* The `surface` traverser: a 3-D DDA over the brick's voxels (Amanatides &
 * Woo 1987) from s_in to s_out. A voxel whose sign bit is 1 is in front of
 * the surface, 0 behind; the ray hits at the first behind voxel after a
 * front one. With RENDER_FLAG_CONFIDENT_ONLY a voxel that is not confident
 * is unknown and skipped (it neither starts nor ends a front run). The hit
 * depth is the entry face of the behind voxel, or with RENDER_FLAG_REFINE
 * render_refine_depth of the two voxel centres. */
bool render_traverse(uint slot, uint level, vec3 brick_lo, float voxel_m, render_ray ray, float s_in, float s_out,
                     uint flags, inout render_trace tr)
{
    vec3 p = ray.o + (s_in + RENDER_NUDGE) * ray.dir;
    ivec3 idx = clamp(ivec3(floor((p - brick_lo) * (1.0 / voxel_m))), ivec3(0), ivec3(7));
    ivec3 stp = ivec3(ray.dir.x > 0.0 ? 1 : -1, ray.dir.y > 0.0 ? 1 : -1, ray.dir.z > 0.0 ? 1 : -1);
    vec3 face = brick_lo + (vec3(idx) + vec3(greaterThan(ray.dir, vec3(0.0)))) * voxel_m;
    vec3 s_max = (face - ray.o) * ray.inv_dir;
    vec3 s_delta = voxel_m * abs(ray.inv_dir);
    bool confident_only = (flags & RENDER_FLAG_CONFIDENT_ONLY) != 0u;
    float s_enter = s_in;
    uint cached = 0xFFFFFFFFu, sign_w = 0u, conf_w = 0u;
    /* A ray crosses at most 22 voxels of a brick (3 * 8 - 2). */
    for (uint k = 0u; k < 24u; k++) {
        uint x = uint(idx.x), y = uint(idx.y), z = uint(idx.z);
        uint w = brick_word(x, y, z), b = brick_bit(x, y, z);
        if (w != cached) {
            cached = w;
            sign_w = render_sign_word(slot, w);
            conf_w = confident_only ? render_conf_word(slot, w) : 0xFFFFFFFFu;
        }
        if (((conf_w >> b) & 1u) != 0u) {
            vec3 c = brick_lo + (vec3(idx) + 0.5) * voxel_m;
            float c_depth = dot(c - ray.o, ray.zc);
            if (((sign_w >> b) & 1u) != 0u) {
                tr.has_front = 1u;
                tr.front_depth = c_depth;
            } else if (tr.has_front != 0u) {
                tr.hit_depth = (flags & RENDER_FLAG_REFINE) != 0u ? render_refine_depth(tr.front_depth, c_depth)
                                                                 : s_enter;
                tr.hit_level = level;
                tr.hit_slot = slot;
                tr.hit_brick = ivec3(floor(brick_lo * (0.125 / voxel_m) + 0.5));
                tr.hit_s_exit = min(s_max.x, min(s_max.y, s_max.z));
                return true;
            }
        }
        /* Next voxel: step the axis whose face comes first. */
        float s_next = min(s_max.x, min(s_max.y, s_max.z));
        if (s_next >= s_out) return false;
        if (s_max.x <= s_max.y && s_max.x <= s_max.z) {
            idx.x += stp.x;
            s_max.x += s_delta.x;
        } else if (s_max.y <= s_max.z) {
            idx.y += stp.y;
            s_max.y += s_delta.y;
        } else {
            idx.z += stp.z;
            s_max.z += s_delta.z;
        }
        if (any(lessThan(idx, ivec3(0))) || any(greaterThan(idx, ivec3(7)))) return false;
        s_enter = s_next;
    }
    return false;
}

#else /* RENDER_TRAVERSE_PARTICLES */

/* The `particles` traverser (Reichl's dissertation, ch. 6: particles binned
 * into a binary grid, each set bit standing for a sphere of the particle
 * radius at its cell's centre; search, then intersect). A sphere reaches up
 * to the radius beyond its cell, so the spheres that can meet the ray's
 * segment in this brick have their centres within the radius of it: the
 * segment's box grown by the radius, which may cross into neighbouring
 * bricks (binning allocates every brick a sphere reaches, so the walk visits
 * each point of each sphere, and sets the reach bit, in the confidence
 * plane, of every cell a sphere overlaps). In each brick of that box the sub-brick words
 * overlapping it are searched for set bits with findLSB, and each bit's
 * sphere is intersected with the ray; the nearest hit in [s_in, s_out) is
 * the hit (a nearer one lies in a brick the walk visited before, where the
 * same sphere was searched). */

/* Camera depth at which ray enters the sphere (c, r), -1 if it misses; the
 * closest-approach form keeps float precision when |o - c| >> r. */
float render_sphere_hit(render_ray ray, vec3 c, float r)
{
    vec3 m = ray.o - c;
    float a = dot(ray.dir, ray.dir);
    float tc = -dot(m, ray.dir) / a;
    vec3 q = m + tc * ray.dir;
    float h = r * r - dot(q, q);
    return h < 0.0 ? -1.0 : tc - sqrt(h / a);
}

/* The last neighbour lookup's parent: the node one level above the bricks
 * (its cell on that level's grid, from the map origin) and its first child.
 * A brick's neighbours mostly share a parent (8 bricks each), so most
 * lookups read two words instead of a hash probe and an octree descent.
 * Per invocation; the shader clears it (render_particles_cache_clear). */
ivec3 render_pcache_parent;
uint render_pcache_child;

void render_particles_cache_clear()
{
    render_pcache_parent = ivec3(-2147483647);
    render_pcache_child = FUSION_NONE;
}

/* render_brick_at through the parent cache (level >= 1). */
uint render_particles_brick(render_walk_map m, ivec3 b, uint level)
{
    ivec3 parent = b >> 1;
    if (parent != render_pcache_parent) {
        render_pcache_parent = parent;
        render_pcache_child = FUSION_NONE;
        ivec3 key = b >> int(level);
        uint e = render_find_chunk(m, key);
        if (e == FUSION_NONE) return FUSION_NONE;
        uvec3 cell = uvec3(parent - (key << int(level - 1u)));
        uint node = fusion_hash_word(e * FUSION_ENTRY_WORDS + FUSION_ENTRY_ROOT);
        for (uint l = 1u; l < level; l++) {
            uint child = render_node_word(node * FUSION_NODE_WORDS + FUSION_NODE_CHILD);
            if (child >= FUSION_LOCKED) return FUSION_NONE;
            uvec3 c = cell >> (level - 1u - l);
            node = child + fusion_octant(c.x, c.y, c.z);
        }
        uint child = render_node_word(node * FUSION_NODE_WORDS + FUSION_NODE_CHILD);
        render_pcache_child = child < FUSION_LOCKED ? child : FUSION_NONE;
    }
    if (render_pcache_child == FUSION_NONE) return FUSION_NONE;
    uvec3 c = uvec3(b);
    uint slot = render_node_word((render_pcache_child + fusion_octant(c.x, c.y, c.z)) * FUSION_NODE_WORDS + FUSION_NODE_BRICK);
    return slot < FUSION_LOCKED ? slot : FUSION_NONE;
}

bool render_traverse(uint slot, uint level, vec3 brick_lo, float voxel_m, render_ray ray, float s_in, float s_out,
                     uint flags, inout render_trace tr)
{
    float r = render_particle_radius_m(), inv_v = 1.0 / voxel_m;
    /* Search only from the first cell on the ray that a sphere reaches (the
     * reach bits, binned with the centres): a DDA over the brick's cells
     * (Amanatides & Woo 1987) reading this brick's words only, so rays that
     * pass between the spheres or through the empty bricks around them skip
     * the search of the neighbours. */
    vec3 p0 = ray.o + (s_in + RENDER_NUDGE) * ray.dir;
    ivec3 idx = clamp(ivec3(floor((p0 - brick_lo) * inv_v)), ivec3(0), ivec3(7));
    ivec3 stp = ivec3(ray.dir.x > 0.0 ? 1 : -1, ray.dir.y > 0.0 ? 1 : -1, ray.dir.z > 0.0 ? 1 : -1);
    vec3 s_max = (brick_lo + (vec3(idx) + vec3(greaterThan(ray.dir, vec3(0.0)))) * voxel_m - ray.o) * ray.inv_dir;
    vec3 s_delta = voxel_m * abs(ray.inv_dir);
    float s_start = -1.0, s_enter = s_in;
    for (uint k = 0u; k < 24u; k++) {
        uint x = uint(idx.x), y = uint(idx.y), z = uint(idx.z);
        if (((render_conf_word(slot, brick_word(x, y, z)) >> brick_bit(x, y, z)) & 1u) != 0u) {
            s_start = s_enter;
            break;
        }
        float s_next = min(s_max.x, min(s_max.y, s_max.z));
        if (s_next >= s_out) break;
        if (s_max.x <= s_max.y && s_max.x <= s_max.z) {
            idx.x += stp.x;
            s_max.x += s_delta.x;
        } else if (s_max.y <= s_max.z) {
            idx.y += stp.y;
            s_max.y += s_delta.y;
        } else {
            idx.z += stp.z;
            s_max.z += s_delta.z;
        }
        if (any(lessThan(idx, ivec3(0))) || any(greaterThan(idx, ivec3(7)))) break;
        s_enter = s_next;
    }
    if (s_start < 0.0) return false;
    render_walk_map m = render_particle_map();
    ivec3 B = ivec3(floor(brick_lo * (0.125 * inv_v) + 0.5));
    /* Cells (global, on this level's grid) whose centre c + 0.5 is within
     * r of the segment's box. */
    vec3 pa = (ray.o + s_start * ray.dir) * inv_v, pb = (ray.o + s_out * ray.dir) * inv_v;
    float rc = r * inv_v;
    ivec3 c0 = ivec3(floor(min(pa, pb) - rc - 0.5)), c1 = ivec3(ceil(max(pa, pb) + rc - 0.5));
    ivec3 b0 = c0 >> 3, b1 = c1 >> 3;
    float best = s_out;
    bool hit = false;
    vec3 best_c = vec3(0.0);
    for (int bz = b0.z; bz <= b1.z; bz++)
        for (int by = b0.y; by <= b1.y; by++)
            for (int bx = b0.x; bx <= b1.x; bx++) {
                ivec3 b = ivec3(bx, by, bz);
                uint sl = b == B ? slot : render_particles_brick(m, b, level);
                if (sl == FUSION_NONE) continue;
                ivec3 lo = clamp(c0 - b * 8, ivec3(0), ivec3(7)), hi = clamp(c1 - b * 8, ivec3(0), ivec3(7));
                for (uint w = 0u; w < BRICK_WORDS; w++) {
                    /* Sub-brick w: x in 4 (w & 1) + [0, 3], y in 4 ((w >> 1) & 1) + [0, 3], z in 2 (w >> 2) + [0, 1]. */
                    ivec3 s0 = ivec3(4 * int(w & 1u), 4 * int((w >> 1) & 1u), 2 * int(w >> 2));
                    if (any(greaterThan(s0, hi)) || any(lessThan(s0 + ivec3(3, 3, 1), lo))) continue;
                    uint bits = render_sign_word(sl, w);
                    while (bits != 0u) {
                        int i = findLSB(bits);
                        bits &= bits - 1u;
                        ivec3 cell = b * 8 + s0 + ivec3(i & 3, (i >> 2) & 3, i >> 4);
                        vec3 c = (vec3(cell) + 0.5) * voxel_m;
                        float t = render_sphere_hit(ray, c, r);
                        if (t >= s_in - RENDER_NUDGE && t < best) {
                            best = t;
                            best_c = c;
                            hit = true;
                        }
                    }
                }
            }
    if (!hit) return false;
    tr.hit_depth = best;
    tr.hit_level = level;
    tr.hit_normal = (ray.o + best * ray.dir - best_c) / r;
    return true;
}

#endif /* RENDER_TRAVERSE_PARTICLES */

#endif
