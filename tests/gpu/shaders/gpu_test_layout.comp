#version 450
/* Writes the push constants, then each input struct with every field
 * changed in a known way, as raw words: the C side checks the layout. */
#include "gpu_test.glsl.h"
BF_LOCAL_SIZE_FROM_SPEC
layout(std430, binding = 0) readonly buffer In { gpu_test_params p[]; } src;
layout(std430, binding = 1) writeonly buffer Out { uint v[]; } result;
layout(push_constant) uniform Push { gpu_test_params pc; };
void put(uint base, gpu_test_params q)
{
    result.v[base + 0u] = q.n;
    result.v[base + 1u] = uint(q.offset);
    result.v[base + 2u] = floatBitsToUint(q.scale);
    result.v[base + 3u] = q.seed;
    for (uint k = 0u; k < 4u; k++) result.v[base + 4u + k] = q.words[k];
}
void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i == 0u) put(0u, pc);
    if (i >= pc.n) return;
    gpu_test_params q = src.p[i];
    q.n += 1u;
    q.offset -= 1;
    q.scale *= 2.0;
    q.seed ^= 0xffffffffu;
    for (uint k = 0u; k < 4u; k++) q.words[k] += k;
    put(GPU_TEST_PARAMS_WORDS * (i + 1u), q);
}
