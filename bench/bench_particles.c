/* The particle renderer on a moving set: binned once (render_particles_create),
 * then re-binned per time step (render_particles_update), each step the
 * particles moved by a swirl about the set's middle. Prints one row per
 * step: host binning, into the GPU pools, M particles/s binned, bricks,
 * whether the map was made anew, and (with --cast) the ray-cast's GPU time.
 *   bench_particles [--ply FILE | --random N] [--radius M] [--cell M] [--steps K] [--cast WxH]
 *                   [--no-host-import]
 * --no-host-import: the driver's own memory for the pools (gpu_config.no_host_import).
 * --random N: uniform in 2 x 1 x 1 m (bench/particles_sweep.sh's sets). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mesh/mesh.h"
#include "render/render.h"

/* A fixed generator: the sets are the same on every run. */
static float *random_set(uint64_t n)
{
    float *xyz = malloc(n * 12);
    if (!xyz) return NULL;
    uint64_t x = 0x9E3779B97F4A7C15ull;
    for (uint64_t i = 0; i < 3 * n; i++) {
        x ^= x << 13, x ^= x >> 7, x ^= x << 17;
        xyz[i] = (float)((double)(x >> 11) / 9007199254740992.0 * (i % 3 == 0 ? 2.0 : 1.0));
    }
    return xyz;
}

/* One step of a swirl about the vertical axis through (cx, cy): a particle
 * turns by an angle falling off with its distance (the inside faster), so
 * the set shears and no two steps bin alike. */
static void swirl(float *xyz, uint64_t n, double cx, double cy, double step)
{
    for (uint64_t i = 0; i < n; i++) {
        double x = xyz[3 * i] - cx, y = xyz[3 * i + 1] - cy, r = sqrt(x * x + y * y);
        double a = step / (0.2 + r), c = cos(a), s = sin(a);
        xyz[3 * i] = (float)(cx + c * x - s * y);
        xyz[3 * i + 1] = (float)(cy + s * x + c * y);
    }
}

int main(int argc, char **argv)
{
    const char *ply = BF_SOURCE_DIR "/../shared/data/particles/dambreak_29814.ply";
    uint64_t n_random = 0;
    render_particles_config pc = render_particles_config_default();
    uint32_t steps = 5, W = 0, H = 0;
    gpu_config gc = {0};
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--ply") && i + 1 < argc) ply = argv[++i];
        else if (!strcmp(argv[i], "--random") && i + 1 < argc) n_random = strtoull(argv[++i], NULL, 10);
        else if (!strcmp(argv[i], "--radius") && i + 1 < argc) pc.radius_m = (float)atof(argv[++i]);
        else if (!strcmp(argv[i], "--cell") && i + 1 < argc) pc.cell_m = (float)atof(argv[++i]);
        else if (!strcmp(argv[i], "--steps") && i + 1 < argc) steps = (uint32_t)atoi(argv[++i]);
        else if (!strcmp(argv[i], "--cast") && i + 1 < argc && sscanf(argv[++i], "%ux%u", &W, &H) == 2) continue;
        else if (!strcmp(argv[i], "--no-host-import")) gc.no_host_import = true;
        else {
            fprintf(stderr, "usage: %s [--ply FILE | --random N] [--radius M] [--cell M] [--steps K] [--cast WxH] "
                    "[--no-host-import]\n", argv[0]);
            return 2;
        }
    }
    mesh_data m = {0};
    float *xyz;
    uint64_t n;
    if (n_random) {
        xyz = random_set(n_random), n = n_random;
    } else {
        if (mesh_read_ply(ply, &m) != BF_OK) {
            fprintf(stderr, "bench_particles: %s\n", bf_last_error());
            return 1;
        }
        xyz = m.xyz, n = m.n_verts;
    }
    if (!xyz) return 1;
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint64_t i = 0; i < 3 * n; i++) lo[i % 3] = fmin(lo[i % 3], xyz[i]), hi[i % 3] = fmax(hi[i % 3], xyz[i]);
    double cx = 0.5 * (lo[0] + hi[0]), cy = 0.5 * (lo[1] + hi[1]);
    gpu_context *ctx;
    if (gpu_context_create(&gc, &ctx) != BF_OK) {
        fprintf(stderr, "bench_particles: %s\n", bf_last_error());
        return 1;
    }
    render_caster *rc = NULL;
    bf_intrinsics K = {W, H, 0.8 * W, 0.8 * W, 0.5 * W - 0.5, 0.5 * H - 0.5, 5000};
    /* From the side, 2.5 set widths away, a little above. */
    double span = fmax(hi[0] - lo[0], hi[1] - lo[1]);
    bf_se3 T = bf_se3_identity();
    double R[3][3] = {{1, 0, 0}, {0, 0, 1}, {0, -1, 0}}; /* camera z along world +y, image y down world -z */
    memcpy(T.R, R, sizeof R);
    T.t = bf_v3(cx, lo[1] - 2.5 * span, 0.5 * (lo[2] + hi[2]));
    render_options opt = render_options_display();
    opt.far_m = 20;
    if (W && render_create(ctx, NULL, W, H, &rc) != BF_OK) return 1;
    printf("| step | particles | bricks (+ coarse) | binning [ms] | binning [CPU ms] | into the pools [ms] | map made [ms] | whole step [ms] | M particles/s binned | M particles/s whole step | ray-cast [ms GPU] |\n");
    printf("|---|---|---|---|---|---|---|---|---|---|---|\n");
    render_particles *ps = NULL;
    int rc_out = 0;
    for (uint32_t k = 0; k <= steps; k++) {
        double t0 = bf_time_s();
        bf_status s = k == 0 ? render_particles_create(ctx, &pc, xyz, n, &ps) : render_particles_update(ps, xyz, n);
        double step_s = bf_time_s() - t0;
        if (s == BF_OK && rc) s = render_scene(rc, NULL, ps, &K, &T, &opt);
        if (s != BF_OK) {
            fprintf(stderr, "bench_particles: step %u: %s\n", k, bf_last_error());
            rc_out = 1;
            break;
        }
        const render_particles_stats *st = render_particles_get_stats(ps);
        char made[32] = "no";
        if (st->map_made) snprintf(made, sizeof made, "%.1f", 1e3 * st->make_s);
        printf("| %u | %llu | %u (+%u) | %.1f | %.1f | %.1f | %s | %.1f | %.2f | %.2f | %.1f |\n", k, (unsigned long long)n,
               st->n_bricks, st->n_coarse_bricks, 1e3 * st->bin_s, 1e3 * st->bin_cpu_s, 1e3 * st->load_s, made, 1e3 * step_s,
               n / st->bin_s / 1e6, n / step_s / 1e6, rc ? render_particles_last_ms(ps) : 0.0);
        fflush(stdout);
        swirl(xyz, n, cx, cy, 0.02);
    }
    render_particles_destroy(ps);
    render_destroy(rc);
    gpu_context_destroy(ctx);
    if (n_random) free(xyz);
    else mesh_free(&m);
    return rc_out;
}
