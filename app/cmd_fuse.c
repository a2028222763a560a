/* bitfuse fuse: fuse a sequence into the sign-bit map with known camera
 * poses, export a mesh and a point cloud, report time and memory. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "app.h"
#include "calib/calib.h"

#include "fusion/fusion.h"
#include "gpu/gpu.h"
#include "recon/recon.h"
#include "replay/replay.h"
#include "export/export.h"

static const char fuse_usage[] =
    "usage: bitfuse fuse SEQUENCE --poses FILE|groundtruth --out DIR [options]\n"
    "\n"
    "Fuses every frame of SEQUENCE into the sign-bit map (DESIGN.md sections 3-4) with the\n"
    "given camera poses, then writes into DIR:\n"
    "  mesh.ply     triangle mesh of the confident surface (binary PLY, normals; --mesh-format\n"
    "               obj|glb for mesh.obj + mesh.mtl or mesh.glb, --max-triangles N)\n"
    "  points.ply   surface voxel centres with normals (binary PLY)\n"
    "  stats.json   the map's config, frames, time per frame (median, p95), GPU time per\n"
    "               stage, map bytes by part, bricks per level, surface voxels, bits per voxel\n";

typedef struct fuse_args {
    const char *seq, *poses, *out, *depth_correction, *calibration;
    app_calibration cal; /* --calibration, read by parse_args */
    replay_options ropt;
    fusion_config fcfg;
    bool skip_repeated;
    bool no_mesh;
    app_mesh_out mesh_out;
} fuse_args;

static int parse_args(int argc, char **argv, fuse_args *a)
{
    memset(a, 0, sizeof *a);
    a->fcfg = fusion_config_default();
    a->skip_repeated = true;
    const app_option own[] = {
        APP_OPT("--poses", APP_OPT_STRING, &a->poses, "P",
                "'groundtruth' (the sequence's own) or a TUM trajectory file (camera-to-world; poses interpolated at "
                "the depth timestamps)",
                .required = true),
        APP_OPT("--out", APP_OPT_STRING, &a->out, "DIR", "output folder (created)", .required = true),
        APP_OPT("--no-mesh", APP_OPT_FLAG, &a->no_mesh, NULL, "skip the mesh (points and stats only)"),
        APP_OPT("--repeated", APP_OPT_CHOICE, &a->skip_repeated, "skip|fuse",
                "a frame whose depth repeats the previous frame's byte for byte (a driver handing on its last "
                "image, an earlier moment than its pose): skipped, or fused like a new one; with skip, a colour "
                "repeated alone is left out of the map's colour"),
        APP_OPT("--max-depth", APP_OPT_FLOAT, &a->fcfg.sensor.max_depth_m, "M",
                "the sensor's range: depth samples beyond M metres are not fused; at most 6, as replay's",
                .min = 0.5, .max = 6),
        APP_OPT("--depth-correction", APP_OPT_STRING, &a->depth_correction, "FILE",
                "depth_correction.json of bitfuse calibrate-depth: the depth camera's fixed error pattern, taken "
                "out of every frame before fusion (docs/calibration.md)", .no_default = true),
        APP_OPT("--calibration", APP_OPT_STRING, &a->calibration, "FILE",
                "calib.json of bitfuse calibrate: the colour is its colour camera's own image, fused into the map "
                "through it; its depth camera, lens included, is the one the depth is read with "
                "(docs/calibration.md)",
                .no_default = true),
        APP_OPT_END,
    };
    app_option map[APP_MAP_ROWS], seq[APP_SEQUENCE_ROWS], msh[APP_MESH_ROWS];
    app_mesh_options(msh, &a->mesh_out, false);
    app_map_options(map, &a->fcfg, NULL);
    app_sequence_options(seq, &a->ropt);
    const app_option *tables[] = {own, msh, map, seq, NULL};
    app_command_spec spec = {
        .name = "fuse", .usage = fuse_usage, .tables = tables, .positional = &a->seq, .min_positional = 1,
        .max_positional = 1, .positional_missing = "no sequence given",
        .epilog = "exit codes: 0 ok (also with pools too small: what did not fit is dropped and counted,\n"
                  "or stopped by Ctrl-C), 1 failure (also: the pools held none of the surface, --bricks too\n"
                  "small), 2 usage (--camera with a --calibration that has a depth camera), 3 bad input (a\n"
                  "corrupt frame mid-sequence: the frames before it are still fused and written; a bad\n"
                  "--calibration file, or its depth camera of another size than the depth images), 4 no\n"
                  "Vulkan device, 5 an output could not be written (disk full, I/O error: the file is named;\n"
                  "every file in DIR is whole or absent)\n",
    };
    int rc = app_options_parse(&spec, argc, argv);
    if (!rc && a->calibration) rc = app_calibration_read("fuse", a->calibration, a->seq, false, &a->ropt, &a->cal);
    if (!rc) rc = app_check_map_options("fuse", &a->fcfg);
    if (!rc) rc = app_check_not_input("fuse", "--out", a->out, a->seq);
    if (!rc) rc = app_check_out_not_sequence("fuse", a->out, false);
    return rc ? rc : app_check_out_not_store("fuse", a->out, NULL);
}

