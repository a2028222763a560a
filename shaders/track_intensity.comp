#version 450
/* The frame's intensity pyramid for the photometric term (track.glsl.h,
 * track_intensity_push): the finest level's luma from the frame's RGB565
 * colour where the pixel has depth (through the colour camera unless the
 * colour is registered), then each coarser level as the mean of its 2x2
 * block's valid samples. */
#extension GL_GOOGLE_include_directive : require
#include "track.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

layout(std430, binding = 0) readonly buffer Raw { uint w[]; } raw;
layout(std430, binding = 1) readonly buffer Depth { float d[]; } depth;
layout(std430, binding = 2) buffer Intensity { float v[]; } inten;

layout(push_constant) uniform Push { track_intensity_push pc; };

float colour_luma(uint i)
{
    return bf_565_luma((raw.w[pc.raw_off + (i >> 1)] >> ((i & 1u) * 16u)) & 0xFFFFu);
}

/* The luma at continuous colour pixel (u, v), pixel centres at integers,
 * bilinear; TRACK_NO_INTENSITY outside the image. */
float colour_at(float u, float v)
{
    if (!(u >= 0.0 && v >= 0.0 && u <= float(pc.width - 1u) && v <= float(pc.height - 1u))) return TRACK_NO_INTENSITY;
    uint x0 = min(BF_TRUNC_U32(u), pc.width - 2u), y0 = min(BF_TRUNC_U32(v), pc.height - 2u);
    float a = u - float(x0), b = v - float(y0);
    uint i = y0 * pc.width + x0;
    float top = mix(colour_luma(i), colour_luma(i + 1u), a);
    float bot = mix(colour_luma(i + pc.width), colour_luma(i + pc.width + 1u), a);
    return mix(top, bot, b);
}

float finest(uint x, uint y)
{
    uint i = y * pc.width + x;
    float z = depth.d[pc.dst_off + i];
    if (!(z > 0.0)) return TRACK_NO_INTENSITY;
    if (pc.mode == TRACK_INT_REGISTERED) return colour_luma(i);
    vec3 p = vec3((float(x) - pc.cx) * z / pc.fx, (float(y) - pc.cy) * z / pc.fy, z);
    vec3 q = vec3(pc.R[0] * p.x + pc.R[1] * p.y + pc.R[2] * p.z + pc.t[0],
                  pc.R[3] * p.x + pc.R[4] * p.y + pc.R[5] * p.z + pc.t[1],
                  pc.R[6] * p.x + pc.R[7] * p.y + pc.R[8] * p.z + pc.t[2]);
    if (!(q.z > 0.0)) return TRACK_NO_INTENSITY;
    float xn = q.x / q.z, yn = q.y / q.z;
    float xd = bf_distort_x(xn, yn, pc.dist[0], pc.dist[1], pc.dist[2], pc.dist[3], pc.dist[4]);
    float yd = bf_distort_y(xn, yn, pc.dist[0], pc.dist[1], pc.dist[2], pc.dist[3], pc.dist[4]);
    return colour_at(pc.cfx * xd + pc.ccx, pc.cfy * yd + pc.ccy);
}

float down(uint x, uint y)
{
    float sum = 0.0, n = 0.0;
    for (uint k = 0u; k < 4u; k++) {
        float v = inten.v[pc.src_off + (2u * y + (k >> 1)) * pc.src_width + 2u * x + (k & 1u)];
        if (v >= 0.0) { sum += v; n += 1.0; }
    }
    return n > 0.0 ? sum / n : TRACK_NO_INTENSITY;
}

void intensity_pixel(uint x, uint y)
{
    if (x >= pc.width || y >= pc.height) return;
    inten.v[pc.dst_off + y * pc.width + x] = pc.mode == TRACK_INT_DOWN ? down(x, y) : finest(x, y);
}

void main()
{
    /* TRACK_IMAGE_PX pixels per invocation (track.glsl.h says why). */
    uint x0 = gl_WorkGroupID.x * (TRACK_IMAGE_TILE * TRACK_IMAGE_PX) + gl_LocalInvocationID.x;
    for (uint j = 0u; j < TRACK_IMAGE_PX; j++) intensity_pixel(x0 + j * TRACK_IMAGE_TILE, gl_GlobalInvocationID.y);
}
