/* Tests of the windowed integration (fusion/integrate.c,
 * shaders/fusion_integrate.comp): the shared per-voxel functions alone, then
 * the GPU kernel against the CPU oracle tests/fusion/integrate_ref.c bit for bit on
 * small synthetic scenes, then physics checks. Validation is on and any
 * message fails a test.
 *
 * Why bit-exactness is fair: every float operation of the rule is an add, a
 * multiply or a conversion, correctly rounded on both sides (Vulkan's
 * precision table; BF_PRECISE forbids contraction, C builds with
 * -ffp-contract=off), except the divisions (projection, ramp weight, prior
 * ratio), which Vulkan allows 2.5 ulp. A division's error moves a pixel
 * coordinate by < 1e-5 px in these 64x48 images and a voxel's sums by a
 * relative ~1e-7, so it can flip a bit only where the exact value lies within
 * that of a decision: the oracle flags such voxels "fragile" (within 1e-4 of
 * a pixel edge that changes the depth, or of the sign or confidence
 * boundary) and every other voxel must match exactly. The scenes are built so
 * fragile voxels are rare (each test bounds them), and the window error is an
 * integer mean, exact on both sides. */
#include "test.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "fusion_ref.h"
#include "gpu/gpu.h"

/* Under ASan, tests/test_main.c pins the validation layer and suppresses its leaks. */

/* ------------------------------------------------------------ shared functions */

static fusion_frame identity_frame(void)
{
    fusion_frame f = {.R = {1, 0, 0, 0, 1, 0, 0, 0, 1}, .fx = 60, .fy = 60, .cx = 31.5f, .cy = 23.5f,
                      .depth_unit_m = 0.001f, .width = 64, .height = 48, .index = 0};
    return f;
}

BF_TEST(observe_weights_follow_the_rule)
{
    float a = 0.008f, b = 0.0019f, c = 0.4f;
    float sigma = bf_sensor_sigma(1.0f, a, b, c);
    /* Free space: W = 1, D clamped to +sigma. */
    fusion_obs o = fusion_observe(1000, 0.001f, 0.9f, a, b, c);
    CHECK_EQ_INT(o.w, 1);
    CHECK(o.wd == sigma);
    /* Just in front: W = 1, D itself. */
    o = fusion_observe(1000, 0.001f, 0.998f, a, b, c);
    CHECK(o.w == 1.0f);
    CHECK_NEAR(o.wd, 0.002, 1e-6);
    /* Behind by a quarter sigma: W = 1, D itself (the clamp is symmetric). */
    o = fusion_observe(1000, 0.001f, 1.0f + 0.25f * sigma, a, b, c);
    CHECK(o.w == 1.0f);
    CHECK_NEAR(o.wd, -0.25 * sigma, 1e-7);
    /* Behind by 1.5 sigma: W = 1, D clamped to -sigma. */
    o = fusion_observe(1000, 0.001f, 1.0f + 1.5f * sigma, a, b, c);
    CHECK(o.w == 1.0f);
    CHECK_NEAR(o.wd, -sigma, 1e-7);
    /* Behind by 2.25 sigma: the fade-out (3 sigma + D)/sigma = 0.75, D clamped. */
    o = fusion_observe(1000, 0.001f, 1.0f + 2.25f * sigma, a, b, c);
    CHECK_NEAR(o.w, 0.75, 1e-4);
    CHECK_NEAR(o.wd, -0.75 * sigma, 1e-6);
    /* Occluded and invalid. */
    o = fusion_observe(1000, 0.001f, 1.0f + 3.01f * sigma, a, b, c);
    CHECK(o.w == 0.0f && o.wd == 0.0f);
    o = fusion_observe(0, 0.001f, 0.5f, a, b, c);
    CHECK(o.w == 0.0f && o.wd == 0.0f);
    /* Symmetry: D and -D within sigma give opposite sums of equal weight. */
    fusion_obs f1 = fusion_observe(1000, 0.001f, 1.0f - 0.5f * sigma, a, b, c);
    fusion_obs f2 = fusion_observe(1000, 0.001f, 1.0f + 0.5f * sigma, a, b, c);
    CHECK(f1.w == f2.w);
    CHECK_NEAR(f1.wd, -f2.wd, 1e-7);
}

BF_TEST(project_pixel_nearest_and_outside)
{
    fusion_frame f = identity_frame();
    fusion_point p = {0.0f, 0.0f, 1.0f}; /* u = 31.5: the edge between pixels 31 and 32 rounds up */
    CHECK_EQ_INT(fusion_project_pixel(f, p), 24 * 64 + 32);
    p.x = -31.4f / 60.0f; /* u = 0.1 */
    CHECK_EQ_INT(fusion_project_pixel(f, p) % 64, 0);
    p.x = -32.1f / 60.0f; /* u = -0.6: outside */
    CHECK_EQ_INT(fusion_project_pixel(f, p), FUSION_NONE);
    p.x = 0.0f;
    p.z = 0.0f;
    CHECK_EQ_INT(fusion_project_pixel(f, p), FUSION_NONE);
    p.z = -1.0f;
    CHECK_EQ_INT(fusion_project_pixel(f, p), FUSION_NONE);
    p.z = NAN;
    CHECK_EQ_INT(fusion_project_pixel(f, p), FUSION_NONE);
    p.z = 1.0f;
    p.x = NAN;
    CHECK_EQ_INT(fusion_project_pixel(f, p), FUSION_NONE);
}

BF_TEST(prior_sweep_and_phi)
{
    /* Voxel x = 3: other-sign confident voxel at x = 5 (2 steps), at z = 7 (4 steps: out of reach). */
    CHECK_EQ_INT(fusion_prior_steps(1u << 5, 0, 1u << 7, 3, 0, 3), 2);
    CHECK_EQ_INT(fusion_prior_steps(0, 0, 1u << 7, 3, 0, 3), 4);
    CHECK_EQ_INT(fusion_prior_steps(0, 1u << 0, 0, 3, 1, 3), 1);
    CHECK_EQ_INT(fusion_prior_steps(0, 0, 0, 0, 0, 0), FUSION_PRIOR_STEPS + 1);
    /* The voxel's own bit is never a neighbour. */
    CHECK_EQ_INT(fusion_prior_steps(1u << 3, 1u << 4, 1u << 5, 3, 4, 5), 4);
    CHECK(fusion_prior_phi(1, 1, 0.01f, 0.0f) == 0.005f);
    CHECK(fusion_prior_phi(0, 4, 0.01f, 0.0f) == -0.035f);
    CHECK(fusion_prior_phi(0, 4, 0.01f, 0.008f) == -0.008f); /* truncated at the band */
    CHECK(fusion_prior_phi(1, 1, 0.01f, 0.008f) == 0.005f);
    CHECK(fusion_prior_psi(2.0f, 0.01f, 0.005f) == 4.0f);
    CHECK(fusion_prior_psi(2.0f, 0.1f, 0.005f) == 8.0f);     /* clamped at 4x */
    CHECK(fusion_prior_psi(2.0f, 0.001f, 0.005f) == 0.5f);   /* clamped at 1/4 */
    CHECK(fusion_prior_psi(2.0f, 0.01f, INFINITY) == 2.0f);  /* a new brick: unscaled */
    CHECK(fusion_prior_psi(2.0f, 0.01f, NAN) == 2.0f);
    CHECK(fusion_prior_psi(2.0f, 0.0f, 0.005f) == 2.0f);
}

