/* calib: depth_correction.json (docs/formats.md, "Depth correction
 * files"), read and written with cJSON. The multipliers are printed with 9
 * significant digits, so a float read back is the one written. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cjson/cJSON.h>

#include "calib.h"

#define DEPTH_FORMAT_NAME "bitfuse-depth-correction"
#define DEPTH_VERSION 1

static cJSON *json_float(double v, const char *fmt)
{
    char text[40];
    snprintf(text, sizeof text, fmt, v);
    return cJSON_CreateRaw(text);
}

bf_status calib_depth_write(const char *path, const calib_depth_correction *c)
{
    cJSON *root = cJSON_CreateObject();
    cJSON_AddStringToObject(root, "format", DEPTH_FORMAT_NAME);
    cJSON_AddNumberToObject(root, "version", DEPTH_VERSION);
    cJSON_AddNumberToObject(root, "width", c->width);
    cJSON_AddNumberToObject(root, "height", c->height);
    cJSON_AddNumberToObject(root, "cell_px", c->cell_px);
    cJSON_AddNumberToObject(root, "grid_w", c->grid_w);
    cJSON_AddNumberToObject(root, "grid_h", c->grid_h);
    cJSON_AddNumberToObject(root, "frames", c->n_frames);
    cJSON_AddNumberToObject(root, "pairs", c->n_pairs);
    cJSON_AddNumberToObject(root, "cells_measured", c->n_cells_measured);
    cJSON_AddItemToObject(root, "rms_before", json_float(c->rms_before, "%.6g"));
    cJSON_AddItemToObject(root, "rms_after", json_float(c->rms_after, "%.6g"));
    /* The pixels the pattern lies in: the lens taken out of the frames
     * (null: none), each number as it reads back bit for bit. */
    if (c->is_lens_known && calib_has_distortion(c->lens)) {
        cJSON *l = cJSON_AddArrayToObject(root, "undistorted");
        char text[BF_FMT_DOUBLE_CAP];
        for (int i = 0; l && i < CALIB_DIST_N; i++) cJSON_AddItemToArray(l, cJSON_CreateRaw(bf_fmt_double(text, c->lens[i])));
    } else if (c->is_lens_known) {
        cJSON_AddNullToObject(root, "undistorted");
    }
    /* One row of the grid per line: the file reads as the image does. */
    cJSON *rows = cJSON_AddArrayToObject(root, "multipliers");
    for (uint32_t y = 0; rows && y < c->grid_h; y++) {
        cJSON *row = cJSON_CreateArray();
        for (uint32_t x = 0; row && x < c->grid_w; x++)
            cJSON_AddItemToArray(row, json_float(c->mult[(size_t)y * c->grid_w + x], "%.9g"));
        cJSON_AddItemToArray(rows, row);
    }
    char *t = cJSON_PrintUnformatted(root);
    cJSON_Delete(root);
    if (!t) return bf_fail(BF_NO_MEMORY, "%s: out of memory building the JSON", path);
    /* Unformatted, then a line break after each row. */
    size_t n = strlen(t), extra = c->grid_h + 2;
    char *file = malloc(n + extra + 1);
    if (!file) {
        cJSON_free(t);
        return bf_fail(BF_NO_MEMORY, "%s: out of memory", path);
    }
    size_t k = 0;
    for (size_t i = 0; i < n; i++) {
        file[k++] = t[i];
        if (t[i] == '[' && i + 1 < n && t[i + 1] == '[') file[k++] = '\n';
        else if (t[i] == ']' && i + 1 < n && t[i + 1] == ',' && i + 2 < n && t[i + 2] == '[') {
            file[k++] = ',';
            file[k++] = '\n';
            i++;
        }
    }
    file[k++] = '\n';
    cJSON_free(t);
    bf_status s = bf_write_file_atomic(path, file, k);
    free(file);
    return s;
}

static bf_status get_count(const char *path, const cJSON *o, const char *name, double lo, double hi, bool required,
                           uint32_t *v)
{
    const cJSON *x = cJSON_GetObjectItemCaseSensitive(o, name);
    if (!x) return required ? bf_fail(BF_FORMAT, "%s: %s: missing", path, name) : BF_OK;
    if (!cJSON_IsNumber(x) || !(x->valuedouble >= lo && x->valuedouble <= hi) ||
        x->valuedouble != floor(x->valuedouble))
        return bf_fail(BF_FORMAT, "%s: %s: not a whole number in %g..%g", path, name, lo, hi);
    *v = (uint32_t)x->valuedouble;
    return BF_OK;
}

static bf_status get_real(const char *path, const cJSON *o, const char *name, double *v)
{
    const cJSON *x = cJSON_GetObjectItemCaseSensitive(o, name);
    if (!x) return BF_OK;
    if (!cJSON_IsNumber(x) || !isfinite(x->valuedouble) || x->valuedouble < 0)
        return bf_fail(BF_FORMAT, "%s: %s: not a finite number >= 0", path, name);
    *v = x->valuedouble;
    return BF_OK;
}

/* "undistorted": absent (a file from before it: unknown), null (frames
 * read as a pinhole) or the lens's CALIB_DIST_N coefficients. */
static bf_status get_lens(const char *path, const cJSON *root, calib_depth_correction *c)
{
    const cJSON *x = cJSON_GetObjectItemCaseSensitive(root, "undistorted");
    if (!x) return BF_OK;
    c->is_lens_known = true;
    if (cJSON_IsNull(x)) return BF_OK;
    if (!cJSON_IsArray(x) || cJSON_GetArraySize(x) != CALIB_DIST_N)
        return bf_fail(BF_FORMAT, "%s: undistorted: not null or a list of %d numbers", path, CALIB_DIST_N);
    for (int i = 0; i < CALIB_DIST_N; i++) {
        const cJSON *v = cJSON_GetArrayItem(x, i);
        if (!cJSON_IsNumber(v) || !isfinite(v->valuedouble))
            return bf_fail(BF_FORMAT, "%s: undistorted[%d]: not a finite number", path, i);
        c->lens[i] = v->valuedouble;
    }
    return BF_OK;
}

