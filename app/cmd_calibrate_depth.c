/* bitfuse calibrate-depth: the depth camera's fixed error pattern from a
 * sequence and its trajectory (calib.h, "depth correction";
 * docs/calibration.md), written as depth_correction.json for replay, live
 * and fuse's --depth-correction. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"
#include "calib/calib.h"
#include "replay/replay.h"

static const char usage_text[] =
    "usage: bitfuse calibrate-depth SEQUENCE --poses FILE|groundtruth --out depth_correction.json [options]\n"
    "\n"
    "Measures the depth camera's fixed error pattern (Kinect v1: vertical bands and a bowl\n"
    "of a few parts per thousand, fixed in the image) from SEQUENCE and its camera poses:\n"
    "pairs of frames 15 and 30 apart are brought together by the poses, and where one frame's\n"
    "points land on the other's surface the relative depth difference is gathered per cell\n"
    "of the image (a self-calibration in the manner of Teichman, Miller and Thrun 2013,\n"
    "CLAMS). The poses may be the sequence's ground truth or a trajectory bitfuse replay\n"
    "made of it (its trajectory.txt): no ground truth is needed. The result is one\n"
    "multiplier per cell, the same at every depth, whose mean over the image is 1; replay,\n"
    "live and fuse take it with --depth-correction. Use a sequence of a few hundred frames\n"
    "that moves about a scene with surfaces at several depths.\n";

typedef struct depth_frames {
    calib_depth_frames in;
    uint16_t **depth;
    uint32_t *index;
    bf_se3 *T_wc;
    uint32_t n, cap;
} depth_frames;

static void frames_free(depth_frames *d)
{
    for (uint32_t i = 0; i < d->n; i++) free(d->depth[i]);
    free(d->depth);
    free(d->index);
    free(d->T_wc);
    memset(d, 0, sizeof *d);
}

/* Keeps f's depth (through lens when not NULL: a log's or a device's frames
 * and a calibration's depth lens) and its pose. */
static bf_status frames_push(depth_frames *d, const bf_frame *f, const bf_se3 *T, const calib_undistort_map *lens)
{
    if (d->n == d->cap) {
        uint32_t cap = d->cap ? 2 * d->cap : 64;
        uint16_t **dp = realloc(d->depth, cap * sizeof *dp);
        if (dp) d->depth = dp;
        uint32_t *ip = realloc(d->index, cap * sizeof *ip);
        if (ip) d->index = ip;
        bf_se3 *tp = realloc(d->T_wc, cap * sizeof *tp);
        if (tp) d->T_wc = tp;
        if (!dp || !ip || !tp) return bf_fail(BF_NO_MEMORY, "calibrate-depth: %u frames", cap);
        d->cap = cap;
    }
    size_t n = (size_t)f->width * f->height;
    uint16_t *copy = malloc(n * sizeof *copy);
    if (!copy) return bf_fail(BF_NO_MEMORY, "calibrate-depth: frame %u", f->index);
    if (lens) calib_undistort_u16(lens, f->depth, copy);
    else memcpy(copy, f->depth, n * sizeof *copy);
    d->depth[d->n] = copy;
    d->index[d->n] = f->index;
    d->T_wc[d->n] = *T;
    d->n++;
    return BF_OK;
}

/* Whether frame i is one a pair needs: a first frame (every stride) or
 * its partner at a gap. */
static bool frame_needed(const calib_depth_config *c, uint32_t i)
{
    if (i % c->stride == 0) return true;
    for (uint32_t g = 0; g < CALIB_DEPTH_GAPS; g++)
        if (c->gaps[g] && i >= c->gaps[g] && (i - c->gaps[g]) % c->stride == 0) return true;
    return false;
}

static bool same_pose(const bf_traj *t, size_t a, size_t b)
{
    return !memcmp(&t->T_wc[a], &t->T_wc[b], sizeof(bf_se3));
}

/* Whether entry i repeats an earlier good pose: it equals the one before,
 * and its run of equal poses does not start at the first entry (frames
 * before the first with depth all hold the starting pose, the first good
 * one among them too). */
static bool held_at(const bf_traj *t, size_t i)
{
    if (i == 0 || !same_pose(t, i, i - 1)) return false;
    size_t j = i;
    while (j > 0 && same_pose(t, j, j - 1)) j--;
    return j > 0;
}

