/* replay: TUM RGB-D benchmark folders (Sturm et al., "A Benchmark for the
 * Evaluation of RGB-D SLAM Systems", IROS 2012): rgb.txt, depth.txt and
 * groundtruth.txt, colour and depth paired by timestamp as the benchmark's
 * associate.py pairs them. */
#include "replay_int.h"

#include <stdlib.h>
#include <string.h>

/* One index file (rgb.txt or depth.txt): times and paths in file order. */
typedef struct tum_index {
    uint32_t n;
    double *t_s;
    char **path; /* joined with the folder, in the list's arena */
} tum_index;

static void tum_index_free(tum_index *x)
{
    free(x->t_s);
    free(x->path);
    memset(x, 0, sizeof *x);
}

/* Reads "timestamp filename" lines; times must increase. A line repeating
 * the previous line's time is dropped (the first kept, one warning). */
static bf_status tum_index_read(const char *dir, const char *name, replay__list *list, tum_index *out)
{
    char file[4096], joined[4096];
    bf_status s = bf_path_join(file, sizeof file, dir, name);
    if (s != BF_OK) return s;
    replay__text t;
    if ((s = replay__text_open(&t, file))) return s;
    tum_index x = {0};
    uint32_t cap = 0;
    char *f[3];
    int n;
    while ((n = replay__text_next(&t, f, 3)) >= 0) {
        if (n != 2) {
            s = bf_fail(BF_FORMAT, "%s:%u: expected 2 fields (timestamp filename), found %d", file, t.line, n);
            goto fail;
        }
        double ts;
        if ((s = replay__text_double(&t, f[0], "timestamp", &ts))) goto fail;
        if (x.n > 0 && ts == x.t_s[x.n - 1]) {
            replay__text_note_repeat(&t);
            continue;
        }
        if (x.n > 0 && !(ts > x.t_s[x.n - 1])) {
            s = bf_fail(BF_FORMAT, "%s:%u: timestamp %.6f is before the previous line's (%.6f); times must increase",
                        file, t.line, ts, x.t_s[x.n - 1]);
            goto fail;
        }
        if (x.n == cap) {
            cap = cap ? 2 * cap : 1024;
            double *nt = bf_realloc(x.t_s, cap * sizeof *nt);
            if (nt) x.t_s = nt;
            char **np = nt ? bf_realloc(x.path, cap * sizeof *np) : NULL;
            if (!np) {
                s = bf_fail(BF_NO_MEMORY, "%s: %u lines", file, cap);
                goto fail;
            }
            x.path = np;
        }
        if (bf_path_join(joined, sizeof joined, dir, f[1]) != BF_OK) {
            s = bf_fail(BF_FORMAT, "%s:%u: the image path (%zu characters with the folder) is longer than %zu", file,
                        t.line, strlen(dir) + 1 + strlen(f[1]), sizeof joined - 1);
            goto fail;
        }
        const char *p = replay__list_str(list, joined);
        if (!p) {
            s = BF_NO_MEMORY;
            goto fail;
        }
        x.t_s[x.n] = ts;
        x.path[x.n] = (char *)p;
        x.n++;
    }
    if (x.n == 0) {
        s = bf_fail(BF_FORMAT, "%s: no frames listed", file);
        goto fail;
    }
    replay__text_warn(&t);
    replay__text_close(&t);
    *out = x;
    return BF_OK;
fail:
    replay__text_close(&t);
    tum_index_free(&x);
    return s;
}

/* Ground truth for a frame at t: interpolated inside the trajectory's time
 * range; just outside it, the end pose if it is within REPLAY_MAX_DT_S (the
 * benchmark's own association tolerance); else none. */
static bool tum_gt_pose(const bf_traj *gt, double t_s, bf_se3 *T_wc)
{
    if (bf_traj_interpolate(gt, t_s, T_wc)) return true;
    if (t_s < gt->t_s[0] && gt->t_s[0] - t_s <= REPLAY_MAX_DT_S) {
        *T_wc = gt->T_wc[0];
        return true;
    }
    if (t_s > gt->t_s[gt->n - 1] && t_s - gt->t_s[gt->n - 1] <= REPLAY_MAX_DT_S) {
        *T_wc = gt->T_wc[gt->n - 1];
        return true;
    }
    return false;
}

/* The TUM sensor a folder's own name mentions ("rgbd_dataset_freiburg2_desk");
 * its parents' names do not count. */
