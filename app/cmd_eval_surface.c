/* bitfuse eval-surface: accuracy and completeness of a reconstruction
 * against a reference mesh (docs/eval.md). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"
#include "calib/calib.h"
#include "core/core.h"
#include "eval/eval.h"
#include "mesh/mesh.h"
#include "replay/replay.h"

static const char usage_text[] =
    "usage: bitfuse eval-surface --reference MESH --reconstruction PLY [options]\n"
    "\n"
    "Accuracy: distance from each reconstruction point (its vertices, plus area\n"
    "samples of its triangles if it is a mesh) to the reference surface.\n"
    "Completeness: share of reference surface samples (area-uniform) within the\n"
    "threshold of the reconstruction, and their distances.\n"
    "\n"
    "With --depth SEQUENCE instead of --reconstruction, the points are the sensor's own\n"
    "depth samples (every K-th frame, every S-th pixel) back-projected at the frames' poses:\n"
    "accuracy is then how far the measured depth lies from the reference mesh (a\n"
    "reconstruction of real frames, which have no true surface), 'within' the share of\n"
    "depth samples the mesh explains, and completeness the share of the mesh that some\n"
    "depth sample supports.\n";

/* What --depth reads. */
typedef struct depth_points_args {
    const char *seq, *poses; /* poses: "groundtruth" or a TUM trajectory file */
    const char *correction;  /* depth_correction.json applied to the depth, or NULL */
    uint32_t every, pixel_step;
    double max_depth_m;
    double max_gap_s; /* --poses TRAJ: a frame between two poses further apart is left out; < 0: not given (0.1) */
    replay_options ropt;
} depth_points_args;

/* The pose of a trajectory at t, interpolated only between neighbours at
 * most max_gap_s apart (a microsecond's slack: 0.1 s is three frames at 30
 * Hz, and TUM's times round either side of it); across a wider gap (frames
 * a tracker lost or did not write) the straight line between its ends is
 * no measurement. *gap: refused so. */
static bool pose_at(const bf_traj *traj, double t, double max_gap_s, bf_se3 *T, bool *gap)
{
    *gap = false;
    if (!bf_traj_interpolate(traj, t, T)) return false;
    size_t lo = 0, hi = traj->n - 1;
    while (hi - lo > 1) {
        size_t mid = (lo + hi) / 2;
        if (traj->t_s[mid] <= t) lo = mid;
        else hi = mid;
    }
    if (traj->t_s[lo] == t || traj->t_s[hi] == t) return true; /* a pose of its own */
    *gap = traj->t_s[hi] - traj->t_s[lo] > max_gap_s + 1e-6;
    return !*gap;
}

/* Back-projects the valid depth of every a->every-th frame, every
 * a->pixel_step-th pixel in x and y, at the frame's pose into pts (a point
 * set: no triangles). Frames without a pose are skipped and counted. */
