#version 450
/* Colour of a window slice's bricks (DESIGN.md section 3): after the
 * slice's integration, every confident voxel within the depth noise of a
 * frame's measured surface takes that frame's colour, weighted by the
 * viewing angle and the distance (fusion_colour_weight), averaged over a
 * subset of the window's frames (push: frame_first + k * frame_stride),
 * then blended half and half with the colour it had. The brick's colours
 * are then packed again in popcount order (fusion.glsl.h, "colour"): a
 * brick whose coloured voxels outgrow its chain takes units off the colour
 * free stack; a voxel that is no longer confident gives its colour up.
 *
 * One workgroup per brick of the list, FUSION_COLOUR_LOCAL invocations of
 * 8 voxels each (voxel v = tid + k * 64: neighbouring lanes, neighbouring
 * x). The frames' stepping is that of the integration (fusion_step), so a
 * voxel lands on the pixel the integration read. */
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_buffer_reference_uvec2 : require
#extension GL_EXT_control_flow_attributes : require
#include "fusion.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

layout(std430, binding = 0) readonly buffer Hash { uint w[]; } hash;
layout(std430, binding = 1) readonly buffer Info { uint w[]; } info;
layout(std430, binding = 2) readonly buffer Conf { uint w[]; } conf_pool;
layout(std430, binding = 3) readonly buffer Frames { fusion_frame f[]; } frames;
layout(std430, binding = 4) readonly buffer Addr { uvec2 a[FUSION_ADDRS]; } addr;
layout(std430, binding = 5) readonly buffer List { uint w[]; } list;
layout(std430, binding = 6) buffer ColourMask { uint w[]; } cmask;
layout(std430, binding = 7) buffer ColourPool { uint w[]; } cpool;
layout(std430, binding = 8) buffer Counters { uint w[]; } cnt;
layout(std430, binding = 9) buffer ColourFree { uint w[]; } cfree;
layout(std430, binding = 10) buffer ColourHead { uint w[]; } chead;
layout(std430, binding = 11) readonly buffer Sign { uint w[]; } sign_pool;
layout(std430, binding = 12) readonly buffer Nodes { uint w[]; } nodes;

/* The depth and colour rings, read through their addresses (the map's
 * table, FUSION_ADDR_*): a gather on lavapipe, where a load through a
 * binding at a per-lane index is a loop over the lanes. */
layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer RingWords { uint w[]; };
RingWords depth, colour_ring; /* main sets them */

layout(push_constant) uniform Push { fusion_colour_push pc; };

uint fusion_hash_word(uint i) { return hash.w[i]; }
#include "fusion_hash.glsl.h"

#define VPT 8u
#define COL_WORDS (BRICK_VOXELS / 2u)
#define PACK_WORDS (FUSION_COLOUR_MAX_UNITS * (FUSION_COLOUR_UNIT_WORDS - 1u))
shared uint s_conf[BRICK_WORDS], s_mask[BRICK_WORDS], s_new[BRICK_WORDS];
shared uint s_pre[BRICK_WORDS + 1u]; /* colours before each sub-brick (old masks, then new) */
shared uint s_col[COL_WORDS];        /* RGB565 per voxel, dense: voxel bit i of word w at w * 16 + i / 2 */
shared uint s_pack[PACK_WORDS];      /* the colours packed for the chain */
shared uint s_unit[FUSION_COLOUR_MAX_UNITS];
shared uint s_n_units, s_n_old_units, s_keep_old, s_changed;
shared uint s_visible, s_n_visible;
shared uint s_order[FUSION_COLOUR_MAX_FRAMES];
shared vec4 s_step[FUSION_COLOUR_MAX_FRAMES * 4u];
shared uint s_sign[BRICK_WORDS], s_s1[BRICK_WORDS], s_surf[BRICK_WORDS];
shared uint s_nb_slot[6];
/* The neighbour across face f, its two layers next to the face: voxel
 * (u, v) of layer l at bit i = u + 8 v of words 4 f + 2 l + i / 32. */
shared uint s_nb_sign[24], s_nb_conf[24];
shared uint s_nb_s1[12]; /* its layer 0's surface voxels: words 2 f + i / 32 */

