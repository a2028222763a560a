#version 450
/* Windowed integration of a list of bricks (DESIGN.md section 4): one
 * workgroup per brick of the list, each invocation FUSION_VOXELS_PER_THREAD
 * voxels (a specialization constant; 512 / it invocations). The per-voxel
 * math is the shared code of shaders/fusion.glsl.h; fusion/integrate_ref.c
 * runs the same functions on the CPU as the test oracle.
 *
 * Phases, separated by workgroup barriers:
 *  1. load the brick's record, chunk key and old sign / confidence words;
 *  2. for each chunk of FUSION_INTEGRATE_CHUNK frames: cull (brick, frame)
 *     pairs (a frame of the window that is in its ring slot and whose
 *     image the brick's box may reach) and keep the visible frames'
 *     stepping (fusion_step) in shared memory; then
 *  3. accumulate every voxel over the chunk's visible frames, in frame
 *     order, in registers (the voxel loop is unrolled); after the last
 *     chunk, a brick no frame sees is left as it is; sum the window's
 *     (voxel, frame) pairs and their sigma (integers) into shared memory;
 *  4. decide each voxel (prior, confidence, replacement rule), OR its bits
 *     into the new words;
 *  5. 16 invocations write the sign and confidence words, one the error. */
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require
#include "fusion.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC
layout(constant_id = BF_SPEC_USER) const uint VOXELS_PER_THREAD = 8u;

layout(std430, binding = 0) readonly buffer Hash { uint w[]; } hash;
layout(std430, binding = 1) buffer Info { uint w[]; } info;
layout(std430, binding = 2) buffer Sign { uint w[]; } sign_pool;
layout(std430, binding = 3) buffer Conf { uint w[]; } conf_pool;
layout(std430, binding = 4) readonly buffer Frames { fusion_frame f[]; } frames;
layout(std430, binding = 5) readonly buffer Depth { uint w[]; } depth;
layout(std430, binding = 6) readonly buffer List { uint w[]; } list;

layout(push_constant) uniform Push { fusion_integrate_push pc; };

shared uint s_old_sign[BRICK_WORDS], s_old_conf[BRICK_WORDS];
shared uint s_new_sign[BRICK_WORDS], s_new_conf[BRICK_WORDS];
/* Frames of the window are handled in chunks: per frame of the chunk,
 * whether the brick may be seen in it, and its stepping: h0 and the depth
 * unit, sx and the depth image's first word, sy and the width, sz and the
 * height. */
#define FUSION_INTEGRATE_CHUNK 64u
shared uint s_visible[FUSION_INTEGRATE_CHUNK];
shared vec4 s_step[FUSION_INTEGRATE_CHUNK * 4u];
shared uint s_pairs, s_sigma_um, s_set, s_seen;

/* Confident voxels of each sign: s_target[0] holds those of sign 0 (the
 * targets of the prior's sweep from a front voxel), s_target[1] those of
 * sign 1. */
shared uint s_target[2][BRICK_WORDS];

/* The sweep's rows through voxel (x, y, z) (fusion_prior_steps): bits of
 * t's voxels (0..7, y, z), (x, 0..7, z) and (x, y, 0..7), gathered from 2,
 * 2 and 4 words instead of 24 bit reads. */
uint row_x(uint t, uint y, uint z)
{
    uint w = brick_word(0u, y, z), sh = brick_bit(0u, y, z);
    return ((s_target[t][w] >> sh) & 15u) | (((s_target[t][w + 1u] >> sh) & 15u) << 4);
}
uint row_y(uint t, uint x, uint z)
{
    uint r = 0u;
    for (uint h = 0u; h < 2u; h++) {
        uint w = s_target[t][brick_word(x, 4u * h, z)] >> brick_bit(x, 0u, z);
        r |= ((w & 1u) | ((w >> 3) & 2u) | ((w >> 6) & 4u) | ((w >> 9) & 8u)) << (4u * h);
    }
    return r;
}
uint row_z(uint t, uint x, uint y)
{
    uint r = 0u;
    for (uint pair = 0u; pair < 4u; pair++) {
        uint w = s_target[t][brick_word(x, y, 2u * pair)] >> brick_bit(x, y, 0u);
        r |= ((w & 1u) | ((w >> 15) & 2u)) << (2u * pair);
    }
    return r;
}

