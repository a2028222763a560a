#version 450
/* Ray-casting of the sign-bit map, one invocation per pixel (DESIGN.md
 * section 5; Reichl, Weiss, Westermann 2016, section 5): the chunk and
 * octree walk of shaders/render_walk.glsl.h with the `surface` traverser
 * (shaders/render_traverse.glsl.h), then the sub-voxel refinement below.
 * Outputs: camera depth of the hit (0: none) and the level of its brick
 * (FUSION_NONE: none); render_shade.comp derives normals and colour.
 */
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_buffer_reference_uvec2 : require
#include "fusion.glsl.h"
#include "render.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

layout(std430, binding = RENDER_RC_ADDR) readonly buffer Addr { uvec2 a[FUSION_ADDRS]; } addr;
layout(std430, binding = RENDER_RC_DEPTH) writeonly buffer Depth { float v[]; } depth_out;
layout(std430, binding = RENDER_RC_LEVEL) writeonly buffer Level { uint v[]; } level_out;
layout(std430, binding = RENDER_RC_START) readonly buffer Start { float v[]; } start_in;
layout(std430, binding = RENDER_RC_CMASK) readonly buffer ColourMask { uint w[]; } cmask;
layout(std430, binding = RENDER_RC_CPOOL) readonly buffer ColourPool { uint w[]; } cpool;
layout(std430, binding = RENDER_RC_RGB) writeonly buffer SurfaceColour { uint v[]; } rgb_out;
layout(std430, binding = RENDER_RC_CHEAD) readonly buffer ColourHead { uint w[]; } chead;

/* The map's words through their addresses (a gather on lavapipe, where a
 * load through a binding at a per-lane index is a loop over the lanes). No
 * bounds check: the walk's indices come from the map's own links. */
layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer MapWords { uint w[]; };

layout(push_constant) uniform Push { render_push pc; };

uint render_sign_word(uint slot, uint w) { return MapWords(addr.a[FUSION_ADDR_SIGN]).w[slot * BRICK_WORDS + w]; }
uint render_conf_word(uint slot, uint w) { return MapWords(addr.a[FUSION_ADDR_CONF]).w[slot * BRICK_WORDS + w]; }

uint fusion_hash_word(uint i) { return MapWords(addr.a[FUSION_ADDR_HASH]).w[i]; }
uint render_node_word(uint i) { return MapWords(addr.a[FUSION_ADDR_NODES]).w[i]; }

#include "render_traverse.glsl.h"

render_walk_map walk_map()
{
    return render_walk_map(pc.view.chunk_m, pc.view.max_level, pc.view.n_buckets, pc.view.n_overflow, RENDER_MAX_CELLS);
}

/* ---------------------------------------------------- sub-voxel refinement
 *
 * The sign bits put a surface somewhere between two voxel centres, so the
 * midpoint hit is a staircase of voxel-sized plateaus on any slanted surface,
 * which point-to-plane ICP cannot tell from a tilted or shifted plane (it
 * pulled a static camera ~1 voxel off). Averaging the bits over a
 * neighbourhood recovers the sub-voxel position: the 3x3x3 mean of the signs
 * (+1 front, -1 behind, over the known voxels only) at the voxel centres,
 * interpolated trilinearly between the centres, is a smooth field F whose
 * zero set follows a plane to a fraction of a voxel (the kernel, a box of 3
 * convolved with the trilinear tent, is flat over +-1 voxel along an axis,
 * so the filtered step is linear there; export/export_mesh.c places mesh
 * vertices on the same field). The refined depth is that of F's zero on the
 * ray, found by Newton steps from the midpoint. On a plane parallel to the
 * image the field is symmetric about the face between the voxel layers, so
 * such a plane stays exactly flat at that face. */

/* Sign and known bits of the 4x4x4 voxels [B, B + 3] of `level` (voxel
 * coordinates from the map origin), bit x + 4y + 16z of a 64-bit word kept
 * as two uints. A voxel is known when its brick exists (and, confident_only,
 * it is confident). Rows along x are read a nibble (4 voxels, one sub-brick
 * row) at a time: 32 word reads for 64 voxels. */
