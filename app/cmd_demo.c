/* bitfuse demo: the main job on built-in data. It renders a short synthetic
 * room sequence along a built-in hand-held trajectory, reads it back through
 * the replay path, and evaluates it: the raw sensor points (ground-truth
 * poses) against the reference surface, then the full loop (ICP tracking
 * against the ray-cast map, fusion, ray-cast, ROF smoothing) started at the
 * first true pose: its trajectory against the truth (ATE), its surface
 * against the reference, time per frame and map memory. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "app.h"
#include "eval/eval.h"
#include "mesh/mesh.h"
#include "synth/synth.h"
#include "fusion/fusion.h"
#include "recon/recon.h"
#include "gpu/gpu.h"
#include "replay/replay.h"
#include "export/export.h"

static const char demo_usage[] =
    "usage: bitfuse demo [--out DIR] [--frames N] [--seed S] [--data DIR] [--no-gpu]\n"
    "\n"
    "Renders a synthetic room (Kinect v1 noise) along a built-in hand-held trajectory,\n"
    "replays it, and reports how far the raw depth lies from the true surface and how\n"
    "much of the seen surface it covers; then runs the full loop on the GPU (tracks the\n"
    "camera by ICP against the map and fuses the frames into the sign-bit map) and reports\n"
    "the trajectory error (ATE), the fused surface's error, the time per frame and the\n"
    "map's memory. Writes into DIR:\n"
    "  seq/            the TUM-format sequence (bitfuse synth output)\n"
    "  trajectory_input.txt  the built-in trajectory\n"
    "  raw_points.ply  back-projected depth with ground-truth poses\n"
    "  trajectory.txt  the tracked trajectory (TUM format)\n"
    "  points.ply      surface voxels of the map\n"
    "  stats.json      everything printed, machine-readable, and the loop's config\n";

/* A hand-held sweep in the first camera's frame (x right, y down, z forward),
 * sampled at 100 Hz like a motion-capture log: sideways sway of +-0.3 m, a
 * little bob and push, yaw +-12 and pitch +-4 degrees. The first pose is the
 * identity, so `synth` places it at the room's viewpoint. */
static bf_status demo_trajectory(double seconds, bf_traj *out)
{
    bf_traj traj = {0};
    const double t0 = 1000.0;
    for (int k = 0; k <= (int)(seconds * 100); k++) {
        double t = k / 100.0, w = 2 * M_PI * t / seconds;
        bf_vec3 p = bf_v3(0.3 * sin(w), 0.03 * sin(3 * w), 0.1 * (1 - cos(w)));
        bf_quat yaw = bf_quat_from_axis_angle(bf_v3(0, 1, 0), -0.21 * sin(w));
        bf_quat pitch = bf_quat_from_axis_angle(bf_v3(1, 0, 0), 0.07 * sin(2 * w));
        bf_se3 T = bf_se3_from_qt(bf_quat_mul(yaw, pitch), p);
        bf_status s = bf_traj_push(&traj, t0 + t, &T);
        if (s != BF_OK) {
            bf_traj_free(&traj);
            return s;
        }
    }
    *out = traj;
    return BF_OK;
}

/* Back-projects every step-th pixel of every frame_step-th frame with its
 * ground-truth pose into a coloured point cloud (world frame). */
