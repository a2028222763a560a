#version 450
/* Evaluates BF_TRUNC_I32 and BF_TRUNC_U32 of bf_common.glsl.h on the floats
 * of the input (as bits), for comparison with C's casts: out[2i] =
 * BF_TRUNC_I32(x_i), out[2i + 1] = BF_TRUNC_U32(x_i). */
#include "gpu_test.glsl.h"
BF_LOCAL_SIZE_FROM_SPEC
layout(std430, binding = 0) readonly buffer In { uint w[]; } values;
layout(std430, binding = 1) writeonly buffer Out { uint v[]; } result;
layout(push_constant) uniform Push { gpu_test_count pc; }; /* n = number of values */
void main()
{
    uint t = gl_GlobalInvocationID.x;
    if (t >= pc.n) return;
    float x = uintBitsToFloat(values.w[t]);
    result.v[2u * t] = uint(BF_TRUNC_I32(x));
    result.v[2u * t + 1u] = BF_TRUNC_U32(x);
}
