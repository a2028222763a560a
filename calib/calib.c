/* calib: the C side of the estimate: boards, the views each camera found,
 * and the calls into calib_cv.cpp with OpenCV's failures turned into
 * statuses. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "calib.h"
#include "calib_int.h"

bf_status calib_parse_board(const char *text, calib_board *out)
{
    unsigned cols, rows;
    char tail;
    if (sscanf(text, "%ux%u%c", &cols, &rows, &tail) != 2 || cols < 2 || rows < 2 || cols > 64 || rows > 64)
        return bf_fail(BF_INVALID_ARG, "board '%s' is not COLSxROWS inner corners, each 2..64 (e.g. 9x6)", text);
    out->cols = cols;
    out->rows = rows;
    return BF_OK;
}

static bf_status cv_status(int code, const char *what, const char *msg)
{
    if (code == CALIB__ERR_MEMORY) return bf_fail(BF_NO_MEMORY, "%s: out of memory in OpenCV", what);
    return bf_fail(BF_NUMERIC, "%s: OpenCV: %s", what, msg);
}

bf_status calib_find_corners(const calib_board *b, const uint8_t *grey, uint32_t w, uint32_t h, bool *is_found,
                             double *corners_px)
{
    char msg[512] = "";
    int found = 0;
    if (b->cols * b->rows > CALIB_MAX_CORNERS || w == 0 || h == 0)
        return bf_fail(BF_INVALID_ARG, "calib: board %ux%u or image %ux%u out of range", b->cols, b->rows, w, h);
    int rc = calib__cv_find_corners(grey, (int)w, (int)h, (int)b->cols, (int)b->rows, &found, corners_px, msg,
                                    sizeof msg);
    if (rc) return cv_status(rc, "calib: corners", msg);
    *is_found = found != 0;
    return BF_OK;
}

static void object_points(const calib_board *b, double *obj)
{
    for (uint32_t j = 0; j < b->rows; j++)
        for (uint32_t i = 0; i < b->cols; i++) {
            obj[2 * (j * b->cols + i)] = i * b->square_m;
            obj[2 * (j * b->cols + i) + 1] = j * b->square_m;
        }
}

/* The found views' corners (those with use[k]) packed one after another. */
static uint32_t pack(const calib_views *v, const bool *use, size_t n_corners, double *out)
{
    uint32_t n = 0;
    for (uint32_t k = 0; k < v->n_views; k++)
        if (use[k]) memcpy(out + 2 * n_corners * n++, v->corners_px + 2 * n_corners * k, 2 * n_corners * sizeof *out);
    return n;
}

calib_config calib_config_default(void) { return (calib_config){.radial_terms = 3}; }

/* calib_camera.coverage of n views' corners (buf, packed). */
static double coverage(const calib_camera *c, const double *buf, size_t n_points)
{
    double far = 0, reach = 0;
    for (int k = 0; k < 4; k++) {
        double x = ((k & 1) ? c->width - 0.5 : -0.5) - c->cx_px, y = ((k & 2) ? c->height - 0.5 : -0.5) - c->cy_px;
        far = fmax(far, hypot(x / c->fx_px, y / c->fy_px));
    }
    for (size_t i = 0; i < n_points; i++)
        reach = fmax(reach, hypot((buf[2 * i] - c->cx_px) / c->fx_px, (buf[2 * i + 1] - c->cy_px) / c->fy_px));
    return far > 0 ? fmin(1.0, reach / far) : 0.0;
}

/* calib_camera.extrapolation_px between fits a and b: the rays through the
 * image's corners and edge centres by a's pinhole, each projected through
 * both fits. Forward only, so a wild fit cannot fail to invert. */
static double extrapolation(const calib_camera *a, const calib_camera *b)
{
    double worst = 0;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            if (i == 1 && j == 1) continue;
            double u = -0.5 + 0.5 * i * a->width, v = -0.5 + 0.5 * j * a->height;
            bf_vec3 ray = bf_v3((u - a->cx_px) / a->fx_px, (v - a->cy_px) / a->fy_px, 1);
            double ua, va, ub, vb;
            calib_project(a, ray, &ua, &va);
            calib_project(b, ray, &ub, &vb);
            double d = hypot(ua - ub, va - vb);
            worst = isfinite(d) ? fmax(worst, d) : 1e9; /* a fit that throws the ray off: as far apart as it gets */
        }
    return worst;
}

static bf_status fit(const calib_views *v, const double *obj, const double *buf, uint32_t n, size_t n_corners,
                     bool fix_k3, const char *name, calib_camera *c)
{
    double K[4], rms;
    char msg[512] = "";
    int rc = calib__cv_calibrate((int)n, (int)n_corners, obj, buf, (int)v->width, (int)v->height, fix_k3, K, c->dist,
                                 &rms, msg, sizeof msg);
    if (rc) return cv_status(rc, name, msg);
    c->width = v->width, c->height = v->height;
    c->fx_px = K[0], c->fy_px = K[1], c->cx_px = K[2], c->cy_px = K[3];
    c->rms_px = rms;
    return BF_OK;
}

