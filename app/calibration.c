/* --calibration for the commands that read a sequence through it (replay,
 * live, fuse, eval-motion, eval-colour): the file read and checked before
 * anything opens, and the cameras it gives applied to the sequence (app.h). */
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>

#include "app.h"
#include "calib/calib.h"
#include "replay/replay.h"

int app_calibration_read(const char *cmd, const char *path, const char *seq, bool is_device, replay_options *ropt,
                         app_calibration *out)
{
    memset(out, 0, sizeof *out);
    bf_status s = calib_read(path, &out->cal);
    if (s != BF_OK) return app_fail(cmd, s);
    out->path = path;
    /* Frames are undistorted to their corners: a lens the boards did not
     * measure there (bitfuse calibrate's extrapolation_px) is worth a word. */
    for (int i = 0; i < (out->cal.has_depth ? 2 : 1); i++) {
        const calib_camera *c = i ? &out->cal.depth : &out->cal.colour;
        if (c->extrapolation_px > CALIB_EXTRAPOLATION_WARN_PX)
            bf_warn("%s: %s: the %s camera's lens is uncertain by %.3g px of its %ux%u images at their edge (its "
                    "boards reached %.0f%% of the way to the corners): %s there may be off", cmd, path,
                    i ? "depth" : "colour", c->extrapolation_px, c->width, c->height, 100 * c->coverage,
                    i ? "the depth, undistorted," : "the colour looked up through it");
    }
    if (out->cal.has_depth && ropt->camera)
        return app_usage_error(cmd, "--camera and --calibration %s both give the depth camera: keep one", path);
    /* The colour is the colour camera's own image, registered through the
     * file: the depth camera's lens must not resample it. */
    ropt->raw_colour = true;
    if (!out->cal.has_depth) return APP_EXIT_OK;
    /* Whether the depth lens describes one (calib_read does not ask), for a
     * folder, a log or a device alike, before anything opens. */
    calib_undistort_map m = {0};
    s = calib_has_distortion(out->cal.depth.dist) ? calib_undistort_map_make(&out->cal.depth, &m) : BF_OK;
    calib_undistort_map_free(&m);
    if (s != BF_OK) {
        char why[512];
        snprintf(why, sizeof why, "%s", bf_last_error());
        return app_fail(cmd, bf_fail(BF_FORMAT, "%s: the depth camera's lens: %s", path, why));
    }
    /* A folder is read with the file's depth camera (its lens taken out of
     * the depth as --camera's would be); a log or a device gives its own
     * intrinsics, which app_calibration_apply replaces. */
    struct stat st;
    bool is_folder = !is_device && seq && stat(seq, &st) == 0 && S_ISDIR(st.st_mode);
    if (is_folder) {
        const calib_camera *d = &out->cal.depth;
        snprintf(out->depth_camera, sizeof out->depth_camera, "%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g",
                 d->fx_px, d->fy_px, d->cx_px, d->cy_px, d->dist[0], d->dist[1], d->dist[2], d->dist[3], d->dist[4]);
        ropt->camera = out->depth_camera;
        snprintf(out->depth_camera_origin, sizeof out->depth_camera_origin, "the depth camera of %s", path);
        ropt->camera_origin = out->depth_camera_origin;
    }
    return APP_EXIT_OK;
}

/* The colour camera at the frames' size: a source gives its colour at the
 * depth's size (a folder must; V4L2 and OpenNI2 cameras' is resized to it
 * by capture__resize_rgb), so a file calibrated at the colour camera's own
 * size (1280x960 where the frames are 640x480) is scaled, each axis by its
 * own ratio, pixel centres kept as that resize keeps them. The lens's
 * coefficients are in the normalised plane and stay. */
static void colour_to_frame_size(app_calibration *c, const bf_intrinsics *K)
{
    calib_camera *cc = &c->cal.colour;
    if (cc->width == K->width && cc->height == K->height) return;
    double sx = (double)K->width / cc->width, sy = (double)K->height / cc->height;
    bf_info("%s: the colour camera is %ux%u, the frames' colour %ux%u: its intrinsics scaled to them", c->path,
            cc->width, cc->height, K->width, K->height);
    cc->fx_px *= sx, cc->fy_px *= sy;
    cc->cx_px = (cc->cx_px + 0.5) * sx - 0.5, cc->cy_px = (cc->cy_px + 0.5) * sy - 0.5;
    cc->width = K->width, cc->height = K->height;
}

bf_status app_calibration_apply(app_calibration *c, const char *seq, rgbd_source *src)
{
    if (!c->path) return BF_OK;
    bf_intrinsics *K = &src->intrinsics;
    const calib_camera *d = &c->cal.depth;
    if (c->cal.has_depth && (d->width != K->width || d->height != K->height))
        return bf_fail(BF_FORMAT, "%s: the depth camera is %ux%u, the depth images of %s are %ux%u", c->path, d->width,
                       d->height, seq, K->width, K->height);
    colour_to_frame_size(c, K);
    if (!c->cal.has_depth) return BF_OK;
    K->fx_px = d->fx_px, K->fy_px = d->fy_px, K->cx_px = d->cx_px, K->cy_px = d->cy_px;
    /* A folder was opened with the file's lens (app_calibration_read); a
     * device or a log gives its depth as the lens made it. */
    double dist[CALIB_DIST_N];
    c->is_lens_left = calib_has_distortion(d->dist) && !app_undistortion(src, dist, NULL);
    return BF_OK;
}

const calib_camera *app_calibration_depth_lens(const app_calibration *c)
{
    return c && c->path && c->is_lens_left ? &c->cal.depth : NULL;
}

const double *app_frames_lens(const rgbd_source *src, const app_calibration *cal, double dist[CALIB_DIST_N])
{
    if (app_undistortion(src, dist, NULL)) return dist;
    const calib_camera *left = app_calibration_depth_lens(cal);
    return left ? left->dist : NULL;
}

/* "the lens (k1 k2 p1 p2 k3)" or "no lens". */
static void lens_words(const double *d, char *buf, size_t n)
{
    if (!d || !calib_has_distortion(d)) snprintf(buf, n, "no lens");
    else snprintf(buf, n, "the lens (%.6g %.6g %.6g %.6g %.6g)", d[0], d[1], d[2], d[3], d[4]);
}

bf_status app_depth_correction_check(const char *path, const calib_depth_correction *c, const rgbd_source *src,
                                     const app_calibration *cal, const char *seq)
{
    const bf_intrinsics *K = rgbd_source_intrinsics(src);
    if (c->width != K->width || c->height != K->height)
        return bf_fail(BF_FORMAT, "%s: the depth correction is for %ux%u depth images, the sequence's are %ux%u (%s)",
                       path, c->width, c->height, K->width, K->height, seq);
    double dist[CALIB_DIST_N];
    const double *frames = app_frames_lens(src, cal, dist);
    if (calib_depth_same_lens(c, frames)) return BF_OK;
    char made[128], now[128];
    lens_words(c->lens, made, sizeof made);
    lens_words(frames, now, sizeof now);
    return bf_fail(BF_FORMAT,
                   "%s: made from frames read through %s, but %s's are read through %s: the pattern lies in other "
                   "pixels (make the file again from these frames with bitfuse calibrate-depth)",
                   path, made, seq, now);
}
