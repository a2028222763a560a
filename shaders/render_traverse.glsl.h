/* The brick traverser seam of the ray-caster (DESIGN.md section 5).
 *
 * The chunk and octree walk of shaders/render_raycast.comp hands every brick
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
 * The brick's bits come through two accessors the including shader defines,
 * so a brick loads only the words the ray touches:
 *   uint render_sign_word(uint slot, uint w);
 *   uint render_conf_word(uint slot, uint w);
 * The particle and mesh renderers will provide their own render_traverse
 * (same signature) and include the walk unchanged.
 *
 * This file is GLSL only.
 */
#ifndef BF_RENDER_TRAVERSE_GLSL_H
#define BF_RENDER_TRAVERSE_GLSL_H

#include "fusion.glsl.h"
#include "render.glsl.h"

/* A ray in the map frame: o + s dir, s = camera depth (dir has camera z 1). */
struct render_ray {
    vec3 o;
    vec3 dir;
    vec3 inv_dir; /* 1 / dir, components of dir kept away from 0 */
    vec3 zc;      /* the camera's optical axis in the map frame: depth(p) = dot(p - o, zc) */
};

/* State carried along the ray from brick to brick. */
struct render_trace {
    uint has_front;    /* a front voxel seen since the last unknown space */
    float front_depth; /* camera depth of its centre */
    float hit_depth;
    uint hit_level;
    uint hit_slot;     /* brick of the first behind voxel (the sub-voxel refinement starts there) */
    ivec3 hit_brick;   /* its brick coordinate on its level's grid (brick units from the map origin) */
    float hit_s_exit;  /* ray parameter where the ray leaves that voxel */
};

/* Nudge into a cell past its entry face before locating the voxel there
 * (metres of camera depth: 10 um, a hundredth of the finest voxel). */
#define RENDER_NUDGE 1.0e-5

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

#endif
