/* The brick traversers of the ray-caster (DESIGN.md section 5).
 *
 * The chunk and octree walk (shaders/render_walk.glsl.h) hands every brick
 * the ray crosses, with the ray's segment inside the part of the brick that
 * is the finest data at those points, to one function:
 *
 *   bool render_traverse(uint slot, uint node, uint parent, uint level,
 *                        vec3 brick_lo, float voxel_m, render_ray ray,
 *                        float s_in, float s_out, uint flags,
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
 *   uint render_particles_budget();                       (particles: work before a pause)
 *   float render_particles_lod_k();                       (particles: level of detail from depth lod_k * cell)
 *   uint render_particles_index_word(uint i);             (particles: the centres' index, render/particles_bin.h)
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
bool render_traverse(uint slot, uint node, uint parent, uint level, vec3 brick_lo, float voxel_m, render_ray ray,
                     float s_in, float s_out, uint flags, inout render_trace tr)
{
    vec3 p = ray.o + render_nudged(s_in) * ray.dir;
    ivec3 idx = clamp(BF_TRUNC_I32(floor((p - brick_lo) * (1.0 / voxel_m))), ivec3(0), ivec3(7));
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
                tr.hit_brick = BF_TRUNC_I32(floor(brick_lo * (0.125 / voxel_m) + 0.5));
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
 * radius at its cell's centre; search, then intersect). It runs on the
 * coarse level (render/particles_bin.h), whose cells are the bricks of
 * centres RENDER_PARTICLES_COARSE_LEVELS levels below: a coarse cell's sign
 * bit says its brick of centres exists, its confidence bit that a sphere
 * reaches into it. The walk visits coarse bricks only (bricks of centres
 * are never walked, and no empty bricks surround them), so a ray crosses
 * empty and sparse space eight times faster than on the centres' level.
 *
 * In a coarse brick a DDA (Amanatides & Woo 1987) visits the ray's cells;
 * at each cell a sphere reaches, the spheres that can meet the ray there
 * have their centres within the radius of that cell: the coarse cells of
 * that box holding centres are found in the coarse sign words, each one's
 * brick of centres through the centres' index (the entry of the coarse
 * word's first brick, plus the set bits below it: one read instead of a
 * descent of three octree levels), and the words of that brick that hold
 * centres (word 0 of its confidence plane says which) searched with
 * findLSB, each bit's sphere intersected with the ray. Consecutive cells'
 * boxes overlap: after a searched cell, the next searches only the slab of
 * its box the last one did not cover, and the nearest entry found is
 * carried along the ray. A sphere's entry point lies in a cell it reaches,
 * so once every reached cell up to the current one was searched, a hit
 * before the current cell's exit is the nearest: the search stops there.
 *
 * The work is counted (render_pwork): past render_particles_budget() the
 * traverser pauses at the entry of the cell it was to search, reported as
 * a hit of level RENDER_PARTICLES_PAUSED at that depth, and the next
 * dispatch resumes the ray there (render_particles.comp). */

/* Camera depth at which ray enters the sphere (c, r), -1 if it misses; the
 * closest-approach form keeps float precision when |o - c| >> r. The ray's
 * 1 / |dir| replaces two divisions by |dir|^2 per sphere. */
float render_sphere_hit(render_ray ray, vec3 c, float r)
{
    vec3 m = ray.o - c;
    float tc = -dot(m, ray.dir) * (ray.inv_len * ray.inv_len);
    vec3 q = m + tc * ray.dir;
    float h = r * r - dot(q, q);
    return h < 0.0 ? -1.0 : tc - sqrt(h) * ray.inv_len;
}

/* Per invocation and dispatch (render_particles_cache_clear): loop
 * iterations of the walk and search so far; the nearest sphere entry found
 * so far on the ray and its centre (carried from brick to brick: a sphere
 * found near a brick's exit may be entered in the next); whether the last
 * cell the DDA visited was searched, and that cell (global, coarse level). */
uint render_pwork;
float render_pbest;
vec3 render_pbest_c;
bool render_pchain;
ivec3 render_plast;
bool render_pbest_lod; /* render_pbest came from a level-of-detail search */
float render_plod_k;    /* render_particles_lod_k(), once per ray */

