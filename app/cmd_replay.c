/* bitfuse replay and bitfuse live: the full reconstruction loop (track,
 * fuse, ray-cast, smooth) on a recorded sequence or a live device; writes
 * the estimated trajectory, the map's mesh and points, per-frame tracking
 * records and stats.json. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"
#include "eval/eval.h"
#include "recon/recon.h"
#include "replay/replay.h"

static const char replay_help[] =
    "usage: bitfuse replay SEQUENCE --out DIR [options]\n"
    "\n"
    "Runs the full loop on every frame of SEQUENCE (DESIGN.md section 1): ICP against the\n"
    "ROF-smoothed ray-cast of the map, fusion at the pose found, ray-cast at that pose.\n"
    "Frames without depth are skipped; frames tracked badly are not fused and keep the\n"
    "last good pose. Writes into DIR:\n"
    "  trajectory.txt  TUM format, one line per input frame at its depth timestamp\n"
    "                  (camera to world, like groundtruth.txt)\n"
    "  frames.csv      per frame: state, ICP outcome, inliers, residual, times\n"
    "  mesh.ply        triangle mesh of the confident surface (binary PLY)\n"
    "  points.ply      surface voxel centres with normals\n"
    "  stats.json      time per frame and per stage, tracking counts, ATE when the\n"
    "                  sequence has ground truth, map memory\n"
    "  views/N.png     shaded ray-cast views, with --view-every\n"
    "\n"
    "options:\n"
    "  --out DIR          output folder (created)\n"
    "  --init P           first pose: 'groundtruth' (the first frame's, when it has one;\n"
    "                     the default) or 'identity'\n"
    "  --ratio R          voxel-to-pixel ratio of the level rule, default 2 (fuse: 1)\n"
    "  --window N         frames per fusion window (even), default 40\n"
    "  --subcache N       frames of the new-brick pass, default 10\n"
    "  --bricks N         brick pool size, default 1048576\n"
    "  --chunk M          chunk edge in metres, default 2\n"
    "  --max-level L      finest octree level, default 8\n"
    "  --icp-iters A,B,C  ICP iterations per pyramid level, finest first, default 5,5,4\n"
    "  --huber K          ICP Huber threshold in units of the sensor noise sigma_z(z),\n"
    "                     default 2 (0: plain least squares)\n"
    "  --noise-weights on|off  weight ICP residuals by 1 / sigma_z(z)^2, default on\n"
    "  --ref-level L      resolution of the tracking reference's ray-cast: 0 full, 1 half\n"
    "                     (default from tracking)\n"
    "  --ray-start frame|near  the reference's rays start just in front of the tracked\n"
    "                     frame's depth (default) or at the near plane\n"
    "  --rof-iters N      ROF iterations on the reference, default from tracking (0: off)\n"
    "  --angle-gate DEG   ICP normal-angle gate, default from tracking (45)\n"
    "  --degenerate-ratio R  eigenvalue ratio below which the ICP system counts as degenerate\n"
    "  --rof-lambda L     ROF data weight at 1 m\n"
    "  --view-every K     write a shaded view every K frames\n"
    "  --no-mesh          skip the mesh (points and stats only)\n"
    "  --fuse-at-groundtruth  track every frame but fuse it at its true pose: the map is\n"
    "                     the one the sensor gives and the trajectory's error is the\n"
    "                     tracker's own, one frame at a time (needs ground truth)\n"
    "%s"
    "\n"
    "exit codes: 0 ok (tracking failures are reported, not fatal), 1 failure, 2 usage,\n"
    "3 bad input, 4 no Vulkan device\n";

static const char live_help[] =
    "usage: bitfuse live --device URI --out DIR [options]\n"
    "\n"
    "Runs the full loop (as bitfuse replay) on a live camera: a capture thread reads the\n"
    "device into a bounded queue and drops the oldest frame when the loop falls behind\n"
    "(counted in stats.json). Ctrl-C ends the scan: the map is flushed and everything is\n"
    "written as after a replay. Writes the files of bitfuse replay into DIR.\n"
    "\n"
    "options:\n"
    "  --device URI       freenect:N, openni2:[URI|FILE.oni], v4l2:/dev/videoN (docs/devices.md),\n"
    "                     or a recorded sequence standing in for a camera\n"
    "  --realtime         play a recorded sequence at its own frame rate, as a camera would\n"
    "  --queue N          capture queue length in frames, default 8\n"
    "  --record FILE      also record the frames the loop consumed into a bitfuse log\n"
    "  and every option of bitfuse replay (--ratio, --window, --icp-iters, --view-every, ...)\n"
    "\n"
    "exit codes: 0 ok (also when stopped by Ctrl-C), 1 failure, 2 usage, 3 bad input or a\n"
    "device error mid-scan (what was reconstructed is still written), 4 no device\n";

typedef struct replay_args {
    const char *seq, *out;   /* seq: the sequence, or the device URI (live) */
    bool is_live_cmd, realtime;
    uint32_t queue;
    const char *record_path; /* live: also record into this log */
    bool init_identity;
    replay_options ropt;
    recon_config rcfg;
    uint32_t view_every;
    bool no_mesh;
    bool fuse_at_gt;         /* fuse at the frames' true poses: the tracker's one-step error */
} replay_args;