/* A replay writes a lost frame's pose as the last good one: a pose the
 * same to the bit as the one before it says nothing of where that frame's
 * depth was taken, and one interpolated next to it little more. True for a
 * time on such an entry or between it and a neighbour. */
static bool pose_is_held(const bf_traj *t, double t_s)
{
    if (t->n < 2 || !(t_s >= t->t_s[0])) return false;
    size_t lo = 0, hi = t->n; /* the last entry at or before t_s */
    while (hi - lo > 1) {
        size_t mid = lo + (hi - lo) / 2;
        if (t->t_s[mid] <= t_s) lo = mid;
        else hi = mid;
    }
    if (t->t_s[lo] == t_s) return held_at(t, lo);
    return held_at(t, lo) || (lo + 1 < t->n && held_at(t, lo + 1));
}

/* Reads the frames the pairs need, each with its pose (the ground truth or
 * traj's at its depth time); frames without one are counted in *n_no_pose,
 * frames whose trajectory pose is held (pose_is_held) in *n_held. */
static bf_status read_frames(rgbd_source *src, const bf_traj *traj, const calib_depth_config *c,
                             const calib_undistort_map *lens, depth_frames *d, uint32_t *n_no_pose, uint32_t *n_held,
                             const char *seq)
{
    bf_frame f;
    bf_status s;
    bf_progress prog;
    bf_progress_begin(&prog, "calibrate-depth: reading", src->n_frames);
    uint32_t seen = 0;
    while ((s = rgbd_source_next(src, &f)) == BF_OK) {
        bf_progress_update(&prog, ++seen);
        if (!frame_needed(c, f.index) || !f.depth) continue;
        const bf_intrinsics *K = rgbd_source_intrinsics(src);
        if (f.width != K->width || f.height != K->height) {
            s = bf_fail(BF_FORMAT, "%s: frame %u is %ux%u, the sequence's camera %ux%u", seq, f.index, f.width,
                        f.height, K->width, K->height);
            break;
        }
        bf_se3 T;
        bool has = traj ? bf_traj_interpolate(traj, f.t_depth_s, &T) : f.has_pose;
        if (!traj && has) T = f.T_wc;
        if (!has) {
            (*n_no_pose)++;
            continue;
        }
        if (traj && pose_is_held(traj, f.t_depth_s)) {
            (*n_held)++;
            continue;
        }
        if ((s = frames_push(d, &f, &T, lens)) != BF_OK) break;
    }
    bf_progress_end(&prog, seen);
    if (s == BF_END) s = BF_OK;
    if (s == BF_OK && *n_held)
        bf_warn("calibrate-depth: %u frame%s left out: %s pose repeats the one before to the bit (a replay's lost "
                "frames keep the last good pose)", *n_held, app_s(*n_held), *n_held == 1 ? "its" : "their");
    if (s == BF_OK && d->n < 2) s = bf_fail(BF_FORMAT, "%s: %u frames with a pose: too few for pairs", seq, d->n);
    return s;
}

static cJSON *result_json(const char *seq, const char *out, const calib_depth_config *cfg,
                          const calib_depth_correction *c, uint32_t n_no_pose, uint32_t n_held, double seconds)
{
    cJSON *o = app_json_stats("calibrate-depth");
    cJSON_AddStringToObject(o, "sequence", seq);
    cJSON_AddStringToObject(o, "out", out);
    cJSON *k = app_json_object(o, "config");
    cJSON_AddNumberToObject(k, "cell_px", cfg->cell_px);
    double gaps[CALIB_DEPTH_GAPS] = {cfg->gaps[0], cfg->gaps[1]};
    app_json_numbers(k, "gaps", gaps, CALIB_DEPTH_GAPS);
    cJSON_AddNumberToObject(k, "stride", cfg->stride);
    cJSON_AddNumberToObject(k, "iterations", cfg->iterations);
    cJSON_AddNumberToObject(k, "max_depth_m", cfg->max_depth_m);
    cJSON_AddNumberToObject(k, "agree", cfg->agree);
    cJSON_AddNumberToObject(k, "min_samples", cfg->min_samples);
    cJSON_AddNumberToObject(o, "frames", c->n_frames);
    cJSON_AddNumberToObject(o, "frames_without_pose", n_no_pose);
    cJSON_AddNumberToObject(o, "frames_held_pose", n_held);
    cJSON_AddNumberToObject(o, "pairs", c->n_pairs);
    cJSON_AddNumberToObject(o, "cells", c->grid_w * c->grid_h);
    cJSON_AddNumberToObject(o, "cells_measured", c->n_cells_measured);
    cJSON_AddNumberToObject(o, "rms_before", c->rms_before);
    cJSON_AddNumberToObject(o, "rms_after", c->rms_after);
    cJSON_AddNumberToObject(o, "seconds", seconds);
    app_json_depth_correction(o, out, c);
    return o;
}