static bf_status demo_raw_points(const char *seq_dir, uint32_t frame_step, uint32_t step, mesh_data *out,
                                 uint32_t *n_frames)
{
    rgbd_source *src;
    bf_status s = replay_open(seq_dir, NULL, &src);
    if (s != BF_OK) return s;
    const bf_intrinsics *K = rgbd_source_intrinsics(src);
    mesh_data pts = {0};
    size_t cap = 0;
    bf_frame f;
    uint32_t n = 0;
    while ((s = rgbd_source_next(src, &f)) == BF_OK) {
        n++;
        if (f.index % frame_step || !f.has_pose) continue;
        for (uint32_t v = 0; v < f.height; v += step)
            for (uint32_t u = 0; u < f.width; u += step) {
                uint16_t d = f.depth[v * f.width + u];
                if (!d) continue;
                if (pts.n_verts == cap) {
                    cap = cap ? 2 * cap : 1 << 16;
                    float *xyz = realloc(pts.xyz, cap * 3 * sizeof *xyz);
                    uint8_t *rgb = xyz ? realloc(pts.rgb, cap * 3) : NULL;
                    if (xyz) pts.xyz = xyz;
                    if (rgb) pts.rgb = rgb;
                    if (!xyz || !rgb) {
                        s = bf_fail(BF_NO_MEMORY, "demo: %zu points do not fit in memory", cap);
                        goto done;
                    }
                }
                bf_vec3 p = bf_se3_apply(&f.T_wc, bf_intrinsics_unproject(K, u, v, d / K->depth_scale));
                float *x = pts.xyz + 3 * (size_t)pts.n_verts;
                x[0] = (float)p.x, x[1] = (float)p.y, x[2] = (float)p.z;
                uint8_t *c = pts.rgb + 3 * (size_t)pts.n_verts;
                if (f.rgb)
                    memcpy(c, f.rgb + 3 * ((size_t)v * f.width + u), 3);
                else
                    c[0] = c[1] = c[2] = 128;
                pts.n_verts++;
            }
    }
    if (s == BF_END) s = BF_OK;
done:
    rgbd_source_close(src);
    if (s != BF_OK) {
        mesh_free(&pts);
        return s;
    }
    *out = pts;
    *n_frames = n;
    return BF_OK;
}

typedef struct demo_report {
    char device[256];
    char device_driver[256]; /* the driver's own words, e.g. Mesa's version */
    synth_result synth;
    uint32_t n_replayed;
    uint32_t n_points;
    eval_surface_result surf;
    eval_ate_result ate;
    /* The full loop (when a Vulkan device is there). */
    bool fused;
    recon_counts counts;
    eval_ate_result track_ate;
    double fuse_ms_median, fuse_ms_p95;
    fusion_stats map;
    uint64_t n_surface_points;
    eval_surface_result fused_surf;
    recon_config config; /* the loop's, echoed in stats.json */
    double seconds;
} demo_report;

/* Distances are null when nothing was measured (JSON has no NaN). */
static cJSON *demo_json(const demo_report *r)
{
    cJSON *o = app_json_stats("demo");
    cJSON_AddStringToObject(o, "device", r->device);
    cJSON_AddStringToObject(o, "device_driver", r->device_driver);
    cJSON_AddNumberToObject(o, "frames", r->synth.n_frames);
    cJSON_AddNumberToObject(o, "render_ms_per_frame_median", 1e3 * r->synth.median_frame_s);
    cJSON_AddNumberToObject(o, "valid_depth_share", r->synth.valid_share);
    cJSON_AddNumberToObject(o, "frames_replayed", r->n_replayed);
    cJSON_AddNumberToObject(o, "raw_points", r->n_points);
    cJSON *acc = app_json_object(o, "raw_accuracy_m");
    cJSON_AddNumberToObject(acc, "mean", r->surf.accuracy.mean);
    cJSON_AddNumberToObject(acc, "median", r->surf.accuracy.median);
    cJSON_AddNumberToObject(acc, "p90", r->surf.accuracy.p90);
    cJSON_AddNumberToObject(acc, "rmse", r->surf.accuracy.rmse);
    cJSON *seen = app_json_object(o, "seen_completeness");
    cJSON_AddNumberToObject(seen, "threshold_m", 0.01);
    cJSON_AddNumberToObject(seen, "share", r->surf.completeness);
    cJSON_AddNumberToObject(seen, "median_m", r->surf.completeness_dist.median);
    cJSON *check = app_json_object(o, "trajectory_check");
    cJSON_AddNumberToObject(check, "pairs", (double)r->ate.n_matched);
    cJSON_AddNumberToObject(check, "ate_rmse_m", r->ate.trans.rmse);
    if (r->fused) {
        cJSON *rec = app_json_object(o, "reconstruction");
        cJSON_AddNumberToObject(rec, "tracked", r->counts.tracked);
        cJSON_AddNumberToObject(rec, "lost", r->counts.lost);
        cJSON_AddNumberToObject(rec, "ate_rmse_m", r->track_ate.trans.rmse);
        cJSON_AddNumberToObject(rec, "frame_ms_median", r->fuse_ms_median);
        cJSON_AddNumberToObject(rec, "frame_ms_p95", r->fuse_ms_p95);
        cJSON_AddNumberToObject(rec, "map_bytes", (double)r->map.bytes_total);
        cJSON_AddNumberToObject(rec, "bricks", r->map.n_bricks);
        cJSON_AddNumberToObject(rec, "surface_points", (double)r->n_surface_points);
        cJSON_AddNumberToObject(rec, "accuracy_median_m", r->fused_surf.accuracy.median);
        cJSON_AddNumberToObject(rec, "accuracy_p90_m", r->fused_surf.accuracy.p90);
        cJSON_AddNumberToObject(rec, "completeness_1cm", r->fused_surf.completeness);
        app_json_recon_config(rec, "config", &r->config);
    }
    cJSON_AddNumberToObject(o, "seconds", r->seconds);
    return o;
}