/* --depth-correction's multipliers (19 KB: not on the stack). */
static calib_depth_correction fuse_depth_fix;

typedef struct fuse_result {
    recon_run run;
    uint32_t n_unreadable; /* frames the source skipped (--skip-bad-frames) */
    app_map_report out;
    double seconds;
    char device[256];
    char device_driver[256]; /* the driver's own words, e.g. Mesa's version */
} fuse_result;

/* Frames fused and still no surface voxel (points.ply empty: every sample
 * too near or too sparse, or taken off the image by the lens): the input's
 * fault, as a replay whose every frame lacks usable depth (exit 3, the
 * outputs written, stats.json's `no_surface`). */
static bool no_surface(const fuse_result *r) { return r->run.n_fused > 0 && r->out.points.n_points == 0; }

static cJSON *stats_json(const fuse_args *a, const fuse_result *r, const rgbd_source *src)
{
    const recon_run_series *t = &r->run.series;
    cJSON *o = app_json_stats("fuse");
    cJSON_AddStringToObject(o, "sequence", a->seq);
    cJSON_AddStringToObject(o, "poses", a->poses); /* "groundtruth" or the file: the run can be repeated */
    cJSON_AddStringToObject(o, "device", r->device);
    cJSON_AddStringToObject(o, "device_driver", r->device_driver);
    app_json_fusion_config(o, "config", &a->fcfg);
    cJSON_AddBoolToObject(o, "interrupted", r->run.is_interrupted); /* Ctrl-C, SIGTERM */
    cJSON_AddBoolToObject(o, "no_surface", no_surface(r));
    app_json_depth_correction(o, a->depth_correction, a->depth_correction ? &fuse_depth_fix : NULL);
    char *cal_text = NULL;
    cJSON *cal = a->calibration && calib_to_text(&a->cal.cal, &cal_text) == BF_OK ? cJSON_CreateRaw(cal_text) : NULL;
    free(cal_text);
    cJSON_AddItemToObject(o, "calibration", cal ? cal : cJSON_CreateNull());
    cJSON_AddNumberToObject(o, "frames", r->run.n_fused);
    cJSON_AddBoolToObject(o, "skip_repeated", a->skip_repeated);
    cJSON_AddNumberToObject(o, "repeated", r->run.counts.repeated);
    cJSON_AddNumberToObject(o, "colour_repeated", r->run.counts.colour_repeated);
    cJSON_AddNumberToObject(o, "no_depth", r->run.counts.no_depth);
    cJSON_AddNumberToObject(o, "pool_full", r->run.counts.pool_full); /* frames whose requests a full pool dropped */
    /* Skipped: unreadable (--skip-bad-frames) or without a pose. */
    cJSON_AddNumberToObject(o, "frames_skipped", r->run.n_skipped + r->n_unreadable);
    cJSON_AddNumberToObject(o, "frames_without_pose", r->run.n_skipped);
    app_json_input(o, &r->run, src);
    app_json_series(o, "frame_ms", &t->frame_ms);
    app_json_gpu_stages(o, &r->run, false); /* as replay's, so one script reads both */
    app_json_map(o, &r->out, a->fcfg.max_level);
    cJSON_AddNumberToObject(o, "seconds", r->seconds);
    return o;
}

