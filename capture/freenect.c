/* capture: Kinect v1 (Xbox 360 Kinect, Kinect for Windows 1414/1473/1517)
 * through libfreenect.
 *
 * Depth modes:
 *  - registered (default): FREENECT_DEPTH_REGISTERED, millimetres already
 *    mapped onto the colour camera by libfreenect's registration, so colour
 *    and depth share the colour camera's intrinsics;
 *  - disparity (?depth=disparity): the raw 11-bit values, turned into depth
 *    here with libfreenect's model and the device's own zero-plane
 *    parameters (freenect_copy_registration); depth stays on the IR camera
 *    and colour is not registered to it.
 * Debian's fakenect (libfreenect-bin, a stand-in libfreenect.so.0.5 that
 * replays dumps) implements neither registration nor freenect_copy_
 * registration, so under it the source uses disparity with libfreenect's
 * default parameters. The registration calls are looked up with dlsym for
 * that reason: calling them by name would end the process inside fakenect.
 *
 * Threading: libfreenect calls the depth and video callbacks from
 * freenect_process_events on the calling thread; next() pumps it until one
 * new depth and one new colour image arrived, so the callbacks write the
 * frame buffers directly and no lock is needed.
 *
 * Timestamps: the Kinect stamps each image with a 32-bit counter of its
 * 60 MHz clock (libfreenect issue #681, PR #465); it is extended to 64 bits
 * (it wraps every 71.6 s) and divided by 60e6, so times are seconds on the
 * device's clock, whose origin is arbitrary (power-on). */
#include "live_int.h"

#include <dlfcn.h>
#include <libfreenect.h>
#include <libfreenect_registration.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <sys/time.h>

#define FN_W 640u
#define FN_H 480u
#define FN_CLOCK_HZ 60e6
/* Disparity-mode depth units: 0.2 mm (TUM's 5000 per metre) keeps the
 * model's precision, which libfreenect's whole-millimetre table drops. */
#define FN_DISPARITY_SCALE 5000.0

typedef freenect_registration (*fn_copy_registration_fn)(freenect_device *);
typedef int (*fn_destroy_registration_fn)(freenect_registration *);

typedef struct fn_source {
    rgbd_source base;
    char uri[512];
    freenect_context *ctx;
    freenect_device *dev;
    bool is_disparity, is_fakenect;
    bool is_depth_started, is_video_started;
    uint16_t *depth_px;
    uint8_t *rgb_px;
    bool has_new_depth, has_new_rgb;
    uint32_t ts_depth, ts_rgb;
    capture__unwrap32 clock; /* one for both: they share the device clock */
    uint16_t raw_to_units[2048]; /* disparity -> 1/FN_DISPARITY_SCALE m, 0 = none */
    uint32_t index;
} fn_source;

static void fn_depth_cb(freenect_device *dev, void *depth, uint32_t timestamp)
{
    fn_source *s = freenect_get_user(dev);
    /* fakenect hands out its file buffer just past the PGM header, at an
     * odd address: read the samples bytewise. */
    const uint8_t *in = depth;
    memcpy(s->depth_px, in, (size_t)FN_W * FN_H * sizeof *s->depth_px);
    if (s->is_disparity)
        for (size_t i = 0; i < (size_t)FN_W * FN_H; i++) s->depth_px[i] = s->raw_to_units[s->depth_px[i] & 2047u];
    s->ts_depth = timestamp;
    s->has_new_depth = true;
}

static void fn_video_cb(freenect_device *dev, void *rgb, uint32_t timestamp)
{
    fn_source *s = freenect_get_user(dev);
    memcpy(s->rgb_px, rgb, (size_t)FN_W * FN_H * 3);
    s->ts_rgb = timestamp;
    s->has_new_rgb = true;
}

