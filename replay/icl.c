/* replay: ICL-NUIM (Handa, Whelan, McDonald and Davison, "A Benchmark for
 * RGB-D Visual Odometry, 3D Reconstruction and SLAM", ICRA 2014) in its
 * numbered layout: depth/N.png, color/N.png (or rgb/N.png) and pose.txt with
 * one "tx ty tz qx qy qz qw" line per frame. Its TUM-like layout (rgb.txt,
 * depth.txt) is read by tum.c with --camera icl. */
#include "replay_int.h"

#include <stdio.h>
#include <string.h>

/* ICL-NUIM's virtual camera: the negative fy flips the image's y axis. */
static const bf_intrinsics icl_camera = {
    .fx_px = 481.2, .fy_px = -480.0, .cx_px = 319.5, .cy_px = 239.5, .depth_scale = 5000};

static bf_status icl_path(replay__list *list, const char *dir, const char *sub, uint32_t n, const char *ext,
                          const char **out)
{
    char name[64], path[4096];
    snprintf(name, sizeof name, "%s/%u.%s", sub, n, ext);
    bf_status s = bf_path_join(path, sizeof path, dir, name);
    if (s != BF_OK) return s;
    *out = replay__list_str(list, path);
    return *out ? BF_OK : BF_NO_MEMORY;
}

bf_status replay__icl_list(const char *dir, const replay_options *opt, replay__list *list, replay__camera *cam)
{
    cam->K = icl_camera;
    cam->origin = "ICL-NUIM camera";
    bf_status s = replay__camera_resolve(dir, opt, cam);
    if (s != BF_OK) return s;
    char path[4096];
    if ((s = bf_path_join(path, sizeof path, dir, "depth/0.png"))) return s;
    uint32_t first = bf_file_exists(path) ? 0 : 1;
    const char *colour_dir = NULL;
    if ((s = bf_path_join(path, sizeof path, dir, "color"))) return s;
    if (replay__is_dir(path)) colour_dir = "color";
    if ((s = bf_path_join(path, sizeof path, dir, "rgb"))) return s;
    if (!colour_dir && replay__is_dir(path)) colour_dir = "rgb";

    /* Frames run from the first number up to the first missing depth image. */
    for (uint32_t k = first;; k++) {
        replay__frame_ref f = {0};
        if ((s = icl_path(list, dir, "depth", k, "png", &f.depth_path))) return s;
        if (!bf_file_exists(f.depth_path)) break;
        if (colour_dir) {
            if ((s = icl_path(list, dir, colour_dir, k, "png", &f.rgb_path))) return s;
            const char *jpg;
            if (!bf_file_exists(f.rgb_path) && (s = icl_path(list, dir, colour_dir, k, "jpg", &jpg)) == BF_OK &&
                bf_file_exists(jpg))
                f.rgb_path = jpg;
            if (s != BF_OK) return s;
        }
        f.t_depth_s = f.t_rgb_s = (double)list->n / REPLAY_NUMBERED_FPS;
        if ((s = replay__list_push(list, &f))) return s;
    }

    if ((s = bf_path_join(path, sizeof path, dir, "pose.txt"))) return s;
    if (!bf_file_exists(path)) return BF_OK;
    replay__text t;
    if ((s = replay__text_open(&t, path))) return s;
    char *f[9];
    int n;
    uint32_t n_poses = 0;
    while ((n = replay__text_next(&t, f, 9)) >= 0) {
        /* 8 fields: a leading timestamp (TUM's trajectory form), ignored. */
        if (n != 7 && n != 8) {
            s = bf_fail(BF_FORMAT, "%s:%u: expected 7 fields (tx ty tz qx qy qz qw), found %d", path, t.line, n);
            break;
        }
        if (n_poses >= list->n) {
            /* The frames end at the first missing depth image: name it. */
            s = bf_fail(BF_FORMAT, "%s:%u: more poses than the %u depth images (depth/%u.png is missing)", path,
                        t.line, list->n, first + list->n);
            break;
        }
        replay__frame_ref *fr = &list->v[n_poses];
        if ((s = replay__pose_from_fields(&t, f + (n - 7), &fr->T_wc))) break;
        fr->has_pose = true;
        n_poses++;
    }
    if (s == BF_OK) replay__text_warn(&t);
    replay__text_close(&t);
    if (s != BF_OK) return s;
    if (n_poses < list->n)
        return bf_fail(BF_FORMAT, "%s: %u poses for %u depth images", path, n_poses, list->n);
    return BF_OK;
}
