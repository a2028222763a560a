#version 450
/* Evaluates the brick bit helpers of bf_common.glsl.h for comparison with
 * the same functions compiled as C: out[v] = word << 8 | bit for each voxel
 * v = x + 8y + 64z, then out[512 + 32k + i] = brick_rank(words[k], i). */
#include "gpu_test.glsl.h"
BF_LOCAL_SIZE_FROM_SPEC
layout(std430, binding = 0) readonly buffer Words { uint w[]; } words;
layout(std430, binding = 1) writeonly buffer Out { uint v[]; } result;
layout(push_constant) uniform Push { gpu_test_count pc; }; /* n = number of words */
void main()
{
    uint t = gl_GlobalInvocationID.x;
    if (t < BRICK_VOXELS) {
        uint x = t & 7u, y = (t >> 3) & 7u, z = t >> 6;
        result.v[t] = (brick_word(x, y, z) << 8) | brick_bit(x, y, z);
    }
    if (t < pc.n * 32u) result.v[BRICK_VOXELS + t] = brick_rank(words.w[t >> 5], t & 31u);
}
