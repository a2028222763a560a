/* calib: calib.json (docs/formats.md, "Calibration files"), read and
 * written with cJSON. Numbers are printed with the fewest digits (15 to 17)
 * that read back bit for bit (bf_fmt_double): a calibration read back is the
 * one written. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cjson/cJSON.h>

#include "calib.h"

#define CALIB_FORMAT_NAME "bitfuse-calibration"
#define CALIB_VERSION 1

/* ------------------------------------------------------------ writing */

static cJSON *json_exact(double v)
{
    char text[BF_FMT_DOUBLE_CAP];
    return cJSON_CreateRaw(bf_fmt_double(text, v));
}

static cJSON *json_numbers(const double *v, int n)
{
    cJSON *a = cJSON_CreateArray();
    for (int i = 0; i < n && a; i++) cJSON_AddItemToArray(a, json_exact(v[i]));
    return a;
}

static cJSON *json_camera(const calib_camera *c)
{
    cJSON *o = cJSON_CreateObject();
    cJSON_AddNumberToObject(o, "width", c->width);
    cJSON_AddNumberToObject(o, "height", c->height);
    cJSON_AddItemToObject(o, "fx", json_exact(c->fx_px));
    cJSON_AddItemToObject(o, "fy", json_exact(c->fy_px));
    cJSON_AddItemToObject(o, "cx", json_exact(c->cx_px));
    cJSON_AddItemToObject(o, "cy", json_exact(c->cy_px));
    cJSON_AddItemToObject(o, "dist", json_numbers(c->dist, CALIB_DIST_N));
    cJSON_AddItemToObject(o, "rms_px", json_exact(c->rms_px));
    cJSON_AddItemToObject(o, "coverage", json_exact(c->coverage));
    cJSON_AddItemToObject(o, "extrapolation_px", json_exact(c->extrapolation_px));
    return o;
}

static cJSON *json_result(const calib_result *r)
{
    cJSON *root = cJSON_CreateObject();
    cJSON_AddStringToObject(root, "format", CALIB_FORMAT_NAME);
    cJSON_AddNumberToObject(root, "version", CALIB_VERSION);
    cJSON_AddItemToObject(root, "colour", json_camera(&r->colour));
    if (r->has_depth) {
        cJSON_AddItemToObject(root, "depth", json_camera(&r->depth));
        cJSON *T = cJSON_AddObjectToObject(root, "T_colour_depth");
        const bf_se3 *X = &r->T_colour_depth;
        double R[9], t[3] = {X->t.x, X->t.y, X->t.z};
        for (int i = 0; i < 9; i++) R[i] = X->R[i / 3][i % 3];
        cJSON_AddItemToObject(T, "R", json_numbers(R, 9));
        cJSON_AddItemToObject(T, "t", json_numbers(t, 3));
    }
    cJSON_AddItemToObject(root, "rms_px", json_exact(r->rms_px));
    cJSON_AddNumberToObject(root, "views", r->n_views);
    return root;
}

bf_status calib_to_text(const calib_result *r, char **text)
{
    cJSON *root = json_result(r);
    char *t = root ? cJSON_Print(root) : NULL;
    cJSON_Delete(root);
    if (!t) return bf_fail(BF_NO_MEMORY, "calib: out of memory building the JSON");
    /* cJSON's allocator is malloc unless a program installs hooks; copy so
     * the caller's free() is right either way. */
    *text = strdup(t);
    cJSON_free(t);
    return *text ? BF_OK : bf_fail(BF_NO_MEMORY, "calib: out of memory building the JSON");
}

bf_status calib_write(const char *path, const calib_result *r)
{
    char *text;
    bf_status s = calib_to_text(r, &text);
    if (s != BF_OK) return s;
    size_t n = strlen(text);
    char *file = realloc(text, n + 2);
    if (!file) {
        free(text);
        return bf_fail(BF_NO_MEMORY, "%s: out of memory", path);
    }
    file[n] = '\n';
    s = bf_write_file_atomic(path, file, n + 1);
    free(file);
    return s;
}

/* ------------------------------------------------------------ reading */

/* A finite number at o.name into *v; the message names the field. */
static bf_status get_number(const char *path, const char *obj, const cJSON *o, const char *name, double *v)
{
    const cJSON *x = cJSON_GetObjectItemCaseSensitive(o, name);
    if (!x) return bf_fail(BF_FORMAT, "%s: %s.%s: missing", path, obj, name);
    if (!cJSON_IsNumber(x)) return bf_fail(BF_FORMAT, "%s: %s.%s: not a number", path, obj, name);
    /* cJSON parses 1e999 as inf; a literal NaN is not JSON at all. */
    if (!isfinite(x->valuedouble)) return bf_fail(BF_FORMAT, "%s: %s.%s: not finite", path, obj, name);
    *v = x->valuedouble;
    return BF_OK;
}

