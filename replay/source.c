/* replay: the one rgbd_source behind every file format. A format reader
 * lists the frames at open (replay__*_list); this file owns the decoding
 * buffers, sized once from the first frame, and delivers frames from the
 * list. Nothing is allocated per frame here (libpng and libjpeg allocate
 * their decoder state per image internally). */
#include "replay_int.h"
#include "log_int.h"

#include <math.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

/* ------------------------------------------------------------ frame lists */

bf_status replay__list_push(replay__list *l, const replay__frame_ref *f)
{
    if (l->n == UINT32_MAX) return bf_fail(BF_FORMAT, "too many frames");
    if (l->n == l->cap) {
        uint32_t cap = l->cap ? (l->cap > UINT32_MAX / 2 ? UINT32_MAX : 2 * l->cap) : 256;
        replay__frame_ref *v = bf_realloc(l->v, (size_t)cap * sizeof *v);
        if (!v) return bf_fail(BF_NO_MEMORY, "frame list of %u frames", cap);
        l->v = v;
        l->cap = cap;
    }
    l->v[l->n++] = *f;
    return BF_OK;
}

const char *replay__list_str(replay__list *l, const char *s)
{
    if (l->n_strings == l->strings_cap) {
        size_t cap = l->strings_cap ? 2 * l->strings_cap : 512;
        char **v = bf_realloc(l->strings, cap * sizeof *v);
        if (!v) {
            bf_fail(BF_NO_MEMORY, "frame list strings");
            return NULL;
        }
        l->strings = v;
        l->strings_cap = cap;
    }
    char *d = strdup(s);
    if (!d) {
        bf_fail(BF_NO_MEMORY, "frame list strings");
        return NULL;
    }
    l->strings[l->n_strings++] = d;
    return d;
}

void replay__list_free(replay__list *l)
{
    for (size_t i = 0; i < l->n_strings; i++) free(l->strings[i]);
    free(l->strings);
    free(l->v);
    memset(l, 0, sizeof *l);
}

/* ------------------------------------------------------------ the source */

typedef struct replay__source {
    rgbd_source base;
    replay__list list;
    uint32_t next_idx;   /* next list entry to deliver */
    /* Frames skipped with --skip-bad-frames. Atomic: behind a capture thread
     * that a stop left reading (capture_next's grace ran out), the count is
     * read while this source may still skip one. */
    atomic_uint n_skipped;
    bool skip_bad;
    bool has_rgb;        /* some frame lists a colour image */
    uint16_t *depth;     /* width*height, reused for every frame */
    uint8_t *rgb;        /* width*height*3, or NULL */
    /* With a lens's distortion: the files are decoded into raw_* and
     * resampled into depth / rgb (calib_undistort_map). */
    bool is_undistorting;
    bool is_colour_raw; /* replay_options.raw_colour: the colour stays as captured */
    double dist[CALIB_DIST_N];
    calib_undistort_map lens;
    uint16_t *raw_depth;
    uint8_t *raw_rgb;
} replay__source;

static const rgbd_source_ops replay__ops;

