#version 450
/* Writes dispatch arguments (pc.n, 1, 1) for gpu_test_count.comp. */
#include "gpu_test.glsl.h"
BF_LOCAL_SIZE_FROM_SPEC
layout(std430, binding = 0) writeonly buffer Args { uint g[3]; } args;
layout(push_constant) uniform Push { gpu_test_count pc; };
void main()
{
    if (gl_GlobalInvocationID.x != 0u) return;
    args.g[0] = pc.n;
    args.g[1] = 1u;
    args.g[2] = 1u;
}
