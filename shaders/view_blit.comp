#version 450
/* The viewer's blit: the ray-cast's shaded image into the pixels copied to
 * the window's swapchain image (view/; the swapchain's byte order and size,
 * view.glsl.h). */
#extension GL_GOOGLE_include_directive : require
#include "view.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

layout(std430, binding = 0) readonly buffer Src { uint v[]; } src;
layout(std430, binding = 1) writeonly buffer Dst { uint v[]; } dst;

layout(push_constant) uniform Push { view_push pc; };

void main()
{
    uint x = gl_GlobalInvocationID.x, y = gl_GlobalInvocationID.y;
    if (x >= pc.dst_w || y >= pc.dst_h) return;
    uint i = view_src_index(x, y, pc.src_w, pc.src_h, pc.dst_w, pc.dst_h);
    dst.v[y * pc.dst_w + x] = view_pixel(src.v[i], pc.is_bgra);
}
