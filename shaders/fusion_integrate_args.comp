#version 450
/* Writes the indirect group counts of one fusion_integrate.comp pass into
 * the list's header: n = min(count - first, max_count) bricks (0 when the
 * list is shorter than first), bricks_per_group per workgroup, as a grid of
 * max_groups_x columns. */
#extension GL_GOOGLE_include_directive : require
#include "fusion.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

layout(std430, binding = 6) buffer List { uint w[]; } list;

layout(push_constant) uniform Push { fusion_integrate_push pc; };

void main()
{
    if (gl_GlobalInvocationID.x != 0u || pc.max_groups_x == 0u) return; /* zero push (warm-up): nothing */
    uint n_list = list.w[FUSION_LIST_COUNT];
    uint n = n_list > pc.first ? min(n_list - pc.first, pc.max_count) : 0u;
    uint per = max(pc.bricks_per_group, 1u);
    n = (n + per - 1u) / per; /* workgroups */
    list.w[FUSION_LIST_ARGS + 0u] = min(n, pc.max_groups_x);
    list.w[FUSION_LIST_ARGS + 1u] = (n + pc.max_groups_x - 1u) / pc.max_groups_x;
    list.w[FUSION_LIST_ARGS + 2u] = 1u;
}