void gather_block(ivec3 B, uint level, uint hit_slot, ivec3 hit_brick, bool confident_only, out uvec2 sgn,
                  out uvec2 known)
{
    ivec3 b0 = B >> 3, b1 = (B + 3) >> 3;
    uint slots[8];
    for (uint i = 0u; i < 8u; i++) {
        ivec3 b = b0 + ivec3(int(i & 1u), int((i >> 1) & 1u), int(i >> 2));
        slots[i] = FUSION_NONE;
        if (all(lessThanEqual(b, b1))) slots[i] = b == hit_brick ? hit_slot : render_brick_at(walk_map(), b, level);
    }
    sgn = uvec2(0u);
    known = uvec2(0u);
    int x0 = B.x & ~3;
    uint xs = uint(B.x - x0);
    for (uint r = 0u; r < 16u; r++) {
        int Y = B.y + int(r & 3u), Z = B.z + int(r >> 2);
        uint row_s = 0u, row_k = 0u;
        for (uint h = 0u; h < 2u; h++) {
            ivec3 X = ivec3(x0 + 4 * int(h), Y, Z);
            ivec3 bb = (X >> 3) - b0;
            uint slot = slots[bb.x + 2 * bb.y + 4 * bb.z];
            if (slot != FUSION_NONE) {
                uvec3 l = uvec3(X & 7);
                uint w = brick_word(l.x, l.y, l.z), sh = brick_bit(l.x, l.y, l.z);
                uint k = confident_only ? (render_conf_word(slot, w) >> sh) & 15u : 15u;
                row_s |= ((render_sign_word(slot, w) >> sh) & k) << (4u * h);
                row_k |= k << (4u * h);
            }
        }
        uint sh = 4u * (r & 3u) + 16u * ((r >> 2) & 1u);
        if ((r >> 3) == 0u) {
            sgn.x |= ((row_s >> xs) & 15u) << sh;
            known.x |= ((row_k >> xs) & 15u) << sh;
        } else {
            sgn.y |= ((row_s >> xs) & 15u) << sh;
            known.y |= ((row_k >> xs) & 15u) << sh;
        }
    }
}

/* RGB565 of the voxel that holds map point p, in brick `slot` (brick
 * coordinates `brick` on its level's grid) or, outside it, in the brick of
 * the same level next to it; 0 without colour. */
uint voxel_colour(uint slot, ivec3 brick, uint level, vec3 p)
{
    float v = fusion_voxel_m(pc.view.chunk_m, level);
    ivec3 G = BF_TRUNC_I32(floor(p / v)), nb = G >> 3;
    if (nb != brick) slot = render_brick_at(walk_map(), nb, level);
    if (slot == FUSION_NONE) return 0u;
    ivec3 g = G - nb * 8;
    uint w = brick_word(uint(g.x), uint(g.y), uint(g.z)), bit = brick_bit(uint(g.x), uint(g.y), uint(g.z));
    uint mask = cmask.w[slot * BRICK_WORDS + w];
    if (((mask >> bit) & 1u) == 0u) return 0u;
    /* Its rank among the brick's coloured voxels, then along the chain. */
    uint r = uint(bitCount(mask & ((1u << bit) - 1u)));
    for (uint k = 0u; k < w; k++) r += uint(bitCount(cmask.w[slot * BRICK_WORDS + k]));
    uint u = chead.w[slot];
    for (uint k = r / FUSION_COLOUR_UNIT_COLOURS; k > 0u && u != FUSION_NONE; k--) u = cpool.w[u * FUSION_COLOUR_UNIT_WORDS];
    if (u == FUSION_NONE) return 0u;
    uint j = r % FUSION_COLOUR_UNIT_COLOURS;
    uint word = cpool.w[u * FUSION_COLOUR_UNIT_WORDS + 1u + j / 2u];
    return (j & 1u) != 0u ? word >> 16 : word & 0xFFFFu;
}

