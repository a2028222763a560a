/* bitfuse fuse: fuse a sequence into the sign-bit map with known camera
 * poses, export a mesh and a point cloud, report time and memory. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"

#include "fusion/fusion.h"
#include "gpu/gpu.h"
#include "recon/recon.h"
#include "replay/replay.h"
#include "export/export.h"

static const char fuse_help[] =
    "usage: bitfuse fuse SEQUENCE --poses FILE|groundtruth --out DIR [options]\n"
    "\n"
    "Fuses every frame of SEQUENCE into the sign-bit map (DESIGN.md sections 3-4) with the\n"
    "given camera poses, then writes into DIR:\n"
    "  mesh.ply     triangle mesh of the confident surface (binary PLY, normals)\n"
    "  points.ply   surface voxel centres with normals (binary PLY)\n"
    "  stats.json   frames, time per frame (median, p95), GPU time per stage, map bytes\n"
    "               by part, bricks per level, surface voxels, bits per voxel\n"
    "\n"
    "options:\n"
    "  --poses P          'groundtruth' (the sequence's own) or a TUM trajectory file\n"
    "                     (camera-to-world; poses interpolated at the depth timestamps)\n"
    "  --out DIR          output folder (created)\n"
    "  --ratio R          voxel-to-pixel ratio of the level rule, default 1\n"
    "  --window N         frames per window (even), default 40\n"
    "  --subcache N       frames of the new-brick pass, default 10\n"
    "  --bricks N         brick pool size, default 1048576\n"
    "  --chunk M          chunk edge in metres, default 2\n"
    "  --max-level L      finest octree level, default 8\n"
    "  --no-mesh          skip the mesh (points and stats only)\n"
    "%s"
    "\n"
    "exit codes: 0 ok, 1 failure (e.g. pool full), 2 usage, 3 bad input, 4 no Vulkan device\n";

typedef struct fuse_args {
    const char *seq, *poses, *out;
    replay_options ropt;
    fusion_config fcfg;
    bool no_mesh;
} fuse_args;

static int parse_args(int argc, char **argv, fuse_args *a)
{
    const char *cmd = "fuse";
    memset(a, 0, sizeof *a);
    a->fcfg = fusion_config_default();
    for (int i = 1; i < argc; i++) {
        int r = replay_parse_option(argc, argv, &i, &a->ropt);
        if (r < 0) return app_usage_error(cmd, "%s", bf_last_error());
        if (r > 0) { /* it moved i past the option: the loop's i++ must not skip one more */
            i--;
            continue;
        }
        const char *o = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (app_is_help(o)) {
            printf(fuse_help, replay_options_help());
            return -1;
        } else if (!strcmp(o, "--no-mesh")) {
            a->no_mesh = true;
        } else if (o[0] != '-') {
            if (a->seq) return app_usage_error(cmd, "more than one sequence: %s", o);
            a->seq = o;
        } else if (!v) {
            return app_usage_error(cmd, "%s needs a value", o);
        } else if (app_parse_map_option(o, v, &a->fcfg)) {
            i++;
        } else if (!strcmp(o, "--poses")) {
            a->poses = v, i++;
        } else if (!strcmp(o, "--out")) {
            a->out = v, i++;
        } else {
            return app_usage_error(cmd, "unknown option or bad value: %s %s", o, v);
        }
    }
    if (!a->seq) return app_usage_error(cmd, "no sequence given");
    if (!a->poses) return app_usage_error(cmd, "--poses is required (groundtruth or a TUM file)");
    if (!a->out) return app_usage_error(cmd, "--out is required");
    return 0;
}

typedef struct fuse_result {
    recon_run run;
    app_map_report out;
    double seconds;
    char device[256];
} fuse_result;

typedef struct fuse_report {
    const fuse_args *a;
    const fuse_result *r;
} fuse_report;