/* Takes a colour unit off the free stack; FUSION_NONE when it is empty. */
uint pop_unit()
{
    int old = int(atomicAdd(cnt.w[FUSION_CNT_COLOUR_TOP], 0xFFFFFFFFu));
    if (old <= 0) {
        atomicAdd(cnt.w[FUSION_CNT_COLOUR_TOP], 1u);
        return FUSION_NONE;
    }
    return cfree.w[old - 1];
}

/* The colour ring's RGB565 at pixel i of ring image `base`. */
uint ring_colour(uint base, uint pixel)
{
    uint word = colour_ring.w[base + (pixel >> 1)];
    return (pixel & 1u) != 0u ? word >> 16 : word & 0xFFFFu;
}

/* Camera point of pixel (u, v) (centres at integers) at depth z. */
vec3 unproject(fusion_frame f, float u, float v, float z) { return vec3((u - f.cx) / f.fx * z, (v - f.cy) / f.fy * z, z); }

/* Slot of the brick at `level` with brick coordinate b (brick units on
 * that level's grid), FUSION_NONE when it does not exist (as the
 * ray-cast's render_brick_at). */
uint brick_at(ivec3 b, uint level)
{
    ivec3 key = b >> int(level);
    uint e = fusion_find_chunk(key.x, key.y, key.z, pc.n_buckets, pc.n_overflow);
    if (e == FUSION_NONE) return FUSION_NONE;
    uvec3 cell = uvec3(b - (key << int(level)));
    uint node = hash.w[e * FUSION_ENTRY_WORDS + FUSION_ENTRY_ROOT];
    for (uint l = 1u; l <= level; l++) {
        uint child = nodes.w[node * FUSION_NODE_WORDS + FUSION_NODE_CHILD];
        if (child >= FUSION_LOCKED) return FUSION_NONE;
        uvec3 c = cell >> (level - l);
        node = child + fusion_octant(c.x, c.y, c.z);
    }
    uint slot = nodes.w[node * FUSION_NODE_WORDS + FUSION_NODE_BRICK];
    return slot < FUSION_LOCKED ? slot : FUSION_NONE;
}

/* Voxel (x, y, z) of the neighbour across face f = 2 * axis + (0: -1,
 * 1: +1) at layer l from the face, for face voxel (u, v). */
uvec3 face_voxel(uint f, uint l, uint u, uint v)
{
    uint a = f >> 1, at = (f & 1u) != 0u ? l : 7u - l;
    return a == 0u ? uvec3(at, u, v) : (a == 1u ? uvec3(u, at, v) : uvec3(u, v, at));
}

/* Where p (brick coordinates, at most one axis outside 0..7, by at most
 * two voxels) is: its face (6: inside the brick, 7: unknown), layer and
 * bit within the face's 64. */
uvec3 locate(ivec3 p)
{
    uint f = 6u, l = 0u;
    [[unroll]] for (uint a = 0u; a < 3u; a++) {
        if (p[a] >= 0 && p[a] < 8) continue;
        if (f != 6u) return uvec3(7u, 0u, 0u);
        f = 2u * a + (p[a] >= 8 ? 1u : 0u);
        l = uint(p[a] >= 8 ? p[a] - 8 : -1 - p[a]);
    }
    if (f == 6u) return uvec3(6u, 0u, 0u);
    uint a = f >> 1;
    uint u = uint(a == 0u ? p.y : p.x), v = uint(a == 2u ? p.y : p.z);
    return uvec3(f, l, u + 8u * v);
}

/* Confidence and sign of the voxel at p: bit 1 confident, bit 0 the sign;
 * 0 where unknown (outside the known layers), CS_NO_BRICK across a face
 * whose neighbour has no brick at this level. */
#define CS_NO_BRICK 4u
uint conf_sign(ivec3 p)
{
    uvec3 at = locate(p);
    if (at.x == 6u) {
        uint w = brick_word(uint(p.x), uint(p.y), uint(p.z)), b = brick_bit(uint(p.x), uint(p.y), uint(p.z));
        return (((s_conf[w] >> b) & 1u) << 1) | ((s_sign[w] >> b) & 1u);
    }
    if (at.x == 7u || at.y > 1u) return 0u;
    if (s_nb_slot[at.x] == FUSION_NONE) return CS_NO_BRICK;
    uint w = 4u * at.x + 2u * at.y + (at.z >> 5), b = at.z & 31u;
    return (((s_nb_conf[w] >> b) & 1u) << 1) | ((s_nb_sign[w] >> b) & 1u);
}

