/* capture: OpenNI2 devices through its C API (OniCAPI.h): PrimeSense
 * Carmine / Asus Xtion (PS1080 driver), Orbbec Astra (with Orbbec's
 * OpenNI2 driver), the Kinect v1 through libfreenect's OpenNI2 driver, and
 * .oni recordings through OpenNI2's file device.
 *
 * Depth is registered to colour by the device when it says it can
 * (ONI_IMAGE_REGISTRATION_DEPTH_TO_COLOR); the intrinsics then come from
 * the colour stream's field of view, else from the depth stream's.
 *
 * Timestamps: OniFrame.timestamp, microseconds on the device's clock (for
 * the PS1080 the sensor's own counter since it started; for a file, the
 * recorded ones), divided by 1e6.
 *
 * Threading: OpenNI2 fills frames on its own threads; next() waits for the
 * depth stream with oniWaitForAnyStream and reads the newest colour frame,
 * all on the caller's thread. */
#include "live_int.h"

#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

/* OpenNI2's C header writes "typedef _OniDevice* OniDeviceHandle;", which
 * only C++ accepts (a struct tag used without 'struct'). These typedefs
 * give C the same names for the same incomplete structs. */
typedef struct _OniDevice _OniDevice;
typedef struct _OniStream _OniStream;
typedef struct _OniRecorder _OniRecorder;
#include <OniCAPI.h>

/* ------------------------------------------------------------ formats */

double capture__oni_depth_scale(int f)
{
    if (f == ONI_PIXEL_FORMAT_DEPTH_1_MM) return 1000.0;
    if (f == ONI_PIXEL_FORMAT_DEPTH_100_UM) return 10000.0;
    return 0.0;
}

const char *capture__oni_format_name(int f)
{
    switch (f) {
    case ONI_PIXEL_FORMAT_DEPTH_1_MM: return "DEPTH_1_MM";
    case ONI_PIXEL_FORMAT_DEPTH_100_UM: return "DEPTH_100_UM";
    case ONI_PIXEL_FORMAT_SHIFT_9_2: return "SHIFT_9_2";
    case ONI_PIXEL_FORMAT_SHIFT_9_3: return "SHIFT_9_3";
    case ONI_PIXEL_FORMAT_RGB888: return "RGB888";
    case ONI_PIXEL_FORMAT_YUV422: return "YUV422";
    case ONI_PIXEL_FORMAT_GRAY8: return "GRAY8";
    case ONI_PIXEL_FORMAT_GRAY16: return "GRAY16";
    case ONI_PIXEL_FORMAT_JPEG: return "JPEG";
    case ONI_PIXEL_FORMAT_YUYV: return "YUYV";
    default: return "unknown format";
    }
}

bf_status capture__oni_colour_to_rgb(int f, const uint8_t *src, size_t src_stride, uint32_t w, uint32_t h,
                                     uint8_t *rgb)
{
    switch (f) {
    case ONI_PIXEL_FORMAT_RGB888: capture__copy_rows(src, src_stride, (size_t)w * 3, h, rgb); return BF_OK;
    case ONI_PIXEL_FORMAT_YUV422: capture__uyvy_to_rgb(src, src_stride, w, h, rgb); return BF_OK;
    case ONI_PIXEL_FORMAT_YUYV: capture__yuyv_to_rgb(src, src_stride, w, h, rgb); return BF_OK;
    case ONI_PIXEL_FORMAT_GRAY8:
        for (uint32_t y = 0; y < h; y++)
            for (uint32_t x = 0; x < w; x++) memset(rgb + ((size_t)y * w + x) * 3, src[y * src_stride + x], 3);
        return BF_OK;
    default:
        return bf_fail(BF_UNSUPPORTED, "OpenNI2 colour format %s (%d) is not converted", capture__oni_format_name(f),
                       f);
    }
}

static bool oni_colour_is_supported(int f)
{
    return f == ONI_PIXEL_FORMAT_RGB888 || f == ONI_PIXEL_FORMAT_YUV422 || f == ONI_PIXEL_FORMAT_YUYV ||
           f == ONI_PIXEL_FORMAT_GRAY8;
}

/* ------------------------------------------------------------ the source */

