#version 450
/* One pyramid level from the one below (KinectFusion, Newcombe et al.
 * 2011, sec. 3.1): each pixel of the coarse level averages the valid depths
 * of its 2x2 block that lie within track_block_thresh of the block's
 * nearest depth; no valid depth gives 0. */
#extension GL_GOOGLE_include_directive : require
#include "track.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

layout(push_constant) uniform Push { track_image_push pc; };

void pyrdown_pixel(uint x, uint y)
{
    if (x >= pc.width || y >= pc.height) return;
    uint i = y * pc.width + x;
    TrackF32 depth = TrackF32(uvec2(pc.depth_lo, pc.depth_hi));
    float z[4];
    float zmin = 1e30;
    for (uint k = 0u; k < 4u; k++) {
        uint sx = 2u * x + (k & 1u), sy = 2u * y + (k >> 1);
        z[k] = depth.v[pc.src_off + sy * pc.src_width + sx];
        if (z[k] > 0.0) zmin = min(zmin, z[k]);
    }
    float sum = 0.0, n = 0.0;
    if (zmin < 1e30) {
        float thr = track_block_thresh(bf_sensor_sigma(zmin, pc.sigma_a, pc.sigma_b, pc.sigma_c));
        for (uint k = 0u; k < 4u; k++)
            if (z[k] > 0.0 && z[k] - zmin <= thr) { sum += z[k]; n += 1.0; }
    }
    depth.v[pc.dst_off + i] = n > 0.0 ? sum / n : 0.0;
}

void main()
{
    /* TRACK_IMAGE_PX pixels per invocation (track.glsl.h says why). */
    uint x0 = gl_WorkGroupID.x * (TRACK_IMAGE_TILE * TRACK_IMAGE_PX) + gl_LocalInvocationID.x;
    for (uint j = 0u; j < TRACK_IMAGE_PX; j++) pyrdown_pixel(x0 + j * TRACK_IMAGE_TILE, gl_GlobalInvocationID.y);
}