/* The device the reconstruction uses; a missing one is reported and the
 * demo goes on without the fusion step. */
static gpu_context *demo_device(bool use_gpu, demo_report *r)
{
    snprintf(r->device, sizeof r->device, "%s", use_gpu ? "none" : "not opened (--no-gpu)");
    if (!use_gpu) return NULL;
    gpu_config gcfg = {0};
    gpu_context *ctx;
    if (gpu_context_create(&gcfg, &ctx) != BF_OK) {
        bf_warn("no Vulkan device, skipping fusion: %s", bf_last_error());
        return NULL;
    }
    snprintf(r->device, sizeof r->device, "%s", gpu_device_name(ctx));
    snprintf(r->device_driver, sizeof r->device_driver, "%s", gpu_device(ctx)->driver_info);
    return ctx;
}

/* The full loop on the sequence (track, fuse, ray-cast, smooth), started at
 * the first true pose: the estimated trajectory against the truth (ATE) and
 * the surface voxels against the reference, as the raw depth was. */
static bf_status demo_reconstruct(gpu_context *ctx, const char *seq, const char *out_dir, const mesh_data *ref,
                                  const mesh_data *seen, demo_report *r)
{
    rgbd_source *src;
    bf_status s = replay_open(seq, NULL, &src);
    if (s != BF_OK) return s;
    recon_run run;
    recon_run_config cfg = recon_run_config_default();
    r->config = cfg.loop;
    cfg.name = seq;
    cfg.label = "track+fuse";
    s = recon_run_sequence(ctx, src, &cfg, NULL, NULL, &run);
    char path[4096];
    if (s == BF_OK && (s = bf_path_join(path, sizeof path, out_dir, "trajectory.txt")) == BF_OK)
        s = replay_traj_write_tum(path, &run.est);
    if (s == BF_OK) s = eval_ate(&run.gt, &run.est, 0, &r->track_ate);
    if (s == BF_OK) r->counts = run.counts;
    hostmap snap = {0};
    mesh_data pts = {0};
    export_stats st;
    if (s == BF_OK) s = fusion_get_stats(run.map, &r->map);
    if (s == BF_OK) s = fusion_snapshot_take(run.map, &snap);
    if (s == BF_OK) s = export_points(&snap, &pts, &st);
    if (s == BF_OK && (s = bf_path_join(path, sizeof path, out_dir, "points.ply")) == BF_OK)
        s = mesh_write_ply(path, &pts);
    if (s == BF_OK) {
        eval_surface_config scfg = eval_surface_config_default();
        scfg.max_dist_m = 0.5;
        s = eval_surface(ref, &pts, seen, &scfg, &r->fused_surf);
    }
    if (s == BF_OK) {
        r->fused = true;
        r->n_surface_points = pts.n_verts;
        r->fuse_ms_median = bf_stats_percentile(&run.series.frame_ms, 50);
        r->fuse_ms_p95 = bf_stats_percentile(&run.series.frame_ms, 95);
    }
    mesh_free(&pts);
    hostmap_free(&snap);
    recon_run_free(&run);
    rgbd_source_close(src);
    return s;
}