BF_TEST(decide_keeps_confident_voxels_unless_replaced)
{
    fusion_acc a = fusion_acc_zero();
    fusion_obs behind = {.w = 1.0f, .wd = -0.001f, .sigma = 0.002f};
    for (int i = 0; i < 5; i++) a = fusion_acc_add(a, behind);
    CHECK_EQ_INT(a.n, 5);
    CHECK_EQ_INT(a.sigma_um, 5 * 2000);
    /* Not confident, observed: new sign (0), confident (5 >= 4). */
    CHECK_EQ_INT(fusion_decide(1, 0, a, 0, 0, 4.0f, 1, 1), FUSION_DECIDE_CONF | FUSION_DECIDE_SET);
    /* Sub-cache: sign only, never confidence. */
    CHECK_EQ_INT(fusion_decide(1, 0, a, 0, 0, 4.0f, 0, 0), 0);
    /* Confident front voxel: kept when the window may not replace. */
    CHECK_EQ_INT(fusion_decide(1, 1, a, 2.0f, 0.005f, 4.0f, 1, 0), FUSION_DECIDE_SIGN | FUSION_DECIDE_CONF);
    /* Replaced when it may: 2 * 0.005 - 0.005 > 0 keeps the sign; a weaker prior loses it. */
    CHECK_EQ_INT(fusion_decide(1, 1, a, 2.0f, 0.005f, 4.0f, 1, 1),
                 FUSION_DECIDE_SIGN | FUSION_DECIDE_CONF | FUSION_DECIDE_SET);
    CHECK_EQ_INT(fusion_decide(1, 1, a, 0.5f, 0.005f, 4.0f, 1, 1), FUSION_DECIDE_CONF | FUSION_DECIDE_SET);
    /* Never touched in the sub-cache. */
    CHECK_EQ_INT(fusion_decide(1, 1, a, 0, 0, 4.0f, 0, 0), FUSION_DECIDE_SIGN | FUSION_DECIDE_CONF);
    /* No observation: unchanged. */
    fusion_acc z = fusion_acc_zero();
    CHECK_EQ_INT(fusion_decide(1, 0, z, 0, 0, 4.0f, 1, 1), FUSION_DECIDE_SIGN);
    CHECK_EQ_INT(fusion_decide(0, 0, z, 0, 0, 4.0f, 1, 1), 0);
    /* The replacement rule. */
    CHECK_EQ_INT(fusion_may_replace(1, 1, 0.004f, 0.003f), 0);
    CHECK_EQ_INT(fusion_may_replace(1, 1, 0.003f, 0.003f), 1);
    CHECK_EQ_INT(fusion_may_replace(1, 0, 0.004f, 0.003f), 1);
    CHECK_EQ_INT(fusion_may_replace(0, 0, 0.001f, 0.003f), 0);
    CHECK(fusion_window_error(4, 4 * 2500 + 3) == 2500 * 1.0e-6f);
    CHECK(fusion_window_error(0, 0) == 0.0f);
}

BF_TEST(box_cull_is_conservative)
{
    fusion_frame f = identity_frame();
    /* In view, behind, far left (u < -1.5 everywhere), straddling the left edge. */
    CHECK_EQ_INT(fusion_box_culled(f, -0.1f, -0.1f, 1.0f, 0.1f, 0.1f, 1.1f), 0);
    CHECK_EQ_INT(fusion_box_culled(f, -0.1f, -0.1f, -1.1f, 0.1f, 0.1f, -1.0f), 1);
    CHECK_EQ_INT(fusion_box_culled(f, -2.0f, -0.1f, 1.0f, -0.7f, 0.1f, 1.1f), 1);
    CHECK_EQ_INT(fusion_box_culled(f, -0.6f, -0.1f, 1.0f, -0.4f, 0.1f, 1.1f), 0);
    /* A box across the camera plane is never culled by the behind test. */
    CHECK_EQ_INT(fusion_box_culled(f, -0.1f, -0.1f, -0.5f, 0.1f, 0.1f, 0.5f), 0);
    /* Random boxes: a culled box has no voxel centre landing on a pixel. */
    uint32_t seed = 12345;
    int n_culled = 0;
    for (int t = 0; t < 2000; t++) {
        float lo[3], hi[3];
        for (int a = 0; a < 3; a++) {
            seed = seed * 1664525u + 1013904223u;
            lo[a] = ((float)(seed >> 8) / 16777216.0f) * 4.0f - 2.0f;
            hi[a] = lo[a] + 0.35f;
        }
        if (!fusion_box_culled(f, lo[0], lo[1], lo[2], hi[0], hi[1], hi[2])) continue;
        n_culled++;
        for (int v = 0; v < 512; v++) {
            float p[3] = {lo[0] + (hi[0] - lo[0]) * (float)(v & 7) / 7.0f,
                          lo[1] + (hi[1] - lo[1]) * (float)((v >> 3) & 7) / 7.0f,
                          lo[2] + (hi[2] - lo[2]) * (float)(v >> 6) / 7.0f};
            CHECK_EQ_INT(fusion_project_pixel(f, fusion_to_camera(f, p[0], p[1], p[2])), FUSION_NONE);
        }
    }
    CHECK(n_culled > 100);
}

/* ------------------------------------------------------------ GPU scenes */

enum { IMG_W = 64, IMG_H = 48, WINDOW = 8, RING = 2 * WINDOW, MAX_BRICKS = 256 };
#define FX 60.0
#define CX 31.5
#define CY 23.5
#define UNIT 0.001