static bool parse_iters(const char *v, uint32_t it[TRACK_MAX_LEVELS], uint32_t *levels)
{
    uint32_t n = 0;
    const char *p = v;
    while (*p && n < TRACK_MAX_LEVELS) {
        char *end;
        unsigned long x = strtoul(p, &end, 10);
        if (end == p || x > 1000) return false;
        it[n++] = (uint32_t)x;
        if (*end == ',') end++;
        else if (*end) return false;
        p = end;
    }
    if (*p || n == 0) return false;
    *levels = n;
    return true;
}

static int parse_args(const char *cmd, bool is_live_cmd, int argc, char **argv, replay_args *a)
{
    memset(a, 0, sizeof *a);
    a->is_live_cmd = is_live_cmd;
    a->queue = 8;
    a->rcfg = recon_config_default();
    for (int i = 1; i < argc; i++) {
        int r = replay_parse_option(argc, argv, &i, &a->ropt);
        if (r < 0) return app_usage_error(cmd, "%s", bf_last_error());
        if (r > 0) { /* it moved i past the option: the loop's i++ must not skip one more */
            i--;
            continue;
        }
        const char *o = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        double d;
        uint32_t u;
        fusion_config *fc = &a->rcfg.fusion;
        track_config *tc = &a->rcfg.track;
        if (app_is_help(o)) {
            if (is_live_cmd) fputs(live_help, stdout);
            else printf(replay_help, replay_options_help());
            return -1;
        } else if (!strcmp(o, "--no-mesh")) {
            a->no_mesh = true;
        } else if (!is_live_cmd && !strcmp(o, "--fuse-at-groundtruth")) {
            a->fuse_at_gt = true;
        } else if (is_live_cmd && !strcmp(o, "--realtime")) {
            a->realtime = true;
        } else if (is_live_cmd && !strcmp(o, "--device") && v) {
            a->seq = v, i++;
        } else if (is_live_cmd && !strcmp(o, "--queue") && v && bf_parse_u32(v, &u) && u > 0) {
            a->queue = u, i++;
        } else if (is_live_cmd && !strcmp(o, "--record") && v) {
            if (!replay_is_log_path(v)) return app_usage_error(cmd, "--record must name a .bflog file, not '%s'", v);
            a->record_path = v, i++;
        } else if (!is_live_cmd && o[0] != '-') {
            if (a->seq) return app_usage_error(cmd, "more than one sequence: %s", o);
            a->seq = o;
        } else if (!v) {
            return app_usage_error(cmd, "%s needs a value", o);
        } else if (app_parse_map_option(o, v, fc)) {
            i++;
        } else if (!strcmp(o, "--out")) {
            a->out = v, i++;
        } else if (!strcmp(o, "--init") && (!strcmp(v, "groundtruth") || !strcmp(v, "identity"))) {
            a->init_identity = !strcmp(v, "identity"), i++;
        } else if (!strcmp(o, "--icp-iters") && parse_iters(v, tc->iterations, &tc->levels)) {
            i++;
        } else if (!strcmp(o, "--degenerate-ratio") && bf_parse_double(v, &d) && d >= 0) {
            tc->degenerate_ratio = d, i++;
        } else if (!strcmp(o, "--angle-gate") && bf_parse_double(v, &d) && d > 0 && d < 90) {
            tc->angle_deg = (float)d, i++;
        } else if (!strcmp(o, "--huber") && bf_parse_double(v, &d) && d >= 0) {
            tc->huber_k = (float)d, i++;
        } else if (!strcmp(o, "--noise-weights") && (!strcmp(v, "on") || !strcmp(v, "off"))) {
            tc->weight_noise = !strcmp(v, "on"), i++;
        } else if (!strcmp(o, "--ray-start") && (!strcmp(v, "frame") || !strcmp(v, "near"))) {
            a->rcfg.start_at_frame = !strcmp(v, "frame"), i++;
        } else if (!strcmp(o, "--ref-level") && bf_parse_u32(v, &u) && u <= 1) {
            tc->ref_level = u, i++;
        } else if (!strcmp(o, "--rof-iters") && bf_parse_u32(v, &u)) {
            tc->rof_iterations = u, i++;
        } else if (!strcmp(o, "--rof-lambda") && bf_parse_double(v, &d) && d > 0) {
            tc->rof_lambda0 = (float)d, i++;
        } else if (!strcmp(o, "--view-every") && bf_parse_u32(v, &u) && u > 0) {
            a->view_every = u, i++;
        } else {
            return app_usage_error(cmd, "unknown option or bad value: %s %s", o, v);
        }
    }
    if (!a->seq) return app_usage_error(cmd, is_live_cmd ? "--device is required" : "no sequence given");
    if (!a->out) return app_usage_error(cmd, "--out is required");
    return 0;
}