int cmd_fuse(int argc, char **argv)
{
    const char *cmd = "fuse";
    fuse_args a;
    int rc = parse_args(argc, argv, &a);
    if (rc) return rc < 0 ? APP_EXIT_OK : rc;
    double t_start = bf_time_s();
    fuse_result r;
    memset(&r, 0, sizeof r);
    bf_traj traj = {0};
    bool use_traj = strcmp(a.poses, "groundtruth") != 0;
    rgbd_source *src = NULL;
    gpu_context *ctx = NULL;
    /* The inputs first: a missing one leaves no empty output folder. */
    bf_status s = use_traj ? replay_traj_read_tum(a.poses, &traj) : BF_OK;
    if (s == BF_OK && a.depth_correction) s = calib_depth_read(a.depth_correction, &fuse_depth_fix);
    if (s == BF_OK) s = replay_open(a.seq, &a.ropt, &src);
    /* Ctrl-C or SIGTERM ends the run as a replay's: the frames fused so far
     * are written (a second one kills the program). From here on, so one
     * during start-up (the GPU's pipelines) ends it cleanly too. */
    const volatile sig_atomic_t *stop = s == BF_OK ? app_stop_begin(NULL) : NULL;
    bool stopped_empty = false; /* stopped before any frame was fused: nothing to write */
    if (s == BF_OK) s = app_calibration_apply(&a.cal, a.seq, src);
    if (s == BF_OK && a.depth_correction)
        s = app_depth_correction_check(a.depth_correction, &fuse_depth_fix, src, &a.cal, a.seq);
    if (s == BF_OK && !use_traj && !src->has_groundtruth)
        s = bf_fail(BF_FORMAT, "%s: --poses groundtruth, but the sequence has no ground truth", a.seq);
    bool made_out = !bf_file_exists(a.out);
    if (s == BF_OK && !made_out) app_warn_earlier_run(cmd, a.out);
    if (s == BF_OK) s = bf_mkdir_p(a.out);
    if (s == BF_OK && made_out) app_signals_made_folder(a.out);
    gpu_config gcfg = {0};
    if (s == BF_OK) s = gpu_context_create(&gcfg, &ctx);
    if (s == BF_OK) {
        snprintf(r.device, sizeof r.device, "%s", gpu_device_name(ctx));
        snprintf(r.device_driver, sizeof r.device_driver, "%s", gpu_device(ctx)->driver_info);
    }
    if (s == BF_OK) {
        recon_run_config rcfg = recon_run_config_default();
        rcfg.loop.fusion = a.fcfg;
        rcfg.loop.sensor = a.fcfg.sensor; /* the loop hands its sensor to fusion */
        rcfg.loop.skip_repeated = a.skip_repeated;
        rcfg.poses = RECON_POSES_KNOWN;
        rcfg.known = use_traj ? &traj : NULL;
        rcfg.depth_correction = a.depth_correction ? &fuse_depth_fix : NULL;
        rcfg.depth_lens = app_calibration_depth_lens(&a.cal);
        rcfg.loop.has_calibration = a.calibration != NULL;
        if (a.calibration) rcfg.loop.calibration = a.cal.cal; /* its colour camera at the frames' size */
        rcfg.name = a.seq;
        rcfg.label = cmd;
        /* A corrupt frame mid-sequence ends the run, and the frames fused
         * before it are written; the exit code still says the input was bad. */
        rcfg.keep_on_source_error = true;
        rcfg.stop = stop;
        s = app_input_status(recon_run_sequence(ctx, src, &rcfg, NULL, NULL, &r.run), src, a.seq);
        app_pool_hint(cmd, s, "--bricks");
        /* Stopped before any frame was fused (during start-up, or while the
         * first frames were being read): nothing to write, and no failure. */
        if ((s == BF_OK || s == BF_FORMAT) && r.run.is_interrupted && r.run.n_fused == 0)
            stopped_empty = true, s = BF_END;
        r.n_unreadable = app_skipped_frames(src);
        /* No frame within the file's time span: give the span. */
        if (s == BF_FORMAT && use_traj && traj.n && r.run.n_fused == 0 && r.run.n_skipped > 0 &&
            r.run.n_skipped == r.run.counts.frames) {
            char msg[BF_ERROR_CAP];
            snprintf(msg, sizeof msg, "%s", bf_last_error());
            s = bf_fail(BF_FORMAT, "%s: %s's poses span t = %.6f to %.6f s, which no frame's time falls in", msg,
                        a.poses, traj.t_s[0], traj.t_s[traj.n - 1]);
        }
    }
    if (stop) app_stop_end();
    /* An output that cannot be written does not stop the others. */
    app_write_failure wf = {0};
    if (s == BF_OK) s = app_note_write(&wf, cmd, app_export_map(r.run.map, NULL, a.out, a.no_mesh ? NULL : &a.mesh_out, &r.out));
    app_note_mesh_refused(&wf, &r.out);
    r.seconds = bf_time_s() - t_start;
    if (s == BF_OK) {
        cJSON *o = stats_json(&a, &r, src);
        if (wf.s != BF_OK) cJSON_AddStringToObject(o, "output_error", wf.message);
        s = app_note_write(&wf, cmd, app_json_write_in(a.out, "stats.json", o));
    }
    /* The summary also when an output could not be written (the failure
     * named instead of the files written); the exit code says so after it. */
    if (s == BF_OK) {
        printf("bitfuse fuse: %u frame%s fused (%u skipped: %u unreadable, %u without a pose) on %s\n", r.run.n_fused,
               app_s(r.run.n_fused), r.run.n_skipped + r.n_unreadable, r.n_unreadable, r.run.n_skipped, r.device);
        if (r.run.is_interrupted)
            printf("  stopped          by a signal: the frames before it are fused and written\n");
        if (r.run.counts.repeated)
            printf("  input            %u frame%s repeated the depth before %s byte for byte: not fused\n",
                   r.run.counts.repeated, app_s(r.run.counts.repeated), r.run.counts.repeated == 1 ? "it" : "them");
        if (r.run.counts.no_depth)
            printf("  input            %u frame%s without a depth sample in the sensor's range: not fused\n",
                   r.run.counts.no_depth, app_s(r.run.counts.no_depth));
        if (r.run.counts.colour_repeated)
            printf("  input            %u frame%s repeated only the colour before %s: fused without it\n",
                   r.run.counts.colour_repeated, app_s(r.run.counts.colour_repeated),
                   r.run.counts.colour_repeated == 1 ? "it" : "them");
        printf("  time per frame   median %.1f ms, p95 %.1f ms\n", bf_stats_percentile(&r.run.series.frame_ms, 50),
               bf_stats_percentile(&r.run.series.frame_ms, 95));
        app_print_map(&r.out, a.fcfg.max_level);
        char tail[96];
        if (wf.s != BF_OK)
            printf("  not written      %s%s in %.1f s\n", wf.message, app_write_failure_tail(&wf, tail, sizeof tail),
                   r.seconds);
        else {
            char files[128];
            app_mesh_file_list(&r.out, files, sizeof files);
            printf("  wrote            %s/{%spoints.ply,stats.json} in %.1f s\n", a.out, files, r.seconds);
        }
    }
    if (s == BF_OK) s = app_write_status(&wf);
    bf_status s_input = r.run.source_status;
    if (s == BF_OK && s_input != BF_OK) {
        printf("  stopped early    %s: the frames before it were fused and written\n", r.run.source_error);
        bf_fail(s_input, "%s", r.run.source_error);
        s = s_input;
    }
    if (s == BF_OK && no_surface(&r) && r.run.counts.pool_full) {
        /* The input may be fine: the pools held none of what it gave. */
        printf("  no surface       the %u frames fused gave the map no surface voxel: the pools dropped what did "
               "not fit (--bricks %u too small?)\n", r.run.n_fused, a.fcfg.brick_cap);
        s = bf_fail(BF_POOL_FULL, "%s: the %u frames fused gave the map no surface voxel: the pools (--bricks %u) "
                    "held none of it", a.seq, r.run.n_fused, a.fcfg.brick_cap);
    } else if (s == BF_OK && no_surface(&r)) {
        printf("  no surface       the %u frames fused gave the map no surface voxel (depth too near or too sparse, "
               "or taken off the image by the lens?)\n", r.run.n_fused);
        s = bf_fail(BF_FORMAT, "%s: the %u frames fused gave the map no surface voxel", a.seq, r.run.n_fused);
    }
    /* A run that wrote nothing (a corrupt first frame, no device) leaves no
     * empty folder it made behind; rmdir takes only an empty one. */
    if (s != BF_OK && made_out) (void)rmdir(a.out);
    recon_run_free(&r.run);
    gpu_context_destroy(ctx);
    rgbd_source_close(src);
    bf_traj_free(&traj);
    if (stopped_empty) {
        printf("bitfuse %s: stopped before any frame was fused: no map written\n", cmd);
        return APP_EXIT_OK;
    }
    return s == BF_OK ? APP_EXIT_OK : app_fail(cmd, s);
}
