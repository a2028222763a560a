/* Benchmark of tracking/ at 640x480: ROF smoothing of the reference and
 * ICP (frame pyramids + all levels), GPU time from timestamps and wall
 * time, against accuracy, for several iteration counts. Frames are the
 * synthetic room with Kinect v1 noise along a hand-held sway (about 1 cm
 * and 1 degree per frame); each frame is tracked against the previous one,
 * given as a float depth buffer on the GPU (as a ray-cast would be), from
 * the previous true pose. Then the real TUM fr2_desk b1 -> b2 pair.
 *
 *   build/bench/bench_tracking [--frames N]
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "eval/eval.h"
#include "replay/replay.h"
#include "tracking/tracking.h"

#ifndef BF_SOURCE_DIR
#define BF_SOURCE_DIR "."
#endif

typedef struct variant {
    const char *name;
    uint32_t it[3];
    uint32_t rof;
    bool no_early_stop;
} variant;

static bf_se3 sway(const bf_se3 *T0, uint32_t k)
{
    double s = 0.15 * k;
    bf_se3 d = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0.2, 1, 0.1), 0.3 * sin(s)),
                              bf_v3(0.08 * sin(s), 0.02 * sin(2 * s), 0.03 * (1 - cos(s))));
    return bf_se3_mul(T0, &d);
}

static double median(double *v, uint32_t n) { return bf_percentile_inplace(v, n, 50); }

int main(int argc, char **argv)
{
    uint32_t n_frames = 16;
    bool quick = false;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--frames") && i + 1 < argc) n_frames = (uint32_t)atoi(argv[++i]);
        else if (!strcmp(argv[i], "--quick")) quick = true; /* the default variant only */
    }
    bf_intrinsics K = {640, 480, 525, 525, 319.5, 239.5, 5000};
    uint32_t n = K.width * K.height;
    eval_scene scene;
    eval_renderer *ren;
    eval_render_config rc = {.K = K, .noise = EVAL_NOISE_KINECT1, .seed = 5};
    if (eval_scene_room(NULL, &scene) != BF_OK || eval_renderer_create(&scene, &rc, &ren) != BF_OK) {
        fprintf(stderr, "bench_tracking: scene: %s\n", bf_last_error());
        return 1;
    }
    uint16_t **depth = calloc(n_frames + 1, sizeof *depth);
    bf_se3 *T = calloc(n_frames + 1, sizeof *T);
    for (uint32_t k = 0; k <= n_frames; k++) {
        depth[k] = malloc(n * 2);
        T[k] = sway(&scene.T_wc_view, k);
        if (eval_render(ren, k, &T[k], depth[k], NULL, NULL) != BF_OK) return 1;
    }
    gpu_context *ctx;
    if (gpu_context_create(NULL, &ctx) != BF_OK) {
        fprintf(stderr, "bench_tracking: %s\n", bf_last_error());
        return 1;
    }
    gpu_buffer_desc bd = {.name = "bench.ref_depth", .size_bytes = (uint64_t)n * 4, .memory = GPU_MEMORY_DEVICE};
    gpu_buffer *ref;
    if (gpu_buffer_create(ctx, &bd, &ref) != BF_OK) return 1;
    float *fdepth = malloc((size_t)n * 4);

    const variant vars[] = {
        {"10/5/4, ROF 10", {10, 5, 4}, 10, false},
        {"10/5/4, ROF 10, no early stop", {10, 5, 4}, 10, true},
        {"10/5/4, ROF 0", {10, 5, 4}, 0, false},
        {"10/5/4, ROF 5", {10, 5, 4}, 5, false},
        {"10/5/4, ROF 20", {10, 5, 4}, 20, false},
        {"5/5/4, ROF 10", {5, 5, 4}, 10, false},
        {"3/5/8, ROF 10", {3, 5, 8}, 10, false},
        {"2/4/8, ROF 10", {2, 4, 8}, 10, false},
    };
    printf("device: %s, 640x480, %u frames of the noisy room (~1 cm, ~1 deg per frame)\n\n", gpu_device_name(ctx),
           n_frames);
    printf("| variant | ROF ms (GPU) | ICP ms (GPU, incl. frame pyramid) | track_frame wall ms | iterations | "
           "error mm (median / max) | error deg (median / max) | failures |\n|---|---|---|---|---|---|---|---|\n");
    double *a = malloc(n_frames * sizeof *a), *b = malloc(n_frames * sizeof *b), *c = malloc(n_frames * sizeof *c),
           *e = malloc(n_frames * sizeof *e), *g = malloc(n_frames * sizeof *g), *h = malloc(n_frames * sizeof *h);
    if (quick) {
        /* Reference preparation alone, ROF counts interleaved (the machine
         * is shared: compare within one run). */
        const uint32_t rofs[] = {0, 1, 5, 10, 20};
        enum { NR = sizeof rofs / sizeof rofs[0], REPS = 7 };
        track_tracker *tr[NR];
        double ms[NR][REPS], ms_ref[NR][REPS];
        for (uint32_t i = 0; i < NR; i++) {
            track_config cfg = track_config_default();
            cfg.rof_iterations = rofs[i];
            if (track_create(ctx, &cfg, &K, &tr[i]) != BF_OK) return 1;
        }
        for (uint32_t i = 0; i < n; i++) fdepth[i] = (float)(depth[0][i] / K.depth_scale);
        gpu_buffer_upload(ref, 0, fdepth, (uint64_t)n * 4);
        bf_frame f = {.index = 1, .width = K.width, .height = K.height, .depth = depth[1]};
        for (uint32_t rep = 0; rep < REPS; rep++)
            for (uint32_t i = 0; i < NR; i++) {
                track_set_reference_gpu(tr[i], ref, &T[0]);
                track_result r;
                track_frame(tr[i], &f, &T[0], &r);
                ms[i][rep] = r.ms_rof;
                ms_ref[i][rep] = r.ms_ref;
            }
        for (uint32_t i = 0; i < NR; i++) {
            printf("ROF %2u: ROF %.2f ms, reference total %.2f ms (GPU, median of %d)\n", rofs[i], median(ms[i], REPS),
                   median(ms_ref[i], REPS), REPS);
            track_destroy(tr[i]);
        }
    }
    size_t n_vars = quick ? 1 : sizeof vars / sizeof vars[0];
    for (size_t v = 0; v < n_vars; v++) {
        track_config cfg = track_config_default();
        memcpy(cfg.iterations, vars[v].it, sizeof cfg.iterations);
        cfg.rof_iterations = vars[v].rof;
        if (vars[v].no_early_stop) cfg.converged_m = cfg.converged_deg = 0;
        track_tracker *t;
        if (track_create(ctx, &cfg, &K, &t) != BF_OK) {
            fprintf(stderr, "bench_tracking: %s\n", bf_last_error());
            return 1;
        }
        uint32_t fails = 0, iters = 0;
        double emax = 0, gmax = 0;
        for (uint32_t k = 1; k <= n_frames; k++) {
            for (uint32_t i = 0; i < n; i++) fdepth[i] = (float)(depth[k - 1][i] / K.depth_scale);
            gpu_buffer_upload(ref, 0, fdepth, (uint64_t)n * 4);
            track_set_reference_gpu(t, ref, &T[k - 1]);
            bf_frame f = {.index = k, .width = K.width, .height = K.height, .depth = depth[k]};
            track_result r;
            double t0 = bf_time_s();
            track_frame(t, &f, &T[k - 1], &r);
            c[k - 1] = 1e3 * (bf_time_s() - t0);
            a[k - 1] = r.ms_rof;
            b[k - 1] = r.ms_gpu;
            iters += r.iterations;
            if (r.outcome != TRACK_OK) fails++;
            bf_se3 ti = bf_se3_inverse(&T[k]), err = bf_se3_mul(&ti, &r.T_wc);
            e[k - 1] = 1e3 * bf_v3_norm(err.t);
            g[k - 1] = bf_se3_angle(&err) * 180 / M_PI;
            emax = fmax(emax, e[k - 1]);
            gmax = fmax(gmax, g[k - 1]);
        }
        printf("| %s | %.2f | %.2f | %.2f | %.1f | %.2f / %.2f | %.3f / %.3f | %u |\n", vars[v].name,
               median(a, n_frames), median(b, n_frames), median(c, n_frames), (double)iters / n_frames,
               median(e, n_frames), emax, median(g, n_frames), gmax, fails);
        fflush(stdout);
        track_destroy(t);
    }

    /* The real pair. */
    char path[512];
    uint16_t *d1 = NULL, *d2 = NULL;
    uint32_t w, hh;
    snprintf(path, sizeof path, "%s/../shared/data/tum/frames/fr2_desk_b1_depth.png", BF_SOURCE_DIR);
    bool have = replay_png_read_u16(path, &d1, &w, &hh) == BF_OK;
    snprintf(path, sizeof path, "%s/../shared/data/tum/frames/fr2_desk_b2_depth.png", BF_SOURCE_DIR);
    have = have && replay_png_read_u16(path, &d2, &w, &hh) == BF_OK;
    if (have) {
        bf_intrinsics Kt = {w, hh, 520.9, 521.0, 325.1, 249.7, 5000};
        track_config cfg = track_config_default();
        track_tracker *t;
        if (track_create(ctx, &cfg, &Kt, &t) == BF_OK) {
            bf_se3 I = bf_se3_identity();
            bf_frame f1 = {.width = w, .height = hh, .depth = d1}, f2 = {.index = 1, .width = w, .height = hh, .depth = d2};
            track_result r;
            double wall = 0;
            for (int rep = 0; rep < 5; rep++) {
                track_set_reference_frame(t, &f1, &I);
                double t0 = bf_time_s();
                track_frame(t, &f2, &I, &r);
                wall = 1e3 * (bf_time_s() - t0);
            }
            bf_quat q;
            bf_vec3 tr;
            bf_se3_to_qt(&r.T_wc, &q, &tr);
            printf("\nTUM fr2_desk b1 -> b2: %s, t = (%.1f, %.1f, %.1f) mm, %.3f deg, %u/%u inliers, rms %.2f mm, "
                   "%u iterations, ROF %.2f ms, ICP %.2f ms GPU, %.2f ms wall\n",
                   track_outcome_name(r.outcome), 1e3 * tr.x, 1e3 * tr.y, 1e3 * tr.z, bf_quat_angle(q) * 180 / M_PI,
                   r.n_inliers, r.n_valid, 1e3 * r.residual_m, r.iterations, r.ms_rof, r.ms_gpu, wall);
            track_destroy(t);
        }
    }
    free(d1), free(d2);
    free(a), free(b), free(c), free(e), free(g), free(h), free(fdepth);
    gpu_buffer_destroy(ref);
    gpu_context_destroy(ctx);
    for (uint32_t k = 0; k <= n_frames; k++) free(depth[k]);
    free(depth), free(T);
    eval_renderer_destroy(ren);
    eval_scene_free(&scene);
    return 0;
}
