#version 450
/* The depth that normals are computed from: a separable bilateral filter
 * (KinectFusion, Newcombe et al. 2011, sec. 3.1, made separable) of one
 * pyramid level, 2 x TRACK_SMOOTH_RADIUS + 1 taps per pass. Kinect-like
 * depth is quantised in disparity: on a slanted surface it is a staircase
 * whose steps span several pixels (step / footprint = z s / b, about 5 px
 * at 3 m), so normals by central differences of the raw (or ROF-smoothed:
 * TV keeps a monotone staircase) depth are off by tens of degrees. The
 * range weight lets a staircase's step through and stops at real depth
 * edges. Vertices keep the unfiltered depth.
 * mode 0: horizontal, depth (binding 1) -> scratch (binding 4);
 * mode 1: vertical, scratch (binding 4) -> smoothed (binding 5); all at the
 * level's pixel offset. */
#extension GL_GOOGLE_include_directive : require
#include "track.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

layout(std430, binding = 1) readonly buffer Depth { float d[]; } depth;
layout(std430, binding = 4) buffer Scratch { float d[]; } scratch;
layout(std430, binding = 5) writeonly buffer Smooth { float d[]; } smoothed;

layout(push_constant) uniform Push { track_image_push pc; };

float src(uint i) { return pc.mode == 0u ? depth.d[i] : scratch.d[i]; }

void main()
{
    if (gl_GlobalInvocationID.x >= pc.width || gl_GlobalInvocationID.y >= pc.height) return;
    int x = int(gl_GlobalInvocationID.x), y = int(gl_GlobalInvocationID.y);
    uint i = uint(y) * pc.width + uint(x);
    uint o = pc.dst_off;
    float z = src(o + i);
    float out_z = 0.0;
    if (z > 0.0) {
        float sr = track_smooth_range(bf_sensor_sigma(z, pc.sigma_a, pc.sigma_b, pc.sigma_c));
        float inv_r = 1.0 / (2.0 * sr * sr);
        float sum = 0.0, wsum = 0.0;
        for (int k = -int(TRACK_SMOOTH_RADIUS); k <= int(TRACK_SMOOTH_RADIUS); k++) {
            int xx = pc.mode == 0u ? x + k : x, yy = pc.mode == 0u ? y : y + k;
            if (xx < 0 || yy < 0 || xx >= int(pc.width) || yy >= int(pc.height)) continue;
            float zk = src(o + uint(yy) * pc.width + uint(xx));
            if (!(zk > 0.0)) continue;
            float dz = zk - z;
            float wk = exp(-float(k * k) * TRACK_SMOOTH_SPACE_W - dz * dz * inv_r);
            sum += wk * zk;
            wsum += wk;
        }
        out_z = sum / wsum;
    }
    if (pc.mode == 0u) scratch.d[o + i] = out_z;
    else smoothed.d[o + i] = out_z;
}
