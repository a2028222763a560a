#version 450
/* The ROF filter's primal solution from its dual field (Chambolle 2004):
 * u = f - div p / lambda on the mask f > 0, written over f (each
 * invocation reads and writes only its own pixel of the depth level). The
 * pixels outside the mask stay 0. */
#extension GL_GOOGLE_include_directive : require
#include "track.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC


layout(push_constant) uniform Push { track_image_push pc; };

void primal_pixel(uint x, uint y, TrackF32 depth, TrackVec2 p_in)
{
    if (x >= pc.width || y >= pc.height) return;
    uint i = y * pc.width + x;
    uint o = pc.dst_off; /* the level's pixel offset; p is level-local */
    float f = depth.v[o + i];
    if (!(f > 0.0)) return;
    vec2 p = p_in.v[i];
    float pl = x > 0u ? p_in.v[i - 1u].x : 0.0;
    float pu = y > 0u ? p_in.v[i - pc.width].y : 0.0;
    BF_PRECISE float d = (p.x - pl) + (p.y - pu);
    BF_PRECISE float u = f - d / track_rof_lambda(f, pc.lambda0);
    /* A smoothing strong enough to push a pixel to the camera would make
     * it invalid; keep the measurement there instead. */
    depth.v[o + i] = u > 0.0 ? u : f;
}

void main()
{
    /* TRACK_IMAGE_PX pixels per invocation (track.glsl.h says why). */
    TrackF32 depth = TrackF32(uvec2(pc.depth_lo, pc.depth_hi));
    TrackVec2 p_in = TrackVec2(uvec2(pc.p_in_lo, pc.p_in_hi));
    uint x0 = gl_WorkGroupID.x * (TRACK_IMAGE_TILE * TRACK_IMAGE_PX) + gl_LocalInvocationID.x;
    for (uint j = 0u; j < TRACK_IMAGE_PX; j++) primal_pixel(x0 + j * TRACK_IMAGE_TILE, gl_GlobalInvocationID.y, depth, p_in);
}
