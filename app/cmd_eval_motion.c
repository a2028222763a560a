/* bitfuse eval-motion: camera trajectories, or a ground truth, against the
 * motion the sequence's own colour images show (eval.h, "motion from
 * colour"; docs/eval.md). No ground truth is needed. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"
#include "eval/eval.h"
#include "replay/replay.h"

#define MAX_TRAJ 8

static const char usage_text[] =
    "usage: bitfuse eval-motion SEQUENCE TRAJ [TRAJ...] [options]\n"
    "\n"
    "Checks camera trajectories against the motion the sequence's own colour images show,\n"
    "without ground truth. For pairs of frames --span apart (one every --every frames), ORB\n"
    "features of the two colour images are matched, the first frame's depth lifts its\n"
    "features to 3-D, and PnP with RANSAC (OpenCV) gives the second camera's pose in the\n"
    "first's frame. Each TRAJ's relative pose over the same pair is compared with it. The\n"
    "colour carries neither the depth camera's fixed error pattern nor anything of a\n"
    "tracker, so this checks a tracker's output, or a sequence's ground truth, by data it\n"
    "did not use. TRAJ is a TUM trajectory file (camera-to-world, e.g. replay's\n"
    "trajectory.txt) or 'groundtruth' (the frames' own poses). The motion is the one\n"
    "between the two colour images' timestamps, and every TRAJ is interpolated there (in\n"
    "TUM sequences a colour image is up to 20 ms from its depth). The colour is taken as\n"
    "registered to the depth (TUM, 7-Scenes folders, bitfuse logs) unless --calibration\n"
    "gives its own camera (bitfuse calibrate's calib.json); pairs are compared\n"
    "where the colour gives a motion and every TRAJ has a pose at both colour times (a\n"
    "time outside a trajectory's span has none). A pair with a frame whose depth or\n"
    "colour repeats the frame before byte for byte (a driver handing on its last image:\n"
    "stale data, which a tracker may also have skipped) is left out and counted.\n";

/* A frame kept until its pairs are made: features and depth. */
typedef struct kept_frame {
    uint32_t index;
    double t_s;          /* its colour's timestamp */
    bool has_pose;       /* its own ground truth */
    eval_motion_image *im;
    uint16_t *depth;
    bool repeat;         /* its depth or colour is the previous frame's byte for byte */
} kept_frame;

/* The colour's motion is from a's colour image to b's: the features are
 * lifted along a's colour rays (by the depth taken nearest in time), and b's
 * colour gives the pose. The trajectories are read at those two moments. */
typedef struct pair_rec {
    uint32_t a, b;
    double t_a, t_b;       /* the colour timestamps */
    bool has_gt;           /* a and b have their own ground truth (not only neighbours far off) */
    bool repeat;           /* a or b repeats the frame before it: left out */
    eval_motion_pair m;
} pair_rec;

typedef struct motion_args {
    const char *paths[1 + MAX_TRAJ];
    eval_motion_config cfg;
    uint32_t span, every;
    const char *csv;
    bool json;
    replay_options ropt;
    const char *calibration;
    app_calibration cal;
    eval_motion_rig rig; /* with --calibration */
} motion_args;

typedef struct pairs {
    pair_rec *v;
    uint32_t n, cap;
    bf_traj gt;            /* the frames' own poses at their depth timestamps ('groundtruth') */
} pairs;

static void kept_free(kept_frame *k)
{
    eval_motion_image_free(k->im);
    free(k->depth);
    memset(k, 0, sizeof *k);
}

static bf_status pairs_push(pairs *p, const pair_rec *r)
{
    if (p->n == p->cap) {
        uint32_t cap = p->cap ? 2 * p->cap : 64;
        pair_rec *v = realloc(p->v, cap * sizeof *v);
        if (!v) return bf_fail(BF_NO_MEMORY, "eval-motion: %u pairs", cap);
        p->v = v;
        p->cap = cap;
    }
    p->v[p->n++] = *r;
    return BF_OK;
}