static bf_status get_numbers(const char *path, const char *obj, const cJSON *o, const char *name, double *v, int n)
{
    const cJSON *a = cJSON_GetObjectItemCaseSensitive(o, name);
    if (!a) return bf_fail(BF_FORMAT, "%s: %s.%s: missing", path, obj, name);
    if (!cJSON_IsArray(a) || cJSON_GetArraySize(a) != n)
        return bf_fail(BF_FORMAT, "%s: %s.%s: not a list of %d numbers", path, obj, name, n);
    for (int i = 0; i < n; i++) {
        const cJSON *x = cJSON_GetArrayItem(a, i);
        if (!cJSON_IsNumber(x) || !isfinite(x->valuedouble))
            return bf_fail(BF_FORMAT, "%s: %s.%s[%d]: not a finite number", path, obj, name, i);
        v[i] = x->valuedouble;
    }
    return BF_OK;
}

static bf_status get_size(const char *path, const char *obj, const cJSON *o, const char *name, uint32_t *v)
{
    double x;
    bf_status s = get_number(path, obj, o, name, &x);
    if (s != BF_OK) return s;
    if (!(x >= 1 && x <= 65535) || x != floor(x))
        return bf_fail(BF_FORMAT, "%s: %s.%s: %g is not a whole number of pixels in 1..65535", path, obj, name, x);
    *v = (uint32_t)x;
    return BF_OK;
}

static bf_status parse_camera(const char *path, const char *obj, const cJSON *o, calib_camera *c)
{
    if (!cJSON_IsObject(o)) return bf_fail(BF_FORMAT, "%s: %s: not an object", path, obj);
    bf_status s;
    memset(c, 0, sizeof *c);
    if ((s = get_size(path, obj, o, "width", &c->width)) || (s = get_size(path, obj, o, "height", &c->height)) ||
        (s = get_number(path, obj, o, "fx", &c->fx_px)) || (s = get_number(path, obj, o, "fy", &c->fy_px)) ||
        (s = get_number(path, obj, o, "cx", &c->cx_px)) || (s = get_number(path, obj, o, "cy", &c->cy_px)))
        return s;
    if (!(c->fx_px > 0)) return bf_fail(BF_FORMAT, "%s: %s.fx: %g is not positive", path, obj, c->fx_px);
    if (!(c->fy_px > 0)) return bf_fail(BF_FORMAT, "%s: %s.fy: %g is not positive", path, obj, c->fy_px);
    /* Pixel centres at integers: the image spans [-0.5, width - 0.5]. */
    if (!(c->cx_px >= -0.5 && c->cx_px <= c->width - 0.5))
        return bf_fail(BF_FORMAT, "%s: %s.cx: %g is outside the image's %u columns", path, obj, c->cx_px, c->width);
    if (!(c->cy_px >= -0.5 && c->cy_px <= c->height - 0.5))
        return bf_fail(BF_FORMAT, "%s: %s.cy: %g is outside the image's %u rows", path, obj, c->cy_px, c->height);
    /* A camera written by hand may leave its distortion out: none. */
    if (cJSON_GetObjectItemCaseSensitive(o, "dist") &&
        (s = get_numbers(path, obj, o, "dist", c->dist, CALIB_DIST_N)) != BF_OK)
        return s;
    if (cJSON_GetObjectItemCaseSensitive(o, "rms_px") && (s = get_number(path, obj, o, "rms_px", &c->rms_px)) != BF_OK)
        return s;
    if (cJSON_GetObjectItemCaseSensitive(o, "coverage") &&
        (s = get_number(path, obj, o, "coverage", &c->coverage)) != BF_OK)
        return s;
    if (!(c->coverage >= 0 && c->coverage <= 1))
        return bf_fail(BF_FORMAT, "%s: %s.coverage: %g is not a fraction in 0..1", path, obj, c->coverage);
    if (cJSON_GetObjectItemCaseSensitive(o, "extrapolation_px") &&
        (s = get_number(path, obj, o, "extrapolation_px", &c->extrapolation_px)) != BF_OK)
        return s;
    if (!(c->extrapolation_px >= 0))
        return bf_fail(BF_FORMAT, "%s: %s.extrapolation_px: %g is negative", path, obj, c->extrapolation_px);
    return BF_OK;
}

/* R must be a rotation: orthonormal within 1e-6 (exact numbers keep
 * 1e-15; six printed decimals keep 1e-6) and right-handed. */
static bool is_rotation(const double R[3][3])
{
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            double d = 0;
            for (int k = 0; k < 3; k++) d += R[k][i] * R[k][j];
            if (fabs(d - (i == j)) > 1e-6) return false;
        }
    double det = R[0][0] * (R[1][1] * R[2][2] - R[1][2] * R[2][1]) - R[0][1] * (R[1][0] * R[2][2] - R[1][2] * R[2][0]) +
                 R[0][2] * (R[1][0] * R[2][1] - R[1][1] * R[2][0]);
    return det > 0;
}