typedef struct replay_result {
    recon_run run;
    app_map_report out;
    bool has_ate;
    eval_ate_result ate;
    uint32_t n_views;
    double seconds;
    char device[256];
    bool has_capture;          /* live: the capture thread's counts */
    capture_thread_stats cap;
    uint32_t n_recorded;
} replay_result;

typedef struct replay_report {
    const replay_args *a;
    const replay_result *r;
} replay_report;

static void json_series(FILE *f, const char *name, const bf_stats *s, const char *tail)
{
    fprintf(f, "\"%s\": {\"median\": ", name);
    bf_json_number(f, bf_stats_percentile(s, 50), 5);
    fprintf(f, ", \"p95\": ");
    bf_json_number(f, bf_stats_percentile(s, 95), 5);
    fprintf(f, ", \"mean\": ");
    bf_json_number(f, bf_stats_mean(s), 5);
    fprintf(f, "}%s", tail);
}

static void write_stats_json(FILE *f, const void *arg)
{
    const replay_report *rep = arg;
    const replay_args *a = rep->a;
    const replay_result *r = rep->r;
    const recon_run_series *t = &r->run.series;
    const fusion_config *fc = &a->rcfg.fusion;
    const track_config *tc = &a->rcfg.track;
    fprintf(f, "{\n  \"command\": \"%s\",\n  \"%s\": ", a->is_live_cmd ? "live" : "replay",
            a->is_live_cmd ? "source" : "sequence");
    bf_json_string(f, a->seq);
    fprintf(f, ",\n  \"device\": ");
    bf_json_string(f, r->device);
    fprintf(f, ",\n  \"config\": {\"voxel_ratio\": %g, \"window\": %u, \"subcache\": %u, \"chunk_m\": %g, "
               "\"max_level\": %u, \"brick_cap\": %u, \"icp_iterations\": [",
            fc->voxel_ratio, fc->window, fc->subcache, fc->chunk_m, fc->max_level, fc->brick_cap);
    for (uint32_t l = 0; l < tc->levels; l++) fprintf(f, "%s%u", l ? ", " : "", tc->iterations[l]);
    fprintf(f, "], \"rof_iterations\": %u, \"rof_lambda0\": %g},\n", tc->rof_iterations, tc->rof_lambda0);
    const recon_counts *c = &r->run.counts;
    fprintf(f, "  \"frames\": %u,\n  \"tracking\": {\"tracked\": %u, \"lost\": %u, \"no_depth\": %u, "
               "\"degenerate\": %u, \"pool_full\": %u, ",
            c->frames, c->tracked, c->lost, c->no_depth, c->degenerate, c->pool_full);
    json_series(f, "inlier_fraction", &t->inlier_frac, ", ");
    json_series(f, "residual_mm", &t->residual_mm, "},\n");
    fprintf(f, "  \"ate_m\": ");
    if (r->has_ate) {
        fprintf(f, "{\"rmse\": ");
        bf_json_number(f, r->ate.trans.rmse, 6);
        fprintf(f, ", \"mean\": ");
        bf_json_number(f, r->ate.trans.mean, 6);
        fprintf(f, ", \"median\": ");
        bf_json_number(f, r->ate.trans.median, 6);
        fprintf(f, ", \"max\": ");
        bf_json_number(f, r->ate.trans.max, 6);
        fprintf(f, ", \"pairs\": %zu},\n", r->ate.n_matched);
    } else {
        fprintf(f, "null,\n");
    }
    fprintf(f, "  ");
    json_series(f, "frame_ms", &t->frame_ms, ",\n");
    fprintf(f, "  \"gpu_stage_ms\": {");
    json_series(f, "track", &t->track_ms, ", ");
    json_series(f, "rof", &t->rof_ms, ", ");
    json_series(f, "raycast", &t->raycast_ms, ", ");
    json_series(f, "upload", &t->upload_ms, ", ");
    json_series(f, "alloc", &t->alloc_ms, ", ");
    json_series(f, "subcache", &t->subcache_ms, ", ");
    json_series(f, "window", &t->window_ms, "},\n");
    if (r->has_capture)
        fprintf(f, "  \"capture\": {\"captured\": %llu, \"delivered\": %llu, \"dropped\": %llu, "
                   "\"interrupted\": %s, \"recorded\": %u},\n",
                (unsigned long long)r->cap.captured, (unsigned long long)r->cap.delivered,
                (unsigned long long)r->cap.dropped, r->run.is_interrupted ? "true" : "false", r->n_recorded);
    app_json_map(f, &r->out, fc->max_level);
    fprintf(f, "  \"views\": %u,\n  \"seconds\": %.3f\n}\n", r->n_views, r->seconds);
}

