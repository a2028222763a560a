/* capture: opening a live source by URI. The scheme picks a backend from
 * one table (Redis's aeApi* idea); each backend is compiled only when its
 * library was found at configure time (BF_HAVE_FREENECT, BF_HAVE_OPENNI2,
 * BF_HAVE_V4L2), and a URI for a missing one says which Debian package
 * would bring it. Also the pure helpers the backends share: URI options,
 * the Kinect v1 disparity model and pixel-format conversions. */
#include "live_int.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

typedef struct capture_backend {
    const char *scheme;
    const char *package; /* Debian 12 package with the library's headers */
    bf_status (*open)(const char *uri, const char *target, const capture__uri_options *opt, rgbd_source **out);
    uint32_t (*list)(capture_device_info *out, uint32_t cap);
} capture_backend;

/* open == NULL: known scheme, backend not compiled in. */
static const capture_backend capture_backends[] = {
#ifdef BF_HAVE_FREENECT
    {"freenect", "libfreenect-dev", capture__freenect_open, capture__freenect_list},
#else
    {"freenect", "libfreenect-dev", NULL, NULL},
#endif
#ifdef BF_HAVE_OPENNI2
    {"openni2", "libopenni2-dev", capture__openni2_open, capture__openni2_list},
#else
    {"openni2", "libopenni2-dev", NULL, NULL},
#endif
#ifdef BF_HAVE_V4L2
    {"v4l2", "linux-libc-dev", capture__v4l2_open, capture__v4l2_list},
#else
    {"v4l2", "linux-libc-dev (V4L2 exists on Linux only)", NULL, NULL},
#endif
};
#define CAPTURE_N_BACKENDS (sizeof capture_backends / sizeof capture_backends[0])

const char *const *capture_backend_names(void)
{
    static const char *names[CAPTURE_N_BACKENDS + 1];
    size_t n = 0;
    for (size_t i = 0; i < CAPTURE_N_BACKENDS; i++)
        if (capture_backends[i].open) names[n++] = capture_backends[i].scheme;
    names[n] = NULL;
    return names;
}

bf_status capture_open(const char *uri, rgbd_source **out)
{
    if (!uri || !out) return bf_fail(BF_INVALID_ARG, "capture_open: NULL argument");
    const char *colon = strchr(uri, ':');
    if (!colon || colon == uri)
        return bf_fail(BF_INVALID_ARG, "%s: not a device URI (expected freenect:N, openni2:[URI|FILE.oni] or "
                                       "v4l2:/dev/videoN)",
                       uri);
    size_t scheme_len = (size_t)(colon - uri);
    for (size_t i = 0; i < CAPTURE_N_BACKENDS; i++) {
        const capture_backend *b = &capture_backends[i];
        if (strlen(b->scheme) != scheme_len || strncmp(uri, b->scheme, scheme_len)) continue;
        if (!b->open)
            return bf_fail(BF_UNSUPPORTED, "%s: this bitfuse was built without the %s backend; install %s and "
                                           "rebuild (scripts/install-deps.sh)",
                           uri, b->scheme, b->package);
        char target[1024];
        capture__uri_options opt;
        bf_status s = capture__uri_split(uri, colon + 1, target, sizeof target, &opt);
        if (s) return s;
        rgbd_source *src = NULL;
        if ((s = b->open(uri, target, &opt, &src))) return s;
        capture__apply_options(&opt, &src->intrinsics);
        *out = src;
        return BF_OK;
    }
    char known[128] = "";
    for (size_t i = 0; i < CAPTURE_N_BACKENDS; i++) {
        size_t used = strlen(known);
        snprintf(known + used, sizeof known - used, "%s%s", i ? ", " : "", capture_backends[i].scheme);
    }
    return bf_fail(BF_INVALID_ARG, "%s: unknown capture scheme '%.*s' (known: %s)", uri, (int)scheme_len, uri, known);
}

bool capture_is_device_uri(const char *uri)
{
    for (size_t i = 0; uri && i < CAPTURE_N_BACKENDS; i++) {
        size_t n = strlen(capture_backends[i].scheme);
        if (!strncmp(uri, capture_backends[i].scheme, n) && uri[n] == ':') return true;
    }
    return false;
}

bool capture_is_recording_uri(const char *uri)
{
    size_t n = uri ? strlen(uri) : 0;
    return n > 4 && capture_is_device_uri(uri) && !strcasecmp(uri + n - 4, ".oni");
}