static bool is_first(const motion_args *a, uint32_t i) { return i % a->every == 0; }
static bool is_second(const motion_args *a, uint32_t i) { return i >= a->span && is_first(a, i - a->span); }

/* Keeps frame f (its features and depth, through lens when not NULL) in
 * the ring slot of its index. */
static bf_status keep(kept_frame *slot, const bf_frame *f, const eval_motion_config *cfg,
                      const calib_undistort_map *lens)
{
    kept_free(slot);
    size_t n = (size_t)f->width * f->height;
    bf_status s = eval_motion_image_make(f->rgb, f->width, f->height, cfg, &slot->im);
    if (s != BF_OK) return s;
    slot->depth = malloc(n * sizeof *slot->depth);
    if (!slot->depth) return bf_fail(BF_NO_MEMORY, "eval-motion: frame %u", f->index);
    if (lens) calib_undistort_u16(lens, f->depth, slot->depth);
    else memcpy(slot->depth, f->depth, n * sizeof *slot->depth);
    slot->index = f->index;
    slot->t_s = f->t_rgb_s;
    slot->has_pose = f->has_pose;
    return BF_OK;
}

/* Reads the sequence once; each frame a pair needs is kept in a ring of
 * span + 1 slots until its partner has come. */
static bf_status read_pairs(const motion_args *a, rgbd_source *src, pairs *out, uint32_t *n_frames)
{
    const char *seq = a->paths[0];
    const bf_intrinsics *K = rgbd_source_intrinsics(src);
    const eval_motion_rig *rig = a->calibration ? &a->rig : NULL;
    uint32_t ring_n = a->span + 1;
    /* A device's or a log's depth still holds the calibration's lens. */
    const calib_camera *lens_cam = app_calibration_depth_lens(&a->cal);
    calib_undistort_map lens = {0};
    bf_status s = lens_cam ? calib_undistort_map_make(lens_cam, &lens) : BF_OK;
    if (s != BF_OK) return s;
    kept_frame *ring = calloc(ring_n, sizeof *ring);
    if (!ring) {
        calib_undistort_map_free(&lens);
        return bf_fail(BF_NO_MEMORY, "eval-motion: %u frames", ring_n);
    }
    bf_progress prog;
    bf_progress_begin(&prog, "eval-motion", src->n_frames);
    bf_frame f;
    uint32_t seen = 0;
    bf_repeats prev = {0}; /* a pair with a repeated frame is left out */
    while ((s = rgbd_source_next(src, &f)) == BF_OK) {
        bf_progress_update(&prog, ++seen);
        bool dr = false, cr = false;
        if (f.width == K->width && f.height == K->height && (s = bf_repeats_note(&prev, &f, &dr, &cr)) != BF_OK) break;
        bool repeat = dr || cr;
        /* Every frame's own pose, for 'groundtruth' at the colour times. */
        if (f.has_pose && (!out->gt.n || f.t_depth_s > out->gt.t_s[out->gt.n - 1]) &&
            (s = bf_traj_push(&out->gt, f.t_depth_s, &f.T_wc)) != BF_OK)
            break;
        bool first = is_first(a, f.index), second = is_second(a, f.index);
        if (!first && !second) continue;
        if (f.width != K->width || f.height != K->height) {
            s = bf_fail(BF_FORMAT, "%s: frame %u is %ux%u, the sequence's camera %ux%u", seq, f.index, f.width,
                        f.height, K->width, K->height);
            break;
        }
        if (!f.rgb) {
            s = bf_fail(BF_FORMAT, "%s: frame %u has no colour image: eval-motion needs colour", seq, f.index);
            break;
        }
        if (!f.depth) continue;
        kept_frame *slot = &ring[f.index % ring_n];
        if ((s = keep(slot, &f, &a->cfg, lens_cam ? &lens : NULL)) != BF_OK) break;
        slot->repeat = repeat;
        if (!second) continue;
        const kept_frame *fa = &ring[(f.index - a->span) % ring_n];
        if (!fa->im || fa->index != f.index - a->span) continue; /* a skipped or depthless first frame */
        pair_rec r = {.a = fa->index, .b = f.index, .t_a = fa->t_s, .t_b = f.t_rgb_s,
                      .has_gt = fa->has_pose && f.has_pose, .repeat = fa->repeat || repeat};
        if (!r.repeat && (s = eval_motion_pnp(fa->im, fa->depth, K, rig, slot->im, &a->cfg, &r.m)) != BF_OK) break;
        if ((s = pairs_push(out, &r)) != BF_OK) break;
    }
    bf_progress_end(&prog, seen);
    bf_repeats_free(&prev);
    for (uint32_t i = 0; i < ring_n; i++) kept_free(&ring[i]);
    free(ring);
    calib_undistort_map_free(&lens);
    *n_frames = seen;
    return s == BF_END ? BF_OK : s;
}

