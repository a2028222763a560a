/* The camera's motion between two frames as their colour images show it
 * (eval.h, "motion from colour"), through features/ (ORB and PnP). */
#include <math.h>
#include <stdlib.h>

#include "eval.h"
#include "features/features.h"

struct eval_motion_image {
    features_set *f;
    uint32_t w, h;
};

eval_motion_config eval_motion_config_default(void)
{
    return (eval_motion_config){.n_features = 4000, .ransac_px = 2.0, .ransac_iterations = 2000,
                                .min_inliers = 50, .min_depth_m = 0.3f, .max_depth_m = 4.0f};
}

bf_status eval_motion_image_make(const uint8_t *rgb, uint32_t w, uint32_t h, const eval_motion_config *cfg,
                                 eval_motion_image **out)
{
    *out = NULL;
    if (!rgb || !w || !h || !cfg || !cfg->n_features)
        return bf_fail(BF_INVALID_ARG, "eval_motion_image_make: no image (%ux%u) or no features asked for", w, h);
    eval_motion_image *im = calloc(1, sizeof *im);
    if (!im) return bf_fail(BF_NO_MEMORY, "eval_motion_image_make: %ux%u", w, h);
    /* The grey image is kept: each match is placed again by Lucas-Kanade. */
    bf_status s = features_detect_rgb(rgb, w, h, cfg->n_features, true, &im->f);
    if (s != BF_OK) {
        free(im);
        return s;
    }
    im->w = w;
    im->h = h;
    *out = im;
    return BF_OK;
}

void eval_motion_image_free(eval_motion_image *im)
{
    if (!im) return;
    features_free(im->f);
    free(im);
}

uint32_t eval_motion_image_features(const eval_motion_image *im)
{
    return im ? features_count(im->f) : 0;
}

/* a's features with their points in a's depth camera: lifted by depth_a
 * at their own pixels, or through the rig's colour camera. */
static bf_status lift(const eval_motion_image *a, const uint16_t *depth_a, const bf_intrinsics *K,
                      const eval_motion_rig *rig, const eval_motion_config *cfg, features_set **out)
{
    if (!rig) return features_lift(a->f, depth_a, K, cfg->min_depth_m, cfg->max_depth_m, true, out);
    float *xyz = malloc((size_t)a->w * a->h * 3 * sizeof *xyz);
    if (!xyz) return bf_fail(BF_NO_MEMORY, "eval_motion_pnp: %ux%u points", a->w, a->h);
    bf_status s = calib_points_on_colour(rig->colour, &rig->T_colour_depth, K, depth_a, a->w, a->h, xyz);
    if (s == BF_OK) s = features_lift_points(a->f, xyz, a->w, a->h, cfg->min_depth_m, cfg->max_depth_m, true, out);
    free(xyz);
    return s;
}

bf_status eval_motion_pnp(const eval_motion_image *a, const uint16_t *depth_a, const bf_intrinsics *K,
                          const eval_motion_rig *rig, const eval_motion_image *b, const eval_motion_config *cfg,
                          eval_motion_pair *out)
{
    *out = (eval_motion_pair){.ok = false, .T_ab = bf_se3_identity()};
    if (!a || !b || !depth_a || !K || !cfg || !(K->depth_scale > 0) || (rig && !rig->colour))
        return bf_fail(BF_INVALID_ARG, "eval_motion_pnp: missing input");
    if (a->w != K->width || a->h != K->height || b->w != K->width || b->h != K->height)
        return bf_fail(BF_INVALID_ARG, "eval_motion_pnp: images %ux%u and %ux%u, camera %ux%u", a->w, a->h, b->w, b->h,
                       K->width, K->height);
    if (rig && (rig->colour->width != a->w || rig->colour->height != a->h))
        return bf_fail(BF_INVALID_ARG, "eval_motion_pnp: images %ux%u, the colour camera %ux%u", a->w, a->h,
                       rig->colour->width, rig->colour->height);
    features_set *lifted;
    bf_status s = lift(a, depth_a, K, rig, cfg, &lifted);
    if (s != BF_OK) return s;
    const features_pnp_config pc = {.ransac_px = cfg->ransac_px, .ransac_iterations = cfg->ransac_iterations,
                                    .min_inliers = cfg->min_inliers};
    bf_intrinsics Kb = rig ? calib_camera_intrinsics(rig->colour) : *K;
    features_pnp_result r;
    s = features_pnp(lifted, b->f, &Kb, rig ? rig->colour->dist : NULL, &pc, &r);
    features_free(lifted);
    if (s != BF_OK) return s;
    out->n_matches = r.n_matches;
    out->n_lifted = r.n_placed;
    out->n_inliers = r.n_inliers;
    out->rms_px = r.rms_px;
    if (!r.ok) return BF_OK;
    /* The pose takes a's points into b's camera, T_ba (with a rig: into b's
     * colour camera, and T_dc T_ba into its depth camera); the pose of
     * camera b in a's frame is its inverse. */
    bf_se3 T_ba = r.T_ba;
    if (rig) {
        bf_se3 T_dc = bf_se3_inverse(&rig->T_colour_depth);
        T_ba = bf_se3_mul(&T_dc, &r.T_ba);
    }
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