bf_status capture_open_device(const char *uri, capture_open_fn open_recording, void *user, bool realtime,
                              uint32_t queue, bool *is_live, rgbd_source **out)
{
    rgbd_source *dev = NULL, *paced = NULL;
    bool live = capture_is_device_uri(uri);
    if (!live && !open_recording) return bf_fail(BF_INVALID_ARG, "%s: not a device URI", uri);
    bf_status s = live ? capture_open(uri, &dev) : open_recording(user, uri, &dev);
    if (s != BF_OK) return s;
    if (!live && realtime) {
        if ((s = capture_paced(dev, &paced)) != BF_OK) {
            rgbd_source_close(dev);
            return s;
        }
        dev = paced;
    }
    /* A camera (or a file played as one) must never wait for us; a file
     * read as fast as it decodes must not lose frames. */
    s = live || realtime ? capture_threaded(dev, queue, out) : capture_threaded_lossless(dev, queue, out);
    if (s != BF_OK) {
        rgbd_source_close(dev);
        return s;
    }
    *is_live = live;
    return BF_OK;
}

uint32_t capture_list_devices(capture_device_info *out, uint32_t cap)
{
    uint32_t n = 0;
    for (size_t i = 0; i < CAPTURE_N_BACKENDS; i++) {
        if (!capture_backends[i].list) continue;
        n += capture_backends[i].list(n < cap ? out + n : NULL, n < cap ? cap - n : 0);
    }
    return n;
}

/* ------------------------------------------------------------ URI options */

static bf_status uri_option(const char *uri, const char *key, size_t key_len, const char *val, size_t val_len,
                            capture__uri_options *opt)
{
    char v[128];
    if (val_len >= sizeof v) return bf_fail(BF_INVALID_ARG, "%s: option value too long", uri);
    memcpy(v, val, val_len);
    v[val_len] = 0;
    if (key_len == 6 && !strncmp(key, "camera", 6)) {
        double k[4];
        char w[sizeof v];
        memcpy(w, v, sizeof w);
        char *p = w; /* cut at the commas; v stays whole for the messages */
        for (int i = 0; i < 4; i++) {
            char *end = strchr(p, ',');
            if ((i < 3) != (end != NULL))
                return bf_fail(BF_INVALID_ARG, "%s: camera=%s: expected fx,fy,cx,cy in pixels", uri, v);
            if (end) *end = 0;
            /* Decimal numbers, as every option takes them. */
            if (!bf_parse_double(p, &k[i]))
                return bf_fail(BF_INVALID_ARG, "%s: camera=%s: expected fx,fy,cx,cy in pixels", uri, v);
            p = end ? end + 1 : p;
        }
        if (k[0] <= 0 || k[1] == 0)
            return bf_fail(BF_INVALID_ARG, "%s: camera=%s: focal lengths must be non-zero (fx > 0)", uri, v);
        opt->has_camera = true;
        opt->fx_px = k[0], opt->fy_px = k[1], opt->cx_px = k[2], opt->cy_px = k[3];
        return BF_OK;
    }
    if (key_len == 11 && !strncmp(key, "depth_scale", 11)) {
        if (!bf_parse_double(v, &opt->depth_scale) || !(opt->depth_scale > 0))
            return bf_fail(BF_INVALID_ARG, "%s: depth_scale=%s: expected raw units per metre > 0", uri, v);
        opt->has_depth_scale = true;
        return BF_OK;
    }
    if (key_len == 5 && !strncmp(key, "depth", 5)) {
        if (strcmp(v, "registered") && strcmp(v, "disparity"))
            return bf_fail(BF_INVALID_ARG, "%s: depth=%s: expected registered or disparity", uri, v);
        strcpy(opt->depth_mode, v); /* one of the two names above */
        return BF_OK;
    }
    return bf_fail(BF_INVALID_ARG, "%s: unknown option '%.*s' (known: camera, depth_scale, depth)", uri,
                   (int)key_len, key);
}

bf_status capture__uri_split(const char *uri, const char *after_scheme, char *target, size_t cap,
                             capture__uri_options *opt)
{
    memset(opt, 0, sizeof *opt);
    const char *q = strchr(after_scheme, '?');
    size_t len = q ? (size_t)(q - after_scheme) : strlen(after_scheme);
    if (len >= cap) return bf_fail(BF_INVALID_ARG, "%s: device part too long", uri);
    if (!q) {
        memcpy(target, after_scheme, len);
        target[len] = 0;
        return BF_OK;
    }
    capture__uri_options o = {0};
    for (const char *p = q + 1; *p;) {
        const char *amp = strchr(p, '&');
        size_t n = amp ? (size_t)(amp - p) : strlen(p);
        const char *eq = memchr(p, '=', n);
        if (!eq) return bf_fail(BF_INVALID_ARG, "%s: option '%.*s' has no '=value'", uri, (int)n, p);
        bf_status s = uri_option(uri, p, (size_t)(eq - p), eq + 1, n - (size_t)(eq - p) - 1, &o);
        if (s) return s;
        p += n + (amp ? 1 : 0);
    }
    memcpy(target, after_scheme, len);
    target[len] = 0;
    *opt = o;
    return BF_OK;
}