typedef struct scene {
    gpu_context *ctx;
    fusion_map *map;
    uint32_t v0;
    uint32_t level;
    fusion_frame frames[RING];
    uint32_t depth[RING * (IMG_W * IMG_H / 2)];
    uint32_t n;
    uint32_t slot[MAX_BRICKS];
    fusion_ref_brick b[MAX_BRICKS]; /* host copy of each brick, as the GPU holds it */
} scene;

/* Camera at c looking at target (y down in the image). */
typedef struct cam {
    double R[3][3]; /* map to camera: rows are the camera axes */
    double c[3];
} cam;

static void v_norm(double v[3])
{
    double n = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    for (int i = 0; i < 3; i++) v[i] /= n;
}

static cam cam_look(double cx, double cy, double cz, double tx, double ty, double tz)
{
    cam k = {.c = {cx, cy, cz}};
    double f[3] = {tx - cx, ty - cy, tz - cz};
    v_norm(f);
    double down[3] = {0, 1, 0};
    double x[3] = {down[1] * f[2] - down[2] * f[1], down[2] * f[0] - down[0] * f[2], down[0] * f[1] - down[1] * f[0]};
    v_norm(x);
    double y[3] = {f[1] * x[2] - f[2] * x[1], f[2] * x[0] - f[0] * x[2], f[0] * x[1] - f[1] * x[0]};
    for (int i = 0; i < 3; i++) k.R[0][i] = x[i], k.R[1][i] = y[i], k.R[2][i] = f[i];
    return k;
}

/* A surface for the ray caster: returns the ray parameter of the first hit
 * of origin + t dir (t > 0), or -1. */
typedef double (*surface_fn)(const double o[3], const double d[3], double u_px, double v_px);

static double hit_plane(const double n[3], double h, const double o[3], const double d[3])
{
    double dn = n[0] * d[0] + n[1] * d[1] + n[2] * d[2];
    if (fabs(dn) < 1e-12) return -1;
    double t = (h - (n[0] * o[0] + n[1] * o[1] + n[2] * o[2])) / dn;
    return t > 0 ? t : -1;
}

static double g_plane_z = 1.0;
static double surf_plane_z(const double o[3], const double d[3], double u, double v)
{
    (void)u, (void)v;
    return hit_plane((double[3]){0, 0, 1}, g_plane_z, o, d);
}
static double surf_tilted(const double o[3], const double d[3], double u, double v)
{
    (void)u, (void)v;
    double n[3] = {0.35, -0.2, 1};
    v_norm(n);
    return hit_plane(n, 1.02, o, d);
}
static double surf_sphere(const double o[3], const double d[3], double u, double v)
{
    (void)u, (void)v;
    double c[3] = {0.02, -0.01, 1.15}, r = 0.2;
    double oc[3] = {o[0] - c[0], o[1] - c[1], o[2] - c[2]};
    double b = oc[0] * d[0] + oc[1] * d[1] + oc[2] * d[2];
    double cc = oc[0] * oc[0] + oc[1] * oc[1] + oc[2] * oc[2] - r * r;
    double dd = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    double disc = b * b - dd * cc;
    if (disc < 0) return -1;
    double t = (-b - sqrt(disc)) / dd;
    return t > 0 ? t : -1;
}
/* A step: z = 0.95 left of map x = 0.013, z = 1.08 right of it. */
static double surf_step(const double o[3], const double d[3], double u, double v)
{
    (void)u, (void)v;
    double t = hit_plane((double[3]){0, 0, 1}, 0.95, o, d);
    if (t > 0 && o[0] + t * d[0] < 0.013) return t;
    t = hit_plane((double[3]){0, 0, 1}, 1.08, o, d);
    return t > 0 && o[0] + t * d[0] >= 0.013 ? t : -1;
}
/* The plane with holes: every 7th pixel and a block have no depth. */
static double surf_holes(const double o[3], const double d[3], double u, double v)
{
    int i = (int)u, j = (int)v;
    if ((i * 3 + j * 5) % 7 == 0 || (i > 20 && i < 30 && j > 10 && j < 20)) return -1;
    return surf_plane_z(o, d, u, v);
}

/* Puts a frame with sequence index `index` in its ring slot: the record
 * and a depth image ray-cast from surface (or all zero with surf NULL). */
static void put_frame(scene *s, uint32_t index, cam k, surface_fn surf)
{
    uint32_t ring = index % RING;
    fusion_frame *f = &s->frames[ring];
    memset(f, 0, sizeof *f);
    for (int r = 0; r < 3; r++) {
        for (int c = 0; c < 3; c++) f->R[3 * r + c] = (float)k.R[r][c];
        f->t[r] = (float)-(k.R[r][0] * k.c[0] + k.R[r][1] * k.c[1] + k.R[r][2] * k.c[2]);
    }
    f->fx = (float)FX, f->fy = (float)FX, f->cx = (float)CX, f->cy = (float)CY;
    f->depth_unit_m = (float)UNIT;
    f->width = IMG_W, f->height = IMG_H;
    f->index = index;
    uint32_t *img = s->depth + (size_t)ring * (IMG_W * IMG_H / 2);
    memset(img, 0, IMG_W * IMG_H / 2 * 4);
    for (uint32_t j = 0; surf && j < IMG_H; j++)
        for (uint32_t i = 0; i < IMG_W; i++) {
            double dc[3] = {(i - CX) / FX, (j - CY) / FX, 1.0}; /* camera z = 1: t is the depth */
            double dm[3];
            for (int a = 0; a < 3; a++) dm[a] = k.R[0][a] * dc[0] + k.R[1][a] * dc[1] + k.R[2][a] * dc[2];
            double t = surf(k.c, dm, i, j);
            if (t <= 0) continue;
            long raw = lround(t / UNIT);
            if (raw <= 0 || raw > 65535) continue;
            uint32_t p = j * IMG_W + i;
            img[p >> 1] |= (uint32_t)raw << (16 * (p & 1));
        }
}

static bf_intrinsics test_K(void)
{
    return (bf_intrinsics){.width = IMG_W, .height = IMG_H, .fx_px = FX, .fy_px = FX, .cx_px = CX, .cy_px = CY,
                           .depth_scale = 1.0 / UNIT};
}

/* Opens a context and a small map (level-4 bricks: 1.5625 cm voxels), or
 * skips without a device. */