static bf_status depth_points(const depth_points_args *a, mesh_data *pts, uint32_t *n_frames, uint32_t *in_gap_out)
{
    rgbd_source *src = NULL;
    bf_traj traj = {0};
    bool use_traj = strcmp(a->poses, "groundtruth") != 0;
    bf_status s = use_traj ? replay_traj_read_tum(a->poses, &traj) : BF_OK;
    if (s == BF_OK) s = replay_open(a->seq, &a->ropt, &src);
    if (s == BF_OK && !use_traj && !src->has_groundtruth)
        s = bf_fail(BF_FORMAT, "%s: --poses groundtruth, but the sequence has no ground truth", a->seq);
    /* --depth-correction: the depth the loop saw (replay --depth-correction). */
    float *mult = NULL;
    if (s == BF_OK && a->correction) {
        static calib_depth_correction dc; /* 19 KB */
        const bf_intrinsics *K = &src->intrinsics;
        s = calib_depth_read(a->correction, &dc);
        if (s == BF_OK && (dc.width != K->width || dc.height != K->height))
            s = bf_fail(BF_FORMAT, "%s: the depth correction is for %ux%u depth images, the sequence's are %ux%u",
                        a->correction, dc.width, dc.height, K->width, K->height);
        if (s == BF_OK && !(mult = malloc((size_t)dc.width * dc.height * sizeof *mult)))
            s = bf_fail(BF_NO_MEMORY, "eval-surface: depth correction");
        if (s == BF_OK) calib_depth_map(&dc, mult);
    }
    size_t cap = 0, n = 0;
    float *xyz = NULL;
    uint32_t used = 0, no_pose = 0, in_gap = 0;
    /* The points relative to the first camera's place (to the metre), so a
     * scan far from the world origin keeps its millimetres in float. */
    bf_vec3 origin = bf_v3(0, 0, 0);
    bool has_origin = false;
    bf_frame f;
    while (s == BF_OK && (s = rgbd_source_next(src, &f)) == BF_OK) {
        if (f.index % a->every) continue;
        bf_se3 T;
        bool gap = false;
        if (use_traj ? !pose_at(&traj, f.t_depth_s, a->max_gap_s, &T, &gap) : !f.has_pose) {
            if (gap) in_gap++;
            else no_pose++;
            continue;
        }
        if (!use_traj) T = f.T_wc;
        if (!has_origin) origin = bf_v3(round(T.t.x), round(T.t.y), round(T.t.z)), has_origin = true;
        const bf_intrinsics *K = &src->intrinsics;
        size_t need = n + ((size_t)f.width / a->pixel_step + 1) * ((size_t)f.height / a->pixel_step + 1);
        if (need > cap) {
            cap = need * 2;
            float *g = bf_realloc(xyz, cap * 3 * sizeof *xyz);
            if (!g) {
                s = bf_fail(BF_NO_MEMORY, "eval-surface: %zu depth points", cap);
                break;
            }
            xyz = g;
        }
        for (uint32_t y = 0; y < f.height; y += a->pixel_step)
            for (uint32_t x = 0; x < f.width; x += a->pixel_step) {
                size_t i = (size_t)y * f.width + x;
                double z = f.depth[i] * (mult && f.width == K->width && f.height == K->height ? mult[i] : 1.0f) /
                           K->depth_scale;
                if (!(z > 0) || z > a->max_depth_m) continue;
                bf_vec3 p = bf_v3((x - K->cx_px) * z / K->fx_px, (y - K->cy_px) * z / K->fy_px, z);
                p = bf_v3_sub(bf_se3_apply(&T, p), origin);
                xyz[3 * n] = (float)p.x, xyz[3 * n + 1] = (float)p.y, xyz[3 * n + 2] = (float)p.z;
                n++;
            }
        used++;
    }
    if (s == BF_END) s = BF_OK;
    free(mult);
    if (src) rgbd_source_close(src);
    bf_traj_free(&traj);
    if (s == BF_OK && n == 0) s = bf_fail(BF_FORMAT, "%s: no depth sample with a pose", a->seq);
    if (s != BF_OK) {
        free(xyz);
        return s;
    }
    if (no_pose) bf_warn("eval-surface: %u frame%s without a pose left out", no_pose, app_s(no_pose));
    if (in_gap)
        bf_warn("eval-surface: %u frame%s in gaps of %s wider than --max-gap %g s left out", in_gap, app_s(in_gap), a->poses,
                a->max_gap_s);
    *in_gap_out = in_gap;
    bf_info("eval-surface: %zu depth samples from %u frames of %s", n, used, a->seq);
    *pts = (mesh_data){.n_verts = (uint32_t)n, .xyz = xyz, .origin = origin};
    *n_frames = used;
    return BF_OK;
}

/* The diagonal of a mesh's bounding box [its units]. */
static double span_m(const mesh_data *m)
{
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (size_t i = 0; i < 3 * (size_t)m->n_verts; i++) {
        lo[i % 3] = fmin(lo[i % 3], m->xyz[i]);
        hi[i % 3] = fmax(hi[i % 3], m->xyz[i]);
    }
    return m->n_verts ? sqrt(pow(hi[0] - lo[0], 2) + pow(hi[1] - lo[1], 2) + pow(hi[2] - lo[2], 2)) : 0;
}