/* One trajectory's comparison over the common pairs. */
typedef struct traj_result {
    const char *name;
    bool is_gt;
    bf_traj traj;
    eval_motion_error *err; /* per pair; NaN where it has no pose */
    eval_err_stats trans, rot;
    double p90_trans, p90_rot;
    double length_ratio;    /* least squares: its steps as a multiple of the colour's */
    uint32_t n_closest;     /* pairs where it alone is the closest */
    uint32_t n_tied;        /* pairs where it ties another for the closest (the same poses there) */
} traj_result;

/* A trajectory's pose at a pair's colour moment; 'groundtruth' is the
 * frames' own poses, interpolated between their depth timestamps, where
 * both frames have one (not across a gap of frames without). A moment
 * outside a trajectory's time span has no pose: the pair is not compared. */
static bool traj_pose(const traj_result *t, const pairs *p, const pair_rec *r, bool second, bf_se3 *T)
{
    if (t->is_gt && !r->has_gt) return false;
    return bf_traj_interpolate(t->is_gt ? &p->gt : &t->traj, second ? r->t_b : r->t_a, T);
}

/* Errors of every trajectory on the pairs where the colour gave a motion
 * and every trajectory has both poses; *common marks those pairs. */
static bf_status compare(const pairs *p, traj_result *t, int n_t, bool *common, uint32_t *n_common)
{
    *n_common = 0;
    for (uint32_t i = 0; i < p->n; i++) {
        const pair_rec *r = &p->v[i];
        common[i] = r->m.ok;
        for (int k = 0; k < n_t && common[i]; k++) {
            bf_se3 Ta, Tb;
            common[i] = traj_pose(&t[k], p, r, false, &Ta) && traj_pose(&t[k], p, r, true, &Tb);
            if (common[i]) eval_motion_compare(&r->m.T_ab, &Ta, &Tb, &t[k].err[i]);
        }
        *n_common += common[i];
    }
    if (!*n_common) return BF_OK;
    double *tr = malloc(*n_common * sizeof *tr), *ro = malloc(*n_common * sizeof *ro);
    if (!tr || !ro) {
        free(tr);
        free(ro);
        return bf_fail(BF_NO_MEMORY, "eval-motion: %u pairs", *n_common);
    }
    for (int k = 0; k < n_t; k++) {
        uint32_t m = 0;
        double num = 0, den = 0;
        for (uint32_t i = 0; i < p->n; i++) {
            if (!common[i]) continue;
            const eval_motion_error *e = &t[k].err[i];
            tr[m] = e->trans_m;
            ro[m] = e->rot_deg;
            m++;
            num += e->along_m * e->colour_m;
            den += e->colour_m * e->colour_m;
            bool closest = true, tied = false;
            for (int j = 0; j < n_t; j++) {
                if (j != k && t[j].err[i].trans_m < e->trans_m) closest = false;
                if (j != k && t[j].err[i].trans_m == e->trans_m) tied = true;
            }
            /* A tie is no trajectory's win: the shares of wins add up to at most 100%. */
            t[k].n_closest += closest && !tied;
            t[k].n_tied += closest && tied;
        }
        eval_err_stats_compute(tr, m, &t[k].trans);
        eval_err_stats_compute(ro, m, &t[k].rot);
        t[k].p90_trans = bf_percentile_inplace(tr, m, 90);
        t[k].p90_rot = bf_percentile_inplace(ro, m, 90);
        t[k].length_ratio = den > 0 ? num / den : NAN;
    }
    free(tr);
    free(ro);
    return BF_OK;
}