/* Whether the voxel at p is confident with a confident face neighbour of
 * the other sign, or one in a brick this level does not have (a coarser or
 * finer brick, or a chunk streamed out, may hold the other sign there: the
 * mesh and the points, which look across levels, may need the colour). */
bool is_s1(ivec3 p)
{
    uint c = conf_sign(p);
    if (c < 2u || c == CS_NO_BRICK) return false;
    bool s1 = false;
    [[unroll]] for (uint f = 0u; f < 6u; f++) {
        ivec3 q = p;
        q[f >> 1] += (f & 1u) != 0u ? 1 : -1;
        uint d = conf_sign(q);
        s1 = s1 || d == CS_NO_BRICK || (d >= 2u && d != c);
    }
    return s1;
}

/* The voxels that keep colour (s_surf): confident and within L1 distance
 * the reach in pc.mode (1 or 2) of a confident voxel of the other sign, from the
 * brick's signs and those of the six neighbouring bricks at its level (two
 * layers each; a neighbour at another level counts as unknown). */
void surface_mask(uint slot, ivec3 bc, uint level, uint tid)
{
    if (tid < BRICK_WORDS) s_sign[tid] = sign_pool.w[slot * BRICK_WORDS + tid], s_surf[tid] = 0u, s_s1[tid] = 0u;
    if (tid < 24u) s_nb_sign[tid] = 0u, s_nb_conf[tid] = 0u;
    if (tid < 12u) s_nb_s1[tid] = 0u;
    if (tid < 6u) {
        ivec3 nb = bc;
        nb[tid >> 1] += (tid & 1u) != 0u ? 1 : -1;
        s_nb_slot[tid] = brick_at(nb, level);
    }
    barrier();
    uint u = tid & 7u, v = tid >> 3;
    for (uint f = 0u; f < 6u; f++) {
        uint ns = s_nb_slot[f];
        if (ns == FUSION_NONE) continue; /* uniform */
        for (uint l = 0u; l < 2u; l++) {
            uvec3 p = face_voxel(f, l, u, v);
            uint w = brick_word(p.x, p.y, p.z), b = brick_bit(p.x, p.y, p.z);
            uint cb = (conf_pool.w[ns * BRICK_WORDS + w] >> b) & 1u;
            uint sb = (sign_pool.w[ns * BRICK_WORDS + w] >> b) & 1u;
            if (cb != 0u) atomicOr(s_nb_conf[4u * f + 2u * l + (tid >> 5)], 1u << (tid & 31u));
            if (sb != 0u) atomicOr(s_nb_sign[4u * f + 2u * l + (tid >> 5)], 1u << (tid & 31u));
        }
    }
    barrier();
    uint k_rule = (pc.mode >> 8) >= 2u ? 2u : 1u;
    for (uint k = 0u; k < VPT; k++) {
        uint i = tid + k * FUSION_COLOUR_LOCAL;
        uint x = i & 7u, y = (i >> 3) & 7u, z = i >> 6;
        if (is_s1(ivec3(x, y, z))) atomicOr(s_s1[brick_word(x, y, z)], 1u << brick_bit(x, y, z));
    }
    if (k_rule == 2u)
        for (uint f = 0u; f < 6u; f++) {
            if (s_nb_slot[f] == FUSION_NONE) continue; /* uniform */
            uint a = f >> 1;
            int at = (f & 1u) != 0u ? 8 : -1;
            ivec3 p = a == 0u ? ivec3(at, u, v) : (a == 1u ? ivec3(u, at, v) : ivec3(u, v, at));
            if (is_s1(p)) atomicOr(s_nb_s1[2u * f + (tid >> 5)], 1u << (tid & 31u));
        }
    barrier();
    for (uint k = 0u; k < VPT; k++) {
        uint i = tid + k * FUSION_COLOUR_LOCAL;
        uint x = i & 7u, y = (i >> 3) & 7u, z = i >> 6;
        uint w = brick_word(x, y, z), b = brick_bit(x, y, z);
        bool keep = ((s_s1[w] >> b) & 1u) != 0u;
        if (k_rule == 2u && ((s_conf[w] >> b) & 1u) != 0u)
            [[unroll]] for (uint f = 0u; f < 6u; f++) {
                ivec3 q = ivec3(x, y, z);
                q[f >> 1] += (f & 1u) != 0u ? 1 : -1;
                uvec3 at = locate(q);
                if (at.x == 6u)
                    keep = keep || ((s_s1[brick_word(uint(q.x), uint(q.y), uint(q.z))] >> brick_bit(uint(q.x), uint(q.y), uint(q.z))) & 1u) != 0u;
                else if (at.x < 6u && s_nb_slot[at.x] != FUSION_NONE)
                    keep = keep || ((s_nb_s1[2u * at.x + (at.z >> 5)] >> (at.z & 31u)) & 1u) != 0u;
            }
        if (keep) atomicOr(s_surf[w], 1u << b);
    }
    barrier();
}