typedef struct oni_source {
    rgbd_source base;
    char uri[512];
    bool is_file, has_colour;
    OniDeviceHandle dev;
    OniStreamHandle depth, colour;
    bool is_depth_started, is_colour_started;
    uint32_t w, h, cw, ch;
    int colour_fmt;
    double native_scale; /* the depth format's own units per metre (a URI's depth_scale= may override the
                            intrinsics' scale: a change of format is judged on this one) */
    uint16_t *depth_px;
    uint8_t *rgb_px, *rgb_native;
    bool has_rgb_frame;
    double t_rgb_s;
    uint32_t index;
} oni_source;

/* OpenNI2 is initialised once per process and never shut down: each
 * oniShutdown() unloads the drivers and leaves their allocations behind
 * (LeakSanitizer counts about 10 KiB per cycle), and loading the drivers
 * again costs a USB scan. */
static pthread_once_t oni_once = PTHREAD_ONCE_INIT;
static OniStatus oni_init_status = ONI_STATUS_ERROR;
static void oni_init_once(void) { oni_init_status = oniInitialize(ONI_API_VERSION); }
static bool oni_init(void)
{
    pthread_once(&oni_once, oni_init_once);
    return oni_init_status == ONI_STATUS_OK;
}

/* OpenNI2's last error on one line: it indents with tabs and ends with
 * blank lines, which would break the message bitfuse prints. */
static const char *oni_error(void)
{
    static _Thread_local char line[512];
    const char *e = oniGetExtendedError();
    size_t n = 0;
    for (bool space = true; e && *e && n + 1 < sizeof line; e++) {
        bool blank = *e == ' ' || *e == '\t' || *e == '\n' || *e == '\r';
        if (blank && !space) line[n++] = ' ';
        else if (!blank) line[n++] = *e;
        space = blank;
    }
    while (n && line[n - 1] == ' ') n--;
    line[n] = '\0';
    return n ? line : "no details";
}

static void oni_close(rgbd_source *base)
{
    if (!base) return;
    oni_source *s = (oni_source *)base;
    if (s->is_colour_started) oniStreamStop(s->colour);
    if (s->is_depth_started) oniStreamStop(s->depth);
    if (s->colour) oniStreamDestroy(s->colour);
    if (s->depth) oniStreamDestroy(s->depth);
    if (s->dev) oniDeviceClose(s->dev);
    free(s->depth_px);
    free(s->rgb_px);
    free(s->rgb_native);
    free(s);
}

/* Takes the newest colour frame that is ready; before the first one it
 * waits up to a 15 Hz period for it. */
static bf_status oni_colour_update(oni_source *s)
{
    int timeout_ms = s->has_rgb_frame ? ONI_TIMEOUT_NONE : 67;
    for (;;) {
        int idx;
        if (oniWaitForAnyStream(&s->colour, 1, &idx, timeout_ms) != ONI_STATUS_OK) return BF_OK;
        timeout_ms = ONI_TIMEOUT_NONE;
        OniFrame *f = NULL;
        if (oniStreamReadFrame(s->colour, &f) != ONI_STATUS_OK || !f)
            return bf_fail(BF_NO_DEVICE, "%s: frame %u: reading colour failed: %s", s->uri, s->index, oni_error());
        if ((uint32_t)f->width != s->cw || (uint32_t)f->height != s->ch || (int)f->videoMode.pixelFormat != s->colour_fmt) {
            bf_debug("%s: colour frame %dx%d %s, expected %ux%u; skipped", s->uri, f->width, f->height,
                     capture__oni_format_name(f->videoMode.pixelFormat), s->cw, s->ch);
            oniFrameRelease(f);
            continue;
        }
        bool same = s->cw == s->w && s->ch == s->h;
        bf_status st = capture__oni_colour_to_rgb(s->colour_fmt, f->data, (size_t)f->stride, s->cw, s->ch,
                                                  same ? s->rgb_px : s->rgb_native);
        if (!st && !same) st = capture__resize_rgb(s->rgb_native, s->cw, s->ch, s->rgb_px, s->w, s->h);
        if (!st) {
            s->has_rgb_frame = true;
            s->t_rgb_s = (double)f->timestamp * 1e-6;
        }
        oniFrameRelease(f);
        if (st) return st;
    }
}

