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

/* Where a depth pixel's point lands in the colour image, worked out once
 * for the two passes over the points. */
typedef struct landing {
    float u, v;     /* its place in the colour image */
    float z;        /* its depth along the colour camera's axis */
    float z_hidden; /* a nearer surface at a pixel it covers hides it when nearer than this */
    int32_t x0, y0; /* the first pixel it covers; x0 < 0: it lands nowhere */
    uint8_t nx, ny; /* how many it covers along x and y (1 or 2) */
} landing;

/* The pixels [lo, hi] along one axis that a landing at a covers, clipped
 * to [0, n): count 0 when none. COVER_PX < 1, so at most two; a > -1. */
static inline void cover_axis(float a, uint32_t n, int32_t *lo, uint8_t *count)
{
    /* ceil(a - COVER_PX) and floor(a + COVER_PX), by truncating
     * non-negative values rather than calling floor and ceil. */
    float b = a - COVER_PX + 2, c = a + COVER_PX + 2;
    int32_t first = (int32_t)b - 2 + ((float)(int32_t)b < b), last = (int32_t)c - 2;
    if (first < 0) first = 0;
    if (last > (int32_t)n - 1) last = (int32_t)n - 1;
    *lo = first;
    *count = last >= first ? (uint8_t)(last - first + 1) : 0;
}

/* Each depth pixel's landing and its point in the depth camera (p). */
static void land(const calib_camera *c, const bf_se3 *T_cd, const bf_intrinsics *Kd, const uint16_t *depth,
                 uint32_t w, uint32_t h, landing *l, float *p)
{
    for (uint32_t v = 0; v < Kd->height; v++)
        for (uint32_t u = 0; u < Kd->width; u++) {
            size_t i = (size_t)v * Kd->width + u;
            l[i].x0 = -1;
            if (!depth[i]) continue;
            double z = depth[i] / Kd->depth_scale;
            bf_vec3 pd = bf_v3(z * (u - Kd->cx_px) / Kd->fx_px, z * (v - Kd->cy_px) / Kd->fy_px, z);
            bf_vec3 q = bf_se3_apply(T_cd, pd);
            double uc, vc;
            if (!calib_project(c, q, &uc, &vc) || !(uc > -1 && vc > -1) || !(uc < w + 1.0 && vc < h + 1.0)) continue;
            landing *a = &l[i];
            a->u = (float)uc, a->v = (float)vc, a->z = (float)q.z;
            a->z_hidden = (float)(q.z - fmax(OCCLUSION_MIN_M, OCCLUSION_REL * q.z));
            int32_t x0, y0;
            cover_axis(a->u, w, &x0, &a->nx);
            cover_axis(a->v, h, &y0, &a->ny);
            if (!a->nx || !a->ny) continue;
            a->x0 = x0, a->y0 = y0;
            p[3 * i] = (float)pd.x, p[3 * i + 1] = (float)pd.y, p[3 * i + 2] = (float)pd.z;
        }
}

/* The nearest depth the colour camera sees at each of its pixels, from
 * the points' covers. */
static void nearest_seen(const landing *l, size_t n, uint32_t w, uint32_t h, float *zbuf)
{
    for (size_t j = 0; j < (size_t)w * h; j++) zbuf[j] = INFINITY;
    for (size_t i = 0; i < n; i++) {
        const landing *a = &l[i];
        if (a->x0 < 0) continue;
        for (uint32_t y = 0; y < a->ny; y++)
            for (uint32_t x = 0; x < a->nx; x++) {
                float *b = &zbuf[(size_t)(a->y0 + y) * w + (size_t)(a->x0 + x)];
                if (a->z < *b) *b = a->z;
            }
    }
}

/* Of the points on the surface the colour camera sees at a pixel (within
 * the occlusion margin of the nearest), the one landing nearest the
 * pixel's centre: best[j], -1 where none. */