static bf_status write_view(recon *rc, const char *out_dir, uint32_t index, const bf_se3 *T_wc)
{
    char dir[4096], name[64], path[4096];
    render_images im = {0};
    bf_status s = bf_path_join(dir, sizeof dir, out_dir, "views");
    if (s == BF_OK) s = bf_mkdir_p(dir);
    if (s == BF_OK) s = recon_render_view(rc, T_wc);
    if (s == BF_OK) s = render_download(recon_caster(rc), &im);
    snprintf(name, sizeof name, "%06u.png", index);
    if (s == BF_OK) s = bf_path_join(path, sizeof path, dir, name);
    if (s == BF_OK) s = replay_png_write_rgb8(path, im.rgb, im.width, im.height);
    render_images_free(&im);
    return s;
}

static void csv_frame(FILE *csv, const bf_frame *f, const recon_frame_result *fr)
{
    bool ran = fr->state == RECON_TRACKED || fr->state == RECON_LOST;
    fprintf(csv, "%u,%.6f,%s,%s,%d,%u,%u,%.4f,%.3f,%.3g,%.3f,%.3f,%.3f,%.3f\n", f->index, f->t_depth_s,
            recon_state_name(fr->state), ran ? track_outcome_name(fr->track.outcome) : "",
            ran ? (int)fr->track.degenerate : 0, fr->n_valid, ran ? fr->track.n_inliers : 0,
            ran ? fr->track.inlier_frac : 0.0, ran ? 1e3 * fr->track.residual_m : 0.0,
            ran ? fr->track.eig_min / (fr->track.eig_max > 0 ? fr->track.eig_max : 1) : 0.0, fr->ms_frame,
            fr->ms_track, fr->ms_raycast, fr->fuse.alloc + fr->fuse.subcache + fr->fuse.window);
}

