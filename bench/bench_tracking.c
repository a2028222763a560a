/* Benchmark of tracking/ at 640x480: ROF smoothing of the reference and
 * ICP (frame pyramids + all levels), GPU time from timestamps and wall
 * time, against accuracy, for several iteration counts. Frames are the
 * synthetic room with Kinect v1 noise along a hand-held sway (about 1 cm
 * and 1 degree per frame); each frame is tracked against the previous one,
 * given as a float depth buffer on the GPU (as a ray-cast would be), from
 * the previous true pose. Then the real TUM fr2_desk b1 -> b2 pair.
 *
 *   build/bench/bench_tracking [--frames N] [--quick] [--profile]
 *   (--quick: the default only; --profile: track_config.profile, every dispatch's GPU time)
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "synth/synth.h"
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
    uint32_t sub;  /* finest_sample_step */
    float angle;   /* 0: the default gate */
    uint32_t rof_level;
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
    bool quick = false, profile = false;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--frames") && i + 1 < argc) n_frames = (uint32_t)atoi(argv[++i]);
        else if (!strcmp(argv[i], "--quick")) quick = true; /* the default variant only */
        else if (!strcmp(argv[i], "--profile")) profile = true;
    }
    bf_intrinsics K = {640, 480, 525, 525, 319.5, 239.5, 5000};
    uint32_t n = K.width * K.height;
    synth_scene scene;
    synth_renderer *ren;
    synth_render_config rc = {.K = K, .noise = SYNTH_NOISE_KINECT1, .seed = 5};
    if (synth_scene_room(NULL, &scene) != BF_OK || synth_renderer_create(&scene, &rc, &ren) != BF_OK) {
        fprintf(stderr, "bench_tracking: scene: %s\n", bf_last_error());
        return 1;
    }
    uint16_t **depth = calloc(n_frames + 1, sizeof *depth);
    bf_se3 *T = calloc(n_frames + 1, sizeof *T);
    for (uint32_t k = 0; k <= n_frames; k++) {
        depth[k] = malloc(n * 2);
        T[k] = sway(&scene.T_wc_view, k);
        if (synth_render(ren, k, &T[k], depth[k], NULL, NULL) != BF_OK) return 1;
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
        {"default (10/5/4, ROF 10 at level 1, gate 45, every pixel)", {10, 5, 4}, 10, false, 1, 0, 1},
        {"ROF 10 at full resolution", {10, 5, 4}, 10, false, 1, 0, 0},
        {"ROF 5 at level 1", {10, 5, 4}, 5, false, 1, 0, 1},
        {"ROF off", {10, 5, 4}, 0, false, 1, 0, 1},
        {"finest level every 2nd pixel", {10, 5, 4}, 10, false, 2, 0, 1},
        {"no early stop", {10, 5, 4}, 10, true, 1, 0, 1},
        {"2/4/8", {2, 4, 8}, 10, false, 1, 0, 1},
        {"normal gate 20 deg", {10, 5, 4}, 10, false, 1, 20, 1},
    };
    enum { NV = sizeof vars / sizeof vars[0] };
    printf("device: %s, 640x480, %u frames of the noisy room (~1 cm, ~1 deg per frame); variants interleaved frame by "
           "frame (the machine is shared), medians\n\n",
           gpu_device_name(ctx), n_frames);
    printf("| variant | reference ms (GPU: ROF / all) | frame preprocessing ms (GPU) | ICP ms (GPU, incl. frame) | "
           "track_frame wall ms | iterations | error mm (median / max) | error deg (median / max) | failures |\n"
           "|---|---|---|---|---|---|---|---|---|\n");
    size_t n_vars = quick ? 1 : NV;
    track_tracker *tv[NV] = {0};
    double *m[NV][7];
    uint32_t fails[NV] = {0}, iters[NV] = {0};
    for (size_t v = 0; v < n_vars; v++) {
        track_config cfg = track_config_default();
        cfg.profile = profile;
        memcpy(cfg.iterations, vars[v].it, sizeof cfg.iterations);
        cfg.rof_iterations = vars[v].rof;
        cfg.finest_sample_step = vars[v].sub;
        cfg.rof_level = vars[v].rof_level;
        if (vars[v].angle > 0) cfg.angle_deg = vars[v].angle;
        if (vars[v].no_early_stop) cfg.converged_m = cfg.converged_deg = 0;
        if (track_create(ctx, &cfg, &K, &tv[v]) != BF_OK) {
            fprintf(stderr, "bench_tracking: %s\n", bf_last_error());
            return 1;
        }
        for (int j = 0; j < 7; j++) m[v][j] = calloc(n_frames, sizeof(double));
    }
    for (uint32_t k = 1; k <= n_frames; k++) {
        for (uint32_t i = 0; i < n; i++) fdepth[i] = (float)(depth[k - 1][i] / K.depth_scale);
        gpu_buffer_upload(ref, 0, fdepth, (uint64_t)n * 4);
        for (size_t v = 0; v < n_vars; v++) {
            track_tracker *t = tv[v];
            track_set_reference_gpu(t, ref, &T[k - 1]);
            bf_frame f = {.index = k, .width = K.width, .height = K.height, .depth = depth[k]};
            track_result r;
            double t0 = bf_time_s();
            track_frame(t, &f, &T[k - 1], &r);
            double wall = 1e3 * (bf_time_s() - t0);
            iters[v] += r.iterations;
            if (r.outcome != TRACK_OK) fails[v]++;
            bf_se3 ti = bf_se3_inverse(&T[k]), err = bf_se3_mul(&ti, &r.T_wc);
            double row[7] = {r.ms_rof, r.ms_ref, r.ms_frame, r.ms_gpu, wall, 1e3 * bf_v3_norm(err.t),
                             bf_se3_angle(&err) * 180 / M_PI};
            for (int j = 0; j < 7; j++) m[v][j][k - 1] = row[j];
        }
    }
    for (size_t v = 0; v < n_vars; v++) {
        double emax = 0, gmax = 0;
        for (uint32_t k = 0; k < n_frames; k++) emax = fmax(emax, m[v][5][k]), gmax = fmax(gmax, m[v][6][k]);
        printf("| %s | %.1f / %.1f | %.1f | %.1f | %.1f | %.1f | %.2f / %.2f | %.3f / %.3f | %u |\n", vars[v].name,
               median(m[v][0], n_frames), median(m[v][1], n_frames), median(m[v][2], n_frames),
               median(m[v][3], n_frames), median(m[v][4], n_frames), (double)iters[v] / n_frames,
               median(m[v][5], n_frames), emax, median(m[v][6], n_frames), gmax, fails[v]);
        track_destroy(tv[v]);
        for (int j = 0; j < 7; j++) free(m[v][j]);
    }
    fflush(stdout);

    /* The real pair. */
    char path[512];
    uint16_t *d1 = NULL, *d2 = NULL;
    uint32_t w, hh;
    snprintf(path, sizeof path, "%s/../shared/data/tum/frames/fr2_desk_b1_depth.png", BF_SOURCE_DIR);
    bool have = replay_png_read_u16(path, &d1, &w, &hh) == BF_OK;
    snprintf(path, sizeof path, "%s/../shared/data/tum/frames/fr2_desk_b2_depth.png", BF_SOURCE_DIR);
    have = have && replay_png_read_u16(path, &d2, &w, &hh) == BF_OK;
    if (have) {
        /* The normal-angle gate and the finest level's sampling on the real
         * pair (no ground truth: forward b1 -> b2 composed with backward
         * b2 -> b1 should give the identity). */
        bf_intrinsics Kt = {w, hh, 520.9, 521.0, 325.1, 249.7, 5000};
        const float angles[] = {20, 25, 30, 35, 45, 60};
        printf("\nTUM fr2_desk b1 -> b2 (640x480, no ground truth):\n\n| gate deg | finest step | outcome | |t| mm | "
               "deg | inliers | rms mm | eig ratio | fwd x bwd mm / deg | iterations | ICP ms GPU | wall ms |\n"
               "|---|---|---|---|---|---|---|---|---|---|---|---|\n");
        for (size_t ai = 0; ai < sizeof angles / sizeof angles[0]; ai++)
            for (uint32_t sub = 1; sub <= 2; sub++) {
                if (quick && (ai > 0 || sub > 1)) continue;
                track_config cfg = track_config_default();
                cfg.profile = profile;
                cfg.angle_deg = angles[ai];
                cfg.finest_sample_step = sub;
                track_tracker *t;
                if (track_create(ctx, &cfg, &Kt, &t) != BF_OK) continue;
                bf_se3 I = bf_se3_identity();
                bf_frame f1 = {.width = w, .height = hh, .depth = d1};
                bf_frame f2 = {.index = 1, .width = w, .height = hh, .depth = d2};
                track_result r, rb;
                double wall[3];
                for (int rep = 0; rep < 3; rep++) {
                    track_set_reference_frame(t, &f1, &I);
                    double t0 = bf_time_s();
                    track_frame(t, &f2, &I, &r);
                    wall[rep] = 1e3 * (bf_time_s() - t0);
                }
                track_set_reference_frame(t, &f2, &I);
                track_frame(t, &f1, &I, &rb);
                bf_se3 c = bf_se3_mul(&r.T_wc, &rb.T_wc);
                printf("| %.0f | %u | %s%s | %.1f | %.2f | %.0f%% | %.2f | %.2g | %.2f / %.3f | %u | %.1f | %.1f |\n",
                       angles[ai], sub, track_outcome_name(r.outcome), r.degenerate ? " (degenerate)" : "",
                       1e3 * bf_v3_norm(r.T_wc.t), bf_se3_angle(&r.T_wc) * 180 / M_PI, 100 * r.inlier_frac,
                       1e3 * r.residual_m, r.eig_min / r.eig_max, 1e3 * bf_v3_norm(c.t), bf_se3_angle(&c) * 180 / M_PI,
                       r.iterations, r.ms_gpu, median(wall, 3));
                track_destroy(t);
            }
        /* Iteration schedules on the real pair (the default gate). */
        const uint32_t sched[][3] = {{10, 5, 4}, {3, 5, 8}, {2, 4, 8}};
        printf("\n| iterations | outcome | |t| mm | deg | inliers | rms mm | iterations run | ICP ms GPU | wall ms |\n"
               "|---|---|---|---|---|---|---|---|---|\n");
        for (size_t si = 0; si < sizeof sched / sizeof sched[0] && !quick; si++) {
            track_config cfg = track_config_default();
            cfg.profile = profile;
            memcpy(cfg.iterations, sched[si], sizeof cfg.iterations);
            track_tracker *t;
            if (track_create(ctx, &cfg, &Kt, &t) != BF_OK) continue;
            bf_se3 I = bf_se3_identity();
            bf_frame f1 = {.width = w, .height = hh, .depth = d1};
            bf_frame f2 = {.index = 1, .width = w, .height = hh, .depth = d2};
            track_result r;
            double wall[3];
            for (int rep = 0; rep < 3; rep++) {
                track_set_reference_frame(t, &f1, &I);
                double t0 = bf_time_s();
                track_frame(t, &f2, &I, &r);
                wall[rep] = 1e3 * (bf_time_s() - t0);
            }
            printf("| %u/%u/%u | %s%s | %.1f | %.2f | %.0f%% | %.2f | %u | %.1f | %.1f |\n", sched[si][0], sched[si][1],
                   sched[si][2], track_outcome_name(r.outcome), r.degenerate ? " (degenerate)" : "",
                   1e3 * bf_v3_norm(r.T_wc.t), bf_se3_angle(&r.T_wc) * 180 / M_PI, 100 * r.inlier_frac,
                   1e3 * r.residual_m, r.iterations, r.ms_gpu, median(wall, 3));
            track_destroy(t);
        }
    }
    free(d1), free(d2);
    free(fdepth);
    gpu_buffer_destroy(ref);
    gpu_context_destroy(ctx);
    for (uint32_t k = 0; k <= n_frames; k++) free(depth[k]);
    free(depth), free(T);
    synth_renderer_destroy(ren);
    synth_scene_free(&scene);
    return 0;
}