/* The last coarse lookup's parent: the node one level above the coarse
 * bricks (its cell on that level's grid, from the map origin) and its first
 * child. A brick's neighbours mostly share a parent (8 bricks each), so
 * most lookups read two words instead of a hash probe and an octree
 * descent. Per invocation; the shader clears it (render_particles_cache_clear). */
ivec3 render_pcache_parent;
uint render_pcache_child;
/* The walked brick's grandparent (its cell one level above the parents)
 * and its first child, from the walk's stack (FUSION_NONE: none). */
ivec3 render_pgp;
uint render_pgp_child;
/* From the centres' index header (once per invocation): the first coarse
 * brick's slot and where the bricks of centres' slots start. */
uint render_pfirst_coarse, render_pslots_at;

void render_particles_cache_clear()
{
    render_pcache_parent = ivec3(-2147483647);
    render_pcache_child = FUSION_NONE;
    render_pgp = ivec3(-2147483647);
    render_pgp_child = FUSION_NONE;
    render_pwork = 0u;
    render_pbest = 3.0e38;
    render_pbest_c = vec3(0.0);
    render_pchain = false;
    render_plast = ivec3(0);
    render_pbest_lod = false;
    render_plod_k = render_particles_lod_k();
    render_pfirst_coarse = render_particles_index_word(0u);
    render_pslots_at = render_particles_index_word(1u);
}

/* The node of coarse brick b (level >= 1) through the parent cache, or
 * FUSION_NONE. */
uint render_particles_node(render_walk_map m, ivec3 b, uint level)
{
    ivec3 parent = b >> 1;
    if (parent != render_pcache_parent) {
        render_pcache_parent = parent;
        render_pcache_child = FUSION_NONE;
        uint node;
        if (render_pgp_child != FUSION_NONE && parent >> 1 == render_pgp) {
            /* A child of the walked brick's grandparent: no hash probe or descent. */
            uvec3 u = uvec3(parent);
            node = render_pgp_child + fusion_octant(u.x, u.y, u.z);
            render_pwork++;
        } else {
            ivec3 key = b >> int(level);
            uint e = render_find_chunk(m, key);
            if (e == FUSION_NONE) return FUSION_NONE;
            uvec3 cell = uvec3(parent - (key << int(level - 1u)));
            node = fusion_hash_word(e * FUSION_ENTRY_WORDS + FUSION_ENTRY_ROOT);
            for (uint l = 1u; l < level; l++) {
                uint child = render_node_word(node * FUSION_NODE_WORDS + FUSION_NODE_CHILD);
                if (child >= FUSION_LOCKED) return FUSION_NONE;
                uvec3 c = cell >> (level - 1u - l);
                node = child + fusion_octant(c.x, c.y, c.z);
            }
            render_pwork += level;
        }
        uint child = render_node_word(node * FUSION_NODE_WORDS + FUSION_NODE_CHILD);
        render_pcache_child = child < FUSION_LOCKED ? child : FUSION_NONE;
    }
    if (render_pcache_child == FUSION_NONE) return FUSION_NONE;
    uvec3 c = uvec3(b);
    return render_pcache_child + fusion_octant(c.x, c.y, c.z);
}

/* The centre of cell (sub-brick word w, bit i) of the brick of centres
 * under coarse cell k (global, coarse grid), map frame. */
vec3 render_particles_centre(ivec3 k, uint w, int i, float fine_m)
{
    /* Sub-brick w: x in 4 (w & 1) + [0, 3], y in 4 ((w >> 1) & 1) + [0, 3], z in 2 (w >> 2) + [0, 1]. */
    ivec3 s0 = ivec3(4 * int(w & 1u), 4 * int((w >> 1) & 1u), 2 * int(w >> 2));
    return (vec3(k * 8 + s0 + ivec3(i & 3, (i >> 2) & 3, i >> 4)) + 0.5) * fine_m;
}

/* The sphere (c, r) as the nearest entry in [s_lo, best) (lod: drawn for a
 * coarse cell). */