/* The window's frames' colours of the brick's voxels, blended into s_col;
 * s_new the new masks, s_changed whether they or a colour changed. */
void colour_from_frames(uint tid, int key_x, int key_y, int key_z, uint cell_x, uint cell_y, uint cell_z,
                        float voxel_m)
{
    float lo_x = fusion_voxel_centre(key_x, cell_x, 0u, pc.chunk_m, voxel_m);
    float lo_y = fusion_voxel_centre(key_y, cell_y, 0u, pc.chunk_m, voxel_m);
    float lo_z = fusion_voxel_centre(key_z, cell_z, 0u, pc.chunk_m, voxel_m);
    float hi_x = fusion_voxel_centre(key_x, cell_x, 7u, pc.chunk_m, voxel_m);
    float hi_y = fusion_voxel_centre(key_y, cell_y, 7u, pc.chunk_m, voxel_m);
    float hi_z = fusion_voxel_centre(key_z, cell_z, 7u, pc.chunk_m, voxel_m);
    uint n_frames = min(pc.n_frames, FUSION_COLOUR_MAX_FRAMES);
    if (tid < n_frames) {
        uint index = pc.frame_first + tid * pc.frame_stride, ring = index % pc.ring_slots;
        fusion_frame f = frames.f[ring];
        if (f.index == index && f.has_colour != 0u && fusion_box_culled(f, lo_x, lo_y, lo_z, hi_x, hi_y, hi_z) == 0u) {
            atomicOr(s_visible, 1u << tid);
            fusion_step st = fusion_step_make(f, lo_x, lo_y, lo_z, voxel_m);
            s_step[4u * tid + 0u] = vec4(st.h0.x, st.h0.y, st.h0.z, f.depth_unit_m);
            s_step[4u * tid + 1u] = vec4(st.sx.x, st.sx.y, st.sx.z, uintBitsToFloat(ring));
            s_step[4u * tid + 2u] = vec4(st.sy.x, st.sy.y, st.sy.z, uintBitsToFloat(f.width));
            s_step[4u * tid + 3u] = vec4(st.sz.x, st.sz.y, st.sz.z, uintBitsToFloat(f.height));
        }
    }
    barrier();
    uint vis = s_visible;
    uint n_visible = uint(bitCount(vis));
    if (n_visible == 0u) return; /* uniform: s_changed stays 0 */
    if (tid < n_frames && ((vis >> tid) & 1u) != 0u) s_order[uint(bitCount(vis & ((1u << tid) - 1u)))] = tid;
    barrier();

    vec4 acc[VPT];
    float acc_d[VPT];
    [[unroll]] for (uint k = 0u; k < VPT; k++) acc[k] = vec4(0.0), acc_d[k] = 0.0;
    uint r = 0u;
    do {
        uint j = s_order[r];
        vec4 a = s_step[4u * j + 0u], b = s_step[4u * j + 1u], c = s_step[4u * j + 2u], d = s_step[4u * j + 3u];
        fusion_step st;
        st.h0.x = a.x, st.h0.y = a.y, st.h0.z = a.z;
        st.sx.x = b.x, st.sx.y = b.y, st.sx.z = b.z;
        st.sy.x = c.x, st.sy.y = c.y, st.sy.z = c.z;
        st.sz.x = d.x, st.sz.y = d.y, st.sz.z = d.z;
        uint ring = floatBitsToUint(b.w), width = floatBitsToUint(c.w), height = floatBitsToUint(d.w);
        fusion_frame f = frames.f[ring];
        uint base = ring * pc.depth_words;
        [[unroll]] for (uint k = 0u; k < VPT; k++) {
            uint v = tid + k * FUSION_COLOUR_LOCAL;
            uint x = v & 7u, y = (v >> 3) & 7u, z = v >> 6;
            uint is_conf = (s_conf[brick_word(x, y, z)] >> brick_bit(x, y, z)) & 1u;
            fusion_point h = fusion_step_point(st, x, y, z);
            uint pixel = fusion_project_step(h, width, height);
            uint p0 = pixel != FUSION_NONE ? pixel : 0u;
            /* Its column and row as fusion_project_step found them: no
             * division by the width (lavapipe divides lane by lane). */
            uint pu = 0u, pv = 0u;
            if (pixel != FUSION_NONE) {
                BF_PRECISE float u = h.x / h.z;
                BF_PRECISE float v = h.y / h.z;
                pu = BF_TRUNC_U32(u), pv = BF_TRUNC_U32(v);
            }
            /* The pixel and its right and lower neighbours (clamped), for the normal. */
            uint u1 = pu + 1u < width ? pu + 1u : pu - 1u, v2 = pv + 1u < height ? pv + 1u : pv - 1u;
            uint p1 = pv * width + u1, p2 = v2 * width + pu;
            float d0 = float(fusion_depth_raw(depth.w[base + (p0 >> 1)], p0)) * a.w;
            float d1 = float(fusion_depth_raw(depth.w[base + (p1 >> 1)], p1)) * a.w;
            float d2 = float(fusion_depth_raw(depth.w[base + (p2 >> 1)], p2)) * a.w;
            float sigma = bf_sensor_sigma(d0, pc.sigma_a, pc.sigma_b, pc.sigma_c);
            float band = max(sigma, voxel_m);
            bool near = pixel != FUSION_NONE && is_conf != 0u && d0 > 0.0 && abs(d0 - h.z) < band;
            /* Normal from the depth image; a neighbour across an edge or
             * without depth leaves the sample at a fixed, low weight. */
            vec3 q0 = unproject(f, float(pu), float(pv), d0);
            vec3 q1 = unproject(f, float(u1), float(pv), d1);
            vec3 q2 = unproject(f, float(pu), float(v2), d2);
            vec3 n = cross(q1 - q0, q2 - q0);
            bool smooth_nb = d1 > 0.0 && d2 > 0.0 && abs(d1 - d0) < 4.0 * band && abs(d2 - d0) < 4.0 * band && dot(n, n) > 0.0;
            float cos_view = smooth_nb ? abs(dot(normalize(n), normalize(q0))) : 0.25;
            /* The colour pixel: the same one when registered, else the
             * voxel's camera point through T_colour_depth, the colour
             * camera's distortion and intrinsics. */
            uint cpix = p0;
            if (pc.registered == 0u) {
                vec3 pcam = vec3((h.x / h.z - 0.5 - f.cx) / f.fx * h.z, (h.y / h.z - 0.5 - f.cy) / f.fy * h.z, h.z);
                vec3 qv = vec3(pc.q[0], pc.q[1], pc.q[2]);
                vec3 pcol = pcam + 2.0 * cross(qv, cross(qv, pcam) + pc.q[3] * pcam) + vec3(pc.t[0], pc.t[1], pc.t[2]);
                float xn = pcol.x / pcol.z, yn = pcol.y / pcol.z;
                float xd = bf_distort_x(xn, yn, pc.dist[0], pc.dist[1], pc.dist[2], pc.dist[3], pc.dist[4]);
                float yd = bf_distort_y(xn, yn, pc.dist[0], pc.dist[1], pc.dist[2], pc.dist[3], pc.dist[4]);
                float cu = pc.cfx * xd + pc.ccx + 0.5, cv = pc.cfy * yd + pc.ccy + 0.5;
                bool inside = pcol.z > 0.0 && cu >= 0.0 && cv >= 0.0 && cu < float(width) && cv < float(height);
                near = near && inside;
                cpix = inside ? BF_TRUNC_U32(cv) * width + BF_TRUNC_U32(cu) : 0u;
            }
            uint c = ring_colour(base, cpix);
            float wgt = near ? fusion_colour_weight(cos_view, d0) : 0.0;
            acc[k] += wgt * vec4(float(bf_565_r(c)), float(bf_565_g(c)), float(bf_565_b(c)), 1.0);
            acc_d[k] += wgt * (d0 - h.z);
        }
    } while (++r < n_visible);

    /* New colours, blended with the old ones. */
    [[unroll]] for (uint k = 0u; k < VPT; k++) {
        uint v = tid + k * FUSION_COLOUR_LOCAL;
        uint x = v & 7u, y = (v >> 3) & 7u, z = v >> 6;
        uint w = brick_word(x, y, z), bit = brick_bit(x, y, z);
        /* Only the shell next to the surface: the voxels whose centre lies
         * within FUSION_COLOUR_SHELL voxels of the measured surface on
         * average (the band alone colours 2-4 voxels across it). */
        if (!(acc[k].w > 0.0) || !(abs(acc_d[k] / acc[k].w) < FUSION_COLOUR_SHELL * voxel_m)) continue;
        vec3 col = acc[k].rgb / acc[k].w;
        uint si = w * 16u + (bit >> 1), sh = (bit & 1u) * 16u;
        uint old = (s_col[si] >> sh) & 0xFFFFu;
        if (old != FUSION_COLOUR_NONE)
            col = 0.5 * (col + vec3(float(bf_565_r(old)), float(bf_565_g(old)), float(bf_565_b(old))));
        uint c = fusion_rgb565(col.r, col.g, col.b);
        /* Two voxels share a word: clear this half, then set it. */
        atomicAnd(s_col[si], ~(0xFFFFu << sh));
        atomicOr(s_col[si], c << sh);
        atomicOr(s_new[w], 1u << bit);
    }
    barrier();
    /* The new masks: the voxels coloured before or now, while confident. */
    if (tid < BRICK_WORDS) {
        uint m = (s_mask[tid] | s_new[tid]) & s_conf[tid];
        if (m != s_mask[tid] || s_new[tid] != 0u) atomicOr(s_changed, 1u);
        s_new[tid] = m;
    }
    barrier();
}

