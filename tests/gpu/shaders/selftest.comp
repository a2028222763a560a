#version 450
/* Adds 1 to each of the first n words of data (the gpu round-trip test). */
#include "gpu_test.glsl.h"
BF_LOCAL_SIZE_FROM_SPEC
layout(std430, binding = 0) buffer Data { uint v[]; } data;
layout(push_constant) uniform Push { gpu_test_count pc; };
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= pc.n) return;
    data.v[i] += 1u;
}
