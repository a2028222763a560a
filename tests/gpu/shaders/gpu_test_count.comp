#version 450
/* Counts workgroups: counter[0] += 1 per group, marks[group] = group + 1. */
#include "gpu_test.glsl.h"
BF_LOCAL_SIZE_FROM_SPEC
layout(std430, binding = 0) buffer Counter { uint c[]; } counter;
layout(std430, binding = 1) writeonly buffer Marks { uint m[]; } marks;
void main()
{
    if (gl_LocalInvocationIndex != 0u) return;
    atomicAdd(counter.c[0], 1u);
    marks.m[gl_WorkGroupID.x] = gl_WorkGroupID.x + 1u;
}