int cmd_calibrate_depth(int argc, char **argv)
{
    const char *cmd = "calibrate-depth", *seq = NULL, *poses = NULL, *out = NULL, *calibration = NULL;
    calib_depth_config cfg = calib_depth_config_default();
    replay_options ropt;
    memset(&ropt, 0, sizeof ropt);
    bool json = false;
    const app_option own[] = {
        APP_OPT("--poses", APP_OPT_STRING, &poses, "P",
                "'groundtruth' (the sequence's own) or a TUM trajectory file (camera-to-world, e.g. replay's "
                "trajectory.txt; poses interpolated at the depth timestamps)",
                .required = true),
        APP_OPT("--out", APP_OPT_STRING, &out, "FILE", "the file to write (depth_correction.json)", .required = true),
        APP_OPT("--cell", APP_OPT_U32, &cfg.cell_px, "PX", "the cells' edge in pixels", .min = 4, .max = 256),
        APP_OPT("--iterations", APP_OPT_U32, &cfg.iterations, "N", "passes that update the multipliers", .min = 1,
                .max = 20),
        APP_OPT("--stride", APP_OPT_U32, &cfg.stride, "N", "a pair's first frame every N frames", .min = 1,
                .max = 1000),
        APP_OPT("--max-depth", APP_OPT_FLOAT, &cfg.max_depth_m, "M", "samples beyond are not used", .min = 0.3,
                .max = 20),
        APP_OPT("--calibration", APP_OPT_STRING, &calibration, "FILE",
                "calib.json: the depth read with its depth camera, lens taken out, as replay --calibration reads "
                "it (the file made then fits those runs)",
                .no_default = true),
        APP_OPT("--json", APP_OPT_FLAG, &json, NULL, "print the result as JSON instead of the summary"),
        APP_OPT_END,
    };
    app_option sq[APP_SEQUENCE_ROWS];
    app_sequence_options(sq, &ropt);
    const app_option *tables[] = {own, sq, NULL};
    app_command_spec spec = {
        .name = cmd, .usage = usage_text, .tables = tables, .positional = &seq, .min_positional = 1,
        .max_positional = 1, .positional_missing = "no sequence given",
        .epilog = "exit codes: 0 ok, 1 failure, 2 usage, 3 bad input (an unreadable frame or trajectory, too few\n"
                  "frames with a pose, no pair of frames at the gaps, no cell measured), 5 the output could not be written\n"
                  "\nSee docs/calibration.md.\n",
    };
    int rc = app_options_parse(&spec, argc, argv);
    if (rc) return rc < 0 ? APP_EXIT_OK : rc;
    /* Not over what is read: the poses, or a file of the sequence (its
     * index files sit in it). */
    if (strcmp(poses, "groundtruth") != 0 && (rc = app_check_not_input(cmd, "--out", out, poses)) != 0) return rc;
    if ((rc = app_check_not_input(cmd, "--out", out, seq)) != 0) return rc;
    if ((rc = app_check_not_inside(cmd, "--out", out, seq, false)) != 0) return rc;
    if ((rc = app_check_json_out(cmd, "--out", out)) != 0) return rc;
    if (cfg.gaps[0] % cfg.stride || cfg.gaps[1] % cfg.stride)
        return app_usage_error(cmd, "--stride %u must divide the gaps %u and %u", cfg.stride, cfg.gaps[0], cfg.gaps[1]);
    app_calibration cal = {0};
    if (calibration && (rc = app_calibration_read(cmd, calibration, seq, false, &ropt, &cal)) != APP_EXIT_OK) return rc;

    double t0 = bf_time_s();
    bool use_traj = strcmp(poses, "groundtruth") != 0;
    bf_traj traj = {0};
    rgbd_source *src = NULL;
    depth_frames d = {0};
    uint32_t n_no_pose = 0, n_held = 0;
    calib_depth_correction *c = malloc(sizeof *c);
    bf_status s = c ? BF_OK : bf_fail(BF_NO_MEMORY, "calibrate-depth");
    if (s == BF_OK && use_traj) s = replay_traj_read_tum(poses, &traj);
    if (s == BF_OK) s = replay_open(seq, &ropt, &src);
    if (s == BF_OK) s = app_calibration_apply(&cal, seq, src);
    /* A log gives its depth through the lens: taken out here as the loop does. */
    const calib_camera *lens_cam = app_calibration_depth_lens(&cal);
    calib_undistort_map lens = {0};
    if (s == BF_OK && lens_cam) s = calib_undistort_map_make(lens_cam, &lens);
    if (s == BF_OK && !use_traj && !src->has_groundtruth)
        s = bf_fail(BF_FORMAT, "%s: --poses groundtruth, but the sequence has no ground truth", seq);
    if (s == BF_OK) s = read_frames(src, use_traj ? &traj : NULL, &cfg, lens_cam ? &lens : NULL, &d, &n_no_pose, &n_held, seq);
    if (s == BF_OK) {
        d.in = (calib_depth_frames){.n = d.n, .depth = (const uint16_t *const *)d.depth, .index = d.index,
                                    .T_wc = d.T_wc, .K = *rgbd_source_intrinsics(src)};
        fprintf(stderr, "calibrate-depth: %u frames read, %u passes over their pairs\n", d.n, cfg.iterations + 1);
        s = calib_depth_estimate(&cfg, &d.in, c);
        if (s == BF_FORMAT) {
            /* The estimate's message, named by the sequence instead of the function. */
            char why[512];
            const char *e = bf_last_error(), *p = strstr(e, ": ");
            snprintf(why, sizeof why, "%s", p ? p + 2 : e);
            bf_fail(BF_FORMAT, "%s: %s", seq, why);
        }
    }
    /* No cell measured (no depth within the range at the pairs' pixels): an
     * all-ones file would read as a camera without a pattern. */
    if (s == BF_OK && c->n_cells_measured == 0)
        s = bf_fail(BF_FORMAT, "%s: no cell of the %ux%u grid was measured (depth within %.2f m where pairs overlap): "
                    "no correction written", seq, c->grid_w, c->grid_h, cfg.max_depth_m);
    if (s == BF_OK) {
        /* The pixels the pattern was found in: the lens taken out of the frames. */
        double dist[CALIB_DIST_N];
        const double *l = app_frames_lens(src, &cal, dist);
        c->is_lens_known = true;
        if (l) memcpy(c->lens, l, sizeof c->lens);
        else memset(c->lens, 0, sizeof c->lens);
        s = calib_depth_write(out, c);
    }
    if (s == BF_OK) {
        double secs = bf_time_s() - t0;
        if (json) {
            s = app_json_print(result_json(seq, out, &cfg, c, n_no_pose, n_held, secs));
        } else {
            float lo, hi;
            calib_depth_range(c, &lo, &hi);
            printf("bitfuse calibrate-depth: %s -> %s\n", seq, out);
            printf("  frames           %u with a pose (%u without, %u with a held pose left out), %u pairs\n",
                   c->n_frames, n_no_pose, n_held, c->n_pairs);
            printf("  cells            %ux%u of %u px, %u measured\n", c->grid_w, c->grid_h, c->cell_px,
                   c->n_cells_measured);
            printf("  pattern          RMS %.2f per mille before, %.2f after; multipliers %.4f..%.4f\n",
                   1000 * c->rms_before, 1000 * c->rms_after, lo, hi);
            printf("  time             %.1f s\n", secs);
        }
    }
    frames_free(&d);
    calib_undistort_map_free(&lens);
    rgbd_source_close(src);
    bf_traj_free(&traj);
    free(c);
    return s == BF_OK ? APP_EXIT_OK : app_fail(cmd, s);
}