void render_particles_try(render_ray ray, vec3 c, float r, float s_lo, bool lod, inout float best, inout vec3 best_c)
{
    float t = render_sphere_hit(ray, c, r);
    if (t >= s_lo && t < best) {
        best = t;
        best_c = c;
        render_pbest_lod = lod;
    }
}

/* The set bits of a sub-brick word whose cells lie in [l, h] (cells of the
 * word, x and y in [0, 3], z in [0, 1]; bit x + 4 y + 16 z). */
uint render_particles_box_mask(ivec3 l, ivec3 h)
{
    uint xm = ((1u << uint(h.x - l.x + 1)) - 1u) << uint(l.x);
    uint ym = ((1u << uint(4 * (h.y - l.y + 1))) - 1u) << uint(4 * l.y);
    uint zm = l.z == 0 ? (h.z == 1 ? 0xffffffffu : 0x0000ffffu) : 0xffff0000u;
    return (xm * 0x11111111u) & (ym | (ym << 16)) & zm;
}

/* The nearest sphere entry in [s_lo, best) among the spheres whose centres
 * lie in the cells [c0, c1] (global, on the centres' grid of cells of
 * fine_m); level is the coarse level, B and slot_B the coarse brick being
 * walked. The coarse cells of the box that hold centres are found as the
 * set sign bits of the coarse bricks' sub-brick words under a mask of the
 * box (findLSB), so empty coarse cells cost nothing. With lod each such
 * coarse cell is one sphere at its centre, its brick of centres unread
 * (render_pbest_lod says which kind the nearest is). */
void render_particles_search(render_walk_map m, render_ray ray, ivec3 c0, ivec3 c1, uint level, ivec3 B, uint slot_B, float fine_m, float r, float s_lo, bool lod, inout float best,
                             inout vec3 best_c)
{
    ivec3 k0 = c0 >> 3, k1 = c1 >> 3;
    /* The box's sub-brick words on the coarse grid (4 x 4 x 2 cells each;
     * a brick holds 2 x 2 x 4 of them) in one loop over a 3-d counter, z
     * fastest (a brick spans most words along z): nested loops cost
     * llvmpipe an execution mask per level. The brick's slot is looked up
     * when the brick changes. */
    ivec3 gw0 = ivec3(k0.x >> 2, k0.y >> 2, k0.z >> 1), gw1 = ivec3(k1.x >> 2, k1.y >> 2, k1.z >> 1);
    ivec3 g = gw0, kc_last = ivec3(-2147483647);
    uint sl = FUSION_NONE;
    bool more = true;
    while (more) {
        ivec3 gc = g;
        if (++g.z > gw1.z) {
            g.z = gw0.z;
            if (++g.y > gw1.y) {
                g.y = gw0.y;
                more = ++g.x <= gw1.x;
            }
        }
        ivec3 kc = ivec3(gc.x >> 1, gc.y >> 1, gc.z >> 2);
        if (kc != kc_last) {
            kc_last = kc;
            render_pwork++;
            sl = slot_B;
            if (kc != B) {
                uint node = render_particles_node(m, kc, level);
                sl = node == FUSION_NONE ? FUSION_NONE : render_node_word(node * FUSION_NODE_WORDS + FUSION_NODE_BRICK);
                if (sl >= FUSION_LOCKED) sl = FUSION_NONE;
            }
        }
        if (sl == FUSION_NONE) continue;
        int wx = gc.x & 1, wy = gc.y & 1, wz = gc.z & 3;
        ivec3 lo = k0 - kc * 8, hi = k1 - kc * 8;
        render_pwork++;
        ivec3 q0 = ivec3(4 * wx, 4 * wy, 2 * wz);
        uint wi = uint(wx + 2 * wy + 4 * wz), sw = render_sign_word(sl, wi);
        uint occ = sw & render_particles_box_mask(max(lo - q0, ivec3(0)), min(hi - q0, ivec3(3, 3, 1)));
        /* The index entry of the word's first brick of centres. */
        uint e0 = occ != 0u && !lod ? render_particles_index_word(RENDER_PARTICLES_INDEX_HEADER +
                                                                 16u * (sl - render_pfirst_coarse) + wi)
                                    : 0u;
        while (occ != 0u) {
            int b = findLSB(occ);
            occ &= occ - 1u;
            render_pwork++;
            ivec3 k = kc * 8 + q0 + ivec3(b & 3, (b >> 2) & 3, b >> 4);
            if (lod) {
                /* Level of detail: the coarse cell's centres as one sphere at its centre. */
                render_particles_try(ray, (vec3(k) + 0.5) * (8.0 * fine_m), r, s_lo, true, best, best_c);
                continue;
            }
            /* The ray must pass within r of the cell's
             * centres: through the cell grown by r (the
             * slab test, beyond s_lo). */
            vec3 g0 = (vec3(k * 8) * fine_m - r - ray.o) * ray.inv_dir,
                 g1 = g0 + (8.0 * fine_m + 2.0 * r) * ray.inv_dir;
            vec3 gn = min(g0, g1), gx = max(g0, g1);
            if (min(gx.x, min(gx.y, gx.z)) < max(s_lo, max(gn.x, max(gn.y, gn.z)))) continue;
            /* Its brick of centres: the entry after the word's set bits below b. */
            uint fs = render_particles_index_word(render_pslots_at + e0 +
                                                  uint(bitCount(sw & ((1u << uint(b)) - 1u))));
            render_pwork++;
            if ((fs & RENDER_PARTICLES_INDEX_ONE) != 0u) {
                /* A brick of one centre: the entry holds its cell. */
                render_particles_try(ray, render_particles_centre(k, fs >> 5 & 15u, int(fs & 31u), fine_m),
                                     r, s_lo, false, best, best_c);
                continue;
            }
            ivec3 flo = clamp(c0 - k * 8, ivec3(0), ivec3(7)), fhi = clamp(c1 - k * 8, ivec3(0), ivec3(7));
            /* The sub-brick words holding centres: word 0 of the brick's confidence plane
             * (render/particles_bin.h). */
            for (uint words = render_conf_word(fs, 0u); words != 0u; words &= words - 1u) {
                uint w = uint(findLSB(words));
                /* Sub-brick w: x in 4 (w & 1) + [0, 3], y in 4 ((w >> 1) & 1) + [0, 3], z in 2 (w >> 2) + [0, 1]. */
                ivec3 s0 = ivec3(4 * int(w & 1u), 4 * int((w >> 1) & 1u), 2 * int(w >> 2));
                if (any(greaterThan(s0, fhi)) || any(lessThan(s0 + ivec3(3, 3, 1), flo))) continue;
                render_pwork++;
                uint bits = render_sign_word(fs, w);
                while (bits != 0u) {
                    int i = findLSB(bits);
                    bits &= bits - 1u;
                    render_pwork++;
                    render_particles_try(ray, render_particles_centre(k, w, i, fine_m), r, s_lo, false,
                                         best, best_c);
                }
            }
        }
    }
}