static bf_status parse_root(const char *path, const cJSON *root, calib_result *r)
{
    if (!cJSON_IsObject(root)) return bf_fail(BF_FORMAT, "%s: not a JSON object", path);
    const cJSON *fmt = cJSON_GetObjectItemCaseSensitive(root, "format");
    if (fmt && (!cJSON_IsString(fmt) || strcmp(fmt->valuestring, CALIB_FORMAT_NAME) != 0))
        return bf_fail(BF_FORMAT, "%s: format: not \"%s\"", path, CALIB_FORMAT_NAME);
    const cJSON *ver = cJSON_GetObjectItemCaseSensitive(root, "version");
    if (ver && (!cJSON_IsNumber(ver) || ver->valuedouble < 1))
        return bf_fail(BF_FORMAT, "%s: version: not a version number", path);
    if (ver && ver->valuedouble > CALIB_VERSION)
        return bf_fail(BF_UNSUPPORTED, "%s: version %g is newer than this program's %d", path, ver->valuedouble,
                       CALIB_VERSION);
    memset(r, 0, sizeof *r);
    const cJSON *colour = cJSON_GetObjectItemCaseSensitive(root, "colour");
    if (!colour) return bf_fail(BF_FORMAT, "%s: colour: missing", path);
    bf_status s = parse_camera(path, "colour", colour, &r->colour);
    if (s != BF_OK) return s;
    const cJSON *depth = cJSON_GetObjectItemCaseSensitive(root, "depth");
    const cJSON *T = cJSON_GetObjectItemCaseSensitive(root, "T_colour_depth");
    if (depth && !T) return bf_fail(BF_FORMAT, "%s: T_colour_depth: missing (the file has a depth camera)", path);
    if (T && !depth) return bf_fail(BF_FORMAT, "%s: depth: missing (the file has T_colour_depth)", path);
    if (depth) {
        if ((s = parse_camera(path, "depth", depth, &r->depth)) != BF_OK) return s;
        if (!cJSON_IsObject(T)) return bf_fail(BF_FORMAT, "%s: T_colour_depth: not an object", path);
        double R[9], t[3];
        if ((s = get_numbers(path, "T_colour_depth", T, "R", R, 9)) ||
            (s = get_numbers(path, "T_colour_depth", T, "t", t, 3)))
            return s;
        for (int i = 0; i < 9; i++) r->T_colour_depth.R[i / 3][i % 3] = R[i];
        r->T_colour_depth.t = bf_v3(t[0], t[1], t[2]);
        if (!is_rotation(r->T_colour_depth.R))
            return bf_fail(BF_FORMAT, "%s: T_colour_depth.R: not a rotation (orthonormal, determinant 1)", path);
        r->has_depth = true;
    }
    if (cJSON_GetObjectItemCaseSensitive(root, "rms_px") && (s = get_number(path, "file", root, "rms_px", &r->rms_px)))
        return s;
    const cJSON *views = cJSON_GetObjectItemCaseSensitive(root, "views");
    if (views) {
        if (!cJSON_IsNumber(views) || !(views->valuedouble >= 0 && views->valuedouble <= 1e9) ||
            views->valuedouble != floor(views->valuedouble))
            return bf_fail(BF_FORMAT, "%s: views: not a count", path);
        r->n_views = (uint32_t)views->valuedouble;
    }
    return BF_OK;
}

bf_status calib_parse(const char *path, const char *text, size_t len, calib_result *out)
{
    /* A byte-order mark is skipped here, so the offsets named are the file's. */
    size_t bom = bf_bom_bytes(text, len);
    const char *end = NULL;
    cJSON *root = cJSON_ParseWithLengthOpts(text + bom, len - bom, &end, false);
    if (!root) {
        const char *at = cJSON_GetErrorPtr();
        size_t off = at && at >= text && at <= text + len ? (size_t)(at - text) : 0;
        return bf_fail(BF_FORMAT, "%s: not JSON (near byte %zu)", path, off);
    }
    size_t tail = bf_trailing_text(text, len, end);
    if (tail < len) {
        cJSON_Delete(root);
        return bf_fail(BF_FORMAT, "%s: text after the JSON value at byte %zu", path, tail);
    }
    calib_result r;
    bf_status s = parse_root(path, root, &r);
    cJSON_Delete(root);
    if (s == BF_OK) *out = r;
    return s;
}

bf_status calib_read(const char *path, calib_result *out)
{
    char *text;
    size_t len;
    bf_status s = bf_read_file(path, &text, &len);
    if (s != BF_OK) return s;
    s = calib_parse(path, text, len, out);
    free(text);
    return s;
}