static bf_status write_csv(const char *path, const pairs *p, const traj_result *t, int n_t, const bool *common)
{
    bf_out o;
    bf_status s = bf_out_open(&o, path);
    if (s != BF_OK) return s;
    bf_out_printf(&o, "# frame_a,frame_b,t_a,t_b,matches,lifted,inliers,rms_px,colour_tx_m,colour_ty_m,colour_tz_m,"
                      "colour_rot_deg,compared");
    for (int k = 0; k < n_t; k++) bf_out_printf(&o, ",trans_err_m_%d,rot_err_deg_%d,along_m_%d", k + 1, k + 1, k + 1);
    bf_out_printf(&o, ",repeat\n");
    for (int k = 0; k < n_t; k++) bf_out_printf(&o, "# trajectory %d: %s\n", k + 1, t[k].name);
    for (uint32_t i = 0; i < p->n; i++) {
        const pair_rec *r = &p->v[i];
        const bf_vec3 *c = &r->m.T_ab.t;
        bf_out_printf(&o, "%u,%u,%.6f,%.6f,%u,%u,%u,%.3f,%.6f,%.6f,%.6f,%.4f,%d", r->a, r->b, r->t_a, r->t_b,
                      r->m.n_matches, r->m.n_lifted, r->m.n_inliers, r->m.rms_px, r->m.ok ? c->x : NAN,
                      r->m.ok ? c->y : NAN, r->m.ok ? c->z : NAN,
                      r->m.ok ? bf_se3_angle(&r->m.T_ab) * (180.0 / M_PI) : NAN, common[i] ? 1 : 0);
        for (int k = 0; k < n_t; k++) {
            const eval_motion_error *e = &t[k].err[i];
            if (common[i])
                bf_out_printf(&o, ",%.6f,%.4f,%.6f", e->trans_m, e->rot_deg, e->along_m);
            else
                bf_out_printf(&o, ",,,");
        }
        bf_out_printf(&o, ",%d\n", r->repeat ? 1 : 0);
    }
    return bf_out_commit(&o);
}

static void colour_summary(const pairs *p, const bool *common, double *med_inl, double *med_rms, double *med_len)
{
    double *v = malloc((p->n ? p->n : 1) * 3 * sizeof *v);
    *med_inl = *med_rms = *med_len = NAN;
    if (!v) return;
    size_t m = 0;
    for (uint32_t i = 0; i < p->n; i++) {
        if (!common[i]) continue;
        v[m] = p->v[i].m.n_inliers;
        v[p->n + m] = p->v[i].m.rms_px;
        const bf_vec3 *c = &p->v[i].m.T_ab.t;
        v[2 * p->n + m] = sqrt(bf_v3_dot(*c, *c));
        m++;
    }
    if (m) {
        *med_inl = bf_percentile_inplace(v, m, 50);
        *med_rms = bf_percentile_inplace(v + p->n, m, 50);
        *med_len = bf_percentile_inplace(v + 2 * p->n, m, 50);
    }
    free(v);
}