/* The trim (docs/colour.md, "Colour off the surface"): the brick's
 * colours farther than the reach from the surface taken off; s_new the
 * masks that stay, s_changed whether any went. */
void trim_masks(uint slot, uint pos, ivec3 key, uint tid)
{
    uint level = fusion_pos_level(pos);
    ivec3 bc = (key << int(level)) + ivec3(fusion_pos_x(pos), fusion_pos_y(pos), fusion_pos_z(pos));
    surface_mask(slot, bc, level, tid);
    if (tid < BRICK_WORDS) {
        uint m = s_mask[tid] & s_surf[tid];
        if (m != s_mask[tid]) atomicOr(s_changed, 1u);
        s_new[tid] = m;
    }
    barrier();
    /* A chain longer than its colours need (grown while colours were
     * taken, then fewer kept: confidence lost) gives its spare units back
     * even when the trim takes no colour. */
    if (tid == 0u) {
        uint total = 0u;
        for (uint w = 0u; w < BRICK_WORDS; w++) total += uint(bitCount(s_new[w]));
        if (s_n_units > (total + FUSION_COLOUR_UNIT_COLOURS - 1u) / FUSION_COLOUR_UNIT_COLOURS) s_changed = 1u;
    }
    barrier();
}

/* The brick's colours (s_col) packed again along its chain for the masks
 * s_new: a longer chain takes units off the free stack (a window slice),
 * a trimmed one gives its surplus back (the trim), never both in one
 * dispatch. */