/* The colour at a hit: the voxel holding it, else the nearest along the
 * ray within 1.2 voxels either way, else one of its six face neighbours
 * (colour lives in a shell about a voxel thick around the surface, which a
 * grazing ray can cross beside the voxel it hits), else one of the voxels
 * at L1 distance 2 (a surface voxel no frame coloured takes its colour
 * along the surface, as the export does: the colour trim keeps none off
 * the surface, docs/colour.md). */
uint hit_colour(render_ray ray, render_trace tr)
{
    float v = fusion_voxel_m(pc.view.chunk_m, tr.hit_level);
    vec3 p = ray.o + tr.hit_depth * ray.dir;
    vec3 dir = normalize(ray.dir);
    uint c = voxel_colour(tr.hit_slot, tr.hit_brick, tr.hit_level, p);
    for (uint k = 1u; k <= 4u && c == 0u; k++) {
        float t = 0.6 * float((k + 1u) / 2u) * ((k & 1u) != 0u ? -1.0 : 1.0);
        c = voxel_colour(tr.hit_slot, tr.hit_brick, tr.hit_level, p + (t * v) * dir);
    }
    for (uint k = 0u; k < 6u && c == 0u; k++) {
        vec3 o = vec3(0.0);
        o[k / 2u] = (k & 1u) != 0u ? -v : v;
        c = voxel_colour(tr.hit_slot, tr.hit_brick, tr.hit_level, p + o);
    }
    /* Distance 2: two along an axis (k < 6), or one along each of two (the 12 edges). */
    for (uint k = 0u; k < 18u && c == 0u; k++) {
        vec3 o = vec3(0.0);
        if (k < 6u) {
            o[k / 2u] = (k & 1u) != 0u ? -2.0 * v : 2.0 * v;
        } else {
            uint e = k - 6u, a = e / 4u, b = (a + 1u) % 3u;
            o[a] = (e & 1u) != 0u ? -v : v;
            o[b] = (e & 2u) != 0u ? -v : v;
        }
        c = voxel_colour(tr.hit_slot, tr.hit_brick, tr.hit_level, p + o);
    }
    return c;
}

/* Depth of the zero of the smoothed sign field on the ray, from the
 * midpoint depth s0 of the two voxel centres of a hit in brick (slot,
 * brick) at level. */
float subvoxel_depth(render_ray ray, uint level, uint slot, ivec3 brick, float s0, bool confident_only, bool want_f,
                     out float f_end)
{
    float v = fusion_voxel_m(pc.view.chunk_m, level), inv_v = 1.0 / v;
    float step_max = RENDER_SUBVOXEL_MAX_STEP * v / length(ray.dir);
    float lo = s0 - RENDER_SUBVOXEL_MAX_MOVE * step_max, hi = s0 + RENDER_SUBVOXEL_MAX_MOVE * step_max;
    float s = s0;
    ivec3 G = ivec3(0x7FFFFFFF);
    float S[8];
    f_end = 1.0;
    /* With want_f one evaluation more than steps: f_end is the field where s ends. */
    uint n_eval = want_f ? RENDER_SUBVOXEL_ITERS + 1u : RENDER_SUBVOXEL_ITERS;
    for (uint it = 0u; it < n_eval; it++) {
        /* Voxel-centre coordinates: centre of voxel i at q = i. */
        vec3 q = (ray.o + s * ray.dir) * inv_v - 0.5;
        ivec3 Gn = BF_TRUNC_I32(floor(q));
        if (Gn != G) {
            /* The 3x3x3 means at the 8 centres around the point: boxes of
             * the 4x4x4 block around them. */
            G = Gn;
            uvec2 sgn, known;
            gather_block(G - 1, level, slot, brick, confident_only, sgn, known);
            for (uint c = 0u; c < 8u; c++) {
                uint i = c & 1u, j = (c >> 1) & 1u, k = c >> 2;
                uint pm = 0x777u << (i + 4u * j);
                uvec2 m = k == 0u ? uvec2(pm | (pm << 16), pm) : uvec2(pm << 16, pm | (pm << 16));
                int nf = bitCount(sgn.x & m.x) + bitCount(sgn.y & m.y);
                int nk = bitCount(known.x & m.x) + bitCount(known.y & m.y);
                S[c] = nk > 0 ? float(2 * nf - nk) / float(nk) : 0.0;
            }
        }
        vec3 f = q - vec3(G);
        float F = 0.0;
        vec3 g = vec3(0.0);
        for (uint c = 0u; c < 8u; c++) {
            vec3 e = vec3(float(c & 1u), float((c >> 1) & 1u), float(c >> 2));
            vec3 w = mix(1.0 - f, f, e), sgnd = 2.0 * e - 1.0;
            F += w.x * w.y * w.z * S[c];
            g += sgnd * vec3(w.y * w.z, w.x * w.z, w.x * w.y) * S[c];
        }
        f_end = F;
        if (it == RENDER_SUBVOXEL_ITERS) break;
        float dFds = dot(g, ray.dir) * inv_v;
        if (!(dFds < 0.0)) break; /* the field must fall into the surface */
        s = clamp(s - clamp(F / dFds, -step_max, step_max), lo, hi);
    }
    return s;
}

