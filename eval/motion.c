/* The camera's motion between two frames as their colour images show it
 * (eval.h, "motion from colour"): the C side of motion_cv.cpp. */
#include <math.h>
#include <stdlib.h>

#include "eval.h"
#include "eval_motion_int.h"

struct eval_motion_image {
    eval__cv_features *f;
    uint32_t w, h;
};

eval_motion_config eval_motion_config_default(void)
{
    return (eval_motion_config){.n_features = 4000, .ransac_px = 2.0, .ransac_iterations = 2000,
                                .min_inliers = 50, .min_depth_m = 0.3f, .max_depth_m = 4.0f};
}

static bf_status cv_status(int rc, const char *what, const char *msg)
{
    if (rc == EVAL__CV_ERR_MEMORY) return bf_fail(BF_NO_MEMORY, "%s: %s", what, msg);
    return bf_fail(BF_NUMERIC, "%s: OpenCV: %s", what, msg);
}

bf_status eval_motion_image_make(const uint8_t *rgb, uint32_t w, uint32_t h, const eval_motion_config *cfg,
                                 eval_motion_image **out)
{
    *out = NULL;
    if (!rgb || !w || !h || !cfg || !cfg->n_features)
        return bf_fail(BF_INVALID_ARG, "eval_motion_image_make: no image (%ux%u) or no features asked for", w, h);
    size_t n = (size_t)w * h;
    uint8_t *grey = malloc(n);
    eval_motion_image *im = calloc(1, sizeof *im);
    if (!grey || !im) {
        free(grey);
        free(im);
        return bf_fail(BF_NO_MEMORY, "eval_motion_image_make: %ux%u", w, h);
    }
    /* Luma as BT.601 weighs it, in integers: what ORB sees of a colour image. */
    for (size_t i = 0; i < n; i++) {
        const uint8_t *p = rgb + 3 * i;
        grey[i] = (uint8_t)((77u * p[0] + 150u * p[1] + 29u * p[2] + 128u) >> 8);
    }
    char msg[256];
    int rc = eval__cv_features_make(grey, (int)w, (int)h, (int)cfg->n_features, &im->f, msg, sizeof msg);
    free(grey);
    if (rc != EVAL__CV_OK) {
        free(im);
        return cv_status(rc, "eval_motion_image_make", msg);
    }
    im->w = w;
    im->h = h;
    *out = im;
    return BF_OK;
}

void eval_motion_image_free(eval_motion_image *im)
{
    if (!im) return;
    eval__cv_features_free(im->f);
    free(im);
}

uint32_t eval_motion_image_features(const eval_motion_image *im)
{
    return im ? (uint32_t)eval__cv_features_count(im->f) : 0;
}

bf_status eval_motion_pnp(const eval_motion_image *a, const uint16_t *depth_a, const bf_intrinsics *K,
                          const eval_motion_image *b, const eval_motion_config *cfg, eval_motion_pair *out)
{
    *out = (eval_motion_pair){.ok = false, .T_ab = bf_se3_identity()};
    if (!a || !b || !depth_a || !K || !cfg || !(K->depth_scale > 0))
        return bf_fail(BF_INVALID_ARG, "eval_motion_pnp: missing input");
    if (a->w != K->width || a->h != K->height || b->w != K->width || b->h != K->height)
        return bf_fail(BF_INVALID_ARG, "eval_motion_pnp: images %ux%u and %ux%u, camera %ux%u", a->w, a->h, b->w, b->h,
                       K->width, K->height);
    size_t n = (size_t)a->w * a->h;
    float *z = malloc(n * sizeof *z);
    if (!z) return bf_fail(BF_NO_MEMORY, "eval_motion_pnp: %ux%u", a->w, a->h);
    for (size_t i = 0; i < n; i++) {
        float m = (float)(depth_a[i] / K->depth_scale);
        z[i] = (m >= cfg->min_depth_m && m <= cfg->max_depth_m) ? m : 0.0f;
    }
    const double Kd[4] = {K->fx_px, K->fy_px, K->cx_px, K->cy_px};
    eval__cv_pnp_result r;
    char msg[256];
    int rc = eval__cv_pnp(a->f, z, b->f, (int)a->w, (int)a->h, Kd, cfg->ransac_px, (int)cfg->ransac_iterations, &r,
                          msg, sizeof msg);
    free(z);
    if (rc != EVAL__CV_OK) return cv_status(rc, "eval_motion_pnp", msg);
    out->n_matches = r.n_matches;
    out->n_lifted = r.n_lifted;
    out->n_inliers = r.n_inliers;
    out->rms_px = r.rms_px;
    if (!r.ok || r.n_inliers < cfg->min_inliers) return BF_OK;
    /* OpenCV's pose takes a's points into b's camera, T_ba; the pose of
     * camera b in a's frame is its inverse. */
    bf_se3 T_ba;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) T_ba.R[i][j] = r.R_ba[3 * i + j];
    T_ba.t = bf_v3(r.t_ba[0], r.t_ba[1], r.t_ba[2]);
    out->T_ab = bf_se3_inverse(&T_ba);
    out->ok = true;
    return BF_OK;
}

void eval_motion_compare(const bf_se3 *T_ab_colour, const bf_se3 *T_wa, const bf_se3 *T_wb, eval_motion_error *out)
{
    bf_se3 Ta_inv = bf_se3_inverse(T_wa);
    bf_se3 T_ab = bf_se3_mul(&Ta_inv, T_wb);
    bf_vec3 d = bf_v3_sub(T_ab.t, T_ab_colour->t);
    bf_se3 Tc_inv = bf_se3_inverse(T_ab_colour);
    bf_se3 dR = bf_se3_mul(&Tc_inv, &T_ab);
    double c = sqrt(bf_v3_dot(T_ab_colour->t, T_ab_colour->t));
    out->trans_m = sqrt(bf_v3_dot(d, d));
    out->rot_deg = bf_se3_angle(&dR) * (180.0 / M_PI);
    out->colour_m = c;
    out->along_m = c > 0 ? bf_v3_dot(T_ab.t, T_ab_colour->t) / c : 0.0;
}
