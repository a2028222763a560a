#version 450
/* Gathers the bricks of a window: every live brick stamped by a frame in
 * [first, last] (DESIGN.md section 4: the bricks visible in at least one
 * frame of the window), grouped by hash bucket (fusion_bucket_of in
 * fusion.glsl.h: which frame integrates a brick follows from what the brick
 * is, not from the order of the atomics, docs/determinism.md; fusion/ cuts
 * the list into slices at bucket boundaries). Three passes: COUNT and
 * SCATTER have one invocation per brick slot, PREFIX one invocation in
 * all; COUNT also lists the bricks to trim (fusion_window_list_push). Within a bucket the order still follows the atomics; the slice's
 * bricks are integrated by one dispatch and each independently of the
 * others, so their order changes nothing. */
#extension GL_GOOGLE_include_directive : require
#include "fusion.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

layout(std430, binding = 0) readonly buffer Info { uint w[]; } info;
layout(std430, binding = 1) readonly buffer Stamp { uint w[]; } stamp;
layout(std430, binding = 2) buffer List { uint w[]; } list;
layout(std430, binding = 3) readonly buffer Hash { uint w[]; } hash;
layout(std430, binding = 4) buffer Slices { uint w[]; } slices;
layout(std430, binding = 5) buffer Trim { uint w[]; } trim;

layout(push_constant) uniform Push { fusion_window_list_push pc; };

void main()
{
    uint n_buckets = clamp(pc.n_buckets, 1u, FUSION_MAX_BUCKETS);
    if (pc.pass == FUSION_GATHER_PREFIX) {
        if (BF_LINEAR_INDEX != 0u) return;
        uint sum = 0u;
        for (uint s = 0u; s < n_buckets; s++) {
            slices.w[FUSION_SLICE_STARTS + s] = sum;
            slices.w[FUSION_SLICE_CURSORS + s] = sum;
            sum += slices.w[FUSION_SLICE_COUNTS + s];
        }
        slices.w[FUSION_SLICE_STARTS + n_buckets] = sum;
        list.w[FUSION_LIST_COUNT] = sum;
        return;
    }
    uint b = BF_LINEAR_INDEX;
    if (b >= pc.brick_cap) return;
    uint chunk = info.w[b * FUSION_BRICK_INFO_WORDS + FUSION_INFO_CHUNK];
    if (chunk >= pc.n_entries) return; /* free slot */
    uint st = stamp.w[b];
    /* (trim_only: every brick, also one loaded and never stamped since) */
    if (pc.pass == FUSION_GATHER_COUNT && (st != FUSION_NONE || pc.trim_only != 0u) && st >= pc.trim_first &&
        st <= pc.trim_last)
        trim.w[FUSION_LIST_HEADER + atomicAdd(trim.w[FUSION_LIST_COUNT], 1u)] = b;
    if (pc.trim_only != 0u) return;
    if (st == FUSION_NONE || st < pc.first || st > pc.last) return;
    uint base = chunk * FUSION_ENTRY_WORDS;
    uint s = fusion_bucket_of(int(hash.w[base + FUSION_ENTRY_X]), int(hash.w[base + FUSION_ENTRY_Y]),
                             int(hash.w[base + FUSION_ENTRY_Z]), info.w[b * FUSION_BRICK_INFO_WORDS + FUSION_INFO_POS],
                              n_buckets);
    if (pc.pass == FUSION_GATHER_COUNT) {
        atomicAdd(slices.w[FUSION_SLICE_COUNTS + s], 1u);
    } else {
        uint i = atomicAdd(slices.w[FUSION_SLICE_CURSORS + s], 1u);
        list.w[FUSION_LIST_HEADER + i] = b;
    }
}
