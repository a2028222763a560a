#version 450
/* A one-dimensional dispatch spread over x and y (gpu_cmd_dispatch_linear):
 * marks[i] = i + 1 for each place i = BF_LINEAR_INDEX below n. */
#include "gpu_test.glsl.h"
BF_LOCAL_SIZE_FROM_SPEC
layout(std430, binding = 0) writeonly buffer Marks { uint m[]; } marks;
layout(push_constant) uniform Push { gpu_test_count pc; };
void main()
{
    uint i = BF_LINEAR_INDEX;
    if (i < pc.n) marks.m[i] = i + 1u;
}