static const char *tum_preset_hint(const char *dir)
{
    size_t n = strlen(dir);
    while (n > 1 && dir[n - 1] == '/') n--;
    size_t start = n;
    while (start > 0 && dir[start - 1] != '/') start--;
    char name[256];
    size_t len = n - start < sizeof name - 1 ? n - start : sizeof name - 1;
    memcpy(name, dir + start, len);
    name[len] = 0;
    if (strstr(name, "freiburg1")) return "fr1";
    if (strstr(name, "freiburg2")) return "fr2";
    if (strstr(name, "freiburg3")) return "fr3";
    return NULL;
}

bf_status replay__tum_list(const char *dir, const replay_options *opt, replay__list *list, replay__camera *cam)
{
    /* TUM's default when the sensor is unknown ("ROS default"); a folder
     * named for its sensor takes that sensor's published calibration, lens
     * included (fr1/rpy from four starts: mean ATE 17.9 mm with it, 39.6 mm
     * with fr1's four numbers, 43.3 mm with this default;
     * docs/real_frames.md, "A second real sequence"). */
    cam->K = (bf_intrinsics){.fx_px = 525.0, .fy_px = 525.0, .cx_px = 319.5, .cy_px = 239.5, .depth_scale = 5000};
    cam->origin = "TUM default camera";
    const char *hint = tum_preset_hint(dir);
    bf_status s;
    if (hint) {
        if ((s = replay_parse_camera_lens(hint, &cam->K, cam->dist)) != BF_OK) return s;
        cam->origin = "the folder's name";
        cam->is_from_name = true;
    }
    if ((s = replay__camera_resolve(dir, opt, cam)) != BF_OK) return s;
    if (cam->is_from_name)
        bf_info("%s: camera: TUM's %s calibration (the folder's name)%s; --camera to choose another", dir, hint,
                calib_has_distortion(cam->dist) ? ", its lens taken out of every frame" : "");

    char file[4096];
    tum_index depth = {0}, rgb = {0};
    bf_traj gt = {0};
    size_t *rgb_of = NULL; /* colour index of each depth image, or SIZE_MAX */
    if ((s = tum_index_read(dir, "depth.txt", list, &depth))) goto done;
    if ((s = bf_path_join(file, sizeof file, dir, "rgb.txt"))) goto done;
    bool has_rgb = bf_file_exists(file);
    if (has_rgb && (s = tum_index_read(dir, "rgb.txt", list, &rgb))) goto done;
    if ((s = bf_path_join(file, sizeof file, dir, "groundtruth.txt"))) goto done;
    if (bf_file_exists(file) && (s = replay_traj_read_tum(file, &gt))) goto done;
    rgb_of = bf_malloc(depth.n * sizeof *rgb_of);
    if (!rgb_of) {
        s = bf_fail(BF_NO_MEMORY, "%s: %u frames", dir, depth.n);
        goto done;
    }
    /* associate.py's rule, depth as the first list. */
    if (has_rgb && (s = bf_associate_stamps(depth.t_s, depth.n, rgb.t_s, rgb.n, REPLAY_MAX_DT_S, rgb_of)))
        goto done;
    uint32_t n_unpaired = 0;
    for (uint32_t i = 0; i < depth.n; i++) {
        replay__frame_ref f = {.t_depth_s = depth.t_s[i], .t_rgb_s = depth.t_s[i], .depth_path = depth.path[i]};
        if (has_rgb) {
            /* associate.py drops a depth image without colour partner. */
            if (rgb_of[i] == SIZE_MAX) {
                n_unpaired++;
                continue;
            }
            f.rgb_path = rgb.path[rgb_of[i]];
            f.t_rgb_s = rgb.t_s[rgb_of[i]];
        }
        if (gt.n) f.has_pose = tum_gt_pose(&gt, f.t_depth_s, &f.T_wc);
        if ((s = replay__list_push(list, &f))) goto done;
    }
    if (n_unpaired)
        bf_info("%s: %u of %u depth images have no colour image within %.2f s and are left out", dir, n_unpaired,
                depth.n, REPLAY_MAX_DT_S);
    if (list->n == 0) s = bf_fail(BF_FORMAT, "%s: no depth image has a colour image within %.2f s", dir,
                                  REPLAY_MAX_DT_S);
done:
    free(rgb_of);
    bf_traj_free(&gt);
    tum_index_free(&depth);
    tum_index_free(&rgb);
    return s;
}
