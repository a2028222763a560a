/* Speed of the integration kernel (not a test: run by hand, see
 * docs/fusion_integrate.md). Renders the synthetic room (synth/) along a short
 * hand-held path at 640x480, adds the frames to a map (allocation, sub-cache
 * and window passes as fusion_add_frame runs them), then times one window
 * pass over every live brick against all frames of the window, and checks a
 * sample of bricks against the CPU oracle on this noisy, real-sized input.
 *
 *   bench_fusion_integrate [n_frames [ratio [vpt [bpg,bpg,...]]]]   (defaults 20, 1, 0, 0)
 *   vpt 1|2|4|8|16 picks voxels per invocation (fusion_config.integrate_vpt;
 *   0: by device); a list of bricks per workgroup (integrate_bpg) compares
 *   them, interleaved.
 * Every timed pass reports the GPU timestamps (wall) and the CPU time the
 * process spent (lavapipe's worker threads): on a shared machine the CPU
 * time is the steadier of the two. */
#include <math.h>
#include <stdio.h>
#include <sys/resource.h>
#include <stdlib.h>
#include <string.h>

#include "synth/synth.h"
#include "fusion_ref.h"
#include "gpu/gpu.h"

static double cpu_seconds(void)
{
    struct rusage u;
    getrusage(RUSAGE_SELF, &u);
    return (double)u.ru_utime.tv_sec + 1e-6 * (double)u.ru_utime.tv_usec + (double)u.ru_stime.tv_sec +
           1e-6 * (double)u.ru_stime.tv_usec;
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

#define TRY(call)                                                                  \
    do {                                                                           \
        bf_status _s = (call);                                                     \
        if (_s != BF_OK) {                                                         \
            fprintf(stderr, "%s: %s (%s)\n", #call, bf_status_name(_s), bf_last_error()); \
            return 1;                                                              \
        }                                                                          \
    } while (0)

int main(int argc, char **argv)
{
    uint32_t n_frames = argc > 1 ? (uint32_t)atoi(argv[1]) : 20;
    float ratio = argc > 2 ? (float)atof(argv[2]) : 1.0f;
    uint32_t vpt = argc > 3 ? (uint32_t)atoi(argv[3]) : 0;
    if (n_frames < 2 || n_frames > 128) n_frames = 20;
    synth_scene scene;
    TRY(synth_scene_room(NULL, &scene));
    bf_intrinsics K = {.width = 640, .height = 480, .fx_px = 525, .fy_px = 525, .cx_px = 319.5, .cy_px = 239.5,
                       .depth_scale = 5000};
    synth_render_config rc = {.K = K, .noise = SYNTH_NOISE_KINECT1, .seed = 1};
    synth_renderer *rend;
    TRY(synth_renderer_create(&scene, &rc, &rend));
    gpu_config gc = {.validation = GPU_VALIDATION_OFF};
    gpu_context *ctx;
    TRY(gpu_context_create(&gc, &ctx));
    fusion_config cfg = fusion_config_default();
    cfg.window = n_frames + (n_frames & 1);
    if (cfg.subcache > cfg.window) cfg.subcache = cfg.window;
    cfg.brick_cap = 1u << 18;
    cfg.voxel_ratio = ratio;
    cfg.integrate_vpt = vpt;
    fusion_map *map;
    TRY(fusion_create(ctx, &cfg, &K, scene.T_wc_view.t, &map));

    uint16_t *depth = malloc((size_t)K.width * K.height * 2);
    for (uint32_t i = 0; i < n_frames; i++) {
        /* A slow hand-held drift: 1 cm and 0.3 degrees per frame. */
        double a = 0.005 * i;
        bf_quat q = bf_quat_from_axis_angle(bf_v3(0.3, 1, 0.1), a);
        bf_se3 d = bf_se3_from_qt(q, bf_v3(0.01 * i, 0.002 * i, 0.004 * i));
        bf_se3 T = bf_se3_mul(&scene.T_wc_view, &d);
        TRY(synth_render(rend, i, &T, depth, NULL, NULL));
        bf_frame f = {.index = i, .width = K.width, .height = K.height, .depth = depth};
        bf_status s = fusion_add_frame(map, &f, &T);
        if (s != BF_OK && s != BF_POOL_FULL) TRY(s);
    }

    /* Every live brick, as one list. */
    uint32_t cap = cfg.brick_cap;
    uint32_t *info = malloc((size_t)cap * 16), *list = malloc(((size_t)cap + FUSION_LIST_HEADER) * 4);
    TRY(gpu_buffer_download(map->info, 0, info, (uint64_t)cap * 16));
    uint32_t n = 0, per_level[16] = {0};
    for (uint32_t b = 0; b < cap; b++)
        if (info[b * 4 + FUSION_INFO_CHUNK] < map->n_entries) {
            list[FUSION_LIST_HEADER + n++] = b;
            per_level[fusion_pos_level(info[b * 4 + FUSION_INFO_POS]) & 15]++;
        }
    list[0] = n;
    TRY(gpu_buffer_upload(map->window_list, 0, list, ((uint64_t)n + FUSION_LIST_HEADER) * 4));
    printf("device %s, %u frames 640x480, ratio %.2g: %u bricks (levels:", gpu_device_name(ctx), n_frames, ratio, n);
    for (int l = 0; l < 16; l++)
        if (per_level[l]) printf(" %d:%u", l, per_level[l]);
    printf(")\n");

    /* Culled (brick, frame) pairs, on the CPU with the same test. */
    fusion_frame *frames = malloc((size_t)map->ring_slots * sizeof *frames);
    TRY(gpu_buffer_download(map->frames, 0, frames, (uint64_t)map->ring_slots * sizeof *frames));
    uint32_t *hash = malloc((size_t)map->n_entries * FUSION_ENTRY_WORDS * 4);
    TRY(gpu_buffer_download(map->hash, 0, hash, (uint64_t)map->n_entries * FUSION_ENTRY_WORDS * 4));
    uint64_t kept = 0;
    for (uint32_t k = 0; k < n; k++) {
        const uint32_t *in = info + (size_t)list[FUSION_LIST_HEADER + k] * 4;
        const uint32_t *e = hash + (size_t)in[FUSION_INFO_CHUNK] * FUSION_ENTRY_WORDS;
        uint32_t p = in[FUSION_INFO_POS], cell[3] = {fusion_pos_x(p), fusion_pos_y(p), fusion_pos_z(p)};
        float vm = fusion_voxel_m(cfg.chunk_m, fusion_pos_level(p)), lo[3], hi[3];
        for (int a = 0; a < 3; a++) {
            lo[a] = fusion_voxel_centre((int32_t)e[a], cell[a], 0, cfg.chunk_m, vm);
            hi[a] = fusion_voxel_centre((int32_t)e[a], cell[a], 7, cfg.chunk_m, vm);
        }
        for (uint32_t i = 0; i < n_frames; i++)
            kept += !fusion_box_culled(frames[i % map->ring_slots], lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]);
    }
    printf("box culling keeps %.1f%% of %llu (brick, frame) pairs\n", 100.0 * kept / ((double)n * n_frames),
           (unsigned long long)n * n_frames);

    /* A sample of bricks for the oracle, before the first timed pass. */
    enum { SAMPLE = 400 };
    uint32_t n_sample = n < SAMPLE ? n : SAMPLE;
    fusion_ref_brick *ref = malloc(n_sample * sizeof *ref);
    uint32_t *depth_ring = malloc(gpu_buffer_size(map->depth_ring));
    TRY(gpu_buffer_download(map->depth_ring, 0, depth_ring, gpu_buffer_size(map->depth_ring)));
    for (uint32_t k = 0; k < n_sample; k++) {
        uint32_t b = list[FUSION_LIST_HEADER + (uint32_t)((uint64_t)k * n / n_sample)];
        const uint32_t *in = info + (size_t)b * 4;
        const uint32_t *e = hash + (size_t)in[FUSION_INFO_CHUNK] * FUSION_ENTRY_WORDS;
        for (int a = 0; a < 3; a++) ref[k].key[a] = (int32_t)e[a];
        ref[k].pos = in[FUSION_INFO_POS];
        memcpy(&ref[k].error, &in[FUSION_INFO_ERROR], 4);
        TRY(gpu_buffer_download(map->sign, (uint64_t)b * 64, ref[k].sign, 64));
        TRY(gpu_buffer_download(map->conf, (uint64_t)b * 64, ref[k].conf, 64));
    }

    /* Variants (bricks per workgroup), interleaved run by run. */
    uint32_t bpg[8], n_var = 0;
    const char *bpg_arg = argc > 4 ? argv[4] : NULL;
    for (const char *c = bpg_arg; c && *c && n_var < 8;) {
        bpg[n_var++] = (uint32_t)strtoul(c, (char **)&c, 10);
        if (*c == ',') c++;
    }
    if (n_var == 0) n_var = 1, bpg[0] = 0;
    enum { RUNS = 7 };
    double ms[8][RUNS], cpu[8][RUNS];
    for (int r = 0; r < RUNS; r++)
        for (uint32_t k = 0; k < n_var; k++) {
            if (bpg[k]) map->integrate_bpg = bpg[k];
            double c0 = cpu_seconds();
            TRY(gpu_begin(ctx));
            gpu_cmd_stage_begin(ctx, "integrate");
            fusion__cmd_integrate(map, map->b_integrate_window, 0, n, 0, n_frames, true);
            gpu_cmd_stage_end(ctx);
            TRY(gpu_submit_wait(ctx));
            cpu[k][r] = 1e3 * (cpu_seconds() - c0);
            const gpu_stage_time *t;
            ms[k][r] = gpu_stage_times(ctx, &t) ? t[0].ms : NAN;
            if (r == 0 && k == 0) { /* the oracle on the sample, against the first pass */
                fusion_integrate_push pc = fusion__integrate_params(map, 0, n, 0, n_frames, true);
                uint32_t bad = 0, fragile = 0, bad_fragile = 0;
                for (uint32_t j = 0; j < n_sample; j++) {
                    uint32_t b = list[FUSION_LIST_HEADER + (uint32_t)((uint64_t)j * n / n_sample)];
                    uint32_t sign[16], conf[16];
                    TRY(gpu_buffer_download(map->sign, (uint64_t)b * 64, sign, 64));
                    TRY(gpu_buffer_download(map->conf, (uint64_t)b * 64, conf, 64));
                    fusion_ref_margins mg;
                    fusion_ref_integrate(&pc, frames, depth_ring, &ref[j], &mg);
                    fragile += mg.n_fragile;
                    for (int w = 0; w < 16; w++) {
                        uint32_t d = (sign[w] ^ ref[j].sign[w]) | (conf[w] ^ ref[j].conf[w]);
                        bad += (uint32_t)__builtin_popcount(d & ~mg.fragile[w]);
                        bad_fragile += (uint32_t)__builtin_popcount(d & mg.fragile[w]);
                    }
                }
                printf("oracle on %u bricks: %u voxels differ (+%u of %u fragile)\n", n_sample, bad, bad_fragile,
                       fragile);
            }
        }
    for (uint32_t k = 0; k < n_var; k++) {
        qsort(ms[k], RUNS, sizeof ms[k][0], cmp_double);
        qsort(cpu[k], RUNS, sizeof cpu[k][0], cmp_double);
        printf("window pass, %u frames, bpg %u: wall median %.1f ms (min %.1f, max %.1f) = %.3f us per (brick, frame); "
               "cpu median %.1f ms (min %.1f) = %.3f us per (brick, frame)\n",
               n_frames, bpg[k], ms[k][RUNS / 2], ms[k][0], ms[k][RUNS - 1], 1000.0 * ms[k][RUNS / 2] / n / n_frames,
               cpu[k][RUNS / 2], cpu[k][0], 1000.0 * cpu[k][RUNS / 2] / n / n_frames);
    }
    /* Fewer frames: the per-brick part of the cost against the per-frame part. */
    for (uint32_t nf = 0; nf < n_frames; nf = nf ? nf * 4 : 1) {
        double c3[3];
        for (int r = 0; r < 3; r++) {
            double c0 = cpu_seconds();
            TRY(gpu_begin(ctx));
            gpu_cmd_stage_begin(ctx, "integrate");
            fusion__cmd_integrate(map, map->b_integrate_window, 0, n, 0, nf, true);
            gpu_cmd_stage_end(ctx);
            TRY(gpu_submit_wait(ctx));
            c3[r] = 1e3 * (cpu_seconds() - c0);
            const gpu_stage_time *t;
            ms[0][r] = gpu_stage_times(ctx, &t) ? t[0].ms : NAN;
        }
        qsort(ms[0], 3, sizeof ms[0][0], cmp_double);
        qsort(c3, 3, sizeof c3[0], cmp_double);
        printf("window pass, %u frames: wall median %.1f ms = %.2f us per brick; cpu median %.1f ms = %.2f us per brick\n",
               nf, ms[0][1], 1000.0 * ms[0][1] / n, c3[1], 1000.0 * c3[1] / n);
    }

    free(depth_ring);
    free(ref);
    free(hash);
    free(frames);
    free(info);
    free(list);
    free(depth);
    fusion_destroy(map);
    gpu_context_destroy(ctx);
    synth_renderer_destroy(rend);
    synth_scene_free(&scene);
    return 0;
}