#define OPEN_SCENE(s)                                                                \
    do {                                                                             \
        bf_status _st = scene_open(s);                                               \
        if (_st == BF_NO_DEVICE) BF_SKIP(bf_last_error());                           \
        CHECK_STATUS(_st, BF_OK);                                                    \
    } while (0)

/* fusion_config.integrate_vpt and max_groups_x of the scenes opened next
 * (0: by device). */
static uint32_t s_integrate_vpt, s_max_groups_x;

static bf_status scene_open(scene *s)
{
    memset(s, 0, sizeof *s);
    s->v0 = gpu_validation_message_total();
    static char dir[512];
    snprintf(dir, sizeof dir, "%s/cache", bf_test_tmpdir());
    gpu_config gc = {.validation = GPU_VALIDATION_ON, .cache_dir = dir};
    bf_status st = gpu_context_create(&gc, &s->ctx);
    if (st != BF_OK) return st;
    fusion_config cfg = fusion_config_default();
    cfg.window = WINDOW;
    cfg.subcache = 4;
    cfg.brick_cap = 4096;
    cfg.hash_buckets = 64;
    cfg.hash_overflow = 64;
    cfg.sensor.sigma_a = 0.008f; /* a sigma band of about a voxel, so ramps matter */
    cfg.integrate_vpt = s_integrate_vpt;
    cfg.max_groups_x = s_max_groups_x;
    bf_intrinsics K = test_K();
    st = fusion_create(s->ctx, &cfg, &K, bf_v3(0, 0, 0), &s->map);
    if (st != BF_OK) return st;
    s->level = 4;
    for (uint32_t r = 0; r < RING; r++) s->frames[r].index = FUSION_NONE;
    return BF_OK;
}

/* Closes the scene; the test fails on any validation message. */
#define CLOSE_SCENE(s)                                                               \
    do {                                                                             \
        fusion_destroy((s)->map);                                                    \
        CHECK_EQ_INT(gpu_validation_message_count((s)->ctx), 0);                     \
        gpu_context_destroy((s)->ctx);                                               \
        CHECK_EQ_INT(gpu_validation_message_total(), (s)->v0);                       \
    } while (0)