/* One camera alone from every view it found. */
static bf_status calibrate_one(const calib_board *b, const calib_config *cfg, const double *obj,
                               const calib_views *v, const char *name, double *buf, calib_camera *c)
{
    size_t n_corners = (size_t)b->cols * b->rows;
    uint32_t n = pack(v, v->is_found, n_corners, buf);
    if (n < CALIB_MIN_VIEWS)
        return bf_fail(BF_FORMAT, "calib: the board was found in %u of the %u %s images; calibration needs %d", n,
                       v->n_views, name, CALIB_MIN_VIEWS);
    bf_status s = fit(v, obj, buf, n, n_corners, cfg->radial_terms < 3, name, c);
    if (s != BF_OK) return s;
    c->coverage = coverage(c, buf, (size_t)n * n_corners);
    c->extrapolation_px = 0;
    if (c->coverage < 1) {
        /* A diagnostic only: its failure loses the figure, not the fit. */
        calib_camera other;
        if (fit(v, obj, buf, n, n_corners, cfg->radial_terms >= 3, name, &other) == BF_OK)
            c->extrapolation_px = extrapolation(c, &other);
        else
            bf_warn("calib: %s: the fit with the other number of radial terms failed (%s): how uncertain the lens "
                    "is beyond the boards is not measured", name, bf_last_error());
    }
    return BF_OK;
}

bf_status calib_estimate(const calib_board *b, const calib_config *cfg, const calib_views *colour,
                         const calib_views *depth, calib_result *out)
{
    if (cfg->radial_terms < 2 || cfg->radial_terms > 3)
        return bf_fail(BF_INVALID_ARG, "calib: %u radial distortion terms (2 or 3)", cfg->radial_terms);
    size_t n_corners = (size_t)b->cols * b->rows;
    if (n_corners > CALIB_MAX_CORNERS || !(b->square_m > 0))
        return bf_fail(BF_INVALID_ARG, "calib: board %ux%u of %g m squares", b->cols, b->rows, b->square_m);
    if (depth && depth->n_views != colour->n_views)
        return bf_fail(BF_INVALID_ARG, "calib: %u depth images for %u colour images: they pair by order",
                       depth->n_views, colour->n_views);
    calib_result r;
    memset(&r, 0, sizeof r);
    double *obj = malloc(2 * n_corners * sizeof *obj);
    double *buf = malloc(2 * n_corners * (colour->n_views ? colour->n_views : 1) * sizeof *buf);
    double *buf2 = depth ? malloc(2 * n_corners * (colour->n_views ? colour->n_views : 1) * sizeof *buf2) : NULL;
    bool *both = depth ? calloc(colour->n_views ? colour->n_views : 1, sizeof *both) : NULL;
    bf_status s = BF_OK;
    if (!obj || !buf || (depth && (!buf2 || !both))) {
        s = bf_fail(BF_NO_MEMORY, "calib: corners of %u views", colour->n_views);
        goto fail;
    }
    object_points(b, obj);
    if ((s = calibrate_one(b, cfg, obj, colour, "colour", buf, &r.colour)) != BF_OK) goto fail;
    r.rms_px = r.colour.rms_px;
    r.n_views = pack(colour, colour->is_found, n_corners, buf);
    if (depth) {
        if ((s = calibrate_one(b, cfg, obj, depth, "depth", buf, &r.depth)) != BF_OK) goto fail;
        for (uint32_t k = 0; k < colour->n_views; k++) both[k] = colour->is_found[k] && depth->is_found[k];
        uint32_t n = pack(depth, both, n_corners, buf);
        pack(colour, both, n_corners, buf2);
        if (n < CALIB_MIN_VIEWS) {
            s = bf_fail(BF_FORMAT, "calib: the board was found in both images of %u of the %u views; the stereo "
                                   "transform needs %d", n, colour->n_views, CALIB_MIN_VIEWS);
            goto fail;
        }
        double K1[4] = {r.depth.fx_px, r.depth.fy_px, r.depth.cx_px, r.depth.cy_px};
        double K2[4] = {r.colour.fx_px, r.colour.fy_px, r.colour.cx_px, r.colour.cy_px};
        double R[9], t[3], rms;
        char msg[512] = "";
        int rc = calib__cv_stereo((int)n, (int)n_corners, obj, buf, buf2, (int)depth->width, (int)depth->height, K1,
                                  r.depth.dist, K2, r.colour.dist, R, t, &rms, msg, sizeof msg);
        if (rc) {
            s = cv_status(rc, "stereo", msg);
            goto fail;
        }
        for (int i = 0; i < 9; i++) r.T_colour_depth.R[i / 3][i % 3] = R[i];
        r.T_colour_depth.t = bf_v3(t[0], t[1], t[2]);
        r.has_depth = true;
        r.rms_px = rms;
        r.n_views = n;
    }
    *out = r;
fail:
    free(obj);
    free(buf);
    free(buf2);
    free(both);
    return s;
}

bf_intrinsics calib_camera_intrinsics(const calib_camera *c)
{
    bf_intrinsics K = {.width = c->width, .height = c->height, .fx_px = c->fx_px, .fy_px = c->fy_px,
                       .cx_px = c->cx_px, .cy_px = c->cy_px};
    return K;
}
