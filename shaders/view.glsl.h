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
    bf_u32 n_chars;       /* the overlay's characters (0: none), glyphs in binding 2 */
    bf_u32 scale;         /* the overlay's pixels per font pixel */
    bf_u32 pad;
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

/* The status overlay: one line of 3x5 pixel glyphs (view/font.c) in the
 * top left corner on a darkened band, white. A glyph is 15 bits, row r's
 * three pixels (left = 4, right = 1) at bits 3r. */
#define VIEW_TEXT_MAX 128u
#define VIEW_GLYPH_W 3u
#define VIEW_GLYPH_H 5u
#define VIEW_CELL_W 4u  /* a glyph and a column of space */

/* The band's size in window pixels: a margin of 2 font pixels around the line. */
BF_FN bf_u32 view_band_w(bf_u32 n_chars, bf_u32 scale) { return (4u + n_chars * VIEW_CELL_W - 1u) * scale; }
BF_FN bf_u32 view_band_h(bf_u32 scale) { return (4u + VIEW_GLYPH_H) * scale; }

/* A pixel under the band, darkened to 3/8 so white text reads on any surface. */
BF_FN bf_u32 view_darken(bf_u32 rgba)
{
    return ((rgba >> 2) & 0x3f3f3fu) + ((rgba >> 3) & 0x1f1f1fu);
}

/* Which font pixel of the line window pixel (x, y) shows: 0 where it is
 * margin or space between glyphs, else 1 + 16 * (the character's index) +
 * (the glyph's bit). */
BF_FN bf_u32 view_text_cell(bf_u32 x, bf_u32 y, bf_u32 scale, bf_u32 n_chars)
{
    bf_u32 fx = x / scale, fy = y / scale;
    if (fx < 2u || fy < 2u || fy >= 2u + VIEW_GLYPH_H) return 0u;
    bf_u32 ci = (fx - 2u) / VIEW_CELL_W, cx = (fx - 2u) % VIEW_CELL_W;
    if (ci >= n_chars || cx >= VIEW_GLYPH_W) return 0u;
    return 1u + 16u * ci + (2u - cx) + 3u * (fy - 2u);
}

#endif