/* What the replay writes per frame beside the runner's own records. */
typedef struct replay_sink {
    const replay_args *a;
    FILE *csv;
    replay_log_writer *log; /* live --record, else NULL */
    replay_result *r;
} replay_sink;

static bf_status on_frame(void *user, recon_run *run, const bf_frame *f, const recon_frame_result *fr)
{
    replay_sink *k = user;
    bf_status s = BF_OK;
    csv_frame(k->csv, f, fr);
    if (k->log && (s = replay_log_writer_add(k->log, f)) == BF_OK) k->r->n_recorded++;
    if (s == BF_OK && k->a->view_every && run->map && f->index % k->a->view_every == 0 &&
        (s = write_view(run->loop, k->a->out, f->index, &fr->T_wc)) == BF_OK)
        k->r->n_views++;
    return s;
}

static void print_summary(const replay_args *a, const replay_result *r)
{
    const recon_counts *c = &r->run.counts;
    const recon_run_series *t = &r->run.series;
    printf("bitfuse %s: %u frames on %s: %u tracked, %u lost, %u without depth (%u degenerate)\n",
           a->is_live_cmd ? "live" : "replay", c->frames, r->device, c->tracked, c->lost, c->no_depth, c->degenerate);
    if (r->has_capture)
        printf("  capture          %llu captured, %llu dropped by the queue of %u%s\n",
               (unsigned long long)r->cap.captured, (unsigned long long)r->cap.dropped, a->queue,
               r->run.is_interrupted ? " (stopped by a signal)" : "");
    printf("  time per frame   median %.1f ms, p95 %.1f ms (GPU median: track %.1f, ROF %.1f, ray-cast %.1f,\n"
           "                   alloc %.1f, sub-cache %.1f, window %.1f ms)\n",
           bf_stats_percentile(&t->frame_ms, 50), bf_stats_percentile(&t->frame_ms, 95),
           bf_stats_percentile(&t->track_ms, 50), bf_stats_percentile(&t->rof_ms, 50),
           bf_stats_percentile(&t->raycast_ms, 50), bf_stats_percentile(&t->alloc_ms, 50),
           bf_stats_percentile(&t->subcache_ms, 50), bf_stats_percentile(&t->window_ms, 50));
    if (r->has_ate)
        printf("  trajectory       ATE RMSE %.4f m (median %.4f, max %.4f) over %zu poses\n", r->ate.trans.rmse,
               r->ate.trans.median, r->ate.trans.max, r->ate.n_matched);
    else
        printf("  trajectory       no ground truth: ATE not computed\n");
    app_print_map(&r->out, a->rcfg.fusion.max_level);
    printf("  wrote            %s/{trajectory.txt,frames.csv,%spoints.ply,stats.json} in %.1f s\n", a->out,
           a->no_mesh ? "" : "mesh.ply,", r->seconds);
}