static bf_status oni_next(rgbd_source *base, bf_frame *out)
{
    oni_source *s = (oni_source *)base;
    if (s->is_file && s->base.n_frames && s->index >= s->base.n_frames) return BF_END;
    int idx;
    OniStatus r = oniWaitForAnyStream(&s->depth, 1, &idx, CAPTURE_FRAME_TIMEOUT_MS);
    if (r == ONI_STATUS_TIME_OUT) {
        if (s->is_file) {
            if (s->base.n_frames && s->index < s->base.n_frames)
                bf_warn("%s: the file device stopped after %u of its %u frames", s->uri, s->index, s->base.n_frames);
            return BF_END;
        }
        return bf_fail(BF_IO, "%s: frame %u: no depth frame within %d ms", s->uri, s->index, CAPTURE_FRAME_TIMEOUT_MS);
    }
    OniFrame *f = NULL;
    if (r != ONI_STATUS_OK || oniStreamReadFrame(s->depth, &f) != ONI_STATUS_OK || !f)
        return bf_fail(BF_NO_DEVICE, "%s: frame %u: the device stopped delivering depth (unplugged?): %s", s->uri,
                       s->index, oni_error());
    if ((uint32_t)f->width != s->w || (uint32_t)f->height != s->h ||
        capture__oni_depth_scale(f->videoMode.pixelFormat) != s->native_scale) {
        bf_status st = bf_fail(BF_FORMAT, "%s: frame %u: depth changed to %dx%d %s mid-stream (started as %ux%u)",
                               s->uri, s->index, f->width, f->height,
                               capture__oni_format_name(f->videoMode.pixelFormat), s->w, s->h);
        oniFrameRelease(f);
        return st;
    }
    capture__copy_rows(f->data, (size_t)f->stride, (size_t)s->w * 2, s->h, (uint8_t *)s->depth_px);
    double t_depth_s = (double)f->timestamp * 1e-6;
    oniFrameRelease(f);
    if (s->has_colour) {
        bf_status st = oni_colour_update(s);
        if (st) return st;
    }
    *out = (bf_frame){.index = s->index++,
                      .width = s->w,
                      .height = s->h,
                      .t_depth_s = t_depth_s,
                      .t_rgb_s = s->has_rgb_frame ? s->t_rgb_s : t_depth_s,
                      .depth = s->depth_px,
                      .rgb = s->has_rgb_frame ? s->rgb_px : NULL};
    return BF_OK;
}

static const rgbd_source_ops oni_ops = {.next = oni_next, .close = oni_close};

/* Picks a mode of the stream's sensor: the wanted size and format at
 * 30 fps if offered, else the first mode with an accepted format. Files
 * keep their recorded mode. */
static void oni_choose_mode(oni_source *s, OniStreamHandle st, const int *fmts, int n_fmts)
{
    if (s->is_file) return;
    const OniSensorInfo *info = oniStreamGetSensorInfo(st);
    if (!info) return;
    const OniVideoMode *best = NULL;
    int best_score = -1;
    for (int i = 0; i < info->numSupportedVideoModes; i++) {
        const OniVideoMode *m = &info->pSupportedVideoModes[i];
        int fmt_rank = -1;
        for (int k = 0; k < n_fmts; k++)
            if ((int)m->pixelFormat == fmts[k]) fmt_rank = k;
        if (fmt_rank < 0) continue;
        int score = (m->resolutionX == 640 && m->resolutionY == 480) * 4 + (m->fps == 30) * 2 + (fmt_rank == 0);
        if (score > best_score) best = m, best_score = score;
    }
    if (best && oniStreamSetProperty(st, ONI_STREAM_PROPERTY_VIDEO_MODE, best, sizeof *best) != ONI_STATUS_OK)
        bf_debug("%s: keeping the default video mode (%s)", s->uri, oni_error());
}

static bool oni_get_mode(OniStreamHandle st, OniVideoMode *m)
{
    int size = sizeof *m;
    return oniStreamGetProperty(st, ONI_STREAM_PROPERTY_VIDEO_MODE, m, &size) == ONI_STATUS_OK;
}

static bool is_oni_file(const char *target)
{
    size_t n = strlen(target);
    return n > 4 && !strcasecmp(target + n - 4, ".oni");
}

