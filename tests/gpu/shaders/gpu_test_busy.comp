#version 450
/* A real workload for the timestamp test: pc.iters steps of a float
 * recurrence per element; the result is stored so it cannot be skipped. */
#include "gpu_test.glsl.h"
BF_LOCAL_SIZE_FROM_SPEC
layout(std430, binding = 0) buffer Data { float v[]; } data;
layout(push_constant) uniform Push { gpu_test_count pc; };
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= pc.n) return;
    float x = data.v[i];
    for (uint k = 0u; k < pc.iters; k++) x = x * 0.999 + sin(x + float(k));
    data.v[i] = x;
}
