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
 *  4. decide each voxel (prior, confidence, replacement rule) from the old
 *     words held in registers, OR its bits into the new words;
 *  5. 16 invocations write the sign and confidence words, one the error. */
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_buffer_reference_uvec2 : require
#include "fusion.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC
layout(constant_id = BF_SPEC_USER) const uint VOXELS_PER_THREAD = 8u;

layout(std430, binding = 0) readonly buffer Hash { uint w[]; } hash;
layout(std430, binding = 1) buffer Info { uint w[]; } info;
layout(std430, binding = 2) buffer Sign { uint w[]; } sign_pool;
layout(std430, binding = 3) buffer Conf { uint w[]; } conf_pool;
layout(std430, binding = 4) readonly buffer Frames { fusion_frame f[]; } frames;
/* Binding 5 is the depth ring, read through its address (pc.depth_addr_*). */
layout(std430, binding = 6) readonly buffer List { uint w[]; } list;

layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer DepthRing { uint w[]; };
layout(push_constant) uniform Push { fusion_integrate_push pc; };

shared uint s_old_sign[BRICK_WORDS], s_old_conf[BRICK_WORDS];
shared uint s_new_sign[BRICK_WORDS], s_new_conf[BRICK_WORDS];
/* Frames of the window are handled in chunks: per frame of the chunk,
 * whether the brick may be seen in it, and its stepping: h0 and the depth
 * unit, sx and the depth image's first word, sy and the width, sz and the
 * height. */
#define FUSION_INTEGRATE_CHUNK 64u
shared uint s_visible[FUSION_INTEGRATE_CHUNK / 32u]; /* bit per frame of the chunk */
shared uint s_order[FUSION_INTEGRATE_CHUNK];         /* the visible frames, in frame order */
shared vec4 s_step[FUSION_INTEGRATE_CHUNK * 4u];
shared uint s_pairs, s_sigma_um, s_set, s_seen;

