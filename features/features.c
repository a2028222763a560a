/* features: the C side of features_cv.cpp (features.h). */
#include <math.h>
#include <stdlib.h>

#include "features.h"
#include "features_int.h"

static bf_status cv_status(int rc, const char *what, const char *msg)
{
    if (rc == FEATURES__ERR_MEMORY) return bf_fail(BF_NO_MEMORY, "%s: %s", what, msg);
    if (rc == FEATURES__ERR_ARG) return bf_fail(BF_INVALID_ARG, "%s: %s", what, msg);
    return bf_fail(BF_NUMERIC, "%s: OpenCV: %s", what, msg);
}

bf_status features_detect_rgb(const uint8_t *rgb, uint32_t w, uint32_t h, uint32_t n_features, bool keep_image,
                              features_set **out)
{
    if (!out) return bf_fail(BF_INVALID_ARG, "features_detect_rgb: no output");
    *out = NULL;
    if (!rgb || !w || !h || !n_features || n_features > (uint32_t)INT32_MAX || w > 65535 || h > 65535)
        return bf_fail(BF_INVALID_ARG, "features_detect_rgb: no image (%ux%u) or %u features asked for", w, h,
                       n_features);
    size_t n = (size_t)w * h;
    uint8_t *grey = bf_malloc(n);
    if (!grey) return bf_fail(BF_NO_MEMORY, "features_detect_rgb: %ux%u", w, h);
    /* Luma as BT.601 weighs it, in integers: what ORB sees of a colour image. */
    for (size_t i = 0; i < n; i++) {
        const uint8_t *p = rgb + 3 * i;
        grey[i] = (uint8_t)((77u * p[0] + 150u * p[1] + 29u * p[2] + 128u) >> 8);
    }
    char msg[256];
    int rc = features__detect(grey, (int)w, (int)h, (int)n_features, keep_image, out, msg, sizeof msg);
    free(grey);
    return rc == FEATURES__OK ? BF_OK : cv_status(rc, "features_detect_rgb", msg);
}

void features_free(features_set *f) { features__free(f); }

uint32_t features_count(const features_set *f) { return (uint32_t)features__count(f); }

size_t features_bytes(const features_set *f) { return features__bytes(f); }

bf_status features_lift(const features_set *f, const uint16_t *depth, const bf_intrinsics *K, float min_m,
                        float max_m, bool keep_image, features_set **out)
{
    if (!out) return bf_fail(BF_INVALID_ARG, "features_lift: no output");
    *out = NULL;
    if (!f || !depth || !K || !(K->depth_scale > 0) || !(K->fx_px > 0) || !(fabs(K->fy_px) > 0) || !K->width ||
        !K->height || K->width > 65535 || K->height > 65535)
        return bf_fail(BF_INVALID_ARG, "features_lift: missing input or a camera without scale or focal length");
    const double Kd[4] = {K->fx_px, K->fy_px, K->cx_px, K->cy_px};
    char msg[256];
    int rc = features__lift(f, depth, (int)K->width, (int)K->height, K->depth_scale, Kd, min_m, max_m, keep_image,
                            out, msg, sizeof msg);
    return rc == FEATURES__OK ? BF_OK : cv_status(rc, "features_lift", msg);
}

bf_status features_lift_points(const features_set *f, const float *xyz, uint32_t w, uint32_t h, float min_m,
                               float max_m, bool keep_image, features_set **out)
{
    if (!out) return bf_fail(BF_INVALID_ARG, "features_lift_points: no output");
    *out = NULL;
    if (!f || !xyz || !w || !h || w > 65535 || h > 65535)
        return bf_fail(BF_INVALID_ARG, "features_lift_points: missing input or no image (%ux%u)", w, h);
    char msg[256];
    int rc = features__lift_points(f, xyz, (int)w, (int)h, min_m, max_m, keep_image, out, msg, sizeof msg);
    return rc == FEATURES__OK ? BF_OK : cv_status(rc, "features_lift_points", msg);
}