void main()
{
    uint n_list = list.w[FUSION_LIST_COUNT];
    uint count = n_list > pc.first ? min(n_list - pc.first, pc.max_count) : 0u;
    uint idx = gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x;
    if (idx >= count) return; /* uniform over the workgroup: before any barrier */
    uint slot = list.w[FUSION_LIST_HEADER + pc.first + idx];
    uint tid = gl_LocalInvocationID.x, n_threads = gl_WorkGroupSize.x;

    /* 1. The brick. A slot freed since the list was gathered (empty-brick
     * removal) has no chunk: nothing to do. */
    uint chunk = info.w[slot * FUSION_BRICK_INFO_WORDS + FUSION_INFO_CHUNK];
    if (chunk == FUSION_NONE) return; /* uniform: before any barrier */
    uint pos = info.w[slot * FUSION_BRICK_INFO_WORDS + FUSION_INFO_POS];
    float brick_err = uintBitsToFloat(info.w[slot * FUSION_BRICK_INFO_WORDS + FUSION_INFO_ERROR]);
    int key_x = int(hash.w[chunk * FUSION_ENTRY_WORDS + FUSION_ENTRY_X]);
    int key_y = int(hash.w[chunk * FUSION_ENTRY_WORDS + FUSION_ENTRY_Y]);
    int key_z = int(hash.w[chunk * FUSION_ENTRY_WORDS + FUSION_ENTRY_Z]);
    uint cell_x = fusion_pos_x(pos), cell_y = fusion_pos_y(pos), cell_z = fusion_pos_z(pos);
    float voxel_m = fusion_voxel_m(pc.chunk_m, fusion_pos_level(pos));
    for (uint w = tid; w < BRICK_WORDS; w += n_threads) { /* loops: any workgroup size works */
        uint sign = sign_pool.w[slot * BRICK_WORDS + w], conf = conf_pool.w[slot * BRICK_WORDS + w];
        s_old_sign[w] = sign;
        s_old_conf[w] = conf;
        s_new_sign[w] = 0u;
        s_new_conf[w] = 0u;
        s_target[0][w] = conf & ~sign;
        s_target[1][w] = conf & sign;
    }
    if (tid == 0u) {
        s_pairs = 0u;
        s_sigma_um = 0u;
        s_set = 0u;
        s_seen = 0u;
    }
    barrier(); /* the zeroed shared words -> phases 2 and 3 */

    float lo_x = fusion_voxel_centre(key_x, cell_x, 0u, pc.chunk_m, voxel_m);
    float lo_y = fusion_voxel_centre(key_y, cell_y, 0u, pc.chunk_m, voxel_m);
    float lo_z = fusion_voxel_centre(key_z, cell_z, 0u, pc.chunk_m, voxel_m);
    float hi_x = fusion_voxel_centre(key_x, cell_x, 7u, pc.chunk_m, voxel_m);
    float hi_y = fusion_voxel_centre(key_y, cell_y, 7u, pc.chunk_m, voxel_m);
    float hi_z = fusion_voxel_centre(key_z, cell_z, 7u, pc.chunk_m, voxel_m);
    uint n_frames = min(pc.n_frames, FUSION_INTEGRATE_MAX_FRAMES);
    /* Invocation tid owns voxels tid + k * n_threads: the lanes of a
     * subgroup take neighbouring x, so they read neighbouring pixels. The
     * k loops are unrolled, so acc[] lives in registers. */
    fusion_acc acc[VOXELS_PER_THREAD];
    [[unroll]] for (uint k = 0u; k < VOXELS_PER_THREAD; k++) acc[k] = fusion_acc_zero();
    for (uint c0 = 0u; c0 < n_frames; c0 += FUSION_INTEGRATE_CHUNK) {
        uint n_chunk = min(n_frames - c0, FUSION_INTEGRATE_CHUNK);
        /* 2. Cull (brick, frame) pairs on the box of the voxel centres; keep
         * the visible frames' stepping. */
        for (uint j = tid; j < n_chunk; j += n_threads) {
            uint index = pc.frame_first + c0 + j, ring = index % pc.ring_slots;
            fusion_frame f = frames.f[ring];
            uint visible = f.index == index && fusion_box_culled(f, lo_x, lo_y, lo_z, hi_x, hi_y, hi_z) == 0u ? 1u : 0u;
            s_visible[j] = visible;
            if (visible != 0u) {
                fusion_step st = fusion_step_make(f, lo_x, lo_y, lo_z, voxel_m);
                s_step[4u * j + 0u] = vec4(st.h0.x, st.h0.y, st.h0.z, f.depth_unit_m);
                s_step[4u * j + 1u] = vec4(st.sx.x, st.sx.y, st.sx.z, uintBitsToFloat(ring * pc.depth_words));
                s_step[4u * j + 2u] = vec4(st.sy.x, st.sy.y, st.sy.z, uintBitsToFloat(f.width));
                s_step[4u * j + 3u] = vec4(st.sz.x, st.sz.y, st.sz.z, uintBitsToFloat(f.height));
                s_seen = 1u; /* every writer stores 1 */
            }
        }
        barrier(); /* s_visible, s_step -> the accumulation */

        /* 3. Accumulate, in frame order. */
        for (uint j = 0u; j < n_chunk; j++) {
            if (s_visible[j] == 0u) continue;
            vec4 a = s_step[4u * j + 0u], b = s_step[4u * j + 1u], c = s_step[4u * j + 2u], d = s_step[4u * j + 3u];
            fusion_step st;
            st.h0.x = a.x, st.h0.y = a.y, st.h0.z = a.z;
            st.sx.x = b.x, st.sx.y = b.y, st.sx.z = b.z;
            st.sy.x = c.x, st.sy.y = c.y, st.sy.z = c.z;
            st.sz.x = d.x, st.sz.y = d.y, st.sz.z = d.z;
            uint base = floatBitsToUint(b.w), width = floatBitsToUint(c.w), height = floatBitsToUint(d.w);
            [[unroll]] for (uint k = 0u; k < VOXELS_PER_THREAD; k++) {
                uint v = tid + k * n_threads;
                fusion_point h = fusion_step_point(st, v & 7u, (v >> 3) & 7u, v >> 6);
                uint pixel = fusion_project_step(h, width, height);
                /* Fetched by every lane (pixel 0 when there is none): no
                 * divergent load. Raw 0 observes nothing. */
                uint word = depth.w[base + (pixel != FUSION_NONE ? pixel >> 1 : 0u)];
                uint raw = pixel != FUSION_NONE ? fusion_depth_raw(word, pixel) : 0u;
                acc[k] = fusion_acc_add(acc[k], fusion_observe(raw, a.w, h.z, pc.sigma_a, pc.sigma_b, pc.sigma_c));
            }
        }
        barrier(); /* the chunk's reads of s_visible and s_step -> the next chunk's writes; s_seen -> below */
    }
    /* No frame sees the brick: every voxel keeps its bits, no error is set. */
    if (s_seen == 0u) return; /* uniform: s_seen is not written after the last barrier */
    uint pairs = 0u, sigma_um = 0u;
    [[unroll]] for (uint k = 0u; k < VOXELS_PER_THREAD; k++) {
        pairs += acc[k].n;
        sigma_um += acc[k].sigma_um;
    }
    if (pairs != 0u) {
        atomicAdd(s_pairs, pairs);
        atomicAdd(s_sigma_um, sigma_um);
    }
    barrier(); /* the window's pair count and sigma sum -> phase 4 */

    /* 4. Decide. */
    float window_err = fusion_window_error(s_pairs, s_sigma_um);
    uint has_conf = 0u;
    for (uint w = 0u; w < BRICK_WORDS; w++) has_conf |= s_old_conf[w];
    uint may_replace = fusion_may_replace(pc.set_confidence, has_conf != 0u ? 1u : 0u, window_err, brick_err);
    float psi_conf = fusion_prior_psi(pc.prior_weight, window_err, brick_err);
    /* A thread's voxels that share a word (z and z + 1 when there are 64
     * threads) are ORed locally first: one shared atomic per word. */
    uint acc_word = FUSION_NONE, acc_sign = 0u, acc_conf = 0u, set = 0u;
    [[unroll]] for (uint k = 0u; k < VOXELS_PER_THREAD; k++) {
        uint v = tid + k * n_threads;
        uint x = v & 7u, y = (v >> 3) & 7u, z = v >> 6;
        uint word = brick_word(x, y, z), bit = brick_bit(x, y, z);
        uint old_sign = (s_old_sign[word] >> bit) & 1u, old_conf = (s_old_conf[word] >> bit) & 1u;
        float psi = 0.0f, phi = 0.0f;
        if (old_conf != 0u && pc.set_confidence != 0u && acc[k].n > 0u) { /* unobserved: kept, no prior needed */
            uint t = old_sign ^ 1u; /* confident voxels of the other sign */
            psi = psi_conf;
            phi = fusion_prior_phi(old_sign, fusion_prior_steps(row_x(t, y, z), row_y(t, x, z), row_z(t, x, y), x, y, z),
                                   voxel_m, window_err);
        }
        uint r = fusion_decide(old_sign, old_conf, acc[k], psi, phi, pc.conf_weight, pc.set_confidence, may_replace);
        if (word != acc_word) {
            if (acc_word != FUSION_NONE) {
                if (acc_sign != 0u) atomicOr(s_new_sign[acc_word], acc_sign);
                if (acc_conf != 0u) atomicOr(s_new_conf[acc_word], acc_conf);
            }
            acc_word = word;
            acc_sign = 0u;
            acc_conf = 0u;
        }
        if ((r & FUSION_DECIDE_SIGN) != 0u) acc_sign |= 1u << bit;
        if ((r & FUSION_DECIDE_CONF) != 0u) acc_conf |= 1u << bit;
        set |= r & FUSION_DECIDE_SET;
    }
    if (acc_sign != 0u) atomicOr(s_new_sign[acc_word], acc_sign);
    if (acc_conf != 0u) atomicOr(s_new_conf[acc_word], acc_conf);
    if (set != 0u) s_set = 1u; /* every writer stores 1: no race on the value */
    barrier(); /* the new words and s_set -> phase 5 */

    /* 5. Write back. The brick belongs to this workgroup alone. */
    for (uint w = tid; w < BRICK_WORDS; w += n_threads) {
        sign_pool.w[slot * BRICK_WORDS + w] = s_new_sign[w];
        conf_pool.w[slot * BRICK_WORDS + w] = s_new_conf[w];
    }
    if (tid == 0u && s_set != 0u && may_replace != 0u)
        info.w[slot * FUSION_BRICK_INFO_WORDS + FUSION_INFO_ERROR] = floatBitsToUint(window_err);
}
