/* calib: a lens's distortion taken out of images by resampling to the
 * pinhole camera with the same intrinsics (calib.h). Used by replay/ for
 * sequences whose published calibration has a distortion (TUM's fr1 and
 * fr2: the depth is registered to the colour camera's raw, distorted
 * pixels). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib.h"

bool calib_has_distortion(const double dist[CALIB_DIST_N])
{
    for (int k = 0; k < CALIB_DIST_N; k++)
        if (dist[k] != 0) return true;
    return false;
}

/* The radial term's image of radius r: r (1 + k1 r^2 + k2 r^4 + k3 r^6). */
static double radial_image(const double dist[CALIB_DIST_N], double r)
{
    double r2 = r * r;
    return r * (1 + r2 * (dist[0] + r2 * (dist[1] + r2 * dist[4])));
}

/* Whether the radial term keeps growing out to radius r_max (normalised):
 * where it stops, two rays land on one pixel and the image folds. */
static bool radial_is_monotonic(const double dist[CALIB_DIST_N], double r_max)
{
    const int steps = 1024;
    double prev = 0;
    for (int i = 1; i <= steps; i++) {
        double cur = radial_image(dist, r_max * i / steps);
        if (!(cur > prev)) return false;
        prev = cur;
    }
    return true;
}

bf_status calib_undistort_map_make(const calib_camera *c, calib_undistort_map *out)
{
    if (c->width == 0 || c->height == 0 || !(c->fx_px != 0) || !(c->fy_px != 0))
        return bf_fail(BF_INVALID_ARG, "undistortion: a %ux%u camera with fx %g, fy %g", c->width, c->height,
                       c->fx_px, c->fy_px);
    static const char *const names[CALIB_DIST_N] = {"k1", "k2", "p1", "p2", "k3"};
    for (int k = 0; k < CALIB_DIST_N; k++)
        if (!isfinite(c->dist[k])) return bf_fail(BF_INVALID_ARG, "undistortion: %s is not finite", names[k]);
    /* Pixel indices are int32_t (-1: none). */
    if ((uint64_t)c->width * c->height > (uint64_t)INT32_MAX)
        return bf_fail(BF_INVALID_ARG, "undistortion: a %ux%u image is too large", c->width, c->height);
    /* The farthest corner of the image, in the normalised plane (a little
     * beyond: the pixels' edges). */
    double r_max = 0;
    for (int corner = 0; corner < 4; corner++) {
        double u = (corner & 1) ? c->width - 0.5 : -0.5, v = (corner & 2) ? c->height - 0.5 : -0.5;
        double x = (u - c->cx_px) / c->fx_px, y = (v - c->cy_px) / c->fy_px;
        r_max = fmax(r_max, sqrt(x * x + y * y));
    }
    if (!radial_is_monotonic(c->dist, r_max))
        return bf_fail(BF_INVALID_ARG,
                       "undistortion: the distortion k1 %g k2 %g p1 %g p2 %g k3 %g folds the %ux%u image over "
                       "itself before its corners (not a lens)",
                       c->dist[0], c->dist[1], c->dist[2], c->dist[3], c->dist[4], c->width, c->height);
    size_t n = (size_t)c->width * c->height;
    int32_t *src = bf_malloc(n * sizeof *src);
    if (!src) return bf_fail(BF_NO_MEMORY, "undistortion map of %ux%u", c->width, c->height);
    uint32_t n_outside = 0;
    double max_shift = 0;
    for (uint32_t v = 0; v < c->height; v++)
        for (uint32_t u = 0; u < c->width; u++) {
            double xd, yd;
            calib_distort(c->dist, (u - c->cx_px) / c->fx_px, (v - c->cy_px) / c->fy_px, &xd, &yd);
            double us = c->fx_px * xd + c->cx_px, vs = c->fy_px * yd + c->cy_px;
            /* Pixel centres at integers: pixel i covers [i - 1/2, i + 1/2). */
            double ui = floor(us + 0.5), vi = floor(vs + 0.5);
            size_t i = (size_t)v * c->width + u;
            if (ui >= 0 && vi >= 0 && ui < c->width && vi < c->height) {
                src[i] = (int32_t)((size_t)vi * c->width + (size_t)ui);
                max_shift = fmax(max_shift, hypot(us - u, vs - v));
            } else {
                src[i] = -1;
                n_outside++;
            }
        }
    /* A real lens loses the corners at most (a few per cent); one that sends
     * most of the image outside it (k1 1e300, p1 1e10: a typo) would leave
     * every frame without depth, blamed on the depth. */
    if (n_outside > n / 2) {
        free(src);
        return bf_fail(BF_INVALID_ARG,
                       "undistortion: the distortion k1 %g k2 %g p1 %g p2 %g k3 %g sends %.0f%% of the %ux%u image's "
                       "pixels outside it (not a lens)",
                       c->dist[0], c->dist[1], c->dist[2], c->dist[3], c->dist[4], 100.0 * n_outside / n, c->width,
                       c->height);
    }
    *out = (calib_undistort_map){.width = c->width, .height = c->height, .src = src, .n_outside = n_outside,
                                 .max_shift_px = max_shift};
    return BF_OK;
}

void calib_undistort_map_free(calib_undistort_map *m)
{
    if (!m) return;
    free(m->src);
    memset(m, 0, sizeof *m);
}

void calib_undistort_u16(const calib_undistort_map *m, const uint16_t *src, uint16_t *dst)
{
    size_t n = (size_t)m->width * m->height;
    for (size_t i = 0; i < n; i++) dst[i] = m->src[i] >= 0 ? src[m->src[i]] : 0;
}

void calib_undistort_rgb8(const calib_undistort_map *m, const uint8_t *src, uint8_t *dst)
{
    size_t n = (size_t)m->width * m->height;
    for (size_t i = 0; i < n; i++) {
        if (m->src[i] >= 0) memcpy(dst + 3 * i, src + 3 * (size_t)m->src[i], 3);
        else memset(dst + 3 * i, 0, 3);
    }
}