bf_status features_export_lifted(const features_set *f, uint32_t *n, uint8_t **desc, float **xyz)
{
    if (!f || !n || !desc || !xyz) return bf_fail(BF_INVALID_ARG, "features_export_lifted: missing input or output");
    *n = 0, *desc = NULL, *xyz = NULL;
    uint32_t k = (uint32_t)features__lifted_count(f);
    if (!k) return BF_OK;
    uint8_t *d = bf_malloc((size_t)k * 32);
    float *p = bf_malloc((size_t)k * 3 * sizeof *p);
    if (!d || !p) {
        free(d), free(p);
        return bf_fail(BF_NO_MEMORY, "features_export_lifted: %u keypoints", k);
    }
    features__lifted_copy(f, d, p);
    *n = k, *desc = d, *xyz = p;
    return BF_OK;
}

bf_status features_import_lifted(uint32_t n, const uint8_t *desc, const float *xyz, features_set **out)
{
    if (!out) return bf_fail(BF_INVALID_ARG, "features_import_lifted: no output");
    *out = NULL;
    if (n > (uint32_t)INT32_MAX || (n && (!desc || !xyz)))
        return bf_fail(BF_INVALID_ARG, "features_import_lifted: %u keypoints without arrays", n);
    for (size_t i = 0; i < 3 * (size_t)n; i++)
        if (!isfinite(xyz[i])) return bf_fail(BF_INVALID_ARG, "features_import_lifted: point %zu not finite", i / 3);
    char msg[256];
    int rc = features__import(n, desc, xyz, out, msg, sizeof msg);
    return rc == FEATURES__OK ? BF_OK : cv_status(rc, "features_import_lifted", msg);
}

bf_status features_match_count(const features_set *a, const features_set *b, uint32_t max_hamming, uint32_t *n)
{
    if (!n) return bf_fail(BF_INVALID_ARG, "features_match_count: no output");
    *n = 0;
    if (!a || !b || max_hamming > 256)
        return bf_fail(BF_INVALID_ARG, "features_match_count: missing input or %u bits of 256", max_hamming);
    char msg[256];
    int rc = features__match_count(a, b, (int)max_hamming, n, msg, sizeof msg);
    return rc == FEATURES__OK ? BF_OK : cv_status(rc, "features_match_count", msg);
}

bf_status features_pnp(const features_set *a, const features_set *b, const bf_intrinsics *K, const double *dist,
                       const features_pnp_config *cfg, features_pnp_result *out)
{
    if (!out) return bf_fail(BF_INVALID_ARG, "features_pnp: no output");
    *out = (features_pnp_result){.ok = false, .T_ba = bf_se3_identity()};
    if (!a || !b || !K || !cfg || !(K->fx_px > 0) || !(fabs(K->fy_px) > 0) || !(cfg->ransac_px > 0) ||
        !cfg->ransac_iterations || cfg->ransac_iterations > (uint32_t)INT32_MAX || cfg->max_hamming > 256)
        return bf_fail(BF_INVALID_ARG, "features_pnp: missing input, a camera without focal length or no RANSAC");
    for (int i = 0; dist && i < 5; i++)
        if (!isfinite(dist[i])) return bf_fail(BF_INVALID_ARG, "features_pnp: lens coefficient %d not finite", i);
    const double Kd[4] = {K->fx_px, K->fy_px, K->cx_px, K->cy_px};
    features__pnp_out r;
    char msg[256];
    int rc = features__pnp(a, b, Kd, dist, cfg->ransac_px, (int)cfg->ransac_iterations, (int)cfg->max_hamming,
                           cfg->fast, &r, msg, sizeof msg);
    if (rc != FEATURES__OK) return cv_status(rc, "features_pnp", msg);
    out->n_matches = r.n_matches;
    out->n_placed = r.n_placed;
    out->n_inliers = r.n_inliers;
    out->rms_px = r.rms_px;
    if (!r.ok || r.n_inliers < cfg->min_inliers) return BF_OK;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) out->T_ba.R[i][j] = r.R_ba[3 * i + j];
    out->T_ba.t = bf_v3(r.t_ba[0], r.t_ba[1], r.t_ba[2]);
    out->ok = true;
    return BF_OK;
}
