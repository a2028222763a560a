/* Benchmark of the ray-caster (render/): a 640x480 ray-cast of the
 * synthetic room fused from noisy frames, GPU time by Vulkan timestamps
 * (median and p95 of N casts) for the tracking and display options, at a
 * fused pose and at one between fused poses.
 *
 *   build/bench/bench_render [--frames N] [--runs N] [--ratio R] [--wg 8x8,4x2,...]
 *
 * --wg compares workgroup shapes (render_config.local_x, local_y),
 * interleaved run by run.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>

#include "synth/synth.h"
#include "fusion/fusion.h"
#include "render/render.h"

/* CPU time of the whole process [ms]: lavapipe runs the shaders on this
 * process's threads, so this is the work done, whatever else loads the
 * machine (the GPU timestamps are wall time and grow with the load). */
static double cpu_ms(void)
{
    struct rusage ru;
    getrusage(RUSAGE_SELF, &ru);
    return 1e3 * (ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) + 1e-3 * (ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
}

/* Up to 8 workgroup shapes, compared interleaved: run r casts with every
 * shape before run r + 1, so the machine's load drifts over all alike. */
#define MAX_SHAPES 8

static bf_status cast_times(render_caster **rc, uint32_t n_rc, fusion_map *map, const bf_intrinsics *K,
                            const bf_se3 *T, const render_options *opt, uint32_t runs, double *median_ms,
                            double *p95_ms, double *cpu_median_ms, double *hit_share)
{
    bf_stats st[MAX_SHAPES] = {{0}}, cpu[MAX_SHAPES] = {{0}};
    bf_status s = BF_OK;
    for (uint32_t r = 0; r < runs && s == BF_OK; r++)
        for (uint32_t v = 0; v < n_rc && s == BF_OK; v++) {
            double c0 = cpu_ms();
            s = render_raycast(rc[v], map, K, T, opt);
            double c1 = cpu_ms();
            if (s == BF_OK) s = bf_stats_push(&st[v], render_last_ms(rc[v]));
            if (s == BF_OK) s = bf_stats_push(&cpu[v], c1 - c0);
        }
    for (uint32_t v = 0; v < n_rc; v++) {
        cpu_median_ms[v] = bf_stats_percentile(&cpu[v], 50);
        median_ms[v] = bf_stats_percentile(&st[v], 50);
        p95_ms[v] = bf_stats_percentile(&st[v], 95);
        bf_stats_free(&cpu[v]);
        bf_stats_free(&st[v]);
    }
    render_images im = {0};
    if (s == BF_OK) s = render_download(rc[0], &im);
    if (s == BF_OK) {
        size_t n = 0, np = (size_t)im.width * im.height;
        for (size_t i = 0; i < np; i++) n += im.depth[i] > 0;
        *hit_share = (double)n / np;
    }
    render_images_free(&im);
    return s;
}

int main(int argc, char **argv)
{
    uint32_t n_frames = 20, runs = 15;
    double ratio = 1.0;
    const char *shapes = "8x8";
    for (int i = 1; i + 1 < argc; i += 2) {
        if (!strcmp(argv[i], "--wg")) shapes = argv[i + 1];
        if (!strcmp(argv[i], "--frames")) n_frames = (uint32_t)atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--runs")) runs = (uint32_t)atoi(argv[i + 1]);
        else if (!strcmp(argv[i], "--ratio")) ratio = atof(argv[i + 1]);
    }
    if (n_frames < 2) n_frames = 2;
    const bf_intrinsics K = {640, 480, 525, 525, 319.5, 239.5, 5000};
    synth_scene scene = {0};
    gpu_context *ctx = NULL;
    synth_renderer *ren = NULL;
    fusion_map *map = NULL;
    render_caster *rc[MAX_SHAPES] = {0};
    char shape[MAX_SHAPES][16];
    uint32_t n_rc = 0;
    uint16_t *depth = malloc((size_t)K.width * K.height * 2);
    bf_se3 *poses = malloc(n_frames * sizeof *poses);
    bf_status s = synth_scene_room(NULL, &scene);
    if (s != BF_OK) goto done;
    synth_render_config rcfg = {.K = K, .noise = SYNTH_NOISE_KINECT1, .seed = 1};
    if ((s = synth_renderer_create(&scene, &rcfg, &ren)) != BF_OK) goto done;
    gpu_config gc = {0};
    if ((s = gpu_context_create(&gc, &ctx)) != BF_OK) goto done;
    fusion_config fc = fusion_config_default();
    fc.voxel_ratio = (float)ratio;
    fc.brick_cap = 1u << 18;
    double t_fuse = 0;
    for (uint32_t k = 0; k < n_frames && s == BF_OK; k++) {
        /* Sway 30 cm sideways around the room's viewpoint (bench_eval's path). */
        bf_se3 step = bf_se3_from_qt(bf_quat_identity(), bf_v3(0.3 * sin(0.2 * k), 0, 0));
        poses[k] = bf_se3_mul(&scene.T_wc_view, &step);
        if ((s = synth_render(ren, k, &poses[k], depth, NULL, NULL)) != BF_OK) break;
        if (!map && (s = fusion_create(ctx, &fc, &K, poses[0].t, &map)) != BF_OK) break;
        bf_frame f = {.index = k, .width = K.width, .height = K.height, .depth = depth};
        double t0 = bf_time_s();
        s = fusion_add_frame(map, &f, &poses[k]);
        t_fuse += bf_time_s() - t0;
    }
    if (s == BF_OK) s = fusion_flush(map);
    fusion_stats fs;
    if (s == BF_OK) s = fusion_get_stats(map, &fs);
    for (const char *p = shapes; s == BF_OK && *p && n_rc < MAX_SHAPES;) {
        size_t len = strcspn(p, ",");
        snprintf(shape[n_rc], sizeof shape[n_rc], "%.*s", (int)(len < 15 ? len : 15), p);
        render_config rcfg = render_config_default();
        if (sscanf(shape[n_rc], "%ux%u", &rcfg.local_x, &rcfg.local_y) != 2) {
            s = bf_fail(BF_INVALID_ARG, "bench_render: --wg %s is not WxH", shape[n_rc]);
            break;
        }
        s = render_create(ctx, &rcfg, K.width, K.height, &rc[n_rc]);
        if (s == BF_OK) n_rc++;
        p += len + (p[len] == ',');
    }
    if (s != BF_OK) goto done;
    printf("# render bench: %s, room fused from %u frames 640x480 (ratio %.2g, %.0f ms/frame), %u bricks\n\n",
           gpu_device_name(ctx), n_frames, ratio, 1e3 * t_fuse / n_frames, fs.n_bricks);
    printf("| pose | options | workgroup | GPU median ms | GPU p95 ms | CPU ms (all threads) | pixels hit |\n"
           "|---|---|---|---|---|---|---|\n");
    bf_se3 between = bf_se3_interpolate(&poses[n_frames / 2 - 1], &poses[n_frames / 2], 0.5);
    const struct {
        const char *name;
        const bf_se3 *T;
    } where[2] = {{"fused", &poses[n_frames / 2]}, {"between", &between}};
    for (int w = 0; w < 2 && s == BF_OK; w++)
        for (int m = 0; m < 3 && s == BF_OK; m++) {
            /* tracking, tracking without the sub-voxel refinement (what it
             * costs), display */
            render_options opt = m == 2 ? render_options_display() : render_options_tracking();
            if (m == 1) opt.refine = false;
            const char *name = m == 0 ? "tracking" : (m == 1 ? "tracking, unrefined" : "display");
            double med[MAX_SHAPES], p95[MAX_SHAPES], cpu[MAX_SHAPES], hit = 0;
            s = cast_times(rc, n_rc, map, &K, where[w].T, &opt, runs, med, p95, cpu, &hit);
            for (uint32_t v = 0; s == BF_OK && v < n_rc; v++)
                printf("| %s | %s | %s | %.2f | %.2f | %.1f | %.1f%% |\n", where[w].name, name, shape[v], med[v],
                       p95[v], cpu[v], 100 * hit);
            fflush(stdout);
        }
done:
    if (s != BF_OK) fprintf(stderr, "bench_render: %s: %s\n", bf_status_name(s), bf_last_error());
    for (uint32_t v = 0; v < n_rc; v++) render_destroy(rc[v]);
    fusion_destroy(map);
    gpu_context_destroy(ctx);
    synth_renderer_destroy(ren);
    synth_scene_free(&scene);
    free(depth);
    free(poses);
    return s == BF_OK ? 0 : 1;
}
