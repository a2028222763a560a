#version 450
/* Between two allocation passes: writes the indirect group counts of the
 * retry queue the next pass reads, empties the queue it will write, and
 * clears the bucket locks (each pass has its own inserters). */
#extension GL_GOOGLE_include_directive : require
#include "fusion.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

layout(std430, binding = 0) buffer Queue { uint w[]; } queue;
layout(std430, binding = 1) buffer Locks { uint w[]; } locks;

layout(push_constant) uniform Push { fusion_alloc_push pc; };

void main()
{
    /* One workgroup: on lavapipe every 8 invocations cost about 16 integer
     * divisions (their local indices), which made a pass of an invocation a
     * lock take 0.12 ms, nine times a frame. */
    uint i = gl_LocalInvocationIndex;
    for (uint k = i; k < pc.n_buckets; k += gl_WorkGroupSize.x) locks.w[k] = 0u;
    if (i != 0u || pc.pass == 0u) return;
    uint q_in = (pc.pass - 1u) % 2u, q_out = pc.pass % 2u;
    uint n = min(queue.w[4u * q_in], pc.queue_cap);
    /* Rows of at most max_groups_x groups (the retry pass reads its place
     * with BF_LINEAR_INDEX): a depth image over about 1.4 MP queues more than
     * 65535 groups of points, Mesa's limit along x. */
    uint groups = (n + FUSION_ALLOC_LOCAL - 1u) / FUSION_ALLOC_LOCAL;
    queue.w[4u * q_in + 1u] = min(groups, pc.max_groups_x);
    queue.w[4u * q_in + 2u] = (groups + pc.max_groups_x - 1u) / pc.max_groups_x;
    queue.w[4u * q_in + 3u] = 1u;
    queue.w[4u * q_out] = 0u;
}