static bf_status demo_run(gpu_context *ctx, const char *out_dir, uint32_t n_frames, uint64_t seed,
                          const char *data_dir, demo_report *r)
{
    char seq[4096], path[4096];
    bf_status s;
    if ((s = bf_mkdir_p(out_dir)) != BF_OK) return s;
    if ((s = bf_path_join(seq, sizeof seq, out_dir, "seq")) != BF_OK) return s;

    /* 1. The built-in trajectory, one extra second so every frame has a pose. */
    bf_traj traj = {0};
    if ((s = demo_trajectory(n_frames / 30.0 + 1.0, &traj)) != BF_OK) return s;
    if ((s = bf_path_join(path, sizeof path, out_dir, "trajectory_input.txt")) == BF_OK)
        s = replay_traj_write_tum(path, &traj);
    if (s != BF_OK) goto done;

    /* 2. Render the room along it. */
    synth_config cfg = {
        .scene = "room", .data_dir = data_dir, .traj_path = path, .n_frames = n_frames,
        .noise = SYNTH_NOISE_KINECT1, .seed = seed, .out_dir = seq, .version = BF_VERSION,
    };
    bf_info("rendering %u frames of the synthetic room into %s", n_frames, seq);
    if ((s = synth_run(&cfg, &r->synth)) != BF_OK) {
        /* A mesh in --data that does not read: nothing rendered, and the
         * trajectory written for it goes too (rmdir takes only an empty
         * folder: an earlier run's frames stay). */
        (void)unlink(path);
        (void)rmdir(seq);
        goto done;
    }

    /* 3. Replay it and back-project the depth with the true poses. */
    mesh_data raw = {0};
    if ((s = demo_raw_points(seq, 3, 3, &raw, &r->n_replayed)) != BF_OK) goto done;
    r->n_points = raw.n_verts;
    if ((s = bf_path_join(path, sizeof path, out_dir, "raw_points.ply")) == BF_OK)
        s = mesh_write_ply(path, &raw);

    /* 4. Raw depth against the reference surface the camera saw. */
    mesh_data ref = {0}, seen = {0};
    if (s == BF_OK && (s = bf_path_join(path, sizeof path, seq, "scene.ply")) == BF_OK)
        s = mesh_read_ply(path, &ref);
    if (s == BF_OK && (s = bf_path_join(path, sizeof path, seq, "seen.ply")) == BF_OK)
        s = mesh_read_ply(path, &seen);
    if (s == BF_OK) {
        eval_surface_config scfg = eval_surface_config_default();
        scfg.max_dist_m = 0.5;
        s = eval_surface(&ref, &raw, &seen, &scfg, &r->surf);
    }
    /* 6. The full loop: tracked trajectory and fused surface against the truth. */
    if (s == BF_OK && ctx) s = demo_reconstruct(ctx, seq, out_dir, &ref, &seen, r);
    mesh_free(&raw);
    mesh_free(&ref);
    mesh_free(&seen);

    /* 5. The rendered ground truth against the trajectory it followed, sampled
     *    at the frame times: Horn's alignment must recover the placement
     *    exactly (the residual is file rounding, micrometres). */
    if (s == BF_OK) {
        bf_traj gt = {0}, followed = {0};
        if ((s = bf_path_join(path, sizeof path, seq, "groundtruth.txt")) == BF_OK &&
            (s = replay_traj_read_tum(path, &gt)) == BF_OK)
            for (size_t i = 0; i < gt.n && s == BF_OK; i++) {
                bf_se3 T;
                if (bf_traj_interpolate(&traj, gt.t_s[i], &T)) s = bf_traj_push(&followed, gt.t_s[i], &T);
            }
        if (s == BF_OK) s = eval_ate(&gt, &followed, 0.02, &r->ate);
        bf_traj_free(&gt);
        bf_traj_free(&followed);
    }
done:
    bf_traj_free(&traj);
    return s;
}

