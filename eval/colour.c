/* Colour of a reconstruction against the input images: the coloured mesh
 * re-rendered at a frame's pose (a ray per pixel through the BVH, vertex
 * colours interpolated at the hit) and compared with the frame's colour
 * image, pixel by pixel where the mesh is hit (PSNR, as texture-mapping
 * and colour-fusion papers report it). */
#include <math.h>
#include <string.h>

#include "eval.h"

typedef struct render_job {
    const mesh_data *m;
    const mesh_bvh *bvh;
    const bf_intrinsics *K;
    const double *dist; /* the camera's lens (CALIB_DIST_N), NULL: a pinhole */
    bf_se3 T;          /* camera to the mesh's local frame */
    uint8_t *rgb, *hit;
} render_job;

static void render_row(void *ctx, size_t v)
{
    const render_job *j = ctx;
    const bf_intrinsics *K = j->K;
    for (uint32_t u = 0; u < K->width; u++) {
        size_t i = v * K->width + u;
        double x = (u - K->cx_px) / K->fx_px, y = ((double)v - K->cy_px) / K->fy_px;
        mesh_hit h;
        j->hit[i] = 0;
        memset(j->rgb + 3 * i, 0, 3);
        /* Through a lens the pixel sees along its undistorted ray. */
        if (j->dist && !calib_undistort(j->dist, x, y, &x, &y)) continue;
        bf_vec3 d = bf_se3_rotate(&j->T, bf_v3(x, y, 1.0));
        if (!mesh_bvh_raycast(j->bvh, j->T.t, d, 1e-3, INFINITY, &h)) continue;
        const uint32_t *t = j->m->tri + 3 * (size_t)h.tri;
        double w[3] = {1 - h.u - h.v, h.u, h.v};
        for (int c = 0; c < 3; c++) {
            double x = 0;
            for (int k = 0; k < 3; k++) x += w[k] * j->m->rgb[3 * (size_t)t[k] + c];
            j->rgb[3 * i + c] = (uint8_t)fmin(255.0, fmax(0.0, x + 0.5));
        }
        j->hit[i] = 1;
    }
}

bf_status eval_colour_render(const mesh_data *m, const mesh_bvh *bvh, const bf_intrinsics *K, const double *dist,
                             const bf_se3 *T_wc, uint8_t *rgb_out, uint8_t *hit_out)
{
    if (!m || !bvh || !K || !T_wc || !rgb_out || !hit_out)
        return bf_fail(BF_INVALID_ARG, "eval_colour_render: NULL argument");
    if (!m->rgb) return bf_fail(BF_INVALID_ARG, "eval: the mesh has no vertex colour");
    render_job j = {m, bvh, K, dist, *T_wc, rgb_out, hit_out};
    j.T.t = bf_v3_sub(T_wc->t, m->origin); /* the BVH holds the local positions */
    bf_parallel_for(K->height, render_row, &j);
    return BF_OK;
}

void eval_colour_compare(const uint8_t *a, const uint8_t *b, const uint8_t *mask, size_t n_px, eval_colour_sums *acc)
{
    for (size_t i = 0; i < n_px; i++) {
        if (!mask[i]) continue;
        for (int c = 0; c < 3; c++) {
            double e = (double)a[3 * i + c] - (double)b[3 * i + c];
            acc->sse += e * e;
        }
        acc->n += 3;
    }
}

double eval_colour_psnr(const eval_colour_sums *s)
{
    if (s->n == 0) return NAN;
    double mse = s->sse / (double)s->n;
    return mse > 0 ? 10.0 * log10(255.0 * 255.0 / mse) : INFINITY;
}
