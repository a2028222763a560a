#version 450
/* The ROF filter's primal solution from its dual field (Chambolle 2004):
 * u = f - div p / lambda on the mask f > 0, written over f (each
 * invocation reads and writes only its own pixel of the depth level). The
 * pixels outside the mask stay 0. */
#extension GL_GOOGLE_include_directive : require
#include "track.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

layout(std430, binding = 1) buffer Depth { float d[]; } depth;
layout(std430, binding = 4) readonly buffer PIn { vec2 p[]; } p_in;

layout(push_constant) uniform Push { track_image_push pc; };

void main()
{
    /* 2D dispatch: x and y without an integer division (lavapipe divides
     * lane by lane). */
    uint x = gl_GlobalInvocationID.x, y = gl_GlobalInvocationID.y;
    if (x >= pc.width || y >= pc.height) return;
    uint i = y * pc.width + x;
    uint o = pc.dst_off; /* the level's pixel offset; p is level-local */
    float f = depth.d[o + i];
    if (!(f > 0.0)) return;
    vec2 p = p_in.p[i];
    float pl = x > 0u ? p_in.p[i - 1u].x : 0.0;
    float pu = y > 0u ? p_in.p[i - pc.width].y : 0.0;
    BF_PRECISE float d = (p.x - pl) + (p.y - pu);
    BF_PRECISE float u = f - d / track_rof_lambda(f, pc.lambda0);
    /* A smoothing strong enough to push a pixel to the camera would make
     * it invalid; keep the measurement there instead. */
    depth.d[o + i] = u > 0.0 ? u : f;
}
