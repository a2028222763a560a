#version 450
/* Gathers the bricks of a window: every live brick stamped by a frame in
 * [first, last] (DESIGN.md section 4: the bricks visible in at least one
 * frame of the window). One invocation per brick slot. */
#extension GL_GOOGLE_include_directive : require
#include "fusion.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

layout(std430, binding = 0) readonly buffer Info { uint w[]; } info;
layout(std430, binding = 1) readonly buffer Stamp { uint w[]; } stamp;
layout(std430, binding = 2) buffer List { uint w[]; } list;

layout(push_constant) uniform Push { fusion_window_list_push pc; };

void main()
{
    uint b = gl_GlobalInvocationID.x;
    if (b >= pc.brick_cap) return;
    if (info.w[b * FUSION_BRICK_INFO_WORDS + FUSION_INFO_CHUNK] >= pc.n_entries) return; /* free slot */
    uint s = stamp.w[b];
    if (s == FUSION_NONE || s < pc.first || s > pc.last) return;
    uint i = atomicAdd(list.w[FUSION_LIST_COUNT], 1u);
    list.w[FUSION_LIST_HEADER + i] = b;
}
