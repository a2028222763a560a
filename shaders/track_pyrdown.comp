#version 450
/* One pyramid level from the one below (KinectFusion, Newcombe et al.
 * 2011, sec. 3.1): each pixel of the coarse level averages the valid depths
 * of its 2x2 block that lie within track_block_thresh of the block's
 * nearest depth; no valid depth gives 0. */
#extension GL_GOOGLE_include_directive : require
#include "track.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

layout(std430, binding = 1) buffer Depth { float d[]; } depth;

layout(push_constant) uniform Push { track_image_push pc; };

void main()
{
    uint x = gl_GlobalInvocationID.x, y = gl_GlobalInvocationID.y;
    if (x >= pc.width || y >= pc.height) return;
    uint i = y * pc.width + x;
    float z[4];
    float zmin = 1e30;
    for (uint k = 0u; k < 4u; k++) {
        uint sx = 2u * x + (k & 1u), sy = 2u * y + (k >> 1);
        z[k] = depth.d[pc.src_off + sy * pc.src_width + sx];
        if (z[k] > 0.0) zmin = min(zmin, z[k]);
    }
    float sum = 0.0, n = 0.0;
    if (zmin < 1e30) {
        float thr = track_block_thresh(bf_sensor_sigma(zmin, pc.sigma_a, pc.sigma_b, pc.sigma_c));
        for (uint k = 0u; k < 4u; k++)
            if (z[k] > 0.0 && z[k] - zmin <= thr) { sum += z[k]; n += 1.0; }
    }
    depth.d[pc.dst_off + i] = n > 0.0 ? sum / n : 0.0;
}
