#version 450
/* The particle pass, one invocation per pixel (render/particles.c; Reichl's
 * dissertation, ch. 6): the chunk and octree walk of
 * shaders/render_walk.glsl.h over the particles' binary grid with the
 * `particles` traverser (shaders/render_traverse.glsl.h). It writes the
 * caster's images itself: depth, level, the sphere's normal and the shaded
 * colour. The walk runs on the particles' coarse level (max_level is that
 * level). The first dispatch covers the image; each later one only the rays
 * the last one left unfinished (a list and indirect group counts). With RENDER_PARTICLES_FLAG_KEEP_NEARER the pixel's existing hit
 * (the map's ray-cast, recorded just before) bounds the ray, and a pixel
 * the particles do not reach in front of it keeps it: one image with the
 * nearest hit of either. A dispatch walks a bounded number of cells per ray
 * and bounded work, and the next resumes the rays not done (render.glsl.h
 * says why).
 */
#extension GL_GOOGLE_include_directive : require
#include "fusion.glsl.h"
#include "render.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

layout(std430, binding = 0) readonly buffer Hash { uint w[]; } hash;
layout(std430, binding = 1) readonly buffer Nodes { uint w[]; } nodes;
layout(std430, binding = 2) readonly buffer Bits { uint w[]; } bits_pool;
layout(std430, binding = 3) buffer Depth { float v[]; } depth_io;
layout(std430, binding = 4) writeonly buffer Level { uint v[]; } level_out;
layout(std430, binding = 5) writeonly buffer Normal { vec4 v[]; } normal_out;
layout(std430, binding = 6) writeonly buffer Colour { uint v[]; } colour_out;
layout(std430, binding = 7) readonly buffer Reach { uint w[]; } reach_pool;
/* Per pixel: the depth where the ray resumes in the next dispatch; -1: done. */
layout(std430, binding = 8) buffer Resume { float v[]; } resume;
/* Two lists of pixels (width x height each): dispatch k appends the rays it
 * did not finish to list k % 2, which dispatch k + 1 walks; and per
 * dispatch RENDER_PARTICLES_ARGS_WORDS: the next dispatch's group counts
 * and the list's length (zeroed before the first). */
layout(std430, binding = 9) buffer Lists { uint v[]; } lists;
layout(std430, binding = 10) buffer Args { uint v[]; } args;
/* The centres' index (render/particles_bin.h): a brick of centres' slot
 * from its coarse cell. */
layout(std430, binding = 11) readonly buffer Index { uint w[]; } cindex;

layout(push_constant) uniform Push { render_particles_push pc; };

uint fusion_hash_word(uint i) { return hash.w[i]; }
uint render_node_word(uint i) { return nodes.w[i]; }
uint render_sign_word(uint slot, uint w) { return bits_pool.w[slot * BRICK_WORDS + w]; }
uint render_conf_word(uint slot, uint w) { return reach_pool.w[slot * BRICK_WORDS + w]; }
uint render_particles_index_word(uint i) { return cindex.w[i]; }

#include "render_walk.glsl.h"

float render_particle_radius_m() { return pc.radius_m; }
render_walk_map render_particle_map()
{
    return render_walk_map(pc.view.chunk_m, pc.view.max_level, pc.view.n_buckets, pc.view.n_overflow,
                           pc.limits & ((1u << RENDER_PARTICLES_LIMIT_CELL_BITS) - 1u));
}
uint render_particles_budget() { return pc.limits >> RENDER_PARTICLES_LIMIT_CELL_BITS; }
/* Level of detail (RENDER_PARTICLES_FLAG_LOD): a coarse cell of edge e
 * beyond depth lod_k * e is drawn as one sphere at its centre. Its spheres
 * then move by at most e sqrt(3) / 2, which is half a pixel's footprint
 * z cos(theta) / f from there on (theta: the image corner's ray, where the
 * footprint is smallest). Off: never. */
float render_particles_lod_k()
{
    if ((pc.flags & RENDER_PARTICLES_FLAG_LOD) == 0u) return 3.0e38;
    float ax = max(pc.view.cx + 0.5, float(pc.view.width) - 0.5 - pc.view.cx) / pc.view.fx;
    float ay = max(pc.view.cy + 0.5, float(pc.view.height) - 0.5 - pc.view.cy) / pc.view.fy;
    float cos_max = inversesqrt(1.0 + ax * ax + ay * ay);
    return sqrt(3.0) * max(pc.view.fx, pc.view.fy) / cos_max;
}

#define RENDER_TRAVERSE_PARTICLES
#include "render_traverse.glsl.h"

/* Appends an unfinished ray to this dispatch's list; the next dispatch
 * runs a workgroup per workgroup size of them. */