bool render_traverse(uint slot, uint node, uint parent, uint level, vec3 brick_lo, float voxel_m, render_ray ray,
                     float s_in, float s_out, uint flags, inout render_trace tr)
{
    render_walk_map m = render_particle_map();
    float r = render_particle_radius_m(), inv_v = 1.0 / voxel_m;
    float fine_m = voxel_m * 0.125, rc = r * 8.0 * inv_v;
    /* The cells of centres (offsets from a coarse cell's first) whose
     * sphere can reach into the coarse cell: centre (i + 0.5) within rc of
     * [0, 8]. */
    int lo_off = int(ceil(-rc - 0.5)), hi_off = int(floor(8.0 + rc - 0.5));
    vec3 p0 = ray.o + render_nudged(s_in) * ray.dir;
    ivec3 idx = clamp(BF_TRUNC_I32(floor((p0 - brick_lo) * inv_v)), ivec3(0), ivec3(7));
    ivec3 stp = ivec3(ray.dir.x > 0.0 ? 1 : -1, ray.dir.y > 0.0 ? 1 : -1, ray.dir.z > 0.0 ? 1 : -1);
    vec3 s_max = (brick_lo + (vec3(idx) + vec3(greaterThan(ray.dir, vec3(0.0)))) * voxel_m - ray.o) * ray.inv_dir;
    vec3 s_delta = voxel_m * abs(ray.inv_dir);
    ivec3 B = BF_TRUNC_I32(floor(brick_lo * inv_v * 0.125 + 0.5));
    if (node != FUSION_NONE) {
        /* The walk's node of this brick: its parent's children are its
         * siblings, which most of the searches' neighbours are. */
        uvec3 u = uvec3(B);
        render_pcache_parent = B >> 1;
        render_pcache_child = node - fusion_octant(u.x, u.y, u.z);
    }
    if (parent != FUSION_NONE && level >= 2u) {
        /* And its parent (not a chunk's root: one of 8 siblings): the
         * grandparent's children are the parents of most other neighbours. */
        uvec3 u = uvec3(B >> 1);
        render_pgp = B >> 2;
        render_pgp_child = parent - fusion_octant(u.x, u.y, u.z);
    }
    float s_enter = s_in;
    render_pwork += 4u; /* the walk's step to this brick */
    for (uint k = 0u; k < 32u; k++) {
        uint x = uint(idx.x), y = uint(idx.y), z = uint(idx.z);
        float s_next = min(min(s_max.x, min(s_max.y, s_max.z)), s_out);
        ivec3 kg = B * 8 + idx;
        render_pwork++;
        uint reach = render_conf_word(slot, brick_word(x, y, z));
        if (reach == 0u) {
            /* No sphere reaches this cell's sub-brick (4 x 4 x 2 cells):
             * the DDA goes on from where the ray leaves it. */
            ivec3 q0 = idx & ivec3(~3, ~3, ~1);
            vec3 q_hi = brick_lo + (vec3(q0) + vec3(greaterThan(ray.dir, vec3(0.0))) * vec3(4.0, 4.0, 2.0)) * voxel_m;
            vec3 qs = (q_hi - ray.o) * ray.inv_dir;
            float s_q = min(qs.x, min(qs.y, qs.z));
            render_pchain = false;
            if (s_q >= s_out) break;
            s_enter = s_q;
            vec3 pq = ray.o + render_nudged(s_q) * ray.dir;
            idx = BF_TRUNC_I32(floor((pq - brick_lo) * inv_v));
            if (any(lessThan(idx, ivec3(0))) || any(greaterThan(idx, ivec3(7)))) break;
            s_max = (brick_lo + (vec3(idx) + vec3(greaterThan(ray.dir, vec3(0.0)))) * voxel_m - ray.o) * ray.inv_dir;
            continue;
        }
        if (((reach >> brick_bit(x, y, z)) & 1u) != 0u) {
            if (render_pwork > render_particles_budget()) {
                tr.hit_depth = s_enter;
                tr.hit_level = RENDER_PARTICLES_PAUSED;
                return true;
            }
            /* The centres whose spheres reach this cell; after a searched
             * neighbour one step back along axis a, only the slab its
             * search did not cover (the window slides one cell). */
            ivec3 c0 = kg * 8 + lo_off, c1 = kg * 8 + hi_off;
            ivec3 d = kg - render_plast;
            if (render_pchain && abs(d.x) + abs(d.y) + abs(d.z) == 1) {
                for (int a = 0; a < 3; a++) {
                    if (d[a] > 0) c0[a] = c1[a] - 7;
                    if (d[a] < 0) c1[a] = c0[a] + 7;
                }
            }
            /* Level of detail from the nearest depth a sphere met here can have (two cells before). */
            bool lod = s_enter - 2.0 * voxel_m >= render_plod_k * voxel_m;
            render_particles_search(m, ray, c0, c1, level, B, slot, fine_m, r, s_in - RENDER_NUDGE, lod,
                                    render_pbest, render_pbest_c);
            render_pchain = true;
            render_plast = kg;
            if (render_pbest < s_next) break;
        } else {
            render_pchain = false;
        }
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
    if (!(render_pbest < s_out)) return false;
    tr.hit_depth = render_pbest;
    /* The level image says which level drew the hit (the coarse one: level of detail). */
    tr.hit_level = render_pbest_lod ? level : level + RENDER_PARTICLES_COARSE_LEVELS;
    tr.hit_normal = (ray.o + render_pbest * ray.dir - render_pbest_c) / r;
    return true;
}

#endif /* RENDER_TRAVERSE_PARTICLES */

#endif