static void json_dist(cJSON *o, const eval_dist_stats *d)
{
    cJSON_AddNumberToObject(o, "mean_m", d->mean);
    cJSON_AddNumberToObject(o, "median_m", d->median);
    cJSON_AddNumberToObject(o, "p90_m", d->p90);
    cJSON_AddNumberToObject(o, "rmse_m", d->rmse);
    cJSON_AddNumberToObject(o, "max_m", d->max);
    cJSON_AddNumberToObject(o, "beyond_max_dist", (double)d->n_beyond);
}

static void print_dist_text(const eval_dist_stats *d)
{
    if (d->n == 0) { /* the statistics are NaN: say why instead */
        printf("  no point within --max-dist (all %zu beyond it)\n", d->n_beyond);
        return;
    }
    printf("  mean %.6f m  median %.6f  p90 %.6f  rmse %.6f  max %.6f", d->mean, d->median, d->p90, d->rmse,
           d->max);
    if (d->n_beyond) printf("  (%zu beyond --max-dist, left out)", d->n_beyond);
    printf("\n");
}

int cmd_eval_surface(int argc, char **argv)
{
    const char *cmd = "eval-surface", *ref_path = NULL, *rec_path = NULL, *vis_path = NULL;
    bool json = false;
    eval_surface_config cfg = eval_surface_config_default();
    depth_points_args dp = {.poses = "groundtruth", .every = 10, .pixel_step = 4, .max_depth_m = 4.5, .max_gap_s = -1};
    const app_option own[] = {
        APP_OPT("--reference", APP_OPT_STRING, &ref_path, "MESH", "the reference mesh (PLY)", .required = true),
        APP_OPT("--reconstruction", APP_OPT_STRING, &rec_path, "PLY",
                "the reconstruction: points or a mesh (or --depth)", .no_default = true),
        APP_OPT("--depth", APP_OPT_STRING, &dp.seq, "SEQUENCE",
                "the reconstruction is SEQUENCE's depth, back-projected at --poses (see above)", .no_default = true),
        APP_OPT("--poses", APP_OPT_STRING, &dp.poses, "P",
                "with --depth: 'groundtruth' (the sequence's own) or a TUM trajectory file", .needs = "--depth"),
        APP_OPT("--max-gap", APP_OPT_DOUBLE, &dp.max_gap_s, "S",
                "with --poses TRAJ: a frame is placed by interpolating TRAJ only between poses at most S seconds "
                "apart (or at a pose's own time); frames in wider gaps are left out and counted (default 0.1)",
                .min_open = true, .needs = "--poses", .no_default = true),
        APP_OPT("--depth-correction", APP_OPT_STRING, &dp.correction, "FILE",
                "with --depth: the depth multiplied by this depth_correction.json first (as replay "
                "--depth-correction has it)", .no_default = true, .needs = "--depth"),
        APP_OPT("--every", APP_OPT_U32, &dp.every, "K", "with --depth: every K-th frame", .min = 1,
                .needs = "--depth"),
        APP_OPT("--pixel-step", APP_OPT_U32, &dp.pixel_step, "S", "with --depth: every S-th pixel in x and y",
                .min = 1, .max = 64, .needs = "--depth"),
        APP_OPT("--max-depth", APP_OPT_DOUBLE, &dp.max_depth_m, "M",
                "with --depth: samples beyond M metres are left out (the loop's sensor range)", .min_open = true,
                .needs = "--depth"),
        APP_OPT("--visible", APP_OPT_STRING, &vis_path, "SEEN.ply",
                "completeness over these observed reference points instead of samples of the whole reference"),
        APP_OPT("--threshold", APP_OPT_DOUBLE, &cfg.threshold_m, "M", "completeness / precision threshold, metres",
                .min_open = true),
        APP_OPT("--max-dist", APP_OPT_DOUBLE, &cfg.max_dist_m, "M",
                "distances beyond M are left out of the statistics and counted as beyond (default: no limit)",
                .min_open = true, .no_default = true),
        APP_OPT("--samples-per-m2", APP_OPT_DOUBLE, &cfg.samples_per_m2, "N", "area sampling density (one per 5 mm^2)",
                .min_open = true),
        APP_OPT("--max-samples", APP_OPT_U64, &cfg.max_samples, "N", "cap on samples per mesh", .min = 1),
        APP_OPT("--seed", APP_OPT_U64, &cfg.seed, "N", "sampling seed"),
        APP_OPT("--json", APP_OPT_FLAG, &json, NULL, "machine-readable output on stdout (docs/eval.md)"),
        APP_OPT_END,
    };
    app_option seq[APP_SEQUENCE_ROWS];
    app_sequence_options(seq, &dp.ropt);
    /* They read --depth's sequence: without it they would mean nothing. */
    for (size_t i = 0; seq[i].name; i++) seq[i].needs = "--depth";
    const app_option *tables[] = {own, seq, NULL};
    app_command_spec spec = {.name = cmd, .usage = usage_text, .tables = tables,
                             .epilog = "exit codes: 0 ok, 1 failure, 2 usage, 3 a mesh, sequence or trajectory "
                                       "unreadable or malformed,\n5 standard output could not be written\n"};
    int rc = app_options_parse(&spec, argc, argv);
    if (rc) return rc < 0 ? APP_EXIT_OK : rc;
    if (!rec_path == !dp.seq) return app_usage_error(cmd, "give exactly one of --reconstruction and --depth");
    /* A point between the two would be left out as beyond --max-dist yet
     * counted as not within --threshold: the share would be wrong. */
    if (cfg.max_dist_m < cfg.threshold_m)
        return app_usage_error(cmd, "--max-dist %g is below --threshold %g", cfg.max_dist_m, cfg.threshold_m);
    /* The sequence's own poses are each frame's: there is no gap to bridge. */
    if (dp.max_gap_s >= 0 && !strcmp(dp.poses, "groundtruth"))
        return app_usage_error(cmd, "--max-gap bridges gaps of a --poses TRAJ file, not the sequence's own poses");
    if (dp.max_gap_s < 0) dp.max_gap_s = 0.1;
    if (dp.seq) rec_path = dp.seq;

    mesh_data ref = {0}, rec = {0}, vis = {0};
    eval_surface_result r;
    uint32_t depth_frames = 0;
    bf_status s = mesh_read_ply(ref_path, &ref);
    uint32_t in_gap = 0;
    if (!s) s = dp.seq ? depth_points(&dp, &rec, &depth_frames, &in_gap) : mesh_read_ply(rec_path, &rec);
    if (!s && vis_path) s = mesh_read_ply(vis_path, &vis);
    if (!s && ref.n_verts == 0) s = bf_fail(BF_FORMAT, "%s: the reference has no vertices", ref_path);
    if (!s && rec.n_verts == 0) s = bf_fail(BF_FORMAT, "%s: the reconstruction has no vertices", rec_path);
    if (!s && vis_path && vis.n_verts == 0) s = bf_fail(BF_FORMAT, "%s: no visible points", vis_path);
    double span_ref = 0, span_rec = 0;
    if (!s) span_ref = span_m(&ref), span_rec = span_m(&rec);
    /* Far apart in size, one is likely in other units (a mesh in millimetres): its distances are then
       all beyond any threshold, which reads as a bad reconstruction. */
    if (!s && span_ref > 0 && span_rec > 0 && (span_ref > 20 * span_rec || span_rec > 20 * span_ref))
        bf_warn("eval-surface: the reference spans %.3g m and the reconstruction %.3g m: are both in metres?", span_ref,
                span_rec);
    if (!s) {
        bf_info("eval-surface: reference %u vertices / %u triangles, reconstruction %u vertices / %u "
                "triangles%s",
                ref.n_verts, ref.n_tris, rec.n_verts, rec.n_tris, vis_path ? ", visibility mask" : "");
        s = eval_surface(&ref, &rec, vis_path ? &vis : NULL, &cfg, &r);
    }
    uint32_t ref_v = ref.n_verts, ref_t = ref.n_tris, rec_v = rec.n_verts, rec_t = rec.n_tris;
    mesh_free(&ref);
    mesh_free(&rec);
    mesh_free(&vis);
    if (s) return app_fail(cmd, s);

    const char *source = r.used_visible ? "visible" : r.used_ref_vertices ? "vertices" : "samples";
    if (json) {
        cJSON *o = cJSON_CreateObject();
        cJSON_AddStringToObject(o, "reference", ref_path);
        cJSON_AddStringToObject(o, "reconstruction", rec_path);
        if (dp.seq) {
            cJSON *d = app_json_object(o, "depth");
            cJSON_AddStringToObject(d, "poses", dp.poses);
            if (dp.correction) cJSON_AddStringToObject(d, "depth_correction", dp.correction);
            else cJSON_AddNullToObject(d, "depth_correction");
            cJSON_AddNumberToObject(d, "frames", depth_frames);
            cJSON_AddNumberToObject(d, "every", dp.every);
            cJSON_AddNumberToObject(d, "pixel_step", dp.pixel_step);
            cJSON_AddNumberToObject(d, "max_depth_m", dp.max_depth_m);
            if (strcmp(dp.poses, "groundtruth") != 0) {
                cJSON_AddNumberToObject(d, "max_gap_s", dp.max_gap_s);
                cJSON_AddNumberToObject(d, "frames_in_gaps", in_gap);
            }
        }
        if (vis_path) cJSON_AddStringToObject(o, "visible", vis_path);
        else cJSON_AddNullToObject(o, "visible");
        cJSON_AddNumberToObject(o, "reference_vertices", ref_v);
        cJSON_AddNumberToObject(o, "reference_triangles", ref_t);
        cJSON_AddNumberToObject(o, "threshold_m", cfg.threshold_m);
        cJSON_AddNumberToObject(o, "max_dist_m", cfg.max_dist_m);
        cJSON_AddNumberToObject(o, "samples_per_m2", cfg.samples_per_m2);
        cJSON_AddNumberToObject(o, "max_samples", (double)cfg.max_samples);
        cJSON_AddNumberToObject(o, "seed", (double)cfg.seed);
        cJSON *acc = app_json_object(o, "accuracy");
        cJSON_AddNumberToObject(acc, "points", (double)(r.n_rec_vertices + r.n_rec_samples));
        cJSON_AddNumberToObject(acc, "rec_vertices", (double)r.n_rec_vertices);
        cJSON_AddNumberToObject(acc, "rec_samples", (double)r.n_rec_samples);
        json_dist(acc, &r.accuracy);
        cJSON_AddNumberToObject(acc, "within_threshold", r.precision);
        cJSON *com = app_json_object(o, "completeness");
        cJSON_AddNumberToObject(com, "points", (double)r.n_ref_points);
        cJSON_AddStringToObject(com, "source", source);
        cJSON_AddNumberToObject(com, "ratio", r.completeness);
        json_dist(com, &r.completeness_dist);
        cJSON_AddNumberToObject(o, "seconds", r.seconds);
        cJSON_AddNumberToObject(o, "threads", bf_thread_count());
        return (s = app_json_print(o)) == BF_OK ? APP_EXIT_OK : app_fail(cmd, s);
    }
    printf("reference %s: %u vertices, %u triangles\n", ref_path, ref_v, ref_t);
    if (dp.seq)
        printf("reconstruction: the depth of %s, %u frames (every %u-th, every %u-th pixel) at %s poses: %u samples\n",
               dp.seq, depth_frames, dp.every, dp.pixel_step, dp.poses, rec_v);
    else printf("reconstruction %s: %u vertices, %u triangles\n", rec_path, rec_v, rec_t);
    printf("accuracy: %zu reconstruction points (%zu vertices + %zu area samples) to the reference\n",
           r.n_rec_vertices + r.n_rec_samples, r.n_rec_vertices, r.n_rec_samples);
    print_dist_text(&r.accuracy);
    printf("  within %g m: %.2f%%\n", cfg.threshold_m, 100 * r.precision);
    printf("completeness: %.2f%% of %zu reference %s within %g m of the reconstruction\n", 100 * r.completeness,
           r.n_ref_points, r.used_visible ? "points (visibility mask)" : r.used_ref_vertices ? "vertices" : "area samples",
           cfg.threshold_m);
    print_dist_text(&r.completeness_dist);
    printf("time %.2f s on %d threads\n", r.seconds, bf_thread_count());
    return APP_EXIT_OK;
}
