/* Benchmark of the CPU evaluation tools that every later result depends on:
 * synthetic rendering (frames per second of the room at 640x480), the
 * surface evaluator (1 M points against the room's ~150 k triangles) and
 * ATE/RPE on the real fr1_xyz files. Prints a markdown table and writes
 * JSON to the path given with --json.
 *
 *   build/bench/bench_eval [--frames N] [--points N] [--json FILE]
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "eval/eval.h"
#include "replay/replay.h"
#include "mesh/mesh.h"
#include "synth/synth.h"

#ifndef BF_SOURCE_DIR
#define BF_SOURCE_DIR "."
#endif

typedef struct bench_result {
    uint32_t threads;
    uint32_t n_tris;
    double bvh_build_s;
    double render_ms_median, render_ms_p95;
    uint32_t n_frames;
    size_t n_points;
    double surface_s;
    double surface_median_m;
    double ate_s, ate_rmse_m;
    size_t ate_pairs;
} bench_result;

static bf_status bench_render(const synth_scene *scene, uint32_t n_frames, bench_result *r)
{
    synth_render_config cfg = {
        .K = {640, 480, 525, 525, 319.5, 239.5, 5000},
        .noise = SYNTH_NOISE_KINECT1,
        .seed = 1,
    };
    synth_renderer *ren;
    double t0 = bf_time_s();
    bf_status s = synth_renderer_create(scene, &cfg, &ren);
    if (s != BF_OK) return s;
    r->bvh_build_s = bf_time_s() - t0;
    uint16_t *depth = malloc(640 * 480 * sizeof *depth);
    uint8_t *rgb = malloc(640 * 480 * 3);
    bf_stats st = {0};
    if (!depth || !rgb) s = bf_fail(BF_NO_MEMORY, "bench: image buffers");
    for (uint32_t k = 0; k < n_frames && s == BF_OK; k++) {
        /* Sway 30 cm sideways around the room's viewpoint. */
        bf_se3 step = bf_se3_from_qt(bf_quat_identity(), bf_v3(0.3 * sin(0.2 * k), 0, 0));
        bf_se3 T = bf_se3_mul(&scene->T_wc_view, &step);
        double t = bf_time_s();
        s = synth_render(ren, k, &T, depth, rgb, NULL);
        if (s == BF_OK) s = bf_stats_push(&st, 1e3 * (bf_time_s() - t));
    }
    r->n_frames = n_frames;
    r->render_ms_median = bf_stats_percentile(&st, 50);
    r->render_ms_p95 = bf_stats_percentile(&st, 95);
    bf_stats_free(&st);
    free(depth);
    free(rgb);
    synth_renderer_destroy(ren);
    return s;
}

/* n points on the reference surface, pushed off it by Gaussian-like noise of
 * 3 mm (sum of uniforms), then evaluated against it. */
static bf_status bench_surface(const mesh_data *ref, size_t n, bench_result *r)
{
    float *xyz = NULL;
    size_t got = 0;
    bf_status s = eval_mesh_sample_area(ref, 1e9, n, 7, &xyz, NULL, &got);
    if (s != BF_OK) return s;
    uint32_t rng = 12345;
    for (size_t i = 0; i < 3 * got; i++) {
        double g = 0;
        for (int k = 0; k < 4; k++) {
            rng = rng * 1664525u + 1013904223u;
            g += rng / 4294967296.0 - 0.5;
        }
        xyz[i] += (float)(g * 0.003 * sqrt(3.0));
    }
    mesh_data rec = {.n_verts = (uint32_t)got, .xyz = xyz};
    eval_surface_config cfg = eval_surface_config_default();
    eval_surface_result res;
    double t0 = bf_time_s();
    s = eval_surface(ref, &rec, NULL, &cfg, &res);
    r->surface_s = bf_time_s() - t0;
    r->n_points = got;
    if (s == BF_OK) r->surface_median_m = res.accuracy.median;
    free(xyz);
    return s;
}

