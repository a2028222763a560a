/* replay: writes a TUM RGB-D-style folder (Sturm et al. 2012) that
 * replay_open() reads back bit for bit. Images are written as frames arrive;
 * the index files only at finish(), atomically, so an interrupted run leaves
 * no folder that looks complete. */
#include "replay_int.h"

#include <math.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>

/* A growing text buffer. */
typedef struct text_buf {
    char *p;
    size_t len, cap;
} text_buf;

static bf_status text_printf(text_buf *b, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static bf_status text_printf(text_buf *b, const char *fmt, ...)
{
    for (;;) {
        va_list ap;
        va_start(ap, fmt);
        int n = vsnprintf(b->p ? b->p + b->len : NULL, b->p ? b->cap - b->len : 0, fmt, ap);
        va_end(ap);
        if (n < 0) return bf_fail(BF_INVALID_ARG, "cannot format an index line");
        if (b->p && (size_t)n < b->cap - b->len) {
            b->len += (size_t)n;
            return BF_OK;
        }
        size_t cap = b->cap ? b->cap : 4096;
        while (cap < b->len + (size_t)n + 1) cap *= 2;
        char *p = bf_realloc(b->p, cap);
        if (!p) return bf_fail(BF_NO_MEMORY, "index file of %zu bytes", cap);
        b->p = p;
        b->cap = cap;
    }
}

struct replay_tum_writer {
    char *dir;
    bf_intrinsics K;
    text_buf rgb_txt, depth_txt, gt_txt;
    uint32_t n_frames, n_poses;
    uint32_t width, height; /* of the first frame */
    double t_last_s, t_last_rgb_s;
    uint32_t n_rgb;
    bool is_finished;
};

static bf_status make_dir(const char *dir, const char *sub)
{
    char path[4096];
    bf_status s = bf_path_join(path, sizeof path, dir, sub);
    return s ? s : bf_mkdir_p(path);
}

bf_status replay_tum_writer_create(const char *dir, const bf_intrinsics *K, replay_tum_writer **out)
{
    if (!dir || !dir[0] || !K) return bf_fail(BF_INVALID_ARG, "TUM writer needs a folder and intrinsics");
    if (!(K->fx_px != 0 && K->fy_px != 0 && isfinite(K->fx_px) && isfinite(K->fy_px) && isfinite(K->cx_px) &&
          isfinite(K->cy_px) && K->depth_scale > 0 && isfinite(K->depth_scale)))
        return bf_fail(BF_INVALID_ARG, "%s: invalid intrinsics for the TUM writer", dir);
    bf_status s;
    if ((s = bf_mkdir_p(dir)) || (s = make_dir(dir, "rgb")) || (s = make_dir(dir, "depth"))) return s;
    replay_tum_writer *w = bf_calloc(1, sizeof *w);
    if (!w || !(w->dir = strdup(dir))) {
        free(w);
        return bf_fail(BF_NO_MEMORY, "%s: TUM writer", dir);
    }
    w->K = *K;
    const char *head = "# written by bitfuse\n# timestamp filename\n";
    if ((s = text_printf(&w->rgb_txt, "# colour images\n%s", head)) ||
        (s = text_printf(&w->depth_txt, "# depth maps (16-bit PNG, %.6g per metre)\n%s", K->depth_scale, head)) ||
        (s = text_printf(&w->gt_txt, "# ground truth (camera-to-world)\n# timestamp tx ty tz qx qy qz qw\n"))) {
        replay_tum_writer_destroy(w);
        return s;
    }
    *out = w;
    return BF_OK;
}

bf_status replay_tum_writer_add(replay_tum_writer *w, const bf_frame *f)
{
    if (w->is_finished) return bf_fail(BF_INVALID_ARG, "%s: TUM writer already finished", w->dir);
    if (!f->depth || f->width == 0 || f->height == 0)
        return bf_fail(BF_INVALID_ARG, "%s: frame %u has no depth image", w->dir, f->index);
    if (w->n_frames == 0) {
        if (w->K.width && (w->K.width != f->width || w->K.height != f->height))
            return bf_fail(BF_INVALID_ARG, "%s: frame %u is %ux%u but the intrinsics say %ux%u", w->dir, f->index,
                           f->width, f->height, w->K.width, w->K.height);
        w->width = f->width;
        w->height = f->height;
    } else if (f->width != w->width || f->height != w->height) {
        return bf_fail(BF_INVALID_ARG, "%s: frame %u is %ux%u, earlier frames %ux%u", w->dir, f->index, f->width,
                       f->height, w->width, w->height);
    }
    /* File names carry the time with 6 decimals, as TUM's do, so times must
     * differ in the first 6 decimals for names and index lines to be unique. */
    if (!isfinite(f->t_depth_s) || !isfinite(f->t_rgb_s))
        return bf_fail(BF_INVALID_ARG, "%s: frame %u: its time (depth %g s, colour %g s) is not a finite number", w->dir,
                       f->index, f->t_depth_s, f->t_rgb_s);
    if (w->n_frames > 0 && !(f->t_depth_s >= w->t_last_s + 1e-6))
        return bf_fail(BF_INVALID_ARG,
                       "%s: frame %u: time %.7f s is not 1 us or more after the previous frame's %.7f s (a TUM "
                       "folder names its images by their time to 6 decimals)",
                       w->dir, f->index, f->t_depth_s, w->t_last_s);
    if (f->rgb && w->n_rgb > 0 && !(f->t_rgb_s >= w->t_last_rgb_s + 1e-6))
        return bf_fail(BF_INVALID_ARG,
                       "%s: frame %u: colour time %.7f s is not 1 us or more after the previous colour image's %.7f s",
                       w->dir, f->index, f->t_rgb_s, w->t_last_rgb_s);
    if (f->has_pose && !bf_se3_is_finite(&f->T_wc))
        return bf_fail(BF_INVALID_ARG, "%s: frame %u: pose is not finite", w->dir, f->index);
    /* A failure part-way leaves the index lines as they were (the contract:
     * outputs untouched), so the caller may retry or finish without the frame;
     * only an image file of the failed frame may remain. */
    size_t len_depth = w->depth_txt.len, len_rgb = w->rgb_txt.len, len_gt = w->gt_txt.len;
    char name[64], path[4096];
    bf_status s;
    snprintf(name, sizeof name, "depth/%.6f.png", f->t_depth_s);
    if ((s = bf_path_join(path, sizeof path, w->dir, name))) goto fail;
    if ((s = replay_png_write_u16(path, f->depth, f->width, f->height))) goto fail;
    if ((s = text_printf(&w->depth_txt, "%.6f %s\n", f->t_depth_s, name))) goto fail;
    if (f->rgb) {
        snprintf(name, sizeof name, "rgb/%.6f.png", f->t_rgb_s);
        if ((s = bf_path_join(path, sizeof path, w->dir, name))) goto fail;
        if ((s = replay_png_write_rgb8(path, f->rgb, f->width, f->height))) goto fail;
        if ((s = text_printf(&w->rgb_txt, "%.6f %s\n", f->t_rgb_s, name))) goto fail;
    }
    if (f->has_pose) {
        bf_quat q;
        bf_vec3 t;
        bf_se3_to_qt(&f->T_wc, &q, &t);
        if (q.w < 0) q = (bf_quat){-q.w, -q.x, -q.y, -q.z};
        if ((s = text_printf(&w->gt_txt, "%.6f %.9f %.9f %.9f %.9f %.9f %.9f %.9f\n", f->t_depth_s, t.x, t.y, t.z,
                             q.x, q.y, q.z, q.w)))
            goto fail;
        w->n_poses++;
    }
    if (f->rgb) {
        w->t_last_rgb_s = f->t_rgb_s;
        w->n_rgb++;
    }
    w->t_last_s = f->t_depth_s;
    w->n_frames++;
    return BF_OK;
fail:
    w->depth_txt.len = len_depth;
    w->rgb_txt.len = len_rgb;
    w->gt_txt.len = len_gt;
    return s;
}

static bf_status write_index(const replay_tum_writer *w, const char *name, const text_buf *b)
{
    char path[4096];
    bf_status s = bf_path_join(path, sizeof path, w->dir, name);
    return s ? s : bf_write_file_atomic(path, b->p, b->len);
}

bf_status replay_tum_writer_finish(replay_tum_writer *w)
{
    if (w->is_finished) return BF_OK;
    if (w->n_frames == 0) return bf_fail(BF_INVALID_ARG, "%s: no frames were added", w->dir);
    char cam[256], v[5][BF_FMT_DOUBLE_CAP];
    int n = snprintf(cam, sizeof cam, "%s %s %s %s %s\n", bf_fmt_double(v[0], w->K.fx_px), bf_fmt_double(v[1], w->K.fy_px),
                     bf_fmt_double(v[2], w->K.cx_px), bf_fmt_double(v[3], w->K.cy_px),
                     bf_fmt_double(v[4], w->K.depth_scale));
    text_buf cam_buf = {cam, (size_t)n, sizeof cam};
    bf_status s;
    /* depth.txt last: a reader detects the folder by it. */
    if ((s = write_index(w, "camera.txt", &cam_buf))) return s;
    /* No colour at all: no rgb.txt (the reader takes a depth-only folder, not an empty index). */
    if (w->n_rgb > 0 && (s = write_index(w, "rgb.txt", &w->rgb_txt))) return s;
    if (w->n_poses > 0 && (s = write_index(w, "groundtruth.txt", &w->gt_txt))) return s;
    if ((s = write_index(w, "depth.txt", &w->depth_txt))) return s;
    w->is_finished = true;
    return BF_OK;
}

void replay_tum_writer_destroy(replay_tum_writer *w)
{
    if (!w) return;
    free(w->rgb_txt.p);
    free(w->depth_txt.p);
    free(w->gt_txt.p);
    free(w->dir);
    free(w);
}