static bf_status fn_next(rgbd_source *base, bf_frame *out)
{
    fn_source *s = (fn_source *)base;
    s->has_new_depth = s->has_new_rgb = false;
    double t_start = bf_time_s();
    while (!(s->has_new_depth && s->has_new_rgb)) {
        /* A short libusb wait, so a silent device is noticed on time. */
        struct timeval tv = {.tv_sec = 0, .tv_usec = 100000};
        if (freenect_process_events_timeout(s->ctx, &tv) < 0) {
            if (s->is_fakenect) return BF_END; /* fakenect: the dump ended */
            return bf_fail(BF_NO_DEVICE, "%s: frame %u: lost the Kinect (libusb event handling failed; unplugged?)",
                           s->uri, s->index);
        }
        if ((bf_time_s() - t_start) * 1000.0 > CAPTURE_FRAME_TIMEOUT_MS)
            return bf_fail(BF_IO, "%s: frame %u: no %s within %d ms", s->uri, s->index,
                           s->has_new_depth ? "colour image" : "depth image", CAPTURE_FRAME_TIMEOUT_MS);
    }
    uint64_t td = capture__unwrap32_push(&s->clock, s->ts_depth);
    uint64_t tc = capture__unwrap32_push(&s->clock, s->ts_rgb);
    *out = (bf_frame){.index = s->index++,
                      .width = FN_W,
                      .height = FN_H,
                      .t_depth_s = (double)td / FN_CLOCK_HZ,
                      .t_rgb_s = (double)tc / FN_CLOCK_HZ,
                      .depth = s->depth_px,
                      .rgb = s->rgb_px};
    return BF_OK;
}

static void fn_close(rgbd_source *base)
{
    if (!base) return;
    fn_source *s = (fn_source *)base;
    if (s->is_depth_started) freenect_stop_depth(s->dev);
    if (s->is_video_started) freenect_stop_video(s->dev);
    if (s->dev) freenect_close_device(s->dev);
    if (s->ctx) freenect_shutdown(s->ctx);
    free(s->depth_px);
    free(s->rgb_px);
    free(s);
}

static const rgbd_source_ops fn_ops = {.next = fn_next, .close = fn_close};

/* fakenect 0.5 exports no registration calls; the real library does. */
static bool fn_is_fakenect(void) { return dlsym(RTLD_DEFAULT, "freenect_copy_registration") == NULL; }

/* fakenect exit()s the process when FAKENECT_PATH, its INDEX.txt or a file
 * it lists is missing; check first so a bad dump is a status. */
static bf_status fn_check_fakenect_dump(const char *uri)
{
    const char *dir = getenv("FAKENECT_PATH");
    if (!dir || !*dir)
        return bf_fail(BF_NO_DEVICE, "%s: libfreenect is fakenect (dump replay) but FAKENECT_PATH is not set",
                       uri);
    char path[4096], *text = NULL;
    size_t size = 0;
    bf_status s = bf_path_join(path, sizeof path, dir, "INDEX.txt");
    if (s) return s;
    if (bf_read_file(path, &text, &size))
        return bf_fail(BF_NO_DEVICE, "%s: fakenect dump %s has no readable INDEX.txt", uri, dir);
    uint32_t line = 0;
    for (char *p = text, *nl; *p; p = nl ? nl + 1 : p + strlen(p)) {
        nl = strchr(p, '\n');
        if (nl) *nl = 0;
        line++;
        if (!*p) continue;
        char file[4096];
        if (bf_path_join(file, sizeof file, dir, p) || !bf_file_exists(file)) {
            s = bf_fail(BF_NO_DEVICE, "%s: %s:%u: listed file '%s' is missing", uri, path, line, p);
            break;
        }
        if (!nl) break;
    }
    free(text);
    return s;
}

/* Fills raw_to_units and the IR intrinsics from the device's registration
 * parameters, or libfreenect's defaults when they are not to be had. */