static bf_status source_load(replay__source *src, uint32_t idx, bf_frame *out)
{
    const replay__frame_ref *f = &src->list.v[idx];
    uint32_t W = src->base.intrinsics.width, H = src->base.intrinsics.height, w, h;
    size_t n_px = (size_t)W * H;
    uint16_t *depth = src->is_undistorting ? src->raw_depth : src->depth;
    uint8_t *rgb = src->is_undistorting && !src->is_colour_raw ? src->raw_rgb : src->rgb;
    bf_status s = replay__png_decode_u16(f->depth_path, depth, n_px, W, H, &w, &h);
    if (s != BF_OK) return replay__fail_frame(s, idx);
    if (src->list.depth_invalid)
        for (size_t i = 0; i < n_px; i++)
            if (depth[i] == src->list.depth_invalid) depth[i] = 0;
    if (f->rgb_path) {
        s = replay__image_decode_rgb8(f->rgb_path, rgb, n_px, W, H, &w, &h);
        if (s != BF_OK) return replay__fail_frame(s, idx);
    }
    if (src->is_undistorting) {
        calib_undistort_u16(&src->lens, depth, src->depth);
        if (f->rgb_path && !src->is_colour_raw) calib_undistort_rgb8(&src->lens, rgb, src->rgb);
    }
    bool has_pose = f->has_pose;
    bf_se3 T_wc = f->T_wc;
    if (f->pose_path) {
        if ((s = replay__pose_matrix_read(f->pose_path, &T_wc))) return replay__fail_frame(s, idx);
        has_pose = true;
    }
    *out = (bf_frame){
        .index = idx,
        .width = W,
        .height = H,
        .t_depth_s = f->t_depth_s,
        .t_rgb_s = f->t_rgb_s,
        .depth = src->depth,
        .rgb = f->rgb_path ? src->rgb : NULL,
        .has_pose = has_pose,
        .T_wc = has_pose ? T_wc : bf_se3_identity(),
    };
    return BF_OK;
}

static bf_status source_next(rgbd_source *base, bf_frame *out)
{
    replay__source *src = (replay__source *)base;
    while (src->next_idx < src->list.n) {
        uint32_t idx = src->next_idx++;
        bf_status s = source_load(src, idx, out);
        if (s == BF_OK) return BF_OK;
        /* Only a bad file is skippable; running out of memory is not. */
        if (!src->skip_bad || (s != BF_IO && s != BF_FORMAT)) return s;
        bf_warn("skipping frame %u: %s", idx, bf_last_error());
        src->n_skipped++;
    }
    return BF_END;
}

/* The list holds each frame's times and pose (a pose-per-frame folder's
 * file is read here, the images are not). */
static bf_status source_pass(rgbd_source *base, double t_s, bf_frame *out)
{
    replay__source *src = (replay__source *)base;
    if (src->next_idx >= src->list.n) return BF_END;
    uint32_t idx = src->next_idx;
    const replay__frame_ref *f = &src->list.v[idx];
    if (!(f->t_depth_s <= t_s)) return BF_END;
    bool has_pose = f->has_pose;
    bf_se3 T_wc = f->T_wc;
    if (f->pose_path) {
        /* A pose file that does not read is left to next(), which reports it. */
        if (replay__pose_matrix_read(f->pose_path, &T_wc) != BF_OK) return BF_END;
        has_pose = true;
    }
    src->next_idx++;
    *out = (bf_frame){.index = idx, .width = base->intrinsics.width, .height = base->intrinsics.height,
                      .t_depth_s = f->t_depth_s, .t_rgb_s = f->t_rgb_s, .has_pose = has_pose,
                      .T_wc = has_pose ? T_wc : bf_se3_identity()};
    return BF_OK;
}

static void source_close(rgbd_source *base)
{
    replay__source *src = (replay__source *)base;
    replay__list_free(&src->list);
    free(src->depth);
    free(src->rgb);
    free(src->raw_depth);
    free(src->raw_rgb);
    calib_undistort_map_free(&src->lens);
    memset(src, 0xff, sizeof *src); /* poison: a use after close fails loudly */
    free(src);
}

static const rgbd_source_ops replay__ops = {.next = source_next, .close = source_close, .pass = source_pass};