static cJSON *result_json(const motion_args *a, const pairs *p, const traj_result *t, int n_t, uint32_t n_common,
                          uint32_t n_frames, double med_inl, double med_rms, double med_len, double secs)
{
    cJSON *o = app_json_stats("eval-motion");
    cJSON_AddStringToObject(o, "sequence", a->paths[0]);
    cJSON *k = app_json_object(o, "config");
    cJSON_AddNumberToObject(k, "span", a->span);
    cJSON_AddNumberToObject(k, "every", a->every);
    cJSON_AddNumberToObject(k, "features", a->cfg.n_features);
    cJSON_AddNumberToObject(k, "ransac_px", a->cfg.ransac_px);
    cJSON_AddNumberToObject(k, "ransac_iterations", a->cfg.ransac_iterations);
    cJSON_AddNumberToObject(k, "min_inliers", a->cfg.min_inliers);
    cJSON_AddNumberToObject(k, "min_depth_m", a->cfg.min_depth_m);
    cJSON_AddNumberToObject(k, "max_depth_m", a->cfg.max_depth_m);
    if (a->calibration) cJSON_AddStringToObject(k, "calibration", a->calibration);
    else cJSON_AddNullToObject(k, "calibration");
    cJSON_AddNumberToObject(o, "frames", n_frames);
    cJSON_AddNumberToObject(o, "pairs", p->n);
    uint32_t n_ok = 0, n_rep = 0;
    for (uint32_t i = 0; i < p->n; i++) n_ok += p->v[i].m.ok, n_rep += p->v[i].repeat;
    cJSON_AddNumberToObject(o, "pairs_repeated", n_rep);
    cJSON_AddNumberToObject(o, "pairs_with_motion", n_ok);
    cJSON_AddNumberToObject(o, "pairs_compared", n_common);
    cJSON *c = app_json_object(o, "colour");
    cJSON_AddNumberToObject(c, "inliers_median", med_inl);
    cJSON_AddNumberToObject(c, "rms_px_median", med_rms);
    cJSON_AddNumberToObject(c, "step_m_median", med_len);
    cJSON *arr = cJSON_AddArrayToObject(o, "trajectories");
    for (int i = 0; i < n_t; i++) {
        cJSON *e = cJSON_CreateObject();
        cJSON_AddStringToObject(e, "name", t[i].name);
        cJSON *tr = app_json_object(e, "trans_err_m");
        cJSON_AddNumberToObject(tr, "median", t[i].trans.median);
        cJSON_AddNumberToObject(tr, "mean", t[i].trans.mean);
        cJSON_AddNumberToObject(tr, "rmse", t[i].trans.rmse);
        cJSON_AddNumberToObject(tr, "p90", t[i].p90_trans);
        cJSON_AddNumberToObject(tr, "max", t[i].trans.max);
        cJSON *ro = app_json_object(e, "rot_err_deg");
        cJSON_AddNumberToObject(ro, "median", t[i].rot.median);
        cJSON_AddNumberToObject(ro, "mean", t[i].rot.mean);
        cJSON_AddNumberToObject(ro, "p90", t[i].p90_rot);
        cJSON_AddNumberToObject(ro, "max", t[i].rot.max);
        cJSON_AddNumberToObject(e, "length_ratio", t[i].length_ratio);
        cJSON_AddNumberToObject(e, "closest_pairs", t[i].n_closest);
        cJSON_AddNumberToObject(e, "tied_pairs", t[i].n_tied);
        cJSON_AddItemToArray(arr, e);
    }
    cJSON_AddNumberToObject(o, "seconds", secs);
    return o;
}