static void fn_setup_disparity(fn_source *s)
{
    capture__kinect_params p = capture__kinect_default_params();
    const char *origin = "libfreenect's default Kinect parameters";
    fn_copy_registration_fn copy = (fn_copy_registration_fn)dlsym(RTLD_DEFAULT, "freenect_copy_registration");
    fn_destroy_registration_fn destroy =
        (fn_destroy_registration_fn)dlsym(RTLD_DEFAULT, "freenect_destroy_registration");
    if (copy && destroy) {
        freenect_registration reg = copy(s->dev);
        const freenect_zero_plane_info *z = &reg.zero_plane_info;
        if (z->reference_distance > 0 && z->reference_pixel_size > 0 && z->dcmos_emitter_dist > 0) {
            p.dcmos_emitter_dist_cm = z->dcmos_emitter_dist;
            p.reference_distance_mm = z->reference_distance;
            p.reference_pixel_size_mm = z->reference_pixel_size;
            p.const_shift = reg.const_shift;
            origin = "the device's zero-plane parameters";
        }
        destroy(&reg);
    }
    for (uint32_t raw = 0; raw < 2048; raw++) {
        double mm = capture__kinect_raw_to_mm((uint16_t)raw, &p);
        double u = isnan(mm) ? 0.0 : floor(mm * (FN_DISPARITY_SCALE / 1000.0) + 0.5);
        s->raw_to_units[raw] = (uint16_t)(u > 65535.0 ? 0.0 : u);
    }
    double f = capture__kinect_ir_focal_px(&p);
    s->base.intrinsics = (bf_intrinsics){.width = FN_W,
                                         .height = FN_H,
                                         .fx_px = f,
                                         .fy_px = f,
                                         .cx_px = (FN_W - 1) * 0.5,
                                         .cy_px = (FN_H - 1) * 0.5,
                                         .depth_scale = FN_DISPARITY_SCALE};
    bf_info("%s: 11-bit disparity converted with %s (IR camera f = %.1f px); colour is not registered", s->uri,
            origin, f);
}

bf_status capture__freenect_open(const char *uri, const char *target, const capture__uri_options *opt,
                                 rgbd_source **out)
{
    uint32_t index = 0;
    if (*target && !bf_parse_u32(target, &index))
        return bf_fail(BF_INVALID_ARG, "%s: expected freenect:INDEX with INDEX a device number (0, 1, ...)", uri);
    bool is_fakenect = fn_is_fakenect();
    bf_status st;
    if (is_fakenect && (st = fn_check_fakenect_dump(uri))) return st;
    bool want_registered = !opt->depth_mode[0] || !strcmp(opt->depth_mode, "registered");
    if (is_fakenect && opt->depth_mode[0] && want_registered)
        return bf_fail(BF_UNSUPPORTED, "%s: fakenect 0.5 replays raw disparity only; use ?depth=disparity", uri);

    fn_source *s = calloc(1, sizeof *s);
    if (!s) return bf_fail(BF_NO_MEMORY, "%s: source", uri);
    snprintf(s->uri, sizeof s->uri, "%s", uri);
    s->base.ops = &fn_ops;
    s->base.kind = is_fakenect ? "freenect (fakenect)" : "freenect";
    s->is_fakenect = is_fakenect;
    s->is_disparity = is_fakenect || !want_registered;
    s->depth_px = calloc((size_t)FN_W * FN_H, sizeof *s->depth_px);
    s->rgb_px = calloc((size_t)FN_W * FN_H, 3);
    if (!s->depth_px || !s->rgb_px) {
        st = bf_fail(BF_NO_MEMORY, "%s: frame buffers", uri);
        goto fail;
    }
    if (freenect_init(&s->ctx, NULL) < 0) {
        s->ctx = NULL;
        st = bf_fail(BF_NO_DEVICE, "%s: libfreenect could not start (no USB access?)", uri);
        goto fail;
    }
    freenect_set_log_level(s->ctx, FREENECT_LOG_ERROR);
    /* The camera only: motor and audio need firmware and other permissions. */
    freenect_select_subdevices(s->ctx, FREENECT_DEVICE_CAMERA);
    int n_dev = freenect_num_devices(s->ctx);
    if (n_dev <= 0 || index >= (uint32_t)n_dev) {
        st = bf_fail(BF_NO_DEVICE, "%s: no Kinect v1 at index %u (found %d)", uri, index, n_dev < 0 ? 0 : n_dev);
        goto fail;
    }
    if (freenect_open_device(s->ctx, &s->dev, (int)index) < 0) {
        s->dev = NULL;
        st = bf_fail(BF_NO_DEVICE, "%s: cannot open Kinect %u (permissions? see the udev rules in "
                                   "docs/devices.md)",
                     uri, index);
        goto fail;
    }
    freenect_set_user(s->dev, s);
    freenect_frame_mode dm = freenect_find_depth_mode(
        FREENECT_RESOLUTION_MEDIUM, s->is_disparity ? FREENECT_DEPTH_11BIT : FREENECT_DEPTH_REGISTERED);
    freenect_frame_mode vm = freenect_find_video_mode(FREENECT_RESOLUTION_MEDIUM, FREENECT_VIDEO_RGB);
    if (!dm.is_valid || !vm.is_valid || freenect_set_depth_mode(s->dev, dm) < 0 ||
        freenect_set_video_mode(s->dev, vm) < 0) {
        st = bf_fail(BF_UNSUPPORTED, "%s: the device refused 640x480 %s depth with RGB video", uri,
                     s->is_disparity ? "11-bit" : "registered");
        goto fail;
    }
    freenect_set_depth_callback(s->dev, fn_depth_cb);
    freenect_set_video_callback(s->dev, fn_video_cb);
    if (s->is_disparity) {
        fn_setup_disparity(s);
    } else {
        /* Registered depth lies on the colour camera: the ROS / TUM default
         * Kinect v1 colour intrinsics (pass ?camera= for a calibration). */
        s->base.intrinsics = (bf_intrinsics){.width = FN_W,
                                             .height = FN_H,
                                             .fx_px = 525.0,
                                             .fy_px = 525.0,
                                             .cx_px = 319.5,
                                             .cy_px = 239.5,
                                             .depth_scale = 1000.0};
    }
    if (freenect_start_depth(s->dev) < 0 || !(s->is_depth_started = true) || freenect_start_video(s->dev) < 0) {
        st = bf_fail(BF_NO_DEVICE, "%s: the Kinect did not start streaming", uri);
        goto fail;
    }
    s->is_video_started = true;
    *out = &s->base;
    return BF_OK;
fail:
    fn_close(&s->base);
    return st;
}