bool calib_depth_same_lens(const calib_depth_correction *c, const double *dist)
{
    if (!c->is_lens_known) return true;
    for (int i = 0; i < CALIB_DIST_N; i++) {
        double a = c->lens[i], b = dist ? dist[i] : 0.0;
        if (fabs(a - b) > 1e-12 * (1.0 + fabs(a))) return false;
    }
    return true;
}

static bf_status parse_root(const char *path, const cJSON *root, calib_depth_correction *c)
{
    if (!cJSON_IsObject(root)) return bf_fail(BF_FORMAT, "%s: not a JSON object", path);
    const cJSON *fmt = cJSON_GetObjectItemCaseSensitive(root, "format");
    if (!fmt || !cJSON_IsString(fmt) || strcmp(fmt->valuestring, DEPTH_FORMAT_NAME) != 0)
        return bf_fail(BF_FORMAT, "%s: format: not \"%s\"", path, DEPTH_FORMAT_NAME);
    const cJSON *ver = cJSON_GetObjectItemCaseSensitive(root, "version");
    if (!ver || !cJSON_IsNumber(ver) || ver->valuedouble < 1)
        return bf_fail(BF_FORMAT, "%s: version: not a version number", path);
    if (ver->valuedouble > DEPTH_VERSION)
        return bf_fail(BF_UNSUPPORTED, "%s: version %g is newer than this program's %d", path, ver->valuedouble,
                       DEPTH_VERSION);
    memset(c, 0, sizeof *c);
    bf_status s;
    if ((s = get_count(path, root, "width", 1, 65535, true, &c->width)) ||
        (s = get_count(path, root, "height", 1, 65535, true, &c->height)) ||
        (s = get_count(path, root, "cell_px", 1, 65535, true, &c->cell_px)) ||
        (s = get_count(path, root, "grid_w", 1, 65535, true, &c->grid_w)) ||
        (s = get_count(path, root, "grid_h", 1, 65535, true, &c->grid_h)) ||
        (s = get_count(path, root, "frames", 0, 4e9, false, &c->n_frames)) ||
        (s = get_count(path, root, "pairs", 0, 4e9, false, &c->n_pairs)) ||
        (s = get_count(path, root, "cells_measured", 0, 4e9, false, &c->n_cells_measured)) ||
        (s = get_real(path, root, "rms_before", &c->rms_before)) || (s = get_real(path, root, "rms_after", &c->rms_after)))
        return s;
    if ((s = get_lens(path, root, c)) != BF_OK) return s;
    if (c->grid_w != (c->width + c->cell_px - 1) / c->cell_px || c->grid_h != (c->height + c->cell_px - 1) / c->cell_px)
        return bf_fail(BF_FORMAT, "%s: grid %ux%u does not cover %ux%u pixels in cells of %u", path, c->grid_w,
                       c->grid_h, c->width, c->height, c->cell_px);
    if ((uint64_t)c->grid_w * c->grid_h > CALIB_DEPTH_GRID_MAX)
        return bf_fail(BF_FORMAT, "%s: %ux%u cells: more than %u", path, c->grid_w, c->grid_h, CALIB_DEPTH_GRID_MAX);
    const cJSON *rows = cJSON_GetObjectItemCaseSensitive(root, "multipliers");
    if (!cJSON_IsArray(rows) || cJSON_GetArraySize(rows) != (int)c->grid_h)
        return bf_fail(BF_FORMAT, "%s: multipliers: not a list of %u rows", path, c->grid_h);
    for (uint32_t y = 0; y < c->grid_h; y++) {
        const cJSON *row = cJSON_GetArrayItem(rows, (int)y);
        if (!cJSON_IsArray(row) || cJSON_GetArraySize(row) != (int)c->grid_w)
            return bf_fail(BF_FORMAT, "%s: multipliers[%u]: not a list of %u numbers", path, y, c->grid_w);
        for (uint32_t x = 0; x < c->grid_w; x++) {
            const cJSON *v = cJSON_GetArrayItem(row, (int)x);
            /* A depth camera's pattern is a few percent at most; a multiplier
             * outside 0.5..2 is a broken file, not a sensor. */
            if (!cJSON_IsNumber(v) || !(v->valuedouble >= 0.5 && v->valuedouble <= 2.0))
                return bf_fail(BF_FORMAT, "%s: multipliers[%u][%u]: not a number in 0.5..2", path, y, x);
            c->mult[(size_t)y * c->grid_w + x] = (float)v->valuedouble;
        }
    }
    return BF_OK;
}

bf_status calib_depth_parse(const char *path, const char *text, size_t len, calib_depth_correction *out)
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
    calib_depth_correction *c = malloc(sizeof *c);
    if (!c) {
        cJSON_Delete(root);
        return bf_fail(BF_NO_MEMORY, "%s: out of memory", path);
    }
    bf_status s = parse_root(path, root, c);
    cJSON_Delete(root);
    if (s == BF_OK) *out = *c;
    free(c);
    return s;
}

bf_status calib_depth_read(const char *path, calib_depth_correction *out)
{
    char *text;
    size_t len;
    bf_status s = bf_read_file(path, &text, &len);
    if (s != BF_OK) return s;
    s = calib_depth_parse(path, text, len, out);
    free(text);
    return s;
}