static void print_result(const motion_args *a, const pairs *p, const traj_result *t, int n_t, uint32_t n_common,
                         double med_inl, double med_rms, double med_len, double secs)
{
    uint32_t n_ok = 0, n_rep = 0;
    for (uint32_t i = 0; i < p->n; i++) n_ok += p->v[i].m.ok, n_rep += p->v[i].repeat;
    printf("bitfuse eval-motion: %s, pairs %u frames apart, one every %u frames\n", a->paths[0], a->span, a->every);
    if (a->calibration) printf("  colour camera    of its own: %s\n", a->calibration);
    printf("  pairs            %u, %u of them with a repeated frame (left out); the colour gave a motion in %u\n"
           "                   (at least %u inliers), %u compared\n",
           p->n, n_rep, n_ok, a->cfg.min_inliers, n_common);
    printf("  colour           median %.0f inliers, %.2f px reprojection RMS, step %.1f mm\n", med_inl, med_rms,
           1e3 * med_len);
    printf("  %-28s %33s  %21s  %7s  %s\n", "", "translation error mm", "rotation error deg", "length", "closest");
    printf("  %-28s %8s %8s %8s %8s  %6s %6s %6s  %7s  %s\n", "trajectory", "median", "mean", "p90", "RMSE",
           "median", "p90", "max", "ratio", "in pairs");
    for (int i = 0; i < n_t; i++) {
        char nm[32];
        size_t L = strlen(t[i].name);
        snprintf(nm, sizeof nm, "%s%s", L > 28 ? "..." : "", L > 28 ? t[i].name + L - 25 : t[i].name);
        char tie[48] = "";
        if (t[i].n_tied) snprintf(tie, sizeof tie, " (+%.0f%% tied)", n_common ? 100.0 * t[i].n_tied / n_common : 0.0);
        printf("  %-28s %8.2f %8.2f %8.2f %8.2f  %6.3f %6.3f %6.3f  %7.3f  %.0f%%%s\n", nm,
               1e3 * t[i].trans.median, 1e3 * t[i].trans.mean, 1e3 * t[i].p90_trans, 1e3 * t[i].trans.rmse,
               t[i].rot.median, t[i].p90_rot, t[i].rot.max, t[i].length_ratio,
               n_common ? 100.0 * t[i].n_closest / n_common : 0.0, tie);
    }
    printf("  time             %.1f s\n", secs);
}