void main()
{
    uvec2 px = gl_GlobalInvocationID.xy;
    if (px.x >= pc.view.width || px.y >= pc.view.height) return;
    uint pixel = px.y * pc.view.width + px.x;
    render_ray ray = render_pixel_ray(px, pc.view.R, pc.view.t, pc.view.fx, pc.view.fy, pc.view.cx, pc.view.cy);

    render_trace tr;
    tr.has_front = 0u;
    tr.front_depth = 0.0;
    tr.hit_depth = 0.0;
    tr.hit_level = FUSION_NONE;

    float s = pc.view.near_m;
    if ((pc.flags & RENDER_FLAG_START) != 0u) {
        /* Skip the free space in front of a surface the caller knows (the
         * frame just fused at this pose): the walk's per-cell cost is what
         * a ray pays, and most of a ray's cells lie before its hit. */
        float z0 = start_in.v[pc.start_off + pixel];
        if (z0 > 0.0) s = max(s, z0 - (pc.start_margin_m + pc.start_margin_z2 * z0 * z0));
    }
    bool hit = render_walk(walk_map(), ray, s, pc.view.far_m, pc.flags, tr), refined = false;
    /* no_graze: a hit whose refined depth stays in front of the smoothed
     * surface grazed a behind voxel's corner; the walk goes on behind it, as
     * from unknown space. */
    for (uint n_graze = 0u; hit && (pc.flags & RENDER_FLAG_NO_GRAZE) != 0u && (pc.flags & RENDER_FLAG_REFINE) != 0u;) {
        float f_end;
        float d = subvoxel_depth(ray, tr.hit_level, tr.hit_slot, tr.hit_brick, tr.hit_depth,
                                 (pc.flags & RENDER_FLAG_CONFIDENT_ONLY) != 0u, true, f_end);
        if (!(f_end > RENDER_GRAZE_F) || ++n_graze > RENDER_GRAZE_MAX) {
            tr.hit_depth = d;
            refined = true;
            break;
        }
        tr.has_front = 0u;
        hit = render_walk(walk_map(), ray, render_nudged(tr.hit_s_exit), pc.view.far_m, pc.flags, tr);
    }
    float f_unused;
    if (hit && !refined && (pc.flags & RENDER_FLAG_REFINE) != 0u)
        tr.hit_depth = subvoxel_depth(ray, tr.hit_level, tr.hit_slot, tr.hit_brick, tr.hit_depth,
                                      (pc.flags & RENDER_FLAG_CONFIDENT_ONLY) != 0u, false, f_unused);
    depth_out.v[pc.depth_off + pixel] = hit ? tr.hit_depth : 0.0;
    level_out.v[pixel] = hit ? tr.hit_level : FUSION_NONE;
    if ((pc.flags & RENDER_FLAG_COLOUR) != 0u) rgb_out.v[pixel] = hit ? hit_colour(ray, tr) : 0u;
}