void capture__apply_options(const capture__uri_options *opt, bf_intrinsics *K)
{
    if (opt->has_camera) {
        K->fx_px = opt->fx_px, K->fy_px = opt->fy_px;
        K->cx_px = opt->cx_px, K->cy_px = opt->cy_px;
    }
    if (opt->has_depth_scale) K->depth_scale = opt->depth_scale;
}

/* ------------------------------------------------------------ Kinect v1 model */

capture__kinect_params capture__kinect_default_params(void)
{
    return (capture__kinect_params){.dcmos_emitter_dist_cm = 7.5,
                                    .reference_distance_mm = 120.0,
                                    .reference_pixel_size_mm = 0.1042,
                                    .const_shift = 200.0};
}

double capture__kinect_raw_to_mm(uint16_t raw, const capture__kinect_params *p)
{
    if (raw >= 2047) return NAN;
    /* libfreenect registration.c: parameter_coefficient 4, shift_scale 10,
     * S2D_CONST_OFFSET 0.375 (from the PrimeSense reference driver). The
     * model mixes cm and mm; shift_scale 10 makes the result millimetres. */
    double fixed_ref_x = (raw - 4.0 * p->const_shift) / 4.0 - 0.375;
    double metric = fixed_ref_x * p->reference_pixel_size_mm;
    double mm = 10.0 * (metric * p->reference_distance_mm / (p->dcmos_emitter_dist_cm - metric) +
                        p->reference_distance_mm);
    if (!(mm > 0.0 && mm <= 10000.0)) return NAN;
    return mm;
}

double capture__kinect_ir_focal_px(const capture__kinect_params *p)
{
    /* The reference pixel size is for the 1280x1024 sensor; at 640x480 a
     * pixel is twice as large. */
    return p->reference_distance_mm / (2.0 * p->reference_pixel_size_mm);
}

double capture__focal_from_fov(uint32_t size_px, double fov_rad)
{
    if (!(fov_rad > 0.0 && fov_rad < M_PI)) return NAN;
    return 0.5 * size_px / tan(0.5 * fov_rad);
}

/* ------------------------------------------------------------ pixel formats */

static inline uint8_t clamp_u8(int v) { return (uint8_t)(v < 0 ? 0 : v > 255 ? 255 : v); }

/* BT.601 limited range in 8.8 fixed point (coefficients 1.164, 1.596,
 * 0.392, 0.813, 2.017 as in the V4L2 colour-space documentation). */
static inline void yuv_to_rgb(int y, int u, int v, uint8_t *rgb)
{
    int c = 298 * (y - 16), d = u - 128, e = v - 128;
    rgb[0] = clamp_u8((c + 409 * e + 128) >> 8);
    rgb[1] = clamp_u8((c - 100 * d - 208 * e + 128) >> 8);
    rgb[2] = clamp_u8((c + 516 * d + 128) >> 8);
}

void capture__yuyv_to_rgb(const uint8_t *src, size_t src_stride, uint32_t w, uint32_t h, uint8_t *rgb)
{
    for (uint32_t y = 0; y < h; y++) {
        const uint8_t *s = src + y * src_stride;
        uint8_t *d = rgb + (size_t)y * w * 3;
        for (uint32_t x = 0; x + 1 < w; x += 2, s += 4, d += 6) {
            yuv_to_rgb(s[0], s[1], s[3], d);
            yuv_to_rgb(s[2], s[1], s[3], d + 3);
        }
    }
}

void capture__uyvy_to_rgb(const uint8_t *src, size_t src_stride, uint32_t w, uint32_t h, uint8_t *rgb)
{
    for (uint32_t y = 0; y < h; y++) {
        const uint8_t *s = src + y * src_stride;
        uint8_t *d = rgb + (size_t)y * w * 3;
        for (uint32_t x = 0; x + 1 < w; x += 2, s += 4, d += 6) {
            yuv_to_rgb(s[1], s[0], s[2], d);
            yuv_to_rgb(s[3], s[0], s[2], d + 3);
        }
    }
}

void capture__bgr_to_rgb(const uint8_t *src, size_t src_stride, uint32_t w, uint32_t h, uint8_t *rgb)
{
    for (uint32_t y = 0; y < h; y++) {
        const uint8_t *s = src + y * src_stride;
        uint8_t *d = rgb + (size_t)y * w * 3;
        for (uint32_t x = 0; x < w; x++, s += 3, d += 3) {
            d[0] = s[2];
            d[1] = s[1];
            d[2] = s[0];
        }
    }
}

