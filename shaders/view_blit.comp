#version 450
/* The viewer's blit: the ray-cast's shaded image into the pixels copied to
 * the window's swapchain image (view/; the swapchain's byte order and size,
 * view.glsl.h), with the status line drawn over its top left corner. */
#extension GL_GOOGLE_include_directive : require
#include "view.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

layout(std430, binding = 0) readonly buffer Src { uint v[]; } src;
layout(std430, binding = 1) writeonly buffer Dst { uint v[]; } dst;
layout(std430, binding = 2) readonly buffer Glyphs { uint v[]; } glyphs;

layout(push_constant) uniform Push { view_push pc; };

void main()
{
    uint x = gl_GlobalInvocationID.x, y = gl_GlobalInvocationID.y;
    if (x >= pc.dst_w || y >= pc.dst_h) return;
    uint i = view_src_index(x, y, pc.src_w, pc.src_h, pc.dst_w, pc.dst_h);
    uint rgba = src.v[i];
    if (pc.n_chars > 0u && x < view_band_w(pc.n_chars, pc.scale) && y < view_band_h(pc.scale)) {
        rgba = view_darken(rgba);
        uint cell = view_text_cell(x, y, pc.scale, pc.n_chars);
        if (cell != 0u && (glyphs.v[(cell - 1u) / 16u] & (1u << ((cell - 1u) % 16u))) != 0u) rgba = 0xffffffu;
    }
    dst.v[y * pc.dst_w + x] = view_pixel(rgba, pc.is_bgra);
}