static void write_stats_json(FILE *f, const void *arg)
{
    const fuse_report *rep = arg;
    const fuse_args *a = rep->a;
    const fuse_result *r = rep->r;
    const recon_run_series *t = &r->run.series;
    fprintf(f, "{\n  \"command\": \"fuse\",\n  \"sequence\": ");
    bf_json_string(f, a->seq);
    fprintf(f, ",\n  \"device\": ");
    bf_json_string(f, r->device);
    fprintf(f, ",\n  \"config\": {\"voxel_ratio\": %g, \"window\": %u, \"subcache\": %u, \"chunk_m\": %g, "
               "\"max_level\": %u, \"brick_cap\": %u},\n",
            a->fcfg.voxel_ratio, a->fcfg.window, a->fcfg.subcache, a->fcfg.chunk_m, a->fcfg.max_level,
            a->fcfg.brick_cap);
    fprintf(f, "  \"frames\": %u,\n  \"frames_skipped\": %u,\n", r->run.n_fused, r->run.n_skipped);
    fprintf(f, "  \"frame_ms\": {\"median\": ");
    bf_json_number(f, bf_stats_percentile(&t->frame_ms, 50), 5);
    fprintf(f, ", \"p95\": ");
    bf_json_number(f, bf_stats_percentile(&t->frame_ms, 95), 5);
    fprintf(f, ", \"mean\": ");
    bf_json_number(f, bf_stats_mean(&t->frame_ms), 5);
    fprintf(f, "},\n  \"gpu_stage_ms_median\": {\"upload\": ");
    bf_json_number(f, bf_stats_percentile(&t->upload_ms, 50), 4);
    fprintf(f, ", \"alloc\": ");
    bf_json_number(f, bf_stats_percentile(&t->alloc_ms, 50), 4);
    fprintf(f, ", \"subcache\": ");
    bf_json_number(f, bf_stats_percentile(&t->subcache_ms, 50), 4);
    fprintf(f, ", \"window\": ");
    bf_json_number(f, bf_stats_percentile(&t->window_ms, 50), 4);
    fprintf(f, "},\n");
    app_json_map(f, &r->out, a->fcfg.max_level);
    fprintf(f, "  \"seconds\": %.3f\n}\n", r->seconds);
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
    bf_status s = bf_mkdir_p(a.out);
    if (s == BF_OK && use_traj) s = replay_traj_read_tum(a.poses, &traj);
    if (s == BF_OK) s = replay_open(a.seq, &a.ropt, &src);
    if (s == BF_OK && !use_traj && !src->has_groundtruth)
        s = bf_fail(BF_FORMAT, "%s: --poses groundtruth, but the sequence has no ground truth", a.seq);
    gpu_config gcfg = {0};
    if (s == BF_OK) s = gpu_context_create(&gcfg, &ctx);
    if (s == BF_OK) snprintf(r.device, sizeof r.device, "%s", gpu_device_name(ctx));
    if (s == BF_OK) {
        recon_run_config rcfg = recon_run_config_default();
        rcfg.loop.fusion = a.fcfg;
        rcfg.poses = RECON_POSES_KNOWN;
        rcfg.known = use_traj ? &traj : NULL;
        rcfg.name = a.seq;
        rcfg.label = cmd;
        s = recon_run_sequence(ctx, src, &rcfg, NULL, NULL, &r.run);
    }
    if (s == BF_OK) s = app_export_map(r.run.map, a.out, !a.no_mesh, &r.out);
    r.seconds = bf_time_s() - t_start;
    fuse_report rep = {&a, &r};
    if (s == BF_OK) s = app_write_json(a.out, "stats.json", write_stats_json, &rep);
    if (s == BF_OK) {
        printf("bitfuse fuse: %u frames fused (%u skipped) on %s\n", r.run.n_fused, r.run.n_skipped, r.device);
        printf("  time per frame   median %.1f ms, p95 %.1f ms\n", bf_stats_percentile(&r.run.series.frame_ms, 50),
               bf_stats_percentile(&r.run.series.frame_ms, 95));
        app_print_map(&r.out, a.fcfg.max_level);
        printf("  wrote            %s/{%spoints.ply,stats.json} in %.1f s\n", a.out, a.no_mesh ? "" : "mesh.ply,",
               r.seconds);
    }
    recon_run_free(&r.run);
    gpu_context_destroy(ctx);
    rgbd_source_close(src);
    bf_traj_free(&traj);
    return s == BF_OK ? APP_EXIT_OK : app_fail(cmd, s);
}