int cmd_eval_motion(int argc, char **argv)
{
    const char *cmd = "eval-motion";
    motion_args a;
    memset(&a, 0, sizeof a);
    a.cfg = eval_motion_config_default();
    a.span = 10;
    a.every = 5;
    const app_option own[] = {
        APP_OPT("--span", APP_OPT_U32, &a.span, "K", "frames between a pair's two frames", .min = 1, .max = 1000),
        APP_OPT("--every", APP_OPT_U32, &a.every, "S", "a pair starts every S frames", .min = 1, .max = 1000),
        APP_OPT("--features", APP_OPT_U32, &a.cfg.n_features, "N", "ORB features per image", .min = 50,
                .max = 100000),
        APP_OPT("--ransac-px", APP_OPT_DOUBLE, &a.cfg.ransac_px, "PX", "RANSAC's reprojection threshold in pixels",
                .min = 0.1, .max = 50),
        APP_OPT("--min-inliers", APP_OPT_U32, &a.cfg.min_inliers, "N",
                "a pair whose PnP keeps fewer inliers gives no motion and is left out", .min = 6, .max = 100000),
        APP_OPT("--max-depth", APP_OPT_FLOAT, &a.cfg.max_depth_m, "M", "features lifted only from nearer depths",
                .min = 0.5, .max = 20),
        APP_OPT("--csv", APP_OPT_STRING, &a.csv, "FILE",
                "one line per pair: the colour's motion, inliers and each trajectory's errors"),
        APP_OPT("--json", APP_OPT_FLAG, &a.json, NULL, "print the result as JSON instead of the summary"),
        APP_OPT("--calibration", APP_OPT_STRING, &a.calibration, "FILE",
                "calib.json of bitfuse calibrate: the colour is its colour camera's own image, its features "
                "lifted by the depth that camera sees and placed through its lens; the motion is the depth "
                "camera's (docs/eval.md)",
                .no_default = true),
        APP_OPT_END,
    };
    app_option sq[APP_SEQUENCE_ROWS];
    app_sequence_options(sq, &a.ropt);
    const app_option *tables[] = {own, sq, NULL};
    app_command_spec spec = {
        .name = cmd, .usage = usage_text, .tables = tables, .positional = a.paths, .min_positional = 2,
        .max_positional = 1 + MAX_TRAJ, .positional_missing = "needs a sequence and at least one trajectory",
        .epilog = "exit codes: 0 ok, 1 failure, 2 usage (--camera with a --calibration that has a depth camera),\n"
                  "3 bad input (an unreadable frame, trajectory or --calibration file, a frame without colour,\n"
                  "'groundtruth' for a sequence without it, a calibration's depth camera of another size, no\n"
                  "pair the colour gives a motion for), 5 the CSV or standard output could not be written\n"
                  "\nSee docs/eval.md.\n",
    };
    int rc = app_options_parse(&spec, argc, argv);
    if (rc) return rc < 0 ? APP_EXIT_OK : rc;
    if (a.calibration) {
        /* Read and checked before the sequence opens. */
        if ((rc = app_calibration_read(cmd, a.calibration, a.paths[0], false, &a.ropt, &a.cal))) return rc;
        a.rig.colour = &a.cal.cal.colour; /* scaled to the frames' size by app_calibration_apply */
        a.rig.T_colour_depth = a.cal.cal.has_depth ? a.cal.cal.T_colour_depth : bf_se3_identity();
    }

    double t0 = bf_time_s();
    int n_t = 0;
    while (n_t < MAX_TRAJ && a.paths[1 + n_t]) n_t++;
    traj_result t[MAX_TRAJ];
    memset(t, 0, sizeof t);
    pairs p = {0};
    bool *common = NULL;
    rgbd_source *src = NULL;
    uint32_t n_frames = 0, n_common = 0;
    bf_status s = BF_OK;
    for (int k = 0; k < n_t && s == BF_OK; k++) {
        t[k].name = a.paths[1 + k];
        t[k].is_gt = strcmp(t[k].name, "groundtruth") == 0;
        if (!t[k].is_gt) s = replay_traj_read_tum(t[k].name, &t[k].traj);
    }
    if (s == BF_OK) s = replay_open(a.paths[0], &a.ropt, &src);
    if (s == BF_OK) s = app_calibration_apply(&a.cal, a.paths[0], src);
    for (int k = 0; k < n_t && s == BF_OK; k++)
        if (t[k].is_gt && !src->has_groundtruth)
            s = bf_fail(BF_FORMAT, "%s: 'groundtruth', but the sequence has no ground truth", a.paths[0]);
    if (s == BF_OK) s = read_pairs(&a, src, &p, &n_frames);
    if (s == BF_OK && !p.n)
        s = bf_fail(BF_FORMAT, "%s: %u frames: no pair %u frames apart", a.paths[0], n_frames, a.span);
    if (s == BF_OK) {
        common = calloc(p.n, sizeof *common);
        for (int k = 0; k < n_t; k++) t[k].err = calloc(p.n, sizeof *t[k].err);
        bool ok = common != NULL;
        for (int k = 0; k < n_t; k++) ok = ok && t[k].err;
        s = ok ? compare(&p, t, n_t, common, &n_common) : bf_fail(BF_NO_MEMORY, "eval-motion: %u pairs", p.n);
    }
    if (s == BF_OK && !n_common) {
        uint32_t n_ok = 0;
        for (uint32_t i = 0; i < p.n; i++) n_ok += p.v[i].m.ok;
        s = bf_fail(BF_FORMAT,
                    "%s: none of %u pairs can be compared: the colour gave a motion in %u (at least %u inliers), "
                    "and the trajectories must have poses at both colour times",
                    a.paths[0], p.n, n_ok, a.cfg.min_inliers);
    }
    if (s == BF_OK && a.csv) s = write_csv(a.csv, &p, t, n_t, common);
    if (s == BF_OK) {
        double med_inl, med_rms, med_len, secs = bf_time_s() - t0;
        colour_summary(&p, common, &med_inl, &med_rms, &med_len);
        if (a.json)
            s = app_json_print(result_json(&a, &p, t, n_t, n_common, n_frames, med_inl, med_rms, med_len, secs));
        else
            print_result(&a, &p, t, n_t, n_common, med_inl, med_rms, med_len, secs);
    }
    for (int k = 0; k < n_t; k++) {
        bf_traj_free(&t[k].traj);
        free(t[k].err);
    }
    free(common);
    free(p.v);
    bf_traj_free(&p.gt);
    rgbd_source_close(src);
    return s == BF_OK ? APP_EXIT_OK : app_fail(cmd, s);
}