bf_status capture__openni2_open(const char *uri, const char *target, const capture__uri_options *opt,
                                rgbd_source **out)
{
    (void)opt;
    bool is_file = is_oni_file(target);
    /* OpenNI2's file device would report a missing file as "no device"; a
     * recording that is not there is input that is not there (exit 3, as
     * replay's missing sequence), not a camera that is not plugged in. */
    if (is_file && !bf_file_exists(target)) return bf_fail(BF_IO, "%s: no such .oni file", uri);
    oni_source *s = calloc(1, sizeof *s);
    if (!s) return bf_fail(BF_NO_MEMORY, "%s: source", uri);
    snprintf(s->uri, sizeof s->uri, "%s", uri);
    s->is_file = is_file;
    bf_status st;
    if (!oni_init()) {
        st = bf_fail(BF_NO_DEVICE, "%s: OpenNI2 did not start: %s", uri, oni_error());
        goto fail;
    }
    if (oniDeviceOpen(*target ? target : NULL, &s->dev) != ONI_STATUS_OK) {
        s->dev = NULL;
        /* A recording that is there but does not open is bad input (exit 3), not a missing camera. */
        if (is_file)
            st = bf_fail(BF_FORMAT, "%s: OpenNI2 cannot play %s (not an OpenNI recording, or a damaged one): %s", uri,
                         target, oni_error());
        else
            st = bf_fail(BF_NO_DEVICE, "%s: no OpenNI2 device%s%s: %s", uri, *target ? " at " : "", target,
                         oni_error());
        goto fail;
    }
    if (s->is_file) {
        /* Once through, as fast as the reader takes frames: the player waits
         * until the last frame was read before it decodes the next one. */
        OniBool repeat = 0;
        float speed = 0.0f;
        oniDeviceSetProperty(s->dev, ONI_DEVICE_PROPERTY_PLAYBACK_REPEAT_ENABLED, &repeat, sizeof repeat);
        oniDeviceSetProperty(s->dev, ONI_DEVICE_PROPERTY_PLAYBACK_SPEED, &speed, sizeof speed);
    }
    if (oniDeviceCreateStream(s->dev, ONI_SENSOR_DEPTH, &s->depth) != ONI_STATUS_OK) {
        s->depth = NULL;
        st = bf_fail(BF_UNSUPPORTED, "%s: the device has no depth sensor: %s", uri, oni_error());
        goto fail;
    }
    static const int depth_fmts[] = {ONI_PIXEL_FORMAT_DEPTH_1_MM, ONI_PIXEL_FORMAT_DEPTH_100_UM};
    oni_choose_mode(s, s->depth, depth_fmts, 2);
    OniVideoMode dm;
    if (!oni_get_mode(s->depth, &dm)) {
        st = bf_fail(BF_NO_DEVICE, "%s: cannot read the depth video mode: %s", uri, oni_error());
        goto fail;
    }
    double scale = capture__oni_depth_scale(dm.pixelFormat);
    if (scale == 0.0 || dm.resolutionX <= 0 || dm.resolutionY <= 0) {
        st = bf_fail(BF_UNSUPPORTED, "%s: depth is %dx%d %s; bitfuse reads DEPTH_1_MM or DEPTH_100_UM", uri,
                     dm.resolutionX, dm.resolutionY, capture__oni_format_name(dm.pixelFormat));
        goto fail;
    }
    s->native_scale = scale;
    s->w = (uint32_t)dm.resolutionX;
    s->h = (uint32_t)dm.resolutionY;

    /* Colour is optional: a depth-only device or recording still works. */
    OniVideoMode cm = {0};
    if (oniDeviceCreateStream(s->dev, ONI_SENSOR_COLOR, &s->colour) == ONI_STATUS_OK) {
        static const int colour_fmts[] = {ONI_PIXEL_FORMAT_RGB888, ONI_PIXEL_FORMAT_YUV422, ONI_PIXEL_FORMAT_YUYV,
                                          ONI_PIXEL_FORMAT_GRAY8};
        oni_choose_mode(s, s->colour, colour_fmts, 4);
        int fmt_ok = oni_get_mode(s->colour, &cm) && cm.resolutionX > 0 && cm.resolutionY > 0 &&
                     oni_colour_is_supported(cm.pixelFormat);
        if (fmt_ok) {
            s->has_colour = true;
            s->cw = (uint32_t)cm.resolutionX;
            s->ch = (uint32_t)cm.resolutionY;
            s->colour_fmt = cm.pixelFormat;
        } else {
            bf_warn("%s: colour stream %s is not read; frames carry depth only", uri,
                    capture__oni_format_name(cm.pixelFormat));
            oniStreamDestroy(s->colour);
            s->colour = NULL;
        }
    } else {
        s->colour = NULL;
    }

    bool is_registered = false;
    if (s->has_colour && !s->is_file &&
        oniDeviceIsImageRegistrationModeSupported(s->dev, ONI_IMAGE_REGISTRATION_DEPTH_TO_COLOR)) {
        OniImageRegistrationMode mode = ONI_IMAGE_REGISTRATION_DEPTH_TO_COLOR;
        is_registered = oniDeviceSetProperty(s->dev, ONI_DEVICE_PROPERTY_IMAGE_REGISTRATION, &mode, sizeof mode) ==
                        ONI_STATUS_OK;
    }
    if (s->has_colour && !s->is_file) oniDeviceEnableDepthColorSync(s->dev); /* best effort */
    if (s->has_colour && !is_registered)
        bf_info("%s: the device does not register depth to colour; colour is not aligned with depth", uri);

    /* Intrinsics from the field of view of the camera depth is on. */
    OniStreamHandle geo = is_registered ? s->colour : s->depth;
    float hfov = 0, vfov = 0;
    int size = sizeof hfov;
    bool has_fov = oniStreamGetProperty(geo, ONI_STREAM_PROPERTY_HORIZONTAL_FOV, &hfov, &size) == ONI_STATUS_OK;
    size = sizeof vfov;
    has_fov = has_fov && oniStreamGetProperty(geo, ONI_STREAM_PROPERTY_VERTICAL_FOV, &vfov, &size) == ONI_STATUS_OK;
    double fx = has_fov ? capture__focal_from_fov(s->w, hfov) : NAN;
    double fy = has_fov ? capture__focal_from_fov(s->h, vfov) : NAN;
    if (!isfinite(fx) || !isfinite(fy)) {
        /* A nominal PrimeSense-class 58 degree field of view. */
        fx = fy = 525.0 * s->w / 640.0;
        bf_info("%s: the device reports no field of view; assuming fx = fy = %.1f px (pass ?camera=fx,fy,cx,cy)",
                uri, fx);
    }
    s->base = (rgbd_source){.ops = &oni_ops,
                            .kind = s->is_file ? "openni2 (.oni file)" : "openni2",
                            .intrinsics = {.width = s->w,
                                           .height = s->h,
                                           .fx_px = fx,
                                           .fy_px = fy,
                                           .cx_px = (s->w - 1) * 0.5,
                                           .cy_px = (s->h - 1) * 0.5,
                                           .depth_scale = scale}};
    if (s->is_file) {
        int n = 0;
        size = sizeof n;
        if (oniStreamGetProperty(s->depth, ONI_STREAM_PROPERTY_NUMBER_OF_FRAMES, &n, &size) == ONI_STATUS_OK && n > 0)
            s->base.n_frames = (uint32_t)n;
    }

    size_t n_px = (size_t)s->w * s->h;
    s->depth_px = malloc(n_px * sizeof *s->depth_px);
    s->rgb_px = s->has_colour ? malloc(n_px * 3) : NULL;
    s->rgb_native = s->has_colour ? malloc((size_t)s->cw * s->ch * 3) : NULL;
    if (!s->depth_px || (s->has_colour && (!s->rgb_px || !s->rgb_native))) {
        st = bf_fail(BF_NO_MEMORY, "%s: frame buffers for %ux%u", uri, s->w, s->h);
        goto fail;
    }
    if (oniStreamStart(s->depth) != ONI_STATUS_OK) {
        st = bf_fail(BF_NO_DEVICE, "%s: depth stream did not start: %s", uri, oni_error());
        goto fail;
    }
    s->is_depth_started = true;
    if (s->has_colour) {
        if (oniStreamStart(s->colour) == ONI_STATUS_OK) {
            s->is_colour_started = true;
        } else {
            bf_warn("%s: colour stream did not start (%s); frames carry depth only", uri, oni_error());
            s->has_colour = false;
        }
    }
    *out = &s->base;
    return BF_OK;
fail:
    oni_close(&s->base);
    return st;
}

uint32_t capture__openni2_list(capture_device_info *out, uint32_t cap)
{
    if (!oni_init()) {
        bf_debug("openni2: OpenNI2 did not start: %s", oni_error());
        return 0;
    }
    OniDeviceInfo *list = NULL;
    int n = 0;
    if (oniGetDeviceList(&list, &n) != ONI_STATUS_OK) n = 0;
    for (int i = 0; i < n && (uint32_t)i < cap; i++) {
        snprintf(out[i].uri, sizeof out[i].uri, "openni2:%.240s", list[i].uri);
        snprintf(out[i].name, sizeof out[i].name, "%.100s %.100s (USB %04x:%04x)", list[i].vendor, list[i].name,
                 list[i].usbVendorId, list[i].usbProductId);
    }
    if (list) oniReleaseDeviceList(list);
    return n > 0 ? (uint32_t)n : 0;
}