/* One brick of the list; every return is uniform over the workgroup. */
void integrate_brick(uint slot, uint tid, uint n_threads)
{
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
    }
    for (uint w = tid; w < FUSION_INTEGRATE_CHUNK / 32u; w += n_threads) s_visible[w] = 0u;
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
    /* Loops are do-whiles: llvmpipe runs a for loop's body once more,
     * masked, when it ends. */
    uint c0 = 0u;
    if (n_frames != 0u) do {
        uint n_chunk = min(n_frames - c0, FUSION_INTEGRATE_CHUNK);
        /* 2. Cull (brick, frame) pairs on the box of the voxel centres; keep
         * the visible frames' stepping. */
        uint it = 0u, n_it = (n_chunk + n_threads - 1u) / n_threads;
        do {
            uint j = tid + it * n_threads;
            if (j >= n_chunk) continue;
            uint index = pc.frame_first + c0 + j, ring = index % pc.ring_slots;
            fusion_frame f = frames.f[ring];
            if (f.index == index && fusion_box_culled(f, lo_x, lo_y, lo_z, hi_x, hi_y, hi_z) == 0u) {
                atomicOr(s_visible[j >> 5], 1u << (j & 31u));
                fusion_step st = fusion_step_make(f, lo_x, lo_y, lo_z, voxel_m);
                s_step[4u * j + 0u] = vec4(st.h0.x, st.h0.y, st.h0.z, f.depth_unit_m);
                s_step[4u * j + 1u] = vec4(st.sx.x, st.sx.y, st.sx.z, uintBitsToFloat(ring * pc.depth_words));
                s_step[4u * j + 2u] = vec4(st.sy.x, st.sy.y, st.sy.z, uintBitsToFloat(f.width));
                s_step[4u * j + 3u] = vec4(st.sz.x, st.sz.y, st.sz.z, uintBitsToFloat(f.height));
            }
        } while (++it < n_it);
        barrier(); /* s_visible -> the ranks */
        /* The visible frames in frame order. llvmpipe runs every statement
         * of a kernel, masked, whether or not a lane needs it: a loop over
         * the visible frames alone is what saves the culled pairs' work. */
        uint vis0 = s_visible[0], vis1 = s_visible[1];
        uint n_visible = uint(bitCount(vis0) + bitCount(vis1));
        for (uint j = tid; j < n_chunk; j += n_threads) {
            uint below = j < 32u ? uint(bitCount(vis0 & ((1u << j) - 1u)))
                                 : uint(bitCount(vis0) + bitCount(vis1 & ((1u << (j - 32u)) - 1u)));
            uint bit = j < 32u ? (vis0 >> j) & 1u : (vis1 >> (j - 32u)) & 1u;
            if (bit != 0u) s_order[below] = j;
        }
        if (n_visible != 0u && tid == 0u) s_seen = 1u;
        barrier(); /* s_order, s_step -> the accumulation */

        /* 3. Accumulate, in frame order. */
        uint r = 0u;
        DepthRing depth = DepthRing(uvec2(pc.depth_addr_lo, pc.depth_addr_hi));
        if (n_visible != 0u) do {
            uint j = s_order[r];
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
        } while (++r < n_visible);
        barrier(); /* the chunk's reads of s_visible, s_order and s_step -> the next chunk's writes; s_seen -> below */
        for (uint w = tid; w < FUSION_INTEGRATE_CHUNK / 32u; w += n_threads) s_visible[w] = 0u;
        barrier(); /* the cleared bits -> the next chunk's atomics */
        c0 += FUSION_INTEGRATE_CHUNK;
    } while (c0 < n_frames);
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
    /* Every invocation keeps the old words in registers: the prior's rows
     * and the old bits are then picked with selects (word indices are
     * constants on a subgroup-sized workgroup, where x = tid), not with
     * shared loads, which llvmpipe runs lane by lane. */
    uint old_s[BRICK_WORDS], old_c[BRICK_WORDS], new_s[BRICK_WORDS], new_c[BRICK_WORDS];
    uint has_conf = 0u;
    [[unroll]] for (uint w = 0u; w < BRICK_WORDS; w++) {
        old_s[w] = s_old_sign[w];
        old_c[w] = s_old_conf[w];
        new_s[w] = 0u;
        new_c[w] = 0u;
        has_conf |= old_c[w];
    }
    uint may_replace = fusion_may_replace(pc.set_confidence, has_conf != 0u ? 1u : 0u, window_err, brick_err);
    float psi_conf = fusion_prior_psi(pc.prior_weight, window_err, brick_err);
    uint set = 0u;
    [[unroll]] for (uint k = 0u; k < VOXELS_PER_THREAD; k++) {
        uint v = tid + k * n_threads;
        uint x = v & 7u, y = (v >> 3) & 7u, z = v >> 6;
        uint wb = brick_word(0u, y, z), bit = brick_bit(x, y, z), hx = x >> 2;
        uint ws = hx != 0u ? old_s[wb + 1u] : old_s[wb], wc = hx != 0u ? old_c[wb + 1u] : old_c[wb];
        uint old_sign = (ws >> bit) & 1u, old_conf = (wc >> bit) & 1u;
        float psi = 0.0f, phi = 0.0f;
        if (old_conf != 0u && pc.set_confidence != 0u && acc[k].n > 0u) { /* unobserved: kept, no prior needed */
            /* Confident voxels of the other sign (fusion_prior_steps's rows). */
            uint m = old_sign != 0u ? 0xFFFFFFFFu : 0u; /* targets: conf & (sign ^ m) */
            uint rx = 0u, ry = 0u, rz = 0u;
            uint sh = brick_bit(0u, y, z);
            rx = (((old_c[wb] & (old_s[wb] ^ m)) >> sh) & 15u) | ((((old_c[wb + 1u] & (old_s[wb + 1u] ^ m)) >> sh) & 15u) << 4);
            [[unroll]] for (uint h = 0u; h < 2u; h++) {
                uint w0 = brick_word(0u, 4u * h, z);
                uint t = hx != 0u ? old_c[w0 + 1u] & (old_s[w0 + 1u] ^ m) : old_c[w0] & (old_s[w0] ^ m);
                t >>= brick_bit(x, 0u, z);
                ry |= ((t & 1u) | ((t >> 3) & 2u) | ((t >> 6) & 4u) | ((t >> 9) & 8u)) << (4u * h);
            }
            [[unroll]] for (uint pair = 0u; pair < 4u; pair++) {
                uint w0 = brick_word(0u, y, 2u * pair);
                uint t = hx != 0u ? old_c[w0 + 1u] & (old_s[w0 + 1u] ^ m) : old_c[w0] & (old_s[w0] ^ m);
                t >>= brick_bit(x, y, 0u);
                rz |= ((t & 1u) | ((t >> 15) & 2u)) << (2u * pair);
            }
            psi = psi_conf;
            phi = fusion_prior_phi(old_sign, fusion_prior_steps(rx, ry, rz, x, y, z), voxel_m, window_err);
        }
        uint r = fusion_decide(old_sign, old_conf, acc[k], psi, phi, pc.conf_weight, pc.set_confidence, may_replace);
        uint bs = (r & FUSION_DECIDE_SIGN) != 0u ? 1u << bit : 0u, bc = (r & FUSION_DECIDE_CONF) != 0u ? 1u << bit : 0u;
        new_s[wb] |= hx != 0u ? 0u : bs;
        new_s[wb + 1u] |= hx != 0u ? bs : 0u;
        new_c[wb] |= hx != 0u ? 0u : bc;
        new_c[wb + 1u] |= hx != 0u ? bc : 0u;
        set |= r & FUSION_DECIDE_SET;
    }
    /* One shared atomic per word and plane. */
    [[unroll]] for (uint w = 0u; w < BRICK_WORDS; w++) {
        if (new_s[w] != 0u) atomicOr(s_new_sign[w], new_s[w]);
        if (new_c[w] != 0u) atomicOr(s_new_conf[w], new_c[w]);
    }
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

void main()
{
    uint n_list = list.w[FUSION_LIST_COUNT];
    uint count = n_list > pc.first ? min(n_list - pc.first, pc.max_count) : 0u;
    uint group = gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x;
    uint tid = gl_LocalInvocationID.x, n_threads = gl_WorkGroupSize.x;
    /* bricks_per_group consecutive entries: llvmpipe pays about 10 us to
     * start a workgroup of this kernel, whatever it does. */
    for (uint b = 0u; b < pc.bricks_per_group; b++) {
        uint idx = group * pc.bricks_per_group + b;
        if (idx >= count) return; /* uniform over the workgroup */
        barrier(); /* the previous brick's reads of shared memory -> this brick's writes */
        integrate_brick(list.w[FUSION_LIST_HEADER + pc.first + idx], tid, n_threads);
    }
}