int cmd_demo(int argc, char **argv)
{
    const char *cmd = "demo", *out_dir = "out/demo", *data_dir = NULL;
    uint32_t n_frames = 60, seed = 1;
    bool no_gpu = false;
    const app_option own[] = {
        APP_OPT("--out", APP_OPT_STRING, &out_dir, "DIR", "output folder"),
        APP_OPT("--frames", APP_OPT_U32, &n_frames, "N", "frames to render (2 s at 30 Hz)", .min = 2, .max = 3000),
        APP_OPT("--seed", APP_OPT_U32, &seed, "S", "noise seed"),
        APP_OPT("--data", APP_OPT_STRING, &data_dir, "DIR",
                "shared data (meshes for the room), default ../shared/data"),
        APP_OPT("--no-gpu", APP_OPT_FLAG, &no_gpu, NULL, "skip the GPU reconstruction"),
        APP_OPT_END,
    };
    const app_option *tables[] = {own, NULL};
    app_command_spec spec = {.name = cmd, .usage = demo_usage, .tables = tables,
                             .epilog = "exit codes: 0 ok (with no Vulkan device the reconstruction is skipped and said "
                                       "so), 1 failure,\n2 usage, 3 --data missing or a mesh in it unreadable, 5 an output could not "
                                       "be written\n"};
    int rc = app_options_parse(&spec, argc, argv);
    if (rc) return rc < 0 ? APP_EXIT_OK : rc;
    /* A missing input is bad input (exit 3), as in every command. */
    if (data_dir && !bf_file_exists(data_dir))
        return app_fail(cmd, bf_fail(BF_IO, "--data: folder '%s' does not exist", data_dir));
    /* Not over an earlier demo: its frames past this run's count and its
     * reconstruction would stay beside the new files (synth refuses the same). */
    if ((rc = app_check_out_not_sequence(cmd, out_dir, false)) != 0) return rc;
    static const char *const held[] = {"seq/depth.txt", "seq/depth", "stats.json"};
    for (size_t i = 0; i < sizeof held / sizeof *held; i++) {
        char p[4200];
        if (snprintf(p, sizeof p, "%s/%s", out_dir, held[i]) < (int)sizeof p && bf_file_exists(p))
            return app_usage_error(cmd, "--out %s holds an earlier run (%s): give a new folder, or remove it first",
                                   out_dir, held[i]);
    }
    bool use_gpu = !no_gpu;
    if (!data_dir) data_dir = app_default_data_dir();

    bool made_out = !bf_file_exists(out_dir);
    demo_report r;
    memset(&r, 0, sizeof r);
    double t0 = bf_time_s();
    gpu_context *ctx = demo_device(use_gpu, &r);
    bf_status s = demo_run(ctx, out_dir, n_frames, seed, data_dir, &r);
    gpu_context_destroy(ctx);
    if (s != BF_OK && made_out) (void)rmdir(out_dir); /* only if it is empty */
    if (s != BF_OK) return app_fail(cmd, s);
    r.seconds = bf_time_s() - t0;

    if ((s = app_json_write_in(out_dir, "stats.json", demo_json(&r))) != BF_OK) return app_fail(cmd, s);

    printf("bitfuse demo: synthetic room, %u frames, Kinect v1 noise (seed %u)\n", r.synth.n_frames, seed);
    printf("  device                 %s\n", r.device);
    printf("  render                 %.0f ms/frame median, %.1f%% pixels with depth\n",
           1e3 * r.synth.median_frame_s, 100 * r.synth.valid_share);
    printf("  replayed               %u frames, %u raw points (every 3rd pixel of every 3rd frame)\n",
           r.n_replayed, r.n_points);
    printf("  raw depth vs surface   median %.1f mm, mean %.1f mm, p90 %.1f mm\n", 1e3 * r.surf.accuracy.median,
           1e3 * r.surf.accuracy.mean, 1e3 * r.surf.accuracy.p90);
    printf("  seen surface covered   %.1f%% within 1 cm\n", 100 * r.surf.completeness);
    printf("  trajectory check       ATE %.3f mm over %zu poses (placement self-check)\n", 1e3 * r.ate.trans.rmse,
           r.ate.n_matched);
    if (r.fused) {
        printf("  tracked                %u of %u frames (%u lost); ATE RMSE %.1f mm against the truth\n",
               r.counts.tracked, r.counts.frames, r.counts.lost, 1e3 * r.track_ate.trans.rmse);
        printf("  time per frame         %.0f ms median, %.0f p95 (track + fuse + ray-cast of the reference)\n",
               r.fuse_ms_median, r.fuse_ms_p95);
        printf("  map                    %.2f MiB, %u bricks\n", r.map.bytes_total / 1048576.0, r.map.n_bricks);
        printf("  fused surface voxels   median %.1f mm, p90 %.1f mm from the surface; %.1f%% of the seen "
               "surface within 1 cm of them\n",
               1e3 * r.fused_surf.accuracy.median, 1e3 * r.fused_surf.accuracy.p90, 100 * r.fused_surf.completeness);
    }
    printf("  wrote                  %s/{seq/,raw_points.ply,%sstats.json} in %.1f s\n", out_dir,
           r.fused ? "trajectory.txt,points.ply," : "", r.seconds);
    return APP_EXIT_OK;
}
