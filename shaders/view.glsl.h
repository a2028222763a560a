/* The viewer's blit (view/, shaders/view_blit.comp): the ray-cast's shaded
 * RGBA8 image into a window's swapchain image, shared by the shader and
 * the C side that checks it. */
#ifndef BF_VIEW_GLSL_H
#define BF_VIEW_GLSL_H

#include "bf_common.glsl.h"

#define VIEW_LOCAL_X 8u
#define VIEW_LOCAL_Y 8u

/* Push constants of view_blit.comp. */
struct view_push {
    bf_u32 src_w, src_h;  /* the ray-cast's image */
    bf_u32 dst_w, dst_h;  /* the swapchain image */
    bf_u32 is_bgra;       /* the swapchain stores B in the low byte */
    bf_u32 pad[3];
};

/* The source pixel of destination pixel (x, y): nearest, so equal sizes
 * copy pixel for pixel (a window resized beyond the ray-cast stretches it). */
BF_FN bf_u32 view_src_index(bf_u32 x, bf_u32 y, bf_u32 src_w, bf_u32 src_h, bf_u32 dst_w, bf_u32 dst_h)
{
    bf_u32 sx = (x * src_w) / dst_w;
    bf_u32 sy = (y * src_h) / dst_h;
    return sy * src_w + sx;
}

/* One pixel: render's RGBA8 (R in the low byte; 0 = no hit, shown black as
 * in render_download's images), opaque, in the swapchain's byte order. */
BF_FN bf_u32 view_pixel(bf_u32 rgba, bf_u32 is_bgra)
{
    bf_u32 r = rgba & 0xffu, g = (rgba >> 8) & 0xffu, b = (rgba >> 16) & 0xffu;
    if (is_bgra != 0u) return 0xff000000u | (r << 16) | (g << 8) | b;
    return 0xff000000u | (b << 16) | (g << 8) | r;
}

#endif