/* Asks libfreenect which Kinects are plugged in; their serials through
 * freenect_list_device_attributes (looked up by dlsym: fakenect lacks it). */
uint32_t capture__freenect_list(capture_device_info *out, uint32_t cap)
{
    if (fn_is_fakenect()) return 0; /* replays are not devices */
    freenect_context *ctx = NULL;
    if (freenect_init(&ctx, NULL) < 0) {
        bf_debug("freenect: libfreenect could not start; no Kinect listed");
        return 0;
    }
    freenect_set_log_level(ctx, FREENECT_LOG_FATAL);
    freenect_select_subdevices(ctx, FREENECT_DEVICE_CAMERA);
    int n = freenect_num_devices(ctx);
    typedef int (*list_fn)(freenect_context *, struct freenect_device_attributes **);
    typedef void (*free_fn)(struct freenect_device_attributes *);
    list_fn list = (list_fn)dlsym(RTLD_DEFAULT, "freenect_list_device_attributes");
    free_fn free_attrs = (free_fn)dlsym(RTLD_DEFAULT, "freenect_free_device_attributes");
    struct freenect_device_attributes *attrs = NULL;
    if (n > 0 && list && free_attrs && list(ctx, &attrs) < 0) attrs = NULL;
    struct freenect_device_attributes *a = attrs;
    for (int i = 0; i < n && (uint32_t)i < cap; i++) {
        snprintf(out[i].uri, sizeof out[i].uri, "freenect:%d", i);
        snprintf(out[i].name, sizeof out[i].name, "Kinect v1%s%s%s", a && a->camera_serial ? " (serial " : "",
                 a && a->camera_serial ? a->camera_serial : "", a && a->camera_serial ? ")" : "");
        if (a) a = a->next;
    }
    if (attrs) free_attrs(attrs);
    freenect_shutdown(ctx);
    return n > 0 ? (uint32_t)n : 0;
}