static bf_status bench_ate(bench_result *r)
{
    const char *dir = BF_SOURCE_DIR "/../shared/data/tum/fr1_xyz";
    char gt_path[4096], est_path[4096];
    snprintf(gt_path, sizeof gt_path, "%s/groundtruth.txt", dir);
    snprintf(est_path, sizeof est_path, "%s/rgbdslam_estimate.txt", dir);
    if (!bf_file_exists(gt_path)) return BF_OK;
    bf_traj gt = {0}, est = {0};
    bf_status s = replay_traj_read_tum(gt_path, &gt);
    if (s == BF_OK) s = replay_traj_read_tum(est_path, &est);
    eval_ate_result ate;
    eval_rpe_result rpe;
    double t0 = bf_time_s();
    if (s == BF_OK) s = eval_ate(&gt, &est, 0.02, &ate);
    if (s == BF_OK) s = eval_rpe(&gt, &est, 0, false, 1.0, &rpe);
    r->ate_s = bf_time_s() - t0;
    if (s == BF_OK) {
        r->ate_rmse_m = ate.trans.rmse;
        r->ate_pairs = ate.n_matched;
    }
    bf_traj_free(&gt);
    bf_traj_free(&est);
    return s;
}

int main(int argc, char **argv)
{
    uint32_t n_frames = 30, n_points = 1000000;
    const char *json = NULL;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--frames") && i + 1 < argc) {
            n_frames = (uint32_t)atoi(argv[++i]);
        } else if (!strcmp(argv[i], "--points") && i + 1 < argc) {
            n_points = (uint32_t)atoi(argv[++i]);
        } else if (!strcmp(argv[i], "--json") && i + 1 < argc) {
            json = argv[++i];
        } else {
            fprintf(stderr, "usage: bench_eval [--frames N] [--points N] [--json FILE]\n");
            return 2;
        }
    }
    bench_result r = {.threads = (uint32_t)bf_thread_count()};
    synth_scene scene;
    bf_status s = synth_scene_room(BF_SOURCE_DIR "/../shared/data", &scene);
    if (s == BF_OK) {
        r.n_tris = scene.mesh.n_tris;
        s = bench_render(&scene, n_frames, &r);
        if (s == BF_OK) s = bench_surface(&scene.mesh, n_points, &r);
        synth_scene_free(&scene);
    }
    if (s == BF_OK) s = bench_ate(&r);
    if (s != BF_OK) {
        fprintf(stderr, "bench_eval: %s: %s\n", bf_status_name(s), bf_last_error());
        return 1;
    }
    printf("| measure | value |\n|---|---|\n");
    printf("| threads | %u |\n", r.threads);
    printf("| room triangles | %u |\n", r.n_tris);
    printf("| BVH build + renderer setup | %.2f s |\n", r.bvh_build_s);
    printf("| synth render 640x480, kinect1 noise, median / p95 (%u frames) | %.0f / %.0f ms |\n", r.n_frames,
           r.render_ms_median, r.render_ms_p95);
    printf("| eval-surface, %zu points vs %u triangles | %.2f s |\n", r.n_points, r.n_tris, r.surface_s);
    printf("| accuracy median of 3 mm-noise points (expect ~0.674*3 mm = 2.0 mm) | %.2f mm |\n",
           1e3 * r.surface_median_m);
    printf("| ATE + RPE fr1_xyz (%zu pairs) | %.3f s, ATE RMSE %.4f m |\n", r.ate_pairs, r.ate_s, r.ate_rmse_m);
    if (json) {
        FILE *f = fopen(json, "w");
        if (!f) return 1;
        fprintf(f,
                "{\"threads\": %u, \"room_triangles\": %u, \"bvh_build_s\": %.3f, \"render_ms_median\": %.1f, "
                "\"render_ms_p95\": %.1f, \"render_frames\": %u, \"surface_points\": %zu, \"surface_s\": %.3f, "
                "\"surface_median_m\": %.6f, \"ate_s\": %.4f, \"ate_rmse_m\": %.6f, \"ate_pairs\": %zu}\n",
                r.threads, r.n_tris, r.bvh_build_s, r.render_ms_median, r.render_ms_p95, r.n_frames, r.n_points,
                r.surface_s, r.surface_median_m, r.ate_s, r.ate_rmse_m, r.ate_pairs);
        fclose(f);
    }
    return 0;
}