bf_status replay__source_create(const char *path, const char *kind, replay__list *list, const replay__camera *cam,
                                const replay_options *opt, rgbd_source **out)
{
    bf_status s = BF_OK;
    replay__source *src = NULL;
    if (list->n == 0) {
        s = bf_fail(BF_FORMAT, "%s sequence has no frames", kind);
        goto fail;
    }
    if (opt->max_frames && list->n > opt->max_frames) list->n = opt->max_frames;
    /* The image size comes from the first depth image whose header reads;
     * with --skip-bad-frames a broken first frame is skipped later. */
    uint32_t w = 0, h = 0;
    for (uint32_t i = 0; i < list->n; i++) {
        s = replay__image_size(list->v[i].depth_path, &w, &h);
        if (s == BF_OK) break;
        if (!opt->skip_bad_frames) {
            s = replay__fail_frame(s, i);
            goto fail;
        }
        if (i + 1 == list->n) { /* every one skipped: say so, with the last reason */
            char last[512];
            snprintf(last, sizeof last, "%s", bf_last_error());
            s = bf_fail(s, "%s sequence: no frame could be read (%u skipped; the last: %s)", kind, list->n, last);
            goto fail;
        }
    }
    /* Numbers no depth camera has for these images: refused before any work. */
    if ((s = replay__camera_fits(&cam->K, w, h, path, cam->origin ? cam->origin : "defaults", cam->is_from_option)))
        goto fail;
    src = bf_calloc(1, sizeof *src);
    if (!src) {
        s = bf_fail(BF_NO_MEMORY, "%s source", kind);
        goto fail;
    }
    src->list = *list;
    memset(list, 0, sizeof *list);
    for (uint32_t i = 0; i < src->list.n; i++) src->has_rgb |= src->list.v[i].rgb_path != NULL;
    src->depth = bf_malloc((size_t)w * h * sizeof *src->depth);
    src->rgb = src->has_rgb ? bf_malloc((size_t)w * h * 3) : NULL;
    if (!src->depth || (src->has_rgb && !src->rgb)) {
        s = bf_fail(BF_NO_MEMORY, "%s source: frame buffers of %ux%u", kind, w, h);
        goto fail;
    }
    if (calib_has_distortion(cam->dist)) {
        calib_camera lens = {.width = w, .height = h, .fx_px = cam->K.fx_px, .fy_px = cam->K.fy_px,
                             .cx_px = cam->K.cx_px, .cy_px = cam->K.cy_px};
        memcpy(lens.dist, cam->dist, sizeof lens.dist);
        if ((s = calib_undistort_map_make(&lens, &src->lens)) != BF_OK) {
            char why[512];
            snprintf(why, sizeof why, "%s", bf_last_error());
            /* A lens the user typed is a usage error; one from a file is bad input. */
            s = bf_fail(s == BF_INVALID_ARG && !cam->is_from_option ? BF_FORMAT : s, "%s (camera from %s)", why,
                        cam->origin ? cam->origin : "defaults");
            goto fail;
        }
        src->is_undistorting = true;
        src->is_colour_raw = opt->raw_colour;
        memcpy(src->dist, cam->dist, sizeof src->dist);
        src->raw_depth = bf_malloc((size_t)w * h * sizeof *src->raw_depth);
        bool needs_raw_rgb = src->has_rgb && !src->is_colour_raw;
        src->raw_rgb = needs_raw_rgb ? bf_malloc((size_t)w * h * 3) : NULL;
        if (!src->raw_depth || (needs_raw_rgb && !src->raw_rgb)) {
            s = bf_fail(BF_NO_MEMORY, "%s source: undistortion buffers of %ux%u", kind, w, h);
            goto fail;
        }
    }
    src->skip_bad = opt->skip_bad_frames;
    src->base.ops = &replay__ops;
    src->base.kind = kind;
    src->base.intrinsics = cam->K;
    src->base.intrinsics.width = w;
    src->base.intrinsics.height = h;
    src->base.n_frames = src->list.n;
    for (uint32_t i = 0; i < src->list.n; i++)
        if (src->list.v[i].has_pose || src->list.v[i].pose_path) src->base.has_groundtruth = true;
    if (src->is_undistorting)
        bf_debug("%s: the lens's distortion taken out of every frame (pixels move up to %.1f px, %u get none)",
                 kind, src->lens.max_shift_px, src->lens.n_outside);
    bf_debug("%s: %u frames, %ux%u, camera from %s", kind, src->base.n_frames, w, h,
             cam->origin ? cam->origin : "defaults");
    /* A principal point far from the image's centre is a camera for another
     * image size (a 640x480 preset on smaller frames): said, not refused;
     * numbers no depth camera has are refused. */
    const bf_intrinsics *K = &src->base.intrinsics;
    if (replay__principal_point_is_off(K, w, h))
        bf_warn("%s: the camera's principal point (%g, %g) lies far from the centre of the %ux%u images (camera "
                "from %s): is it for another image size?",
                path, K->cx_px, K->cy_px, w, h, cam->origin ? cam->origin : "defaults");
    *out = &src->base;
    return BF_OK;
fail:
    replay__list_free(list);
    if (src) {
        replay__list_free(&src->list);
        free(src->depth);
        free(src->rgb);
        free(src->raw_depth);
        free(src->raw_rgb);
        calib_undistort_map_free(&src->lens);
        free(src);
    }
    return s;
}