void commit(uint slot, uint tid, bool trim)
{
    /* Units for the new count: the chain grows off the free stack; when
     * the stack runs dry the brick keeps its old masks (counted). */
    if (tid == 0u) {
        uint total = 0u;
        for (uint w = 0u; w < BRICK_WORDS; w++) total += uint(bitCount(s_new[w]));
        uint need = (total + FUSION_COLOUR_UNIT_COLOURS - 1u) / FUSION_COLOUR_UNIT_COLOURS;
        uint n = s_n_units;
        while (n < need && !trim) { /* the trim only pushes (it never needs more: its masks only lose bits) */
            uint u = pop_unit();
            if (u == FUSION_NONE) break;
            s_unit[n++] = u;
        }
        s_n_units = n;
        s_keep_old = n < need ? 1u : 0u;
        if (n < need) atomicAdd(cnt.w[FUSION_CNT_FAIL_COLOUR], 1u);
    }
    barrier();
    if (tid < BRICK_WORDS && s_keep_old != 0u) s_new[tid] = s_mask[tid];
    barrier();
    if (tid == 0u) {
        uint acc = 0u;
        for (uint w = 0u; w < BRICK_WORDS; w++) s_pre[w] = acc, acc += uint(bitCount(s_new[w]));
        s_pre[BRICK_WORDS] = acc;
    }
    for (uint i = tid; i < PACK_WORDS; i += FUSION_COLOUR_LOCAL) s_pack[i] = 0u;
    barrier();
    /* Pack: colour r of the brick to unit r / 14, slot r % 14. */
    for (uint i = tid; i < BRICK_VOXELS; i += FUSION_COLOUR_LOCAL) {
        uint w = i / 32u, bit = i % 32u;
        if (((s_new[w] >> bit) & 1u) == 0u) continue;
        uint r = s_pre[w] + uint(bitCount(s_new[w] & ((1u << bit) - 1u)));
        uint c = (s_col[w * 16u + (bit >> 1)] >> ((bit & 1u) * 16u)) & 0xFFFFu;
        uint k = r / FUSION_COLOUR_UNIT_COLOURS, j = r % FUSION_COLOUR_UNIT_COLOURS;
        atomicOr(s_pack[k * (FUSION_COLOUR_UNIT_WORDS - 1u) + j / 2u], c << ((j & 1u) * 16u));
    }
    barrier();
    uint used = (s_pre[BRICK_WORDS] + FUSION_COLOUR_UNIT_COLOURS - 1u) / FUSION_COLOUR_UNIT_COLOURS;
    for (uint i = tid; i < used * (FUSION_COLOUR_UNIT_WORDS - 1u); i += FUSION_COLOUR_LOCAL) {
        uint k = i / (FUSION_COLOUR_UNIT_WORDS - 1u), j = i % (FUSION_COLOUR_UNIT_WORDS - 1u);
        cpool.w[s_unit[k] * FUSION_COLOUR_UNIT_WORDS + 1u + j] = s_pack[i];
    }
    /* Links of the units just taken. */
    if (tid == 0u) {
        uint n_old = s_n_old_units, n = s_n_units;
        for (uint k = n_old; k < n; k++) {
            if (k == 0u) chead.w[slot] = s_unit[0];
            else cpool.w[s_unit[k - 1u] * FUSION_COLOUR_UNIT_WORDS] = s_unit[k];
            cpool.w[s_unit[k] * FUSION_COLOUR_UNIT_WORDS] = FUSION_NONE;
        }
        /* The trim: the chain ends after the units in use, the rest go back. */
        if (trim && used < n) {
            if (used == 0u) chead.w[slot] = FUSION_NONE;
            else cpool.w[s_unit[used - 1u] * FUSION_COLOUR_UNIT_WORDS] = FUSION_NONE;
            for (uint k = used; k < n; k++) cfree.w[atomicAdd(cnt.w[FUSION_CNT_COLOUR_TOP], 1u)] = s_unit[k];
        }
    }
    if (tid < BRICK_WORDS) cmask.w[slot * BRICK_WORDS + tid] = s_new[tid];
}