static int64_t floor_div(int64_t a, int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

/* Inserts every brick of the scene's level meeting the map box [lo, hi]. */
static bf_status add_box(scene *s, double x0, double y0, double z0, double x1, double y1, double z1)
{
    double brick_m = 8.0 * hostmap_level_voxel_m(s->map->cfg.chunk_m, s->level);
    int64_t per = (int64_t)1 << s->level;
    double lo[3] = {x0, y0, z0}, hi[3] = {x1, y1, z1};
    int64_t g0[3], g1[3];
    for (int a = 0; a < 3; a++) g0[a] = (int64_t)floor(lo[a] / brick_m), g1[a] = (int64_t)floor(hi[a] / brick_m);
    for (int64_t gz = g0[2]; gz <= g1[2]; gz++)
        for (int64_t gy = g0[1]; gy <= g1[1]; gy++)
            for (int64_t gx = g0[0]; gx <= g1[0]; gx++) {
                if (s->n >= MAX_BRICKS) return bf_fail(BF_POOL_FULL, "test: too many bricks");
                int64_t g[3] = {gx, gy, gz};
                int32_t key[3];
                uint32_t cell[3];
                for (int a = 0; a < 3; a++) {
                    key[a] = (int32_t)floor_div(g[a], per);
                    cell[a] = (uint32_t)(g[a] - (int64_t)key[a] * per);
                }
                uint32_t slot;
                bf_status st = fusion_ref_insert_brick(s->map, key, s->level, cell, &slot);
                if (st != BF_OK) return st;
                fusion_ref_brick *b = &s->b[s->n];
                memset(b, 0, sizeof *b);
                memcpy(b->key, key, sizeof key);
                b->pos = fusion_pack_pos(cell[0], cell[1], cell[2], s->level);
                b->error = INFINITY;
                s->slot[s->n++] = slot;
            }
    return BF_OK;
}

/* Uploads the host copies of the bricks' planes and errors. */
static bf_status upload_bricks(scene *s)
{
    bf_status st = BF_OK;
    for (uint32_t i = 0; i < s->n && st == BF_OK; i++) {
        st = gpu_buffer_upload(s->map->sign, (uint64_t)s->slot[i] * 64, s->b[i].sign, 64);
        if (st == BF_OK) st = gpu_buffer_upload(s->map->conf, (uint64_t)s->slot[i] * 64, s->b[i].conf, 64);
        if (st == BF_OK)
            st = gpu_buffer_upload(s->map->info, ((uint64_t)s->slot[i] * FUSION_BRICK_INFO_WORDS + FUSION_INFO_ERROR) * 4,
                                   &s->b[i].error, 4);
    }
    return st;
}

typedef struct pass_result {
    uint32_t n_fragile, n_voxels_observed, n_mismatch_fragile, n_changed;
    uint32_t n_error_written;
    double min_pixel_margin;
} pass_result;

/* Runs one integration pass over list entries [first, first + count) of the
 * scene's bricks on the GPU and on the oracle; requires every non-fragile
 * bit and every error written from a brick without fragile voxels to be
 * equal; then adopts the GPU's state as the host copy. */
static bf_status run_pass(scene *s, uint32_t first, uint32_t count, uint32_t frame_first, uint32_t n_frames,
                          bool set_conf, bool window_list, pass_result *res, int *mismatch)
{
    fusion_map *m = s->map;
    memset(res, 0, sizeof *res);
    res->min_pixel_margin = INFINITY;
    *mismatch = 0;
    bf_status st = gpu_buffer_upload(m->frames, 0, s->frames, sizeof s->frames);
    if (st == BF_OK) st = gpu_buffer_upload(m->depth_ring, 0, s->depth, sizeof s->depth);
    uint32_t list[FUSION_LIST_HEADER + MAX_BRICKS] = {s->n};
    memcpy(list + FUSION_LIST_HEADER, s->slot, s->n * 4);
    gpu_buffer *lb = window_list ? m->window_list : m->new_list;
    if (st == BF_OK) st = gpu_buffer_upload(lb, 0, list, (FUSION_LIST_HEADER + s->n) * 4);
    if (st == BF_OK) st = upload_bricks(s);
    if (st == BF_OK) st = gpu_begin(m->ctx);
    if (st != BF_OK) return st;
    fusion__cmd_integrate(m, window_list ? m->b_integrate_window : m->b_integrate_new, first, count, frame_first,
                          n_frames, set_conf);
    if ((st = gpu_submit_wait(m->ctx)) != BF_OK) return st;

    fusion_integrate_push pc = fusion__integrate_params(m, first, count, frame_first, n_frames, set_conf);
    for (uint32_t i = 0; i < s->n; i++) {
        fusion_ref_brick gpu = s->b[i], ref = s->b[i];
        uint32_t info[FUSION_BRICK_INFO_WORDS];
        st = gpu_buffer_download(m->sign, (uint64_t)s->slot[i] * 64, gpu.sign, 64);
        if (st == BF_OK) st = gpu_buffer_download(m->conf, (uint64_t)s->slot[i] * 64, gpu.conf, 64);
        if (st == BF_OK) st = gpu_buffer_download(m->info, (uint64_t)s->slot[i] * sizeof info, info, sizeof info);
        if (st != BF_OK) return st;
        memcpy(&gpu.error, &info[FUSION_INFO_ERROR], 4);
        fusion_ref_margins mg;
        bool in_pass = i >= first && i - first < count;
        if (in_pass) {
            fusion_ref_integrate(&pc, s->frames, s->depth, &ref, &mg);
            res->n_fragile += mg.n_fragile;
            res->n_voxels_observed += mg.n_observed;
            res->n_error_written += mg.error_written;
            if (mg.pixel < res->min_pixel_margin) res->min_pixel_margin = mg.pixel;
            if (mg.error_gap < 1e-2) {
                fprintf(stderr, "  brick %u: window error %.6g within 1%% of the stored %.6g\n", i, mg.window_err,
                        s->b[i].error);
                (*mismatch)++;
            }
        } else {
            memset(&mg, 0, sizeof mg);
        }
        for (uint32_t w = 0; w < BRICK_WORDS; w++) {
            uint32_t d_sign = gpu.sign[w] ^ ref.sign[w], d_conf = gpu.conf[w] ^ ref.conf[w];
            uint32_t bad = (d_sign | d_conf) & ~mg.fragile[w];
            res->n_mismatch_fragile += (uint32_t)__builtin_popcount((d_sign | d_conf) & mg.fragile[w]);
            res->n_changed += (uint32_t)__builtin_popcount((gpu.sign[w] ^ s->b[i].sign[w]) | (gpu.conf[w] ^ s->b[i].conf[w]));
            if (bad) {
                if (*mismatch < 5)
                    fprintf(stderr, "  brick %u word %u: gpu sign %08x conf %08x, cpu sign %08x conf %08x\n", i, w,
                            gpu.sign[w], gpu.conf[w], ref.sign[w], ref.conf[w]);
                (*mismatch)++;
            }
        }
        bool err_equal = !memcmp(&gpu.error, &ref.error, 4);
        if (!err_equal && (!in_pass || mg.n_fragile == 0)) {
            fprintf(stderr, "  brick %u: gpu error %.9g, cpu %.9g\n", i, gpu.error, ref.error);
            (*mismatch)++;
        }
        s->b[i] = gpu;
    }
    return BF_OK;
}

/* Runs a pass and checks it; fragile voxels at most max_fragile of the observed ones. */
#define PASS(s, first, count, ff, nf, conf, wl, res, max_fragile)                                 \
    do {                                                                                         \
        int _mis = 0;                                                                            \
        CHECK_OK(run_pass((s), (first), (count), (ff), (nf), (conf), (wl), (res), &_mis));      \
        fprintf(stderr, "  pass: %u voxels observed, %u fragile (%u differ), %u bits changed, "   \
                "pixel margin %.2g\n", (res)->n_voxels_observed, (res)->n_fragile,               \
                (res)->n_mismatch_fragile, (res)->n_changed, (res)->min_pixel_margin);           \
        CHECK_EQ_INT(_mis, 0);                                                                   \
        /* lavapipe divides as C does (LLVM fdiv, IEEE): even fragile voxels agree. */          \
        if (strstr(gpu_device_name((s)->ctx), "llvmpipe")) CHECK_EQ_INT((res)->n_mismatch_fragile, 0); \
        CHECK_LE((res)->n_fragile, (max_fragile) * (double)(res)->n_voxels_observed + 0.5);      \
    } while (0)

/* Small camera motions around a base position, like a hand-held window. */
static cam cam_jitter(double x, double y, double z, double tx, double ty, double tz, int i)
{
    double a = 0.011 * (double)((i * 7) % 5 - 2), b = 0.009 * (double)((i * 3) % 5 - 2);
    return cam_look(x + a, y + b, z + 0.004 * i, tx + 0.5 * b, ty - 0.5 * a, tz);
}

/* ------------------------------------------------------------ GPU equals CPU */

static void run_surface_case(surface_fn surf, uint32_t n_frames, double max_fragile)
{
    scene s;
    OPEN_SCENE(&s);
    g_plane_z = 1.0;
    CHECK_OK(add_box(&s, -0.2, -0.15, 0.85, 0.2, 0.15, 1.2));
    for (uint32_t i = 0; i < n_frames; i++) put_frame(&s, 10 + i, cam_jitter(0, 0, 0, 0, 0, 1, (int)i), surf);
    pass_result r;
    PASS(&s, 0, s.n, 10, n_frames, true, true, &r, max_fragile);
    CHECK(r.n_changed > 0);
    CHECK(r.n_error_written > 0);
    CLOSE_SCENE(&s);
}

BF_TEST(gpu_equals_cpu_fronto_parallel_plane) { run_surface_case(surf_plane_z, 5, 0.01); }
BF_TEST(gpu_equals_cpu_tilted_plane) { run_surface_case(surf_tilted, 5, 0.05); }
BF_TEST(gpu_equals_cpu_sphere) { run_surface_case(surf_sphere, 6, 0.05); }
BF_TEST(gpu_equals_cpu_step_edge) { run_surface_case(surf_step, 4, 0.05); }
BF_TEST(gpu_equals_cpu_invalid_pixels) { run_surface_case(surf_holes, 4, 0.05); }

/* The kernel's workgroup size (voxels per invocation, 512 / it threads) is
 * a tuning choice, and its indirect grid goes out in rows of at most
 * max_groups_x groups (a list past 65535 groups runs so on Mesa): every
 * shape gives the same bits. */
BF_TEST(gpu_equals_cpu_at_every_kernel_shape)
{
    static const struct {
        uint32_t vpt, rows_of;
    } shapes[] = {{1, 0}, {8, 0}, {16, 0}, {32, 0}, {0, 1}, {0, 3}};
    for (size_t k = 0; k < sizeof shapes / sizeof shapes[0]; k++) {
        s_integrate_vpt = shapes[k].vpt, s_max_groups_x = shapes[k].rows_of;
        fprintf(stderr, "  %u voxels per invocation, rows of %u groups (0: by device)\n", shapes[k].vpt,
                shapes[k].rows_of);
        run_surface_case(surf_sphere, 4, 0.05);
        s_integrate_vpt = 0, s_max_groups_x = 0;
        if (bf__test_failed_now) return;
    }
}

/* Frames that see the bricks partly, from behind, or not at all, and a
 * stale ring slot (a record with another index): culling and skipping must
 * change no bit. */
BF_TEST(gpu_equals_cpu_frames_partly_outside_and_stale)
{
    scene s;
    OPEN_SCENE(&s);
    g_plane_z = 1.0;
    CHECK_OK(add_box(&s, -0.55, -0.15, 0.85, 0.3, 0.15, 1.1));
    put_frame(&s, 20, cam_look(0, 0, 0, 0, 0, 1), surf_plane_z);         /* left bricks partly outside */
    put_frame(&s, 21, cam_look(0.35, 0, 0.1, 0.5, 0, 1), surf_plane_z);  /* most bricks outside on the left */
    put_frame(&s, 22, cam_look(0, 0, 2.5, 0, 0, 4), surf_plane_z);       /* bricks behind the camera */
    put_frame(&s, 23, cam_look(0, 0, 0, 0, 1, 1), surf_plane_z);         /* looking down: partly above */
    put_frame(&s, 24, cam_look(0.01, 0, 0, 0, 0, 1), surf_plane_z);
    s.frames[24 % RING].index = 24 + RING;                              /* stale: skipped by both */
    pass_result r;
    PASS(&s, 0, s.n, 20, 5, true, false, &r, 0.05);
    CHECK(r.n_changed > 0);
    CLOSE_SCENE(&s);
}

/* A confident prior from a good window; then a worse window (farther
 * camera, larger sigma) must leave the confident voxels alone, and a better
 * one (nearer) may replace them. Both against the oracle. */
BF_TEST(gpu_equals_cpu_prior_and_replacement_rule)
{
    scene s;
    OPEN_SCENE(&s);
    g_plane_z = 1.0;
    CHECK_OK(add_box(&s, -0.12, -0.1, 0.9, 0.12, 0.1, 1.1));
    for (uint32_t i = 0; i < 6; i++) put_frame(&s, i, cam_jitter(0, 0, 0, 0, 0, 1, (int)i), surf_plane_z);
    pass_result r;
    PASS(&s, 0, s.n, 0, 6, true, true, &r, 0.05);
    CHECK(r.n_error_written > 0);
    fusion_ref_brick before[MAX_BRICKS];
    memcpy(before, s.b, sizeof before);

    /* Worse window: seen from 1 m farther back (larger sigma), the plane
     * 13 mm nearer (5 mm in front of the last confident front voxels), 12 frames: the window would flip confident front voxels
     * if it were allowed to (the oracle says so with the brick errors
     * forgotten). */
    g_plane_z = 0.987;
    for (uint32_t i = 0; i < 12; i++) put_frame(&s, 8 + i, cam_jitter(0, 0, -1.0, 0, 0, 1, (int)i), surf_plane_z);
    fusion_integrate_push pc = fusion__integrate_params(s.map, 0, s.n, 8, 12, true);
    uint32_t would_flip = 0;
    for (uint32_t i = 0; i < s.n; i++) {
        fusion_ref_brick cf = before[i];
        cf.error = INFINITY;
        fusion_ref_integrate(&pc, s.frames, s.depth, &cf, NULL);
        for (uint32_t w = 0; w < BRICK_WORDS; w++)
            would_flip += (uint32_t)__builtin_popcount((cf.sign[w] ^ before[i].sign[w]) & before[i].conf[w]);
    }
    CHECK(would_flip > 0);
    PASS(&s, 0, s.n, 8, 12, true, true, &r, 0.05);
    uint32_t kept = 0;
    for (uint32_t i = 0; i < s.n; i++) {
        uint32_t any = 0;
        for (uint32_t w = 0; w < BRICK_WORDS; w++) {
            any |= before[i].conf[w];
            /* Confident voxels kept exactly: sign and confidence. */
            CHECK_EQ_INT(s.b[i].sign[w] & before[i].conf[w], before[i].sign[w] & before[i].conf[w]);
            CHECK_EQ_INT(s.b[i].conf[w] & before[i].conf[w], before[i].conf[w]);
        }
        if (any) {
            CHECK(!memcmp(&s.b[i].error, &before[i].error, 4));
            kept++;
        }
    }
    CHECK(kept > 0);

    /* Better window, from the state before: nearer camera, plane 1 cm
     * nearer, 12 frames (the prior weighs like 2 frames at +sigma). */
    memcpy(s.b, before, sizeof before);
    g_plane_z = 0.99;
    for (uint32_t i = 0; i < 12; i++) put_frame(&s, 8 + i, cam_jitter(0, 0, 0.6, 0, 0, 1, (int)i), surf_plane_z);
    PASS(&s, 0, s.n, 8, 12, true, true, &r, 0.05);
    uint32_t replaced = 0, lowered = 0;
    for (uint32_t i = 0; i < s.n; i++) {
        for (uint32_t w = 0; w < BRICK_WORDS; w++)
            replaced += (uint32_t)__builtin_popcount((s.b[i].sign[w] ^ before[i].sign[w]) & before[i].conf[w]);
        if (before[i].error < INFINITY && s.b[i].error < before[i].error) lowered++;
    }
    CHECK(replaced > 0);
    CHECK(lowered > 0);
    CLOSE_SCENE(&s);
}

/* Sub-cache mode never touches confident voxels or the error, never sets
 * confidence, and writes the signs of the others. */
BF_TEST(gpu_equals_cpu_subcache_mode)
{
    scene s;
    OPEN_SCENE(&s);
    g_plane_z = 1.0;
    CHECK_OK(add_box(&s, -0.12, -0.1, 0.9, 0.12, 0.1, 1.1));
    for (uint32_t i = 0; i < 6; i++) put_frame(&s, i, cam_jitter(0, 0, 0, 0, 0, 1, (int)i), surf_plane_z);
    pass_result r;
    PASS(&s, 0, s.n, 0, 6, true, true, &r, 0.05);
    fusion_ref_brick before[MAX_BRICKS];
    memcpy(before, s.b, sizeof before);
    g_plane_z = 1.03;
    for (uint32_t i = 0; i < 3; i++) put_frame(&s, 6 + i, cam_jitter(0, 0, 0.1, 0, 0, 1, (int)i), surf_plane_z);
    PASS(&s, 0, s.n, 6, 3, false, false, &r, 0.05);
    uint32_t changed = 0;
    for (uint32_t i = 0; i < s.n; i++) {
        CHECK(!memcmp(&s.b[i].error, &before[i].error, 4));
        for (uint32_t w = 0; w < BRICK_WORDS; w++) {
            CHECK_EQ_INT(s.b[i].conf[w], before[i].conf[w]);
            CHECK_EQ_INT(s.b[i].sign[w] & before[i].conf[w], before[i].sign[w] & before[i].conf[w]);
            changed += (uint32_t)__builtin_popcount((s.b[i].sign[w] ^ before[i].sign[w]) & ~before[i].conf[w]);
        }
    }
    CHECK(changed > 0); /* the plane moved 3 cm back: free space in front of it */
    CLOSE_SCENE(&s);
}

/* Confident voxels of both signs all over the bricks (random planes), so
 * the prior's sweep finds neighbours 1, 2, 3 steps away and none: the
 * kernel's word-wise row gathers against the oracle's bit-by-bit ones, and
 * the error rule against a stored error between the two windows'. */
BF_TEST(gpu_equals_cpu_random_confident_state)
{
    scene s;
    OPEN_SCENE(&s);
    g_plane_z = 1.0;
    s.level = 7; /* 2 mm voxels: 1, 2, 3 and 4 steps give distinct Phi within the ~9 mm band */
    CHECK_OK(add_box(&s, -0.02, -0.02, 0.98, 0.02, 0.02, 1.02));
    uint32_t seed = 777;
    for (uint32_t i = 0; i < s.n; i++) {
        for (uint32_t w = 0; w < BRICK_WORDS; w++) {
            uint32_t r[3];
            for (int k = 0; k < 3; k++) {
                seed ^= seed << 13, seed ^= seed >> 17, seed ^= seed << 5;
                r[k] = seed;
            }
            s.b[i].sign[w] = r[0];
            s.b[i].conf[w] = i % 3 == 0 ? r[1] & r[2] : r[1] | r[2]; /* sparse or dense confidence */
        }
        /* Above this window's error (~8.7 mm: replaced, Psi ~1.8, so Phi
         * decides near the surface) and below it (kept). */
        s.b[i].error = i % 2 ? 0.0095f : 0.006f;
    }
    for (uint32_t i = 0; i < 6; i++) put_frame(&s, i, cam_jitter(0, 0, 0, 0, 0, 1, (int)i), surf_plane_z);
    pass_result r;
    PASS(&s, 0, s.n, 0, 6, true, true, &r, 0.05);
    CHECK(r.n_changed > 0);
    CLOSE_SCENE(&s);
}

/* A slice of the list: only entries [first, first + count) change. */
BF_TEST(list_slice_touches_only_its_bricks)
{
    scene s;
    OPEN_SCENE(&s);
    g_plane_z = 1.0;
    CHECK_OK(add_box(&s, -0.2, -0.15, 0.85, 0.2, 0.15, 1.2));
    for (uint32_t i = 0; i < 3; i++) put_frame(&s, i, cam_jitter(0, 0, 0, 0, 0, 1, (int)i), surf_plane_z);
    fusion_ref_brick before[MAX_BRICKS];
    memcpy(before, s.b, sizeof before);
    pass_result r;
    uint32_t first = 5, count = 9;
    PASS(&s, first, count, 0, 3, true, true, &r, 0.05);
    for (uint32_t i = 0; i < s.n; i++) {
        if (i >= first && i < first + count) continue;
        CHECK(!memcmp(&s.b[i], &before[i], sizeof before[i]));
    }
    CHECK(r.n_changed > 0);
    /* A slice past the end of the list does nothing. */
    memcpy(before, s.b, sizeof before);
    PASS(&s, s.n + 3, 10, 0, 3, true, true, &r, 0.0);
    CHECK_EQ_INT(r.n_changed, 0);
    CLOSE_SCENE(&s);
}

/* A list entry whose slot was freed after the list was gathered (its record
 * says no chunk) is skipped: nothing is read through it or written. */
BF_TEST(freed_slot_in_the_list_is_skipped)
{
    scene s;
    OPEN_SCENE(&s);
    g_plane_z = 1.0;
    CHECK_OK(add_box(&s, -0.12, -0.1, 0.9, 0.12, 0.1, 1.1));
    for (uint32_t i = 0; i < 3; i++) put_frame(&s, i, cam_jitter(0, 0, 0, 0, 0, 1, (int)i), surf_plane_z);
    fusion_map *m = s.map;
    uint32_t freed = m->cfg.brick_cap - 1; /* never handed out: its record is all FUSION_NONE */
    uint32_t marker[BRICK_WORDS];
    for (uint32_t w = 0; w < BRICK_WORDS; w++) marker[w] = 0x5a5a0000u + w;
    CHECK_OK(gpu_buffer_upload(m->sign, (uint64_t)freed * 64, marker, 64));
    CHECK_OK(gpu_buffer_upload(m->frames, 0, s.frames, sizeof s.frames));
    CHECK_OK(gpu_buffer_upload(m->depth_ring, 0, s.depth, sizeof s.depth));
    uint32_t list[FUSION_LIST_HEADER + 2] = {2, 0, 0, 0, freed, s.slot[0]};
    CHECK_OK(gpu_buffer_upload(m->new_list, 0, list, sizeof list));
    CHECK_OK(gpu_begin(m->ctx));
    fusion__cmd_integrate(m, m->b_integrate_new, 0, 2, 0, 3, false);
    CHECK_OK(gpu_submit_wait(m->ctx));
    uint32_t got[BRICK_WORDS], info[FUSION_BRICK_INFO_WORDS], sign0[BRICK_WORDS];
    CHECK_OK(gpu_buffer_download(m->sign, (uint64_t)freed * 64, got, 64));
    CHECK_OK(gpu_buffer_download(m->info, (uint64_t)freed * sizeof info, info, sizeof info));
    CHECK(!memcmp(got, marker, sizeof got));
    for (uint32_t k = 0; k < FUSION_BRICK_INFO_WORDS; k++) CHECK_EQ_INT(info[k], FUSION_NONE);
    CHECK_OK(gpu_buffer_download(m->sign, (uint64_t)s.slot[0] * 64, sign0, 64));
    uint32_t any = 0;
    for (uint32_t w = 0; w < BRICK_WORDS; w++) any |= sign0[w];
    CHECK(any != 0); /* the live brick next to it was integrated */
    CHECK_OK(fusion_check(m));
    CLOSE_SCENE(&s);
}

/* ------------------------------------------------------------ physics */

/* A fronto-parallel plane at depth d seen by 5 frames from near the origin:
 * voxels in front of it get sign 1 and, seen in every frame with weight 1,
 * confidence; voxels behind it within 3 sigma get sign 0 (confident down to
 * about 2.2 sigma); those beyond are not observed (W = 0) and stay as they
 * were (0, not confident). */
BF_TEST(plane_gives_front_sign_and_confidence_where_weight_suffices)
{
    scene s;
    OPEN_SCENE(&s);
    g_plane_z = 1.0;
    CHECK_OK(add_box(&s, -0.12, -0.1, 0.85, 0.12, 0.1, 1.15));
    for (uint32_t i = 0; i < 5; i++) put_frame(&s, i, cam_look(0.002 * i, 0, 0, 0.002 * i, 0, 1), surf_plane_z);
    pass_result r;
    PASS(&s, 0, s.n, 0, 5, true, true, &r, 0.01);
    double voxel = hostmap_level_voxel_m(s.map->cfg.chunk_m, s.level);
    float d = 1000.0f * (float)UNIT;
    double sigma = bf_sensor_sigma(d, s.map->cfg.sensor.sigma_a, s.map->cfg.sensor.sigma_b, s.map->cfg.sensor.sigma_c);
    uint32_t n_front = 0, n_behind = 0, n_far = 0;
    for (uint32_t i = 0; i < s.n; i++) {
        const fusion_ref_brick *b = &s.b[i];
        for (uint32_t v = 0; v < BRICK_VOXELS; v++) {
            uint32_t x = v & 7, y = (v >> 3) & 7, z = v >> 6;
            double cz = (double)b->key[2] * s.map->cfg.chunk_m + (fusion_pos_z(b->pos) * 8 + z + 0.5) * voxel;
            uint32_t sg = (b->sign[brick_word(x, y, z)] >> brick_bit(x, y, z)) & 1;
            uint32_t cf = (b->conf[brick_word(x, y, z)] >> brick_bit(x, y, z)) & 1;
            if (cz < d - 1e-4) { /* in front: W = 1 in all 5 frames >= conf_weight 4 */
                CHECK_EQ_INT(sg, 1);
                CHECK_EQ_INT(cf, 1);
                n_front++;
            } else if (cz > d + 1e-4 && cz < d + 3 * sigma) { /* behind, in the band */
                CHECK_EQ_INT(sg, 0);
                n_behind++;
                /* W = 1 down to -2 sigma, then the fade (3 sigma - D)/sigma: confident
                 * when the 5 frames' weights reach 4, i.e. D <= 2.2 sigma. */
                double D = cz - d;
                double w = D <= 2 * sigma ? 5.0 : 5 * (3 * sigma - D) / sigma;
                if (fabs(w - 4.0) > 0.05) CHECK_EQ_INT(cf, w >= 4.0 ? 1 : 0);
            } else if (cz > d + 3 * sigma + 1e-4) {
                CHECK_EQ_INT(sg, 0);
                CHECK_EQ_INT(cf, 0);
                n_far++;
            }
        }
    }
    CHECK(n_front > 1000 && n_behind > 50 && n_far > 1000);
    CLOSE_SCENE(&s);
}

/* All-zero depth, or no frame of the window in the ring, changes nothing. */
BF_TEST(empty_frames_change_nothing)
{
    scene s;
    OPEN_SCENE(&s);
    g_plane_z = 1.0;
    CHECK_OK(add_box(&s, -0.12, -0.1, 0.9, 0.12, 0.1, 1.1));
    for (uint32_t i = 0; i < 5; i++) put_frame(&s, i, cam_jitter(0, 0, 0, 0, 0, 1, (int)i), surf_plane_z);
    pass_result r;
    PASS(&s, 0, s.n, 0, 5, true, true, &r, 0.05); /* some confident state to keep */
    fusion_ref_brick before[MAX_BRICKS];
    memcpy(before, s.b, sizeof before);
    for (uint32_t i = 0; i < 4; i++) put_frame(&s, 5 + i, cam_jitter(0, 0, 0, 0, 0, 1, (int)i), NULL);
    PASS(&s, 0, s.n, 5, 4, true, true, &r, 0.0);
    PASS(&s, 0, s.n, 5, 4, false, false, &r, 0.0);
    PASS(&s, 0, s.n, 100, 4, true, true, &r, 0.0); /* frames 100..103 are not in the ring */
    CHECK(!memcmp(before, s.b, sizeof before));
    CLOSE_SCENE(&s);
}

/* Garbage poses in the ring (NaN or infinite) give no observation: NaN
 * never reaches the map. The host refuses such poses before (fusion_add_frame). */
BF_TEST(non_finite_pose_changes_nothing)
{
    scene s;
    OPEN_SCENE(&s);
    g_plane_z = 1.0;
    CHECK_OK(add_box(&s, -0.12, -0.1, 0.9, 0.12, 0.1, 1.1));
    for (uint32_t i = 0; i < 3; i++) put_frame(&s, i, cam_jitter(0, 0, 0, 0, 0, 1, (int)i), surf_plane_z);
    s.frames[0].R[4] = NAN;
    s.frames[1].t[2] = NAN;
    s.frames[2].R[0] = INFINITY;
    s.frames[2].t[0] = -INFINITY;
    fusion_ref_brick before[MAX_BRICKS];
    memcpy(before, s.b, sizeof before);
    pass_result r;
    PASS(&s, 0, s.n, 0, 3, true, true, &r, 0.0);
    CHECK(!memcmp(before, s.b, sizeof before));

    bf_se3 T = bf_se3_identity();
    T.t.x = NAN;
    uint16_t depth[IMG_W * IMG_H] = {0};
    bf_frame f = {.index = 0, .width = IMG_W, .height = IMG_H, .depth = depth};
    CHECK_STATUS(fusion_add_frame(s.map, &f, &T), BF_INVALID_ARG);
    CLOSE_SCENE(&s);
}