void append(uint pixel)
{
    uint k = pc.flags >> RENDER_PARTICLES_PASS_SHIFT, n_px = pc.view.width * pc.view.height;
    uint a = k * RENDER_PARTICLES_ARGS_WORDS;
    uint i = atomicAdd(args.v[a + 3u], 1u);
    lists.v[(k & 1u) * n_px + i] = pixel;
    atomicMax(args.v[a], i / (gl_WorkGroupSize.x * gl_WorkGroupSize.y) + 1u);
    args.v[a + 1u] = 1u;
    args.v[a + 2u] = 1u;
}

void main()
{
    uint pixel;
    uvec2 px;
    if ((pc.flags & RENDER_PARTICLES_FLAG_LIST) != 0u) {
        uint k = pc.flags >> RENDER_PARTICLES_PASS_SHIFT, n_px = pc.view.width * pc.view.height;
        uint i = gl_WorkGroupID.x * (gl_WorkGroupSize.x * gl_WorkGroupSize.y) + gl_LocalInvocationIndex;
        if (i >= args.v[(k - 1u) * RENDER_PARTICLES_ARGS_WORDS + 3u]) return;
        pixel = lists.v[((k - 1u) & 1u) * n_px + i];
        px = uvec2(pixel % pc.view.width, pixel / pc.view.width);
    } else {
        px = gl_GlobalInvocationID.xy;
        if (px.x >= pc.view.width || px.y >= pc.view.height) return;
        pixel = px.y * pc.view.width + px.x;
    }
    float s = (pc.flags & RENDER_PARTICLES_FLAG_FIRST) != 0u ? pc.view.near_m : resume.v[pixel];
    if (s < 0.0) return; /* done in an earlier dispatch */
    render_ray ray = render_pixel_ray(px, pc.view.R, pc.view.t, pc.view.fx, pc.view.fy, pc.view.cx, pc.view.cy);
    bool keep = (pc.flags & RENDER_PARTICLES_FLAG_KEEP_NEARER) != 0u;
    float far_m = pc.view.far_m;
    if (keep) {
        float z = depth_io.v[pixel];
        if (z > 0.0) far_m = min(far_m, z);
    }
    /* Only the set's box can hold a hit: the ray from where it enters the
     * box to where it leaves (a ray that misses it is done). */
    vec3 b0 = (vec3(pc.box_lo) - ray.o) * ray.inv_dir, b1 = (vec3(pc.box_hi[0], pc.box_hi[1], pc.box_hi[2]) - ray.o) * ray.inv_dir;
    vec3 bn = min(b0, b1), bx = max(b0, b1);
    s = max(s, max(bn.x, max(bn.y, bn.z)));
    far_m = min(far_m, min(bx.x, min(bx.y, bx.z)));
    render_trace tr;
    tr.has_front = 0u;
    tr.front_depth = 0.0;
    tr.hit_depth = 0.0;
    tr.hit_level = FUSION_NONE;
    tr.hit_normal = vec3(0.0);
    render_particles_cache_clear();
    bool walked = render_walk_from(render_particle_map(), ray, s, far_m, 0u, tr);
    bool paused = walked && tr.hit_level == RENDER_PARTICLES_PAUSED;
    if (paused) s = tr.hit_depth;
    bool hit = walked && !paused && tr.hit_depth < far_m;
    bool done = hit || s >= far_m || (pc.flags & RENDER_PARTICLES_FLAG_LAST) != 0u;
    resume.v[pixel] = done ? -1.0 : s;
    if (!done) {
        append(pixel);
        return;
    }
    if (hit) {
        /* The normal in camera coordinates: R^T n (R takes camera to map). */
        vec3 n = tr.hit_normal;
        vec3 nc = vec3(pc.view.R[0] * n.x + pc.view.R[3] * n.y + pc.view.R[6] * n.z, pc.view.R[1] * n.x + pc.view.R[4] * n.y + pc.view.R[7] * n.z,
                       pc.view.R[2] * n.x + pc.view.R[5] * n.y + pc.view.R[8] * n.z);
        vec3 view = normalize(vec3((float(px.x) - pc.view.cx) / pc.view.fx, (float(px.y) - pc.view.cy) / pc.view.fy, 1.0));
        depth_io.v[pixel] = tr.hit_depth;
        level_out.v[pixel] = tr.hit_level;
        normal_out.v[pixel] = vec4(nc, 0.0);
        colour_out.v[pixel] = render_shade_particle(-dot(nc, view), pc.rgb);
    } else if (!keep) {
        depth_io.v[pixel] = 0.0;
        level_out.v[pixel] = FUSION_NONE;
        normal_out.v[pixel] = vec4(0.0);
        colour_out.v[pixel] = 0u;
    }
}
