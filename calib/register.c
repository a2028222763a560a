/* calib: the depth camera's points as a separate colour camera sees them
 * (calib.h). Used where something found in the colour image must be lifted
 * by the depth (recon's ORB keypoints) but the frames' colour is the colour
 * camera's own image (--calibration). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib.h"

/* A point behind the colour camera's nearest surface at its pixel by more
 * than this (relative, with a floor in metres) is hidden from it: Kinect
 * v1's noise is a few per cent of the depth at range. */
#define OCCLUSION_REL 0.03
#define OCCLUSION_MIN_M 0.01

/* A point covers the colour pixels whose centres lie within this of it
 * along both axes: its nearest pixel always, and a neighbour too when it
 * lands near their border, so a near surface leaves no gaps between its
 * points for a far one behind to show through (the two cameras' pixels
 * are about the same size: points land at most 1.8 pixels apart unless
 * the surface turns away), while a point on a pixel's centre covers that
 * pixel alone (the same camera twice gives each pixel its own point). */
#define COVER_PX 0.9

/* Where depth pixel i's point lands in the colour image: its position
 * (u, v; NaN: nowhere), its point in the depth camera (p) and its depth
 * along the colour camera's axis. */
static void land(const calib_camera *c, const bf_se3 *T_cd, const bf_intrinsics *Kd, const uint16_t *depth,
                 float *uv, float *p, float *zc)
{
    for (uint32_t v = 0; v < Kd->height; v++)
        for (uint32_t u = 0; u < Kd->width; u++) {
            size_t i = (size_t)v * Kd->width + u;
            uv[2 * i] = NAN;
            if (!depth[i]) continue;
            double z = depth[i] / Kd->depth_scale;
            bf_vec3 pd = bf_v3(z * (u - Kd->cx_px) / Kd->fx_px, z * (v - Kd->cy_px) / Kd->fy_px, z);
            bf_vec3 q = bf_se3_apply(T_cd, pd);
            double uc, vc;
            if (!calib_project(c, q, &uc, &vc) || !(uc > -1 && vc > -1) || !(uc < 1e6 && vc < 1e6)) continue;
            uv[2 * i] = (float)uc, uv[2 * i + 1] = (float)vc;
            p[3 * i] = (float)pd.x, p[3 * i + 1] = (float)pd.y, p[3 * i + 2] = (float)pd.z;
            zc[i] = (float)q.z;
        }
}

/* The colour pixels point i covers: [x0, x1] x [y0, y1], clipped. */
static bool cover(const float *uv, size_t i, uint32_t w, uint32_t h, uint32_t *x0, uint32_t *x1, uint32_t *y0,
                  uint32_t *y1)
{
    if (isnan(uv[2 * i])) return false;
    double a0 = fmax(ceil(uv[2 * i] - COVER_PX), 0), a1 = fmin(floor(uv[2 * i] + COVER_PX), w - 1.0);
    double b0 = fmax(ceil(uv[2 * i + 1] - COVER_PX), 0), b1 = fmin(floor(uv[2 * i + 1] + COVER_PX), h - 1.0);
    if (a0 > a1 || b0 > b1) return false;
    *x0 = (uint32_t)a0, *x1 = (uint32_t)a1, *y0 = (uint32_t)b0, *y1 = (uint32_t)b1;
    return true;
}

/* The nearest depth the colour camera sees at each of its pixels, from
 * the points' covers. */
static void nearest_seen(const float *uv, const float *zc, size_t n, uint32_t w, uint32_t h, float *zbuf)
{
    for (size_t j = 0; j < (size_t)w * h; j++) zbuf[j] = INFINITY;
    uint32_t x0, x1, y0, y1;
    for (size_t i = 0; i < n; i++) {
        if (!cover(uv, i, w, h, &x0, &x1, &y0, &y1)) continue;
        for (uint32_t y = y0; y <= y1; y++)
            for (uint32_t x = x0; x <= x1; x++) {
                float *b = &zbuf[(size_t)y * w + x];
                if (zc[i] < *b) *b = zc[i];
            }
    }
}

bf_status calib_points_on_colour(const calib_camera *colour, const bf_se3 *T_colour_depth, const bf_intrinsics *Kd,
                                 const uint16_t *depth, uint32_t w, uint32_t h, float *xyz)
{
    if (!colour || !T_colour_depth || !Kd || !depth || !xyz || !w || !h || !Kd->width || !Kd->height ||
        !(Kd->depth_scale > 0) || !(Kd->fx_px != 0) || !(Kd->fy_px != 0))
        return bf_fail(BF_INVALID_ARG, "calib_points_on_colour: a NULL argument, an empty image or no depth scale");
    size_t n = (size_t)Kd->width * Kd->height, m = (size_t)w * h;
    float *uv = malloc(2 * n * sizeof *uv), *p = malloc(3 * n * sizeof *p), *zc = malloc(n * sizeof *zc);
    float *zbuf = malloc(m * sizeof *zbuf), *best = malloc(m * sizeof *best);
    if (!uv || !p || !zc || !zbuf || !best) {
        free(uv), free(p), free(zc), free(zbuf), free(best);
        return bf_fail(BF_NO_MEMORY, "calib_points_on_colour: %ux%u colour for %ux%u depth", w, h, Kd->width,
                       Kd->height);
    }
    land(colour, T_colour_depth, Kd, depth, uv, p, zc);
    nearest_seen(uv, zc, n, w, h, zbuf);
    /* Of the points on the surface the colour camera sees at a pixel
     * (within the occlusion margin of the nearest), the one that lands
     * nearest the pixel's centre. */
    const float nan = NAN;
    for (size_t j = 0; j < m; j++) best[j] = INFINITY, xyz[3 * j] = xyz[3 * j + 1] = xyz[3 * j + 2] = nan;
    uint32_t x0, x1, y0, y1;
    for (size_t i = 0; i < n; i++) {
        if (!cover(uv, i, w, h, &x0, &x1, &y0, &y1)) continue;
        for (uint32_t y = y0; y <= y1; y++)
            for (uint32_t x = x0; x <= x1; x++) {
                size_t j = (size_t)y * w + x;
                if (zc[i] > zbuf[j] + (float)fmax(OCCLUSION_MIN_M, OCCLUSION_REL * zc[i])) continue;
                float du = uv[2 * i] - (float)x, dv = uv[2 * i + 1] - (float)y, d = du * du + dv * dv;
                if (d >= best[j]) continue;
                best[j] = d;
                memcpy(xyz + 3 * j, p + 3 * i, 3 * sizeof *p);
            }
    }
    free(uv), free(p), free(zc), free(zbuf), free(best);
    return BF_OK;
}
