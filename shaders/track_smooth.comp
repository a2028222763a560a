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
 * mode 0: horizontal, depth -> scratch (pc.p_in_*);
 * mode 1: vertical, scratch -> smoothed (pc.p_out_*); all at the level's
 * pixel offset. */
#extension GL_GOOGLE_include_directive : require
#include "track.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

layout(push_constant) uniform Push { track_image_push pc; };

/* The pass's input, the depth (mode 0) or the horizontal pass's output,
 * and its output (main sets them). */
TrackF32 g_src, g_dst;
float src(uint i) { return g_src.v[i]; }

void smooth_pixel(uint ux, uint uy)
{
    if (ux >= pc.width || uy >= pc.height) return;
    int x = int(ux), y = int(uy);
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
    g_dst.v[o + i] = out_z;
}

void main()
{
    /* TRACK_IMAGE_PX pixels per invocation (track.glsl.h says why). */
    g_src = pc.mode == 0u ? TrackF32(uvec2(pc.depth_lo, pc.depth_hi)) : TrackF32(uvec2(pc.p_in_lo, pc.p_in_hi));
    g_dst = pc.mode == 0u ? TrackF32(uvec2(pc.p_in_lo, pc.p_in_hi)) : TrackF32(uvec2(pc.p_out_lo, pc.p_out_hi));
    uint x0 = gl_WorkGroupID.x * (TRACK_IMAGE_TILE * TRACK_IMAGE_PX) + gl_LocalInvocationID.x;
    for (uint j = 0u; j < TRACK_IMAGE_PX; j++) smooth_pixel(x0 + j * TRACK_IMAGE_TILE, gl_GlobalInvocationID.y);
}