bool replay_undistortion(const rgbd_source *src, double dist[CALIB_DIST_N], double *max_shift_px)
{
    if (!src || src->ops != &replay__ops) return false;
    const replay__source *r = (const replay__source *)src;
    if (!r->is_undistorting) return false;
    memcpy(dist, r->dist, sizeof r->dist);
    if (max_shift_px) *max_shift_px = r->lens.max_shift_px;
    return true;
}

uint32_t replay_skipped_frames(const rgbd_source *src)
{
    if (src && src->ops != &replay__ops) return replay__log_skipped(src);
    if (!src) return 0;
    return ((const replay__source *)src)->n_skipped;
}

/* ------------------------------------------------------------ opening */

static bool has_file(const char *dir, const char *name)
{
    char p[4096];
    return bf_path_join(p, sizeof p, dir, name) == BF_OK && bf_file_exists(p);
}

bool replay_is_sequence_dir(const char *path)
{
    return replay__is_dir(path) && (has_file(path, "depth.txt") || has_file(path, "rgb.txt") ||
                                    has_file(path, "depth/1.png") || has_file(path, "depth/0.png") ||
                                    has_file(path, "frame-000000.depth.png"));
}

bf_status replay_open(const char *path, const replay_options *opt, rgbd_source **out)
{
    replay_options defaults = {0};
    if (!opt) opt = &defaults;
    if (!path || !path[0]) return bf_fail(BF_INVALID_ARG, "no sequence path given");
    if (!bf_file_exists(path)) return bf_fail(BF_IO, "%s: no such file or folder", path);
    if (replay_is_log_path(path) || replay__log_sniff(path)) return replay__log_open(path, opt, out);
    if (!replay__is_dir(path))
        return bf_fail(BF_FORMAT, "%s: not a folder or a bitfuse log (expected a TUM, ICL-NUIM or pose-per-frame "
                       "folder, or a .bflog file)", path);
    replay__list list = {0};
    replay__camera cam = {0};
    bf_status s;
    const char *kind;
    if (has_file(path, "depth.txt") || has_file(path, "rgb.txt")) {
        kind = "tum";
        s = replay__tum_list(path, opt, &list, &cam);
    } else if (replay__is_dir(path) && (has_file(path, "depth/1.png") || has_file(path, "depth/0.png"))) {
        kind = "icl-nuim";
        s = replay__icl_list(path, opt, &list, &cam);
    } else if (has_file(path, "frame-000000.depth.png")) {
        kind = "pose-folder";
        s = replay__posefolder_list(path, opt, &list, &cam);
    } else {
        return bf_fail(BF_FORMAT,
                       "%s: not a recognised sequence folder (expected depth.txt + rgb.txt (TUM), "
                       "depth/N.png + pose.txt (ICL-NUIM) or frame-000000.depth.png (pose per frame))",
                       path);
    }
    if (s != BF_OK) {
        replay__list_free(&list);
        return s;
    }
    return replay__source_create(path, kind, &list, &cam, opt, out);
}