void capture__copy_rows(const uint8_t *src, size_t src_stride, size_t row_bytes, uint32_t h, uint8_t *dst)
{
    if (src_stride == row_bytes) {
        memcpy(dst, src, row_bytes * h);
        return;
    }
    for (uint32_t y = 0; y < h; y++) memcpy(dst + y * row_bytes, src + y * src_stride, row_bytes);
}

/* One axis of the resize: for each destination pixel, up to k source
 * taps and their weights. Shrinking averages the source pixels the
 * destination pixel covers, each by the length it covers (an area resize);
 * growing interpolates between the two nearest source centres. Either way
 * a destination pixel's centre x + 0.5 sits at (x + 0.5) * s / d in the
 * source, which is what a colour camera scaled to the new size assumes
 * (app/calibration.c): taking the nearest source pixel instead put a half
 * size image a quarter of a pixel off. */
static void resize_taps(uint32_t s, uint32_t d, uint32_t k, uint32_t *idx, float *w)
{
    double r = (double)s / d;
    for (uint32_t x = 0; x < d; x++) {
        uint32_t *ix = idx + (size_t)x * k;
        float *wx = w + (size_t)x * k;
        for (uint32_t j = 0; j < k; j++) ix[j] = 0, wx[j] = 0.0f;
        if (r >= 1.0) {
            double a = x * r, b = (x + 1) * r;
            uint32_t j = 0;
            for (uint32_t i = (uint32_t)a; i < s && i < b && j < k; i++, j++) {
                double lo = i > a ? i : a, hi = i + 1.0 < b ? i + 1.0 : b;
                ix[j] = i;
                wx[j] = (float)((hi - lo) / r);
            }
        } else {
            double c = (x + 0.5) * r - 0.5;
            if (c < 0) c = 0;
            if (c > s - 1) c = s - 1;
            uint32_t i = (uint32_t)c;
            ix[0] = i;
            ix[1] = i + 1 < s ? i + 1 : i;
            wx[1] = (float)(c - i);
            wx[0] = 1.0f - wx[1];
        }
    }
}

/* Taps one axis needs at most: a shrink by r covers ceil(r) + 1 pixels. */
static uint32_t resize_tap_count(uint32_t s, uint32_t d) { return s >= d ? (s + d - 1) / d + 1 : 2u; }

bf_status capture__resize_rgb(const uint8_t *src, uint32_t sw, uint32_t sh, uint8_t *dst, uint32_t dw, uint32_t dh)
{
    if (!src || !dst || !sw || !sh || !dw || !dh)
        return bf_fail(BF_INVALID_ARG, "colour resize %ux%u -> %ux%u: an empty image", sw, sh, dw, dh);
    uint32_t kx = resize_tap_count(sw, dw), ky = resize_tap_count(sh, dh);
    uint32_t *ix = malloc((size_t)dw * kx * sizeof *ix), *iy = malloc((size_t)dh * ky * sizeof *iy);
    float *wx = malloc((size_t)dw * kx * sizeof *wx), *wy = malloc((size_t)dh * ky * sizeof *wy);
    bf_status s = BF_OK;
    if (!ix || !iy || !wx || !wy) {
        s = bf_fail(BF_NO_MEMORY, "colour resize %ux%u -> %ux%u: out of memory", sw, sh, dw, dh);
        goto done;
    }
    resize_taps(sw, dw, kx, ix, wx);
    resize_taps(sh, dh, ky, iy, wy);
    for (uint32_t y = 0; y < dh; y++) {
        for (uint32_t x = 0; x < dw; x++) {
            double acc[3] = {0, 0, 0};
            for (uint32_t b = 0; b < ky; b++) {
                double vy = wy[(size_t)y * ky + b];
                if (vy == 0.0) continue;
                const uint8_t *row = src + (size_t)iy[(size_t)y * ky + b] * sw * 3;
                for (uint32_t a = 0; a < kx; a++) {
                    double v = vy * wx[(size_t)x * kx + a];
                    const uint8_t *p = row + (size_t)ix[(size_t)x * kx + a] * 3;
                    acc[0] += v * p[0], acc[1] += v * p[1], acc[2] += v * p[2];
                }
            }
            uint8_t *q = dst + ((size_t)y * dw + x) * 3;
            for (int c = 0; c < 3; c++) q[c] = (uint8_t)(acc[c] > 255.0 ? 255 : acc[c] + 0.5);
        }
    }
done:
    free(ix), free(iy), free(wx), free(wy);
    return s;
}

uint64_t capture__unwrap32_push(capture__unwrap32 *u, uint32_t raw)
{
    if (u->has_last && raw < u->last && u->last - raw > 0x80000000u) u->high += 1ull << 32;
    u->has_last = true;
    u->last = raw;
    return u->high + raw;
}
