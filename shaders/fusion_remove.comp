#version 450
/* Removes the bricks a window slice left empty (DESIGN.md section 4): after
 * the slice's integration, a brick of the slice without a single confident
 * voxel holds nothing the map can use (it was seen only from behind the
 * surface, or too rarely), unless a frame after the window touched it again
 * (it will be in the next window). Its node forgets it, its bit planes are
 * cleared and its slot goes back on the free stack. Pops happen only in the
 * allocation passes, never concurrently with this pass. */
#extension GL_GOOGLE_include_directive : require
#include "fusion.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

layout(std430, binding = 0) readonly buffer List { uint w[]; } list;
layout(std430, binding = 1) buffer Info { uint w[]; } info;
layout(std430, binding = 2) buffer Nodes { uint w[]; } nodes;
layout(std430, binding = 3) buffer Sign { uint w[]; } sign_pool;
layout(std430, binding = 4) buffer Conf { uint w[]; } conf_pool;
layout(std430, binding = 5) readonly buffer Stamp { uint w[]; } stamp;
layout(std430, binding = 6) buffer Counters { uint w[]; } cnt;
layout(std430, binding = 7) buffer FreeStack { uint w[]; } free_stack;
layout(std430, binding = 8) buffer ColourMask { uint w[]; } cmask;
layout(std430, binding = 9) buffer ColourFree { uint w[]; } cfree;
layout(std430, binding = 10) buffer ColourHead { uint w[]; } chead;
layout(std430, binding = 11) readonly buffer ColourPool { uint w[]; } cpool;

layout(push_constant) uniform Push { fusion_remove_push pc; };

void main()
{
    uint i = pc.first + BF_LINEAR_INDEX;
    if (BF_LINEAR_INDEX >= pc.max_count || i >= list.w[FUSION_LIST_COUNT]) return;
    uint b = list.w[FUSION_LIST_HEADER + i];
    if (info.w[b * FUSION_BRICK_INFO_WORDS + FUSION_INFO_CHUNK] == FUSION_NONE) return;
    uint s = stamp.w[b];
    if (s != FUSION_NONE && s > pc.last_frame) return; /* seen again since: keep */
    for (uint k = 0u; k < BRICK_WORDS; k++)
        if (conf_pool.w[b * BRICK_WORDS + k] != 0u) return;
    uint node = info.w[b * FUSION_BRICK_INFO_WORDS + FUSION_INFO_NODE];
    nodes.w[node * FUSION_NODE_WORDS + FUSION_NODE_BRICK] = FUSION_NONE;
    for (uint k = 0u; k < BRICK_WORDS; k++) sign_pool.w[b * BRICK_WORDS + k] = 0u;
    for (uint k = 0u; k < FUSION_BRICK_INFO_WORDS; k++) info.w[b * FUSION_BRICK_INFO_WORDS + k] = FUSION_NONE;
    if (pc.has_colour != 0u) {
        /* Its colour units go back too (the colour pass, which pops, runs
         * in another dispatch). */
        for (uint k = 0u; k < BRICK_WORDS; k++) cmask.w[b * BRICK_WORDS + k] = 0u;
        uint u = chead.w[b];
        chead.w[b] = FUSION_NONE;
        for (uint n = 0u; u != FUSION_NONE && n < FUSION_COLOUR_MAX_UNITS; n++) {
            uint next = cpool.w[u * FUSION_COLOUR_UNIT_WORDS];
            cfree.w[atomicAdd(cnt.w[FUSION_CNT_COLOUR_TOP], 1u)] = u;
            u = next;
        }
    }
    atomicAdd(cnt.w[FUSION_CNT_BRICKS], 0xFFFFFFFFu);
    uint top = atomicAdd(cnt.w[FUSION_CNT_FREE_TOP], 1u);
    free_stack.w[top] = b;
    atomicAdd(cnt.w[FUSION_CNT_REMOVED], 1u);
}
