/* Soak run of the full loop (issue 4): N frames (default 10,000) of a
 * synthetic room, rendered once into memory along a closed hand-held loop
 * and fed to the loop back and forth (ping-pong, so the motion stays
 * continuous), with the time per frame, the process's resident memory and
 * the map's bytes reported per block of frames. Time per frame and memory
 * must not grow beyond what the map itself needs.
 *
 *   bench_soak [--frames N] [--loop M] [--size WxH] [--block B] [--out FILE.tsv]
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "synth/synth.h"
#include "recon/recon.h"

static double rss_mib(void)
{
    FILE *f = fopen("/proc/self/statm", "r");
    long pages = 0, resident = 0;
    if (f) {
        if (fscanf(f, "%ld %ld", &pages, &resident) != 2) resident = 0;
        fclose(f);
    }
    return resident * (double)sysconf(_SC_PAGESIZE) / 1048576.0;
}

/* A closed hand-held loop: sway, bob and yaw, period M frames. */
static bf_se3 loop_pose(const synth_scene *sc, uint32_t k, uint32_t m)
{
    double w = 2 * M_PI * k / m;
    bf_se3 M = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0, 1, 0), -0.2 * sin(w)),
                              bf_v3(0.35 * sin(w), 0.03 * sin(2 * w), 0.15 * (1 - cos(w))));
    return bf_se3_mul(&sc->T_wc_view, &M);
}

int main(int argc, char **argv)
{
    uint32_t n = 10000, m = 300, block = 250, w = 640, h = 480;
    const char *out_path = "soak.tsv";
    for (int i = 1; i + 1 < argc; i += 2) {
        if (!strcmp(argv[i], "--frames")) n = (uint32_t)atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--loop")) m = (uint32_t)atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--block")) block = (uint32_t)atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--size")) sscanf(argv[i + 1], "%ux%u", &w, &h);
        else if (!strcmp(argv[i], "--out")) out_path = argv[i + 1];
        else {
            fprintf(stderr, "usage: bench_soak [--frames N] [--loop M] [--size WxH] [--block B] [--out FILE]\n");
            return 2;
        }
    }
    if (argc > 1 && (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h"))) {
        printf("usage: bench_soak [--frames N] [--loop M] [--size WxH] [--block B] [--out FILE.tsv]\n");
        return 0;
    }
    if (m < 2 || block < 1 || w < 16 || h < 16) return 2;
    double f_px = 525.0 * w / 640.0;
    bf_intrinsics K = {w, h, f_px, f_px, (w - 1) / 2.0, (h - 1) / 2.0, 5000};
    synth_scene sc = {0};
    synth_renderer *ren = NULL;
    gpu_context *ctx = NULL;
    recon *r = NULL;
    size_t np = (size_t)w * h;
    uint16_t *frames = malloc(np * m * sizeof *frames);
    bf_status s = frames ? synth_scene_room(NULL, &sc) : BF_NO_MEMORY;
    synth_render_config rc = {.K = K, .noise = SYNTH_NOISE_KINECT1, .seed = 5};
    if (s == BF_OK) s = synth_renderer_create(&sc, &rc, &ren);
    fprintf(stderr, "bench_soak: rendering a loop of %u frames at %ux%u\n", m, w, h);
    for (uint32_t k = 0; s == BF_OK && k < m; k++) {
        bf_se3 T = loop_pose(&sc, k, m);
        s = synth_render(ren, k, &T, frames + np * k, NULL, NULL);
    }
    gpu_config gcfg = {0};
    if (s == BF_OK) s = gpu_context_create(&gcfg, &ctx);
    recon_config cfg = recon_config_default();
    /* The synthetic sensor's disparity steps scale with 1/f: below 640
     * wide its depth is coarser than a Kinect's, so the residual gate widens
     * as in tests/tracking. */
    cfg.track.max_residual_m *= (float)(640.0 / w);
    bf_se3 T0 = loop_pose(&sc, 0, m);
    if (s == BF_OK) s = recon_create(ctx, &cfg, &K, &T0, &r);
    FILE *out = s == BF_OK ? fopen(out_path, "w") : NULL;
    if (s == BF_OK && !out) s = bf_fail(BF_IO, "%s: cannot create", out_path);
    if (out) fprintf(out, "frames\tms_median\tms_p95\trss_mib\tmap_mib\tbricks\ttracked\tlost\tmax_error_mm\n");
    bf_stats ms = {0};
    double max_err = 0;
    double t_start = bf_time_s();
    for (uint32_t i = 0; s == BF_OK && i < n; i++) {
        /* Ping-pong through the loop: 0..m-1, m-2..1, 0.. */
        uint32_t period = 2 * (m - 1), p = i % period, k = p < m ? p : period - p;
        bf_frame f = {.index = i, .width = w, .height = h, .t_depth_s = i / 30.0, .depth = frames + np * k};
        f.t_rgb_s = f.t_depth_s;
        recon_frame_result fr;
        if ((s = recon_add_frame(r, &f, &fr)) != BF_OK) break;
        bf_se3 T = loop_pose(&sc, k, m);
        double err = bf_v3_norm(bf_v3_sub(T.t, fr.T_wc.t));
        if (err > max_err) max_err = err;
        if ((s = bf_stats_push(&ms, fr.ms_frame)) != BF_OK) break;
        if ((i + 1) % block == 0 || i + 1 == n) {
            fusion_stats st;
            if ((s = fusion_get_stats(recon_map(r), &st)) != BF_OK) break;
            recon_counts c = recon_get_counts(r);
            fprintf(out, "%u\t%.2f\t%.2f\t%.1f\t%.2f\t%u\t%u\t%u\t%.2f\n", i + 1, bf_stats_percentile(&ms, 50),
                    bf_stats_percentile(&ms, 95), rss_mib(), st.bytes_total / 1048576.0, st.n_bricks, c.tracked,
                    c.lost, 1e3 * max_err);
            fflush(out);
            fprintf(stderr, "bench_soak: %u/%u frames, %.1f ms median, RSS %.0f MiB, map %.2f MiB, %u lost, "
                            "max error %.1f mm, %.0f s\n",
                    i + 1, n, bf_stats_percentile(&ms, 50), rss_mib(), st.bytes_total / 1048576.0, c.lost,
                    1e3 * max_err, bf_time_s() - t_start);
            bf_stats_free(&ms);
            memset(&ms, 0, sizeof ms);
            max_err = 0;
        }
    }
    if (s != BF_OK) fprintf(stderr, "bench_soak: %s: %s\n", bf_status_name(s), bf_last_error());
    bf_stats_free(&ms);
    if (out) fclose(out);
    recon_destroy(r);
    gpu_context_destroy(ctx);
    synth_renderer_destroy(ren);
    synth_scene_free(&sc);
    free(frames);
    return s == BF_OK ? 0 : 1;
}