void colour_brick(uint slot, uint tid)
{
    uint chunk = info.w[slot * FUSION_BRICK_INFO_WORDS + FUSION_INFO_CHUNK];
    if (chunk == FUSION_NONE) return; /* uniform */
    uint pos = info.w[slot * FUSION_BRICK_INFO_WORDS + FUSION_INFO_POS];
    int key_x = int(hash.w[chunk * FUSION_ENTRY_WORDS + FUSION_ENTRY_X]);
    int key_y = int(hash.w[chunk * FUSION_ENTRY_WORDS + FUSION_ENTRY_Y]);
    int key_z = int(hash.w[chunk * FUSION_ENTRY_WORDS + FUSION_ENTRY_Z]);
    uint cell_x = fusion_pos_x(pos), cell_y = fusion_pos_y(pos), cell_z = fusion_pos_z(pos);
    float voxel_m = fusion_voxel_m(pc.chunk_m, fusion_pos_level(pos));
    if (tid < BRICK_WORDS) {
        s_conf[tid] = conf_pool.w[slot * BRICK_WORDS + tid];
        s_mask[tid] = cmask.w[slot * BRICK_WORDS + tid];
        s_new[tid] = 0u;
    }
    if (tid == 0u) s_visible = 0u, s_changed = 0u;
    barrier();
    uint any_conf = 0u;
    [[unroll]] for (uint w = 0u; w < BRICK_WORDS; w++) any_conf |= s_conf[w];
    if (any_conf == 0u) return; /* uniform: nothing to colour */
    /* The brick's chain and where each sub-brick's colours start on it. */
    if (tid == 0u) {
        uint n = 0u, u = chead.w[slot];
        while (u != FUSION_NONE && n < FUSION_COLOUR_MAX_UNITS) {
            s_unit[n++] = u;
            u = cpool.w[u * FUSION_COLOUR_UNIT_WORDS];
        }
        s_n_units = n, s_n_old_units = n;
        uint acc = 0u;
        for (uint w = 0u; w < BRICK_WORDS; w++) s_pre[w] = acc, acc += uint(bitCount(s_mask[w]));
        s_pre[BRICK_WORDS] = acc;
    }
    barrier();
    /* The old colours, dense (0 where a voxel has none). */
    for (uint i = tid; i < COL_WORDS; i += FUSION_COLOUR_LOCAL) {
        uint w = i / 16u, word = 0u;
        for (uint h = 0u; h < 2u; h++) {
            uint bit = (i % 16u) * 2u + h;
            if (((s_mask[w] >> bit) & 1u) == 0u) continue;
            uint r = s_pre[w] + uint(bitCount(s_mask[w] & ((1u << bit) - 1u)));
            uint k = r / FUSION_COLOUR_UNIT_COLOURS, j = r % FUSION_COLOUR_UNIT_COLOURS;
            if (k >= s_n_units) continue;
            uint c = cpool.w[s_unit[k] * FUSION_COLOUR_UNIT_WORDS + 1u + j / 2u];
            word |= ((j & 1u) != 0u ? c >> 16 : c & 0xFFFFu) << (16u * h);
        }
        s_col[i] = word;
    }

    bool trim = (pc.mode & 0xFFu) == FUSION_COLOUR_MODE_TRIM;
    if (trim) trim_masks(slot, pos, ivec3(key_x, key_y, key_z), tid);
    else colour_from_frames(tid, key_x, key_y, key_z, cell_x, cell_y, cell_z, voxel_m);
    if (s_changed == 0u) return; /* uniform: no colour moved */
    commit(slot, tid, trim);
}

void main()
{
    uint n_list = list.w[FUSION_LIST_COUNT];
    uint count = n_list > pc.first ? min(n_list - pc.first, pc.max_count) : 0u;
    uint group = gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x;
    depth = RingWords(addr.a[FUSION_ADDR_DEPTH_RING]);
    colour_ring = RingWords(addr.a[FUSION_ADDR_COLOUR_RING]);
    /* bricks_per_group consecutive entries: llvmpipe pays about 10 us to
     * start a workgroup (as for the integration). */
    for (uint b = 0u; b < pc.bricks_per_group; b++) {
        uint idx = group * pc.bricks_per_group + b;
        if (idx >= count) return; /* uniform */
        barrier(); /* the previous brick's reads of shared memory -> this brick's writes */
        colour_brick(list.w[FUSION_LIST_HEADER + pc.first + idx], gl_LocalInvocationID.x);
    }
}