int app_reconstruct(const char *cmd, int argc, char **argv, bool is_live_cmd)
{
    replay_args a;
    int rc_args = parse_args(cmd, is_live_cmd, argc, argv, &a);
    if (rc_args) return rc_args < 0 ? APP_EXIT_OK : rc_args;
    double t_start = bf_time_s();
    replay_result r;
    memset(&r, 0, sizeof r);
    rgbd_source *src = NULL;
    gpu_context *ctx = NULL;
    replay_log_writer *log = NULL;
    FILE *csv = NULL;
    char path[4096];
    const volatile sig_atomic_t *stop = NULL;
    bf_status s = bf_mkdir_p(a.out);
    if (s == BF_OK && is_live_cmd) {
        bool is_live;
        s = app_open_device(a.seq, &a.ropt, a.realtime, a.queue, &is_live, &src);
        r.has_capture = s == BF_OK;
        /* Ctrl-C ends the scan, not the program: what was seen is kept. */
        if (s == BF_OK) stop = app_stop_begin(src);
    } else if (s == BF_OK) {
        s = replay_open(a.seq, &a.ropt, &src);
    }
    if (s == BF_OK && a.record_path) {
        replay_log_config lc = {.colour = REPLAY_LOG_COLOUR_JPEG, .device = a.seq,
                                .has_groundtruth = src->has_groundtruth};
        s = replay_log_writer_create(a.record_path, rgbd_source_intrinsics(src), &lc, &log);
    }
    if (s == BF_OK && (s = bf_path_join(path, sizeof path, a.out, "frames.csv")) == BF_OK && !(csv = fopen(path, "w")))
        s = bf_fail(BF_IO, "%s: cannot create", path);
    if (csv)
        fprintf(csv, "index,t_depth_s,state,icp,degenerate,valid,inliers,inlier_frac,residual_mm,eig_ratio,"
                     "frame_ms,track_ms,raycast_ms,fuse_ms\n");
    gpu_config gcfg = {0};
    if (s == BF_OK) s = gpu_context_create(&gcfg, &ctx);
    if (s == BF_OK) snprintf(r.device, sizeof r.device, "%s", gpu_device_name(ctx));
    if (s == BF_OK) {
        recon_run_config rcfg = {
            .loop = a.rcfg, .poses = a.fuse_at_gt ? RECON_POSES_TRACK_FUSE_GT : RECON_POSES_TRACK,
            .init_identity = a.init_identity, .keep_on_source_error = is_live_cmd, .name = a.seq,
            .label = cmd, .stop = stop,
        };
        replay_sink sink = {&a, csv, log, &r};
        s = recon_run_sequence(ctx, src, &rcfg, on_frame, &sink, &r.run);
    }
    if (r.has_capture) {
        r.cap = capture_threaded_stats(src);
        app_stop_end();
    }
    if (log) {
        bf_status s_log = replay_log_writer_finish(log);
        if (s == BF_OK) s = s_log;
    }
    /* The trajectory first: it is what a crashed export must not lose. */
    if (s == BF_OK && (s = bf_path_join(path, sizeof path, a.out, "trajectory.txt")) == BF_OK)
        s = replay_traj_write_tum(path, &r.run.est);
    if (s == BF_OK && r.run.gt.n >= 2 && eval_ate(&r.run.gt, &r.run.est, 0, &r.ate) == BF_OK) r.has_ate = true;
    if (s == BF_OK) s = app_export_map(r.run.map, a.out, !a.no_mesh, &r.out);
    r.seconds = bf_time_s() - t_start;
    replay_report rep = {&a, &r};
    if (s == BF_OK) s = app_write_json(a.out, "stats.json", write_stats_json, &rep);
    if (csv && fclose(csv) != 0 && s == BF_OK) s = bf_fail(BF_IO, "%s/frames.csv: write failed", a.out);
    if (s == BF_OK) print_summary(&a, &r);
    bf_status s_dev = r.run.source_status;
    if (s == BF_OK && s_dev != BF_OK) bf_fail(s_dev, "%s", r.run.source_error);
    replay_log_writer_destroy(log);
    recon_run_free(&r.run);
    gpu_context_destroy(ctx);
    rgbd_source_close(src);
    if (s == BF_OK && s_dev != BF_OK) return app_fail(cmd, s_dev);
    return s == BF_OK ? APP_EXIT_OK : app_fail(cmd, s);
}

int cmd_replay(int argc, char **argv) { return app_reconstruct("replay", argc, argv, false); }