static void pick_points(const landing *l, size_t n, const float *zbuf, uint32_t w, uint32_t h, float *best_d2,
                        int32_t *best)
{
    for (size_t j = 0; j < (size_t)w * h; j++) best_d2[j] = INFINITY, best[j] = -1;
    for (size_t i = 0; i < n; i++) {
        const landing *a = &l[i];
        if (a->x0 < 0) continue;
        for (uint32_t y = 0; y < a->ny; y++)
            for (uint32_t x = 0; x < a->nx; x++) {
                int32_t px = a->x0 + (int32_t)x, py = a->y0 + (int32_t)y;
                size_t j = (size_t)py * w + (size_t)px;
                if (a->z_hidden > zbuf[j]) continue;
                float du = a->u - (float)px, dv = a->v - (float)py, d2 = du * du + dv * dv;
                if (d2 >= best_d2[j]) continue;
                best_d2[j] = d2;
                best[j] = (int32_t)i;
            }
    }
}

/* Each pixel's point, moved across the colour camera's view from where
 * it landed to the ray through the pixel's centre, at its depth: so a
 * keypoint between pixels can be lifted by interpolating its neighbours
 * (features_lift_points). To first order: the move takes the pinhole's
 * scale, which the lens changes by a few per cent, so a point half a
 * pixel off is left within a few hundredths of a pixel. NaN where none. */
static void place_points(const calib_camera *c, const bf_se3 *T_cd, const landing *l, const float *p,
                         const int32_t *best, uint32_t w, uint32_t h, float *xyz)
{
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            size_t j = (size_t)y * w + x;
            float *o = xyz + 3 * j;
            if (best[j] < 0) {
                o[0] = o[1] = o[2] = NAN;
                continue;
            }
            const landing *a = &l[best[j]];
            const float *q = p + 3 * (size_t)best[j];
            /* The move in the colour camera's frame, then in the depth
             * camera's: R_cd^T times it. */
            double mx = -(a->u - (double)x) * a->z / c->fx_px, my = -(a->v - (double)y) * a->z / c->fy_px;
            for (int k = 0; k < 3; k++) o[k] = (float)(q[k] + T_cd->R[0][k] * mx + T_cd->R[1][k] * my);
        }
}

bf_status calib_points_on_colour(const calib_camera *colour, const bf_se3 *T_colour_depth, const bf_intrinsics *Kd,
                                 const uint16_t *depth, uint32_t w, uint32_t h, float *xyz)
{
    if (!colour || !T_colour_depth || !Kd || !depth || !xyz || !w || !h || !Kd->width || !Kd->height ||
        !(Kd->depth_scale > 0) || !(Kd->fx_px != 0) || !(Kd->fy_px != 0) || w > INT32_MAX / 2 || h > INT32_MAX / 2)
        return bf_fail(BF_INVALID_ARG, "calib_points_on_colour: a NULL argument, an empty image or no depth scale");
    size_t n = (size_t)Kd->width * Kd->height, m = (size_t)w * h;
    landing *l = malloc(n * sizeof *l);
    float *p = malloc(3 * n * sizeof *p), *zbuf = malloc(m * sizeof *zbuf), *best_d2 = malloc(m * sizeof *best_d2);
    int32_t *best = malloc(m * sizeof *best);
    bf_status s = BF_OK;
    if (l && p && zbuf && best_d2 && best) {
        land(colour, T_colour_depth, Kd, depth, w, h, l, p);
        nearest_seen(l, n, w, h, zbuf);
        pick_points(l, n, zbuf, w, h, best_d2, best);
        place_points(colour, T_colour_depth, l, p, best, w, h, xyz);
    } else {
        s = bf_fail(BF_NO_MEMORY, "calib_points_on_colour: %ux%u colour for %ux%u depth", w, h, Kd->width, Kd->height);
    }
    free(l), free(p), free(zbuf), free(best_d2), free(best);
    return s;
}
