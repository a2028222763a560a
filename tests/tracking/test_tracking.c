/* tracking: the ROF filter against its CPU oracle and its energies, ICP on
 * rendered frames of the synthetic room (with and without Kinect v1
 * noise, at the origin and 10 km away), closed-loop frame-to-frame
 * tracking from any pose, the real TUM fr2_desk pair, and
 * the hard cases (a single plane, empty and NaN depth, a sudden jump).
 * Validation is on; any message fails a test. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "mesh/mesh.h"
#include "synth/synth.h"
#include "gpu_fixture.h"
#include "mosaic_scene.h"
#include "replay/replay.h"
#include "rof_ref.h"
#include "shaders/fusion.glsl.h"
#include "tracking/tracking.h"
#include "tracking/tracking_int.h"

/* ------------------------------------------------------------ helpers */

static const bf_intrinsics K_SMALL = {160, 120, 131.25, 131.25, 79.5, 59.5, 5000};
static const bf_intrinsics K_MID = {320, 240, 262.5, 262.5, 159.5, 119.5, 5000};

/* The defaults, with the residual gate widened for the small test images:
 * the Kinect v1 model quantises disparity in 1/8 pixel of the image's own
 * focal length, so at 160x120 (f = 131) a depth step is 4 times that of a
 * 640x480 sensor (3.8 cm at 2 m) and the RMS residual of a correct pose is
 * about 2-3 cm instead of 5-10 mm. */
static track_config test_config(const bf_intrinsics *K)
{
    track_config c = track_config_default();
    c.max_residual_m *= (float)(525.0 / K->fx_px);
    return c;
}

static uint64_t rng_state = 88172645463325252ull;
static double rng_uniform(void)
{
    rng_state ^= rng_state << 13, rng_state ^= rng_state >> 7, rng_state ^= rng_state << 17;
    return ((rng_state >> 11) + 0.5) / 9007199254740992.0;
}
static double rng_gauss(void) { return sqrt(-2 * log(rng_uniform())) * cos(2 * M_PI * rng_uniform()); }

/* A float depth image into a device buffer, as a ray-cast would leave it. */
static bf_status upload_float(gpu_context *ctx, const float *d, uint32_t n, gpu_buffer **out)
{
    gpu_buffer_desc bd = {.name = "test.depth", .size_bytes = (uint64_t)n * 4, .memory = GPU_MEMORY_DEVICE};
    bf_status s = gpu_buffer_create(ctx, &bd, out);
    if (s == BF_OK) s = gpu_buffer_upload(*out, 0, d, (uint64_t)n * 4);
    return s;
}

/* Pose error of est against truth: translation [m] and angle [deg]. */
static void pose_error(const bf_se3 *truth, const bf_se3 *est, double *dt_m, double *da_deg)
{
    bf_se3 ti = bf_se3_inverse(truth);
    bf_se3 e = bf_se3_mul(&ti, est);
    *dt_m = bf_v3_norm(e.t);
    *da_deg = bf_se3_angle(&e) * 180 / M_PI;
}

/* The test motion: 2 cm and 2 degrees, in the camera's own frame. */
static bf_se3 small_motion(void)
{
    bf_se3 d = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0.3, 1.0, 0.2), 2.0 * M_PI / 180), bf_v3(0, 0, 0));
    d.t = bf_v3_scale(bf_v3_normalize(bf_v3(1.0, -0.5, 0.7)), 0.02);
    return d;
}

static bf_frame frame_of(const bf_intrinsics *K, const uint16_t *depth, uint32_t index)
{
    return (bf_frame){.index = index, .width = K->width, .height = K->height, .depth = depth};
}

/* Depth d1 tracked from the guess T0 against d0 as the reference at T0,
 * by a tracker of its own (cfg, camera K). */
static bf_status track_pair(gpu_context *ctx, const track_config *cfg, const bf_intrinsics *K, const uint16_t *d0,
                            const uint16_t *d1, const bf_se3 *T0, track_result *r)
{
    track_tracker *t;
    bf_status s = track_create(ctx, cfg, K, &t);
    if (s != BF_OK) return s;
    bf_frame f0 = frame_of(K, d0, 0), f1 = frame_of(K, d1, 1);
    s = track_set_reference_frame(t, &f0, T0);
    if (s == BF_OK) s = track_frame(t, &f1, T0, r);
    track_destroy(t);
    return s;
}

/* Renders the room at T_wc (noise as given) into a new depth image. */
typedef struct room {
    synth_scene scene;
    synth_renderer *r;
    bf_intrinsics K;
} room;

static bf_status room_open(room *rm, const bf_intrinsics *K, synth_noise noise)
{
    memset(rm, 0, sizeof *rm);
    rm->K = *K;
    bf_status s = synth_scene_room(NULL, &rm->scene);
    synth_render_config rc = {.K = *K, .noise = noise, .seed = 7};
    if (s == BF_OK) s = synth_renderer_create(&rm->scene, &rc, &rm->r);
    return s;
}
static void room_close(room *rm)
{
    synth_renderer_destroy(rm->r);
    synth_scene_free(&rm->scene);
}
static uint16_t *render(room *rm, uint32_t frame, const bf_se3 *T_wc)
{
    uint16_t *d = malloc((size_t)rm->K.width * rm->K.height * 2);
    if (d && synth_render(rm->r, frame, T_wc, d, NULL, NULL) != BF_OK) {
        free(d);
        return NULL;
    }
    return d;
}

/* ------------------------------------------------------------ ROF */

/* A test image at 160 x 120: a plane at 1.5 m (left) and 2.0 m (right)
 * with a depth step between, a hole outside the mask in the middle, and
 * Gaussian noise of sigma_m. */
static float *rof_image(double sigma_m, float *clean)
{
    uint32_t w = K_SMALL.width, h = K_SMALL.height;
    float *f = malloc((size_t)w * h * 4);
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            uint32_t i = y * w + x;
            double z = x < w / 2 ? 1.5 : 2.0;
            bool hole = x >= 30 && x < 50 && y >= 40 && y < 80;
            if (clean) clean[i] = hole ? 0.0f : (float)z;
            f[i] = hole ? 0.0f : (float)(z + sigma_m * rng_gauss());
        }
    return f;
}

BF_TEST(rof_gpu_matches_cpu_oracle)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    uint32_t w = K_SMALL.width, h = K_SMALL.height, n = w * h;
    float *f = rof_image(0.01, NULL);
    track_config cfg = track_config_default();
    cfg.rof_iterations = 10; /* the smoothing's design (off in the loop by default) */
    cfg.rof_level = 0; /* the filter itself, at full resolution */
    cfg.ref_level = 0;
    track_tracker *t;
    CHECK_OK(track_create(ctx, &cfg, &K_SMALL, &t));
    gpu_buffer *buf;
    CHECK_OK(upload_float(ctx, f, n, &buf));
    float *p = calloc((size_t)n * 2, 4), *q = calloc((size_t)n * 2, 4), *u = malloc((size_t)n * 4),
          *g = malloc((size_t)n * 4);
    uint32_t done = 0;
    bf_se3 I = bf_se3_identity();
    for (uint32_t iters = 1; iters <= 64; iters *= 4) {
        for (; done < iters; done++) {
            rof_ref_iterate(f, w, h, cfg.rof_lambda0, 0.25f, p, q);
            float *tmp = p;
            p = q, q = tmp;
        }
        rof_ref_primal(f, w, h, cfg.rof_lambda0, p, u);
        track__set_rof_iterations(t, iters);
        CHECK_OK(track_set_reference_gpu(t, buf, &I));
        CHECK_OK(track_download_reference(t, g));
        double max_diff = 0;
        for (uint32_t i = 0; i < n; i++) max_diff = fmax(max_diff, fabs((double)g[i] - u[i]));
        fprintf(stderr, "  %2u iterations: max |GPU - CPU| = %.3g m\n", iters, max_diff);
        /* Divisions and square roots may differ by a few ulp on the GPU
         * (Vulkan allows 2.5 ulp); through 64 iterations such differences
         * stay far below a micrometre at depths of 2 m (ulp 0.24 um). */
        CHECK_LE(max_diff, 2e-6);
    }
    gpu_buffer_destroy(buf);
    track_destroy(t);
    free(f), free(p), free(q), free(u), free(g);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

BF_TEST(rof_energy_decreases_and_duality_gap_closes)
{
    /* The dual value D(p) must rise monotonically (the step is a
     * preconditioned projected gradient ascent on a concave function within
     * Chambolle's bound), the primal energy E(u) must fall overall, and the
     * gap E(u) - D(p) >= 0 (weak duality) must shrink towards 0. */
    uint32_t w = K_SMALL.width, h = K_SMALL.height, n = w * h;
    float *f = rof_image(0.01, NULL);
    float lambda0 = track_config_default().rof_lambda0;
    float *p = calloc((size_t)n * 2, 4), *q = calloc((size_t)n * 2, 4), *u = malloc((size_t)n * 4);
    rof_ref_primal(f, w, h, lambda0, p, u);
    double e0 = rof_ref_energy(f, u, w, h, lambda0), d_prev = rof_ref_dual(f, p, w, h, lambda0);
    double gap0 = e0 - d_prev, gap = gap0, e = e0;
    for (uint32_t it = 1; it <= 200; it++) {
        rof_ref_iterate(f, w, h, lambda0, 0.25f, p, q);
        float *tmp = p;
        p = q, q = tmp;
        rof_ref_primal(f, w, h, lambda0, p, u);
        double d = rof_ref_dual(f, p, w, h, lambda0);
        e = rof_ref_energy(f, u, w, h, lambda0);
        gap = e - d;
        if (it == 1 || it == 10 || it == 50 || it == 200)
            fprintf(stderr, "  iteration %3u: E(u) %.4f, D(p) %.4f, gap %.4g\n", it, e, d, gap);
        /* Float rounding of the sums of about 10^4 terms of ~1: 1e-6
         * relative. */
        CHECK(d >= d_prev - 1e-6 * fabs(d_prev));
        CHECK(gap >= -1e-6 * fabs(e));
        d_prev = d;
    }
    CHECK_LE(e, e0);
    CHECK_LE(gap, 0.02 * gap0);
    free(f), free(p), free(q), free(u);
}

/* Standard deviation of img - clean over a rectangle that must stay in the
 * mask. */
static double region_noise(const float *img, const float *clean, uint32_t w, uint32_t x0, uint32_t x1, uint32_t y0,
                           uint32_t y1)
{
    double s = 0, s2 = 0;
    uint32_t k = 0;
    for (uint32_t y = y0; y < y1; y++)
        for (uint32_t x = x0; x < x1; x++) {
            double d = (double)img[y * w + x] - clean[y * w + x];
            s += d, s2 += d * d, k++;
        }
    return sqrt(fmax(s2 / k - (s / k) * (s / k), 0));
}

BF_TEST(rof_smooths_noise_keeps_the_step_and_the_mask_edge)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    uint32_t w = K_SMALL.width, h = K_SMALL.height, n = w * h;
    float *clean = malloc((size_t)n * 4);
    float *f = rof_image(0.006, clean), *u = malloc((size_t)n * 4);
    track_config cfg = track_config_default();
    cfg.rof_iterations = 10; /* the smoothing's design (off in the loop by default) */
    cfg.rof_level = 0; /* the filter itself, at full resolution */
    cfg.ref_level = 0;
    track_tracker *t;
    CHECK_OK(track_create(ctx, &cfg, &K_SMALL, &t));
    gpu_buffer *buf;
    CHECK_OK(upload_float(ctx, f, n, &buf));
    bf_se3 I = bf_se3_identity();
    CHECK_OK(track_set_reference_gpu(t, buf, &I));
    CHECK_OK(track_download_reference(t, u));
    /* Noise away from every edge, on both planes. */
    double before = region_noise(f, clean, w, 55, 75, 10, 110), after = region_noise(u, clean, w, 55, 75, 10, 110);
    double before_far = region_noise(f, clean, w, 90, 150, 10, 110), after_far = region_noise(u, clean, w, 90, 150, 10, 110);
    fprintf(stderr, "  noise at 1.5 m %.2f -> %.2f mm (x%.2f), at 2.0 m %.2f -> %.2f mm (x%.2f), %u iterations\n",
            1e3 * before, 1e3 * after, before / after, 1e3 * before_far, 1e3 * after_far, before_far / after_far,
            cfg.rof_iterations);
    CHECK(after < before / 2);
    CHECK(after_far < before_far / 1.5);
    /* The step (0.5 m between columns 79 and 80) stays: columns next to it
     * keep their side's depth within the noise, no blur across. */
    double worst_step = 0, worst_hole = 0, bias_hole = 0;
    uint32_t k = 0;
    for (uint32_t y = 5; y < h - 5; y++) {
        worst_step = fmax(worst_step, fabs(u[y * w + 79] - 1.5));
        worst_step = fmax(worst_step, fabs(u[y * w + 80] - 2.0));
        if (y >= 42 && y < 78) {
            /* Pixels bordering the hole (outside the mask, depth 0) keep
             * their depth: no pull towards 0. */
            for (uint32_t x = 28; x < 30; x++) {
                double d = u[y * w + x] - 1.5;
                worst_hole = fmax(worst_hole, fabs(d));
                bias_hole += d, k++;
            }
            CHECK(u[y * w + 40] == 0.0f);
        }
    }
    bias_hole /= k;
    fprintf(stderr, "  step columns off by %.2f mm at most; hole border off by %.2f mm at most, mean %.3f mm\n",
            1e3 * worst_step, 1e3 * worst_hole, 1e3 * bias_hole);
    /* 4 sigma of the input noise bounds one pixel; the border's mean over
     * 72 pixels must be unbiased within 3 sigma / sqrt(72) ~ 2 mm. */
    CHECK_LE(worst_step, 4 * 0.006);
    CHECK_LE(worst_hole, 4 * 0.006);
    CHECK_LE(fabs(bias_hole), 0.002);
    gpu_buffer_destroy(buf);
    track_destroy(t);
    free(f), free(u), free(clean);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

BF_TEST(rof_smooths_near_more_than_far)
{
    /* The same noise (5 mm) on a plane at 1 m (top half) and one at 3 m
     * (bottom half): lambda(z) = lambda0 z^2 must remove more of it near. */
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    uint32_t w = K_SMALL.width, h = K_SMALL.height, n = w * h;
    float *f = malloc((size_t)n * 4), *clean = malloc((size_t)n * 4), *u = malloc((size_t)n * 4);
    for (uint32_t i = 0; i < n; i++) {
        clean[i] = i / w < h / 2 ? 1.0f : 3.0f;
        f[i] = (float)(clean[i] + 0.005 * rng_gauss());
    }
    track_config cfg = track_config_default();
    cfg.rof_iterations = 10; /* the smoothing's design (off in the loop by default) */
    cfg.rof_level = 0; /* the filter itself, at full resolution */
    cfg.ref_level = 0;
    track_tracker *t;
    CHECK_OK(track_create(ctx, &cfg, &K_SMALL, &t));
    gpu_buffer *buf;
    CHECK_OK(upload_float(ctx, f, n, &buf));
    bf_se3 I = bf_se3_identity();
    CHECK_OK(track_set_reference_gpu(t, buf, &I));
    CHECK_OK(track_download_reference(t, u));
    double near = region_noise(f, clean, w, 5, 155, 5, 55) / region_noise(u, clean, w, 5, 155, 5, 55);
    double far = region_noise(f, clean, w, 5, 155, 65, 115) / region_noise(u, clean, w, 5, 155, 65, 115);
    fprintf(stderr, "  noise reduced x%.2f at 1 m, x%.2f at 3 m\n", near, far);
    CHECK(near > 1.5 * far);
    gpu_buffer_destroy(buf);
    track_destroy(t);
    free(f), free(u), free(clean);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

/* ------------------------------------------------------------ ICP */

/* Reference rendered at T0, frame at T0 * motion, guess T0. */
static void track_room_pair_step(synth_noise noise, const bf_intrinsics *K, const bf_se3 *T_off, float noise_exp,
                                 uint32_t sample_step, bf_se3 *est_rel, track_result *res, bool *ok)
{
    *ok = false;
    gpu_context *ctx;
    gpu_config gc = gpu_fixture_config();
    if (gpu_context_create(&gc, &ctx) != BF_OK) return;
    room rm;
    if (room_open(&rm, K, noise) != BF_OK) return;
    bf_se3 T0 = rm.scene.T_wc_view, d = small_motion();
    bf_se3 T1 = bf_se3_mul(&T0, &d);
    uint16_t *d0 = render(&rm, 0, &T0), *d1 = render(&rm, 1, &T1);
    track_config cfg = test_config(K);
    cfg.noise_weight_exp = noise_exp;
    if (sample_step) cfg.finest_sample_step = sample_step;
    track_tracker *t;
    if (d0 && d1 && track_create(ctx, &cfg, K, &t) == BF_OK) {
        bf_frame f0 = frame_of(K, d0, 0), f1 = frame_of(K, d1, 1);
        /* The tracker is told the world is offset by T_off: it must not care. */
        bf_se3 R0 = bf_se3_mul(T_off, &T0);
        if (track_set_reference_frame(t, &f0, &R0) == BF_OK && track_frame(t, &f1, &R0, res) == BF_OK) {
            bf_se3 inv = bf_se3_inverse(&R0);
            *est_rel = bf_se3_mul(&inv, &res->T_wc);
            *ok = gpu_validation_message_count(ctx) == 0;
        }
        track_destroy(t);
    }
    free(d0), free(d1);
    room_close(&rm);
    gpu_context_destroy(ctx);
}

static void track_room_pair(synth_noise noise, const bf_intrinsics *K, const bf_se3 *T_off, float noise_exp,
                            bf_se3 *est_rel, track_result *res, bool *ok)
{
    track_room_pair_step(noise, K, T_off, noise_exp, 0, est_rel, res, ok);
}

/* The room pair at K from the true reference pose: tracked, not degenerate,
 * within tol_m and tol_deg of the true motion; the estimate in *est. */
static void check_room_at(const bf_intrinsics *K, synth_noise noise, double tol_m, double tol_deg, bf_se3 *est)
{
    bf_se3 I = bf_se3_identity();
    track_result r;
    bool ok;
    track_room_pair(noise, K, &I, track_config_default().noise_weight_exp, est, &r, &ok);
    CHECK(ok);
    double dt, da;
    bf_se3 truth = small_motion();
    pose_error(&truth, est, &dt, &da);
    fprintf(stderr, "  %ux%u %s: %s, error %.3f mm %.4f deg; %u/%u inliers, rms %.2f mm, eig %.3g/%.3g, %u iterations, "
                    "%.2f ms GPU\n",
            K->width, K->height, noise == SYNTH_NOISE_NONE ? "noiseless" : "kinect1", track_outcome_name(r.outcome),
            1e3 * dt, da, r.n_inliers, r.n_valid, 1e3 * r.residual_m, r.eig_min, r.eig_max, r.iterations, r.ms_gpu);
    CHECK_EQ_INT(r.outcome, TRACK_OK);
    CHECK(!r.degenerate);
    CHECK_LE(dt, tol_m);
    CHECK_LE(da, tol_deg);
}

static void check_room(synth_noise noise, double tol_m, double tol_deg)
{
    bf_se3 est, est_far;
    track_result r_far;
    bool ok;
    double dt, da;
    check_room_at(&K_MID, noise, tol_m, tol_deg, &est);
    /* 10 km from the world origin, turned: the same relative estimate (the
     * GPU sees the same relative pose; composition is in double). */
    bf_se3 off = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0.2, 0.3, 1), 0.7), bf_v3(1e4, -3e3, 250));
    track_room_pair(noise, &K_MID, &off, track_config_default().noise_weight_exp, &est_far, &r_far, &ok);
    CHECK(ok);
    CHECK_EQ_INT(r_far.outcome, TRACK_OK);
    pose_error(&est, &est_far, &dt, &da);
    fprintf(stderr, "  10 km away: differs by %.3g m, %.3g deg\n", dt, da);
    CHECK_LE(dt, 1e-6);
    CHECK_LE(da, 1e-5);
}

BF_TEST(icp_recovers_2cm_2deg_noiseless_room_at_origin_and_10km)
{
    /* Noiseless frames at 320x240: point-to-plane ICP converges to the
     * pose up to the projective association's sub-pixel bias; 1 mm and 0.1
     * degree are the bounds. */
    check_room(SYNTH_NOISE_NONE, 0.001, 0.1);
}

BF_TEST(icp_recovers_2cm_2deg_noisy_room)
{
    /* Kinect v1 noise at 1-4 m is 2-25 mm per pixel; averaged over ~5e4
     * inliers the pose error stays at a few mm. */
    check_room(SYNTH_NOISE_KINECT1, 0.004, 0.25);
}

BF_TEST(odd_sized_images_track_the_noiseless_room)
{
    /* 321x241: every level has an odd side, so the finest level's last row
     * and column have no parent pixel to take their normals from (and an
     * image kernel's last tile is partly outside the image). Tracked like
     * the even size: within the noiseless bounds, not degenerate. */
    const bf_intrinsics K = {321, 241, 262.5, 262.5, 160, 120, 5000};
    bf_se3 est;
    check_room_at(&K, SYNTH_NOISE_NONE, 0.001, 0.1, &est);
}

BF_TEST(sparser_finest_samples_track_the_noisy_room)
{
    /* The finest level on every pixel, on a checkerboard (the default) and
     * on every fourth pixel: the sample counts follow the step (the
     * rendered room fills the image), and averaged over ~1.2e4 samples
     * instead of ~5e4 the Kinect v1 noise still leaves a few mm. */
    static const uint32_t steps[3] = {1, 2, 4};
    track_result r[3];
    bf_se3 I = bf_se3_identity(), truth = small_motion(), est;
    for (int k = 0; k < 3; k++) {
        bool ok;
        track_room_pair_step(SYNTH_NOISE_KINECT1, &K_MID, &I, track_config_default().noise_weight_exp, steps[k], &est,
                             &r[k], &ok);
        CHECK(ok);
        double dt, da;
        pose_error(&truth, &est, &dt, &da);
        fprintf(stderr, "  finest sample step %u: %s, %u valid samples, %u inliers, error %.3f mm %.4f deg\n", steps[k],
                track_outcome_name(r[k].outcome), r[k].n_valid, r[k].n_inliers, 1e3 * dt, da);
        CHECK_EQ_INT(r[k].outcome, TRACK_OK);
        CHECK_LE(dt, 0.004);
        CHECK_LE(da, 0.25);
    }
    CHECK_NEAR((double)r[1].n_valid / r[0].n_valid, 0.5, 0.02);
    CHECK_NEAR((double)r[2].n_valid / r[0].n_valid, 0.25, 0.02);
    /* Other steps are refused at create. */
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    track_config c = test_config(&K_MID);
    c.finest_sample_step = 3;
    track_tracker *bad;
    CHECK_STATUS(track_create(ctx, &c, &K_MID, &bad), BF_INVALID_ARG);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

/* The noiseless room's pair with Gaussian noise of k sigma_z(z) added to
 * the frame's depth (the reference stays clean): what the tracker reports
 * as the residual in the sensor model's units, and the pose error. */
static void track_room_scaled_noise(double k, bool scaled, track_result *res, double *dt, double *da, bool *ok)
{
    *ok = false;
    gpu_context *ctx;
    gpu_config gc = gpu_fixture_config();
    if (gpu_context_create(&gc, &ctx) != BF_OK) return;
    room rm;
    if (room_open(&rm, &K_MID, SYNTH_NOISE_NONE) != BF_OK) return;
    bf_se3 T0 = rm.scene.T_wc_view, d = small_motion();
    bf_se3 T1 = bf_se3_mul(&T0, &d);
    uint16_t *d0 = render(&rm, 0, &T0), *d1 = render(&rm, 1, &T1);
    track_config cfg = test_config(&K_MID);
    cfg.huber_scaled = scaled;
    cfg.max_residual_m *= (float)k;
    bf_sensor sn = cfg.sensor;
    rng_state = 88172645463325252ull;
    for (uint32_t i = 0; d1 && i < K_MID.width * K_MID.height; i++) {
        if (!d1[i]) continue;
        double z = d1[i] / K_MID.depth_scale;
        z += k * bf_sensor_sigma(z, sn.sigma_a, sn.sigma_b, sn.sigma_c) * rng_gauss();
        d1[i] = (uint16_t)fmin(65535, fmax(1, z * K_MID.depth_scale + 0.5));
    }
    track_tracker *t;
    if (d0 && d1 && track_create(ctx, &cfg, &K_MID, &t) == BF_OK) {
        bf_frame f0 = frame_of(&K_MID, d0, 0), f1 = frame_of(&K_MID, d1, 1);
        if (track_set_reference_frame(t, &f0, &T0) == BF_OK && track_frame(t, &f1, &T0, res) == BF_OK) {
            bf_se3 inv = bf_se3_inverse(&T0);
            bf_se3 est = bf_se3_mul(&inv, &res->T_wc);
            pose_error(&d, &est, dt, da);
            *ok = gpu_validation_message_count(ctx) == 0;
        }
        track_destroy(t);
    }
    free(d0), free(d1);
    room_close(&rm);
    gpu_context_destroy(ctx);
}

BF_TEST(huber_unit_follows_the_residuals)
{
    /* Real Kinect v1 depth leaves residuals a few times the Gaussian model's
     * (docs/real_frames.md). The residual in sigma units must say so: with
     * noise of k sigma_z the frame's own part of r / sigma_z has RMS about
     * k |n_z| (the normal's view component, ~0.7-1 in the room), so the
     * ratio between k = 3 and k = 1 is 3 up to the clean reference's part
     * and the normals' own noise. Scaled Huber must track the k = 3 frame
     * within the noisy-room test's bounds times 3 (the noise's). */
    track_result r1, r3, r3u;
    double dt1, da1, dt3, da3, dt3u, da3u;
    bool ok1, ok3, ok3u;
    track_room_scaled_noise(1.0, true, &r1, &dt1, &da1, &ok1);
    track_room_scaled_noise(3.0, true, &r3, &dt3, &da3, &ok3);
    track_room_scaled_noise(3.0, false, &r3u, &dt3u, &da3u, &ok3u);
    CHECK(ok1 && ok3 && ok3u);
    fprintf(stderr, "  k = 1: r/sigma RMS %.2f, error %.2f mm %.3f deg; k = 3: %.2f, %.2f mm %.3f deg (sensor unit: "
                    "%.2f mm %.3f deg)\n",
            r1.residual_sigma, 1e3 * dt1, da1, r3.residual_sigma, 1e3 * dt3, da3, 1e3 * dt3u, da3u);
    CHECK_EQ_INT(r1.outcome, TRACK_OK);
    CHECK_EQ_INT(r3.outcome, TRACK_OK);
    CHECK(r1.residual_sigma > 0.4 && r1.residual_sigma < 1.5);
    double ratio = r3.residual_sigma / r1.residual_sigma;
    CHECK(ratio > 2.4 && ratio < 3.6);
    CHECK_LE(dt3, 3 * 0.004);
    CHECK_LE(da3, 3 * 0.25);
}

BF_TEST(noise_weight_exponent_reaches_the_icp_and_is_validated)
{
    /* Each exponent of the noise weight (track_config.noise_weight_exp,
     * docs/real_frames.md) tracks the noisy room within the default's
     * bounds; a different exponent weighs the residuals differently, so the
     * estimates differ (identical ones: the exponent never reached the
     * kernel). */
    bf_se3 I = bf_se3_identity(), truth = small_motion(), est[3];
    const float exps[3] = {2.0f, 1.0f, 0.5f};
    for (int k = 0; k < 3; k++) {
        track_result r;
        bool ok;
        track_room_pair(SYNTH_NOISE_KINECT1, &K_MID, &I, exps[k], &est[k], &r, &ok);
        CHECK(ok);
        CHECK_EQ_INT(r.outcome, TRACK_OK);
        double dt, da;
        pose_error(&truth, &est[k], &dt, &da);
        fprintf(stderr, "  exponent %.1f: error %.3f mm %.4f deg\n", exps[k], 1e3 * dt, da);
        CHECK_LE(dt, 0.004);
        CHECK_LE(da, 0.25);
        if (k > 0) {
            pose_error(&est[0], &est[k], &dt, &da);
            fprintf(stderr, "    differs from exponent 2 by %.4f mm %.5f deg\n", 1e3 * dt, da);
            CHECK(dt > 1e-5);
        }
    }
    /* Out of (0, 4] with the weights on: refused; with them off: unused. */
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    const float bad[3] = {0.0f, 4.5f, NAN};
    for (int k = 0; k < 3; k++) {
        track_config c = test_config(&K_SMALL);
        c.noise_weight_exp = bad[k];
        track_tracker *t = NULL;
        CHECK_STATUS(track_create(ctx, &c, &K_SMALL, &t), BF_INVALID_ARG);
        CHECK(t == NULL);
        c.weight_noise = false;
        CHECK_OK(track_create(ctx, &c, &K_SMALL, &t));
        track_destroy(t);
    }
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

/* A reference rendered at K_MID's level 1 from the room's viewpoint T0 and
 * a full-resolution frame moved by small_motion() from it. */
typedef struct half_pair {
    room full, half;
    bf_intrinsics Kh; /* K_MID at the reference's level (0: the same images' size) */
    bf_se3 T0, d;     /* the reference's pose; the frame's motion from it */
    uint16_t *ref, *d1;
} half_pair;

static bf_status half_pair_open(half_pair *p, synth_noise noise, uint32_t level)
{
    memset(p, 0, sizeof *p);
    p->Kh = bf_intrinsics_level(&K_MID, level);
    bf_status s = room_open(&p->full, &K_MID, noise);
    if (s == BF_OK) s = room_open(&p->half, &p->Kh, noise);
    if (s != BF_OK) return s;
    p->T0 = p->full.scene.T_wc_view, p->d = small_motion();
    bf_se3 T1 = bf_se3_mul(&p->T0, &p->d);
    p->ref = render(&p->half, 0, &p->T0), p->d1 = render(&p->full, 1, &T1);
    return p->ref && p->d1 ? BF_OK : bf_fail(BF_NO_MEMORY, "test: rendering the pair");
}

static void half_pair_close(half_pair *p)
{
    free(p->ref), free(p->d1);
    room_close(&p->full);
    room_close(&p->half);
}

/* The residual gate: over max_residual_m counts as lost only where the
 * inliers' RMS of r / sigma_z(z) is over max_residual_sigma too (real
 * frames of a far view leave 18-21 mm at the right pose, docs/tracking.md).
 * A noisy pair at the right pose leaves about sqrt(2) sigma (two noisy
 * images); with the metric gate set below its residual, the frame is kept
 * by the sigma gate, and lost without it or with a gate below its RMS. */
BF_TEST(residual_gate_counts_in_the_sensor_noise)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    half_pair hp; /* level 0: both images at K_MID */
    CHECK_OK(half_pair_open(&hp, SYNTH_NOISE_KINECT1, 0));
    bf_se3 T0 = hp.T0;
    const uint16_t *d0 = hp.ref, *d1 = hp.d1;
    track_config base = test_config(&K_MID);
    CHECK(base.max_residual_sigma > 0);
    double r_m = 0, r_sigma = 0;
    for (int run = 0; run < 4; run++) {
        track_config cfg = base;
        if (run > 0) cfg.max_residual_m = (float)(0.5 * r_m);
        if (run == 2) cfg.max_residual_sigma = 0;
        if (run == 3) cfg.max_residual_sigma = (float)(0.5 * r_sigma);
        track_result r;
        CHECK_OK(track_pair(ctx, &cfg, &K_MID, d0, d1, &T0, &r));
        fprintf(stderr, "  gate %.1f mm / %.2f sigma: %s, residual %.2f mm, %.2f sigma\n", 1e3 * cfg.max_residual_m,
                cfg.max_residual_sigma, track_outcome_name(r.outcome), 1e3 * r.residual_m, r.residual_sigma);
        if (run == 0) {
            CHECK_EQ_INT(r.outcome, TRACK_OK);
            r_m = r.residual_m, r_sigma = r.residual_sigma;
            CHECK(r_m > 0 && r_m < base.max_residual_m);
            CHECK(r_sigma > 0.5 && r_sigma < base.max_residual_sigma);
        } else {
            CHECK_EQ_INT(r.outcome, run == 1 ? TRACK_OK : TRACK_HIGH_RESIDUAL);
        }
    }
    half_pair_close(&hp);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

/* A GPU reference at half resolution (the default: the ray-cast of
 * recon/) or a quarter (`--ref-level 2`), the frame at full resolution. The
 * finest frame level is associated with the reference's level, so the
 * motion must come out as well as with a full-resolution reference:
 * noiseless 320x240 frames against a 160x120 or 80x60 reference rendered at
 * that level's intrinsics. */
static void check_coarse_reference(uint32_t level)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    half_pair hp;
    CHECK_OK(half_pair_open(&hp, SYNTH_NOISE_NONE, level));
    bf_intrinsics Kh = hp.Kh;
    CHECK_EQ_INT(Kh.width, 320u >> level);
    CHECK(fabs(Kh.cx_px - (160.0 / (1u << level) - 0.5)) < 1e-12 && fabs(Kh.fx_px - 262.5 / (1u << level)) < 1e-12);
    bf_se3 T0 = hp.T0, d = hp.d;
    const uint16_t *ref = hp.ref, *d1 = hp.d1;
    uint32_t nh = Kh.width * Kh.height;
    float *zf = malloc(nh * 4);
    for (uint32_t i = 0; i < nh; i++) zf[i] = (float)(ref[i] / Kh.depth_scale);
    gpu_buffer *buf;
    CHECK_OK(upload_float(ctx, zf, nh, &buf));
    track_config cfg = test_config(&K_MID);
    CHECK_EQ_INT(track_config_default().ref_level, 1);
    cfg.ref_level = level;
    track_tracker *t;
    CHECK_OK(track_create(ctx, &cfg, &K_MID, &t));
    CHECK_OK(track_set_reference_gpu(t, buf, &T0));
    /* What comes back is the reference's own level, smoothed: no pixel
     * moves by more than a few centimetres, holes stay holes. */
    CHECK_OK(track_download_reference(t, zf));
    uint32_t kept = 0;
    for (uint32_t i = 0; i < nh; i++) {
        double z = ref[i] / Kh.depth_scale;
        if (z > 0 && z <= cfg.sensor.max_depth_m) kept += zf[i] > 0 && fabs(zf[i] - z) < 0.03;
        else CHECK(zf[i] == 0);
    }
    track_result r;
    bf_frame f1 = frame_of(&K_MID, d1, 1);
    CHECK_OK(track_frame(t, &f1, &T0, &r));
    double dt, da;
    bf_se3 inv = bf_se3_inverse(&T0), est = bf_se3_mul(&inv, &r.T_wc);
    pose_error(&d, &est, &dt, &da);
    fprintf(stderr, "  reference at level %u: %s, error %.3f mm %.4f deg; %u/%u inliers, %u of %u pixels kept\n", level,
            track_outcome_name(r.outcome), 1e3 * dt, da, r.n_inliers, r.n_valid, kept, nh);
    CHECK(kept >= nh * 9 / 10);
    CHECK_EQ_INT(r.outcome, TRACK_OK);
    CHECK_LE(dt, 0.001);
    CHECK_LE(da, 0.1);
    /* A reference of the full size is accepted (its first part is read);
     * one too small is not. */
    gpu_buffer *small;
    CHECK_OK(upload_float(ctx, zf, nh / 2, &small));
    CHECK_STATUS(track_set_reference_gpu(t, small, &T0), BF_INVALID_ARG);
    gpu_buffer_destroy(small);
    gpu_buffer_destroy(buf);
    track_destroy(t);
    free(zf);
    half_pair_close(&hp);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

BF_TEST(half_resolution_reference_tracks_like_a_full_one) { check_coarse_reference(1); }

BF_TEST(quarter_resolution_reference_tracks_like_a_full_one) { check_coarse_reference(2); }

/* The reference's level must be one of the tracker's pyramid levels. */
BF_TEST(reference_level_beyond_the_pyramid_is_refused)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    track_config cfg = test_config(&K_MID);
    cfg.ref_level = cfg.levels;
    track_tracker *t = NULL;
    CHECK_STATUS(track_create(ctx, &cfg, &K_MID, &t), BF_INVALID_ARG);
    CHECK(t == NULL);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

/* The loop's paths (recon/) read the frame where fusion uploaded it and
 * prepare a reference written in place in the caller's submission: the
 * same inputs through the same kernels as the host copies, so the same
 * bits. */
BF_TEST(frame_on_the_gpu_and_reference_in_place_match_the_copying_paths)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    half_pair hp;
    CHECK_OK(half_pair_open(&hp, SYNTH_NOISE_KINECT1, 1));
    bf_intrinsics Kh = hp.Kh;
    bf_se3 T0 = hp.T0;
    const uint16_t *ref = hp.ref, *d1 = hp.d1;
    uint32_t nh = Kh.width * Kh.height, n1 = K_MID.width * K_MID.height;
    float *zf = malloc(nh * 4), *za = malloc(nh * 4), *zb = malloc(nh * 4);
    for (uint32_t i = 0; i < nh; i++) zf[i] = (float)(ref[i] / Kh.depth_scale);
    gpu_buffer *buf;
    CHECK_OK(upload_float(ctx, zf, nh, &buf));
    /* The frame's raw depth 12 bytes into a buffer, as in fusion's slot. */
    gpu_buffer *raw;
    gpu_buffer_desc rd = {.name = "test.raw", .size_bytes = 12 + (uint64_t)(n1 + 1) / 2 * 4,
                          .memory = GPU_MEMORY_UPLOAD};
    CHECK_OK(gpu_buffer_create(ctx, &rd, &raw));
    CHECK_OK(gpu_buffer_fill(raw, 0, 12, 0xdeadbeefu));
    CHECK_OK(gpu_buffer_upload(raw, 12, d1, (uint64_t)n1 * 2));
    track_config cfg = test_config(&K_MID);
    track_tracker *t;
    CHECK_OK(track_create(ctx, &cfg, &K_MID, &t));
    bf_frame f1 = frame_of(&K_MID, d1, 1);
    track_result ra, rb;
    /* Copying paths. */
    CHECK_OK(track_set_reference_gpu(t, buf, &T0));
    CHECK_OK(track_download_reference(t, za));
    CHECK_OK(track_frame(t, &f1, &T0, &ra));
    /* In place, in a submission the caller owns, and the frame on the GPU. */
    gpu_buffer *target;
    uint64_t target_px;
    CHECK_OK(track_reference_target(t, &target, &target_px));
    CHECK_OK(gpu_begin(ctx));
    gpu_cmd_copy(ctx, buf, 0, target, target_px * 4, (uint64_t)nh * 4);
    gpu_cmd_barrier(ctx, GPU_BARRIER_TRANSFER_TO_COMPUTE);
    CHECK_OK(track_cmd_reference(t, &T0, false));
    gpu_cmd_barrier(ctx, GPU_BARRIER_HOST);
    CHECK_OK(gpu_submit_wait(ctx));
    CHECK_OK(track_finish_reference(t));
    CHECK_OK(track_download_reference(t, zb));
    CHECK_OK(track_frame_gpu(t, raw, 12, 1, &T0, &rb));
    CHECK(memcmp(za, zb, nh * 4) == 0);
    CHECK_EQ_INT(ra.outcome, TRACK_OK);
    CHECK_EQ_INT(rb.outcome, ra.outcome);
    CHECK_EQ_INT(rb.n_inliers, ra.n_inliers);
    CHECK_EQ_INT(rb.iterations, ra.iterations);
    CHECK(memcmp(&rb.T_wc, &ra.T_wc, sizeof ra.T_wc) == 0);
    /* A slot that does not hold the image, or is misaligned, is refused. */
    CHECK_STATUS(track_frame_gpu(t, raw, 16, 1, &T0, &rb), BF_INVALID_ARG);
    CHECK_STATUS(track_frame_gpu(t, raw, 14, 1, &T0, &rb), BF_INVALID_ARG);
    gpu_buffer_destroy(raw);
    gpu_buffer_destroy(buf);
    track_destroy(t);
    free(zf), free(za), free(zb);
    half_pair_close(&hp);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

/* max |R^T R - I|: how far a pose's rotation is from orthonormal. */
static double rigidity_error(const bf_se3 *T)
{
    double e = 0;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            double g = T->R[0][i] * T->R[0][j] + T->R[1][i] * T->R[1][j] + T->R[2][i] * T->R[2][j];
            e = fmax(e, fabs(g - (i == j)));
        }
    return e;
}

/* Frame-to-frame tracking in a closed loop, as recon runs it: the reference
 * is set at the last estimate and the guess is the last estimate, so the
 * relative pose starts at the identity every time. Here the pair is the
 * same every round (reference frame 0, frame 1), so every round must find
 * the same relative motion, from any starting pose. The tracker used to
 * hand back R (I + E) for a reference rotation R with R^T R = I + E, which
 * tripled E every round: from 1e-16, 1e-3 after ~25 rounds and the motion
 * mm off (the synthetic fr1_xyz room lost tracking at frame 29). */
static void closed_loop(track_tracker *t, const bf_frame *f0, const bf_frame *f1, const bf_se3 *start, uint32_t rounds,
                        bf_se3 *motion0, bool have_motion0)
{
    bf_se3 T = *start;
    double worst_dt = 0, worst_da = 0, worst_rigid = 0;
    for (uint32_t k = 0; k < rounds; k++) {
        track_result r;
        CHECK_OK(track_set_reference_frame(t, f0, &T));
        CHECK_OK(track_frame(t, f1, &T, &r));
        CHECK_EQ_INT(r.outcome, TRACK_OK);
        if (r.outcome != TRACK_OK) return;
        bf_se3 inv = bf_se3_inverse(&T);
        bf_se3 m = bf_se3_mul(&inv, &r.T_wc);
        if (!have_motion0) *motion0 = m, have_motion0 = true;
        double dt, da;
        pose_error(motion0, &m, &dt, &da);
        worst_dt = fmax(worst_dt, dt), worst_da = fmax(worst_da, da);
        worst_rigid = fmax(worst_rigid, rigidity_error(&r.T_wc));
        T = r.T_wc;
    }
    fprintf(stderr, "  %u rounds: motion differs by up to %.3g m, %.3g deg; |R^T R - I| up to %.3g\n", rounds,
            worst_dt, worst_da, worst_rigid);
    CHECK_LE(worst_dt, 1e-6);
    CHECK_LE(worst_da, 1e-5);
    CHECK_LE(worst_rigid, 1e-12);
}

BF_TEST(closed_loop_tracking_depends_only_on_the_relative_pose)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    room rm;
    CHECK_OK(room_open(&rm, &K_SMALL, SYNTH_NOISE_KINECT1));
    bf_se3 T0 = rm.scene.T_wc_view, d = small_motion();
    bf_se3 T1 = bf_se3_mul(&T0, &d);
    uint16_t *d0 = render(&rm, 0, &T0), *d1 = render(&rm, 1, &T1);
    bf_frame f0 = frame_of(&K_SMALL, d0, 0), f1 = frame_of(&K_SMALL, d1, 1);
    track_config cfg = test_config(&K_SMALL);
    track_tracker *t;
    CHECK_OK(track_create(ctx, &cfg, &K_SMALL, &t));
    /* 40 rounds from the true pose, then from the identity and from 10 km
     * away, turned (B = C A): the same motion to 1e-6 m throughout, and
     * every estimate a rotation to rounding. */
    bf_se3 motion0, I = bf_se3_identity();
    bf_se3 C = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0.2, 0.3, 1), 0.7), bf_v3(1e4, -3e3, 250));
    bf_se3 far = bf_se3_mul(&C, &T0);
    closed_loop(t, &f0, &f1, &T0, 40, &motion0, false);
    closed_loop(t, &f0, &f1, &I, 40, &motion0, true);
    closed_loop(t, &f0, &f1, &far, 40, &motion0, true);
    /* A reference and guess whose rotation is off orthonormal by 1e-6 (a
     * symmetric stretch): the estimate is a rotation, and the motion is the
     * same as from the exact pose within that 1e-6. */
    bf_se3 S = T0;
    double e[3][3] = {{1e-6, 4e-7, -3e-7}, {4e-7, -5e-7, 2e-7}, {-3e-7, 2e-7, 8e-7}};
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            for (int k = 0; k < 3; k++) S.R[i][j] += T0.R[i][k] * e[k][j];
    CHECK(rigidity_error(&S) > 1e-6);
    track_result r;
    CHECK_OK(track_set_reference_frame(t, &f0, &S));
    CHECK_OK(track_frame(t, &f1, &S, &r));
    CHECK_EQ_INT(r.outcome, TRACK_OK);
    fprintf(stderr, "  stretched reference: |R^T R - I| %.3g in, %.3g out\n", rigidity_error(&S),
            rigidity_error(&r.T_wc));
    CHECK_LE(rigidity_error(&r.T_wc), 1e-12);
    bf_se3 inv = bf_se3_inverse(&T0), m = bf_se3_mul(&inv, &r.T_wc);
    double dt, da;
    pose_error(&motion0, &m, &dt, &da);
    CHECK_LE(dt, 1e-5);
    CHECK_LE(da, 1e-3);
    /* A reflection is not a pose. */
    bf_se3 M = T0;
    for (int j = 0; j < 3; j++) M.R[0][j] = -M.R[0][j];
    CHECK_STATUS(track_set_reference_frame(t, &f0, &M), BF_INVALID_ARG);
    CHECK_STATUS(track_frame(t, &f1, &M, &r), BF_INVALID_ARG);
    track_destroy(t);
    free(d0), free(d1);
    room_close(&rm);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

BF_TEST(icp_reduction_paths_agree)
{
    /* The subgroup and the shared-memory reduction sum in different orders:
     * the same pose within float rounding of the sums. */
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    room rm;
    CHECK_OK(room_open(&rm, &K_SMALL, SYNTH_NOISE_KINECT1));
    bf_se3 T0 = rm.scene.T_wc_view, d = small_motion();
    bf_se3 T1 = bf_se3_mul(&T0, &d);
    uint16_t *d0 = render(&rm, 0, &T0), *d1 = render(&rm, 1, &T1);
    bf_frame f0 = frame_of(&K_SMALL, d0, 0), f1 = frame_of(&K_SMALL, d1, 1);
    track_config cfg = test_config(&K_SMALL);
    track_result r[2];
    bool sg[2];
    for (int k = 0; k < 2; k++) {
        cfg.icp_subgroup = k == 0;
        track_tracker *t;
        CHECK_OK(track_create(ctx, &cfg, &K_SMALL, &t));
        sg[k] = t->icp_subgroup;
        CHECK_OK(track_set_reference_frame(t, &f0, &T0));
        CHECK_OK(track_frame(t, &f1, &T0, &r[k]));
        track_destroy(t);
    }
    CHECK(!sg[1]);
    double dt, da;
    pose_error(&r[0].T_wc, &r[1].T_wc, &dt, &da);
    fprintf(stderr, "  subgroup kernel %s; paths differ by %.3g m, %.3g deg\n", sg[0] ? "used" : "unavailable", dt, da);
    CHECK_EQ_INT(r[0].outcome, TRACK_OK);
    CHECK_EQ_INT(r[1].outcome, TRACK_OK);
    CHECK_LE(dt, 1e-4);
    CHECK_LE(da, 0.01);
    free(d0), free(d1);
    room_close(&rm);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

BF_TEST(icp_tum_fr2_desk_b1_to_b2)
{
    const char *dir = bf_test_data("tum/frames");
    if (!dir) BF_SKIP("shared TUM frames absent");
    char path[600];
    uint16_t *d[2] = {NULL, NULL};
    uint32_t w, h;
    const char *names[2] = {"fr2_desk_b1_depth.png", "fr2_desk_b2_depth.png"};
    for (int k = 0; k < 2; k++) {
        snprintf(path, sizeof path, "%s/%s", dir, names[k]);
        CHECK_OK(replay_png_read_u16(path, &d[k], &w, &h));
    }
    /* fr2 intrinsics from ../shared/data/README.md. */
    bf_intrinsics K = {w, h, 520.9, 521.0, 325.1, 249.7, 5000};
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    /* The pair is about 13 cm and 3.4 degrees apart, more than a 30 Hz
     * frame step. With DESIGN.md's 20 degree normal gate a third of the
     * real (quantised) normals disagree by more and ICP settles, flagged
     * degenerate, at about 5 cm; with the default gate (45 degrees,
     * docs/tracking.md) it converges with 85% inliers. Both are printed;
     * the default's result is checked. */
    for (int pass = 0; pass < 2; pass++) {
    track_config cfg = track_config_default();
    if (pass == 0) cfg.angle_deg = 20;
    fprintf(stderr, "  normal gate %.0f deg:\n", cfg.angle_deg);
    track_tracker *t;
    CHECK_OK(track_create(ctx, &cfg, &K, &t));
    bf_se3 I = bf_se3_identity(), est[2];
    for (int k = 0; k < 2; k++) {
        bf_frame fr = frame_of(&K, d[k], 0), fc = frame_of(&K, d[1 - k], 1);
        track_result r;
        CHECK_OK(track_set_reference_frame(t, &fr, &I));
        CHECK_OK(track_frame(t, &fc, &I, &r));
        est[k] = r.T_wc;
        bf_quat q;
        bf_vec3 tr;
        bf_se3_to_qt(&r.T_wc, &q, &tr);
        fprintf(stderr, "  %s -> %s: %s%s, t = (%.1f, %.1f, %.1f) mm, |t| %.1f mm, %.3f deg; %u/%u inliers (%.0f%%), "
                        "rms %.2f mm, eig ratio %.3g, %u iterations, ICP %.1f ms, ROF %.1f ms\n",
                k ? "b2" : "b1", k ? "b1" : "b2", track_outcome_name(r.outcome), r.degenerate ? " (degenerate)" : "", 1e3 * tr.x, 1e3 * tr.y, 1e3 * tr.z,
                1e3 * bf_v3_norm(tr), bf_quat_angle(q) * 180 / M_PI, r.n_inliers, r.n_valid, 100 * r.inlier_frac,
                1e3 * r.residual_m, r.eig_min / r.eig_max, r.iterations, r.ms_gpu, r.ms_rof);
        if (pass == 0) continue;
        CHECK_EQ_INT(r.outcome, TRACK_OK);
        CHECK(!r.degenerate);
        CHECK(r.inlier_frac > 0.8);
    }
    if (pass == 0) {
        track_destroy(t);
        continue;
    }
    /* No ground truth comes with the pair: the forward and backward
     * estimates must be each other's inverse (each has its own smoothed
     * reference and its own association), within a few mm and tenths of a
     * degree. */
    bf_se3 loop = bf_se3_mul(&est[0], &est[1]);
    double dt = bf_v3_norm(loop.t), da = bf_se3_angle(&loop) * 180 / M_PI;
    fprintf(stderr, "  forward * backward = %.2f mm, %.3f deg from the identity\n", 1e3 * dt, da);
    CHECK_LE(dt, 0.005);
    CHECK_LE(da, 0.3);
    track_destroy(t);
    }
    free(d[0]), free(d[1]);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

/* ------------------------------------------------------------ hard cases */

/* A floor-sized plane z = 0 seen from 1.5 m, 35 degrees from straight down. */
static bf_status plane_scene(synth_scene *sc, bf_se3 *T0)
{
    mesh_data m = {0};
    m.n_verts = 4, m.n_tris = 2;
    m.xyz = malloc(12 * sizeof(float));
    m.tri = malloc(6 * sizeof(uint32_t));
    if (!m.xyz || !m.tri) return BF_NO_MEMORY;
    float v[12] = {-20, -20, 0, 20, -20, 0, 20, 20, 0, -20, 20, 0};
    uint32_t tr[6] = {0, 1, 2, 0, 2, 3};
    memcpy(m.xyz, v, sizeof v);
    memcpy(m.tri, tr, sizeof tr);
    *T0 = synth_look_at(bf_v3(0, -1.05, 1.5), bf_v3(0, 0, 0), bf_v3(0, 0, 1));
    return synth_scene_from_mesh(&m, T0, sc);
}

static void check_plane(synth_noise noise, double tol_m)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    synth_scene sc;
    bf_se3 T0;
    CHECK_OK(plane_scene(&sc, &T0));
    synth_renderer *rr;
    synth_render_config rc = {.K = K_MID, .noise = noise, .seed = 11};
    CHECK_OK(synth_renderer_create(&sc, &rc, &rr));
    bf_se3 d = small_motion(), T1 = bf_se3_mul(&T0, &d);
    uint32_t n = K_MID.width * K_MID.height;
    uint16_t *d0 = malloc(n * 2), *d1 = malloc(n * 2);
    CHECK_OK(synth_render(rr, 0, &T0, d0, NULL, NULL));
    CHECK_OK(synth_render(rr, 1, &T1, d1, NULL, NULL));
    track_config cfg = test_config(&K_MID);
    track_result r;
    CHECK_OK(track_pair(ctx, &cfg, &K_MID, d0, d1, &T0, &r));
    /* Constrained: the frame's plane lands on the world plane. Every
     * pixel's true point, taken into the frame camera and back to the world
     * with the estimate, must lie on z = 0. */
    bf_se3 T1i = bf_se3_inverse(&T1);
    double worst = 0;
    for (uint32_t v = 0; v < K_MID.height; v += 7)
        for (uint32_t u = 0; u < K_MID.width; u += 7) {
            bf_vec3 ray = bf_se3_rotate(&T1, bf_intrinsics_unproject(&K_MID, u, v, 1.0));
            double s = -T1.t.z / ray.z;
            bf_vec3 p_w = bf_v3_add(T1.t, bf_v3_scale(ray, s));
            bf_vec3 p_c = bf_se3_apply(&T1i, p_w);
            worst = fmax(worst, fabs(bf_se3_apply(&r.T_wc, p_c).z));
        }
    /* Weak: translation along the plane and rotation about its normal, as
     * the guess has them (it is T0). In the reference camera, the estimate
     * relative to the guess. */
    bf_se3 T0i = bf_se3_inverse(&T0), rel = bf_se3_mul(&T0i, &r.T_wc);
    bf_vec3 n_c = bf_se3_rotate(&T0i, bf_v3(0, 0, 1));
    double xi[6];
    bf_se3_log(&rel, xi);
    bf_vec3 t_in = bf_v3_sub(rel.t, bf_v3_scale(n_c, bf_v3_dot(rel.t, n_c)));
    double w_n = bf_v3_dot(bf_v3(xi[3], xi[4], xi[5]), n_c) * 180 / M_PI;
    fprintf(stderr, "  %s plane: %s, degenerate %d (eig ratio %.3g); off the plane %.2f mm at most; "
                    "in-plane shift %.3f mm, turn about the normal %.4f deg\n",
            noise == SYNTH_NOISE_NONE ? "noiseless" : "kinect1", track_outcome_name(r.outcome), r.degenerate,
            r.eig_min / r.eig_max, 1e3 * worst, 1e3 * bf_v3_norm(t_in), w_n);
    CHECK_EQ_INT(r.outcome, TRACK_OK);
    CHECK(r.degenerate);
    CHECK_LE(worst, tol_m);
    CHECK_LE(bf_v3_norm(t_in), 0.001);
    CHECK_LE(fabs(w_n), 0.05);
    free(d0), free(d1);
    synth_renderer_destroy(rr);
    synth_scene_free(&sc);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

BF_TEST(single_plane_is_degenerate_and_keeps_the_guess_in_weak_directions)
{
    check_plane(SYNTH_NOISE_NONE, 0.001);
    check_plane(SYNTH_NOISE_KINECT1, 0.004);
}

/* Depth (u16) and then RGB565 colour (two per word), as in fusion's
 * incoming slot, in one host-visible buffer; the colour's byte offset. */
static bf_status slot_of(gpu_context *ctx, const uint16_t *depth, const uint8_t *rgb, uint32_t n, gpu_buffer **out,
                         uint64_t *colour_off)
{
    uint64_t words = (n + 1) / 2;
    gpu_buffer_desc d = {.name = "test.slot", .size_bytes = 2 * words * 4, .memory = GPU_MEMORY_UPLOAD};
    bf_status s = gpu_buffer_create(ctx, &d, out);
    uint32_t *w = calloc(2 * words, 4);
    if (s == BF_OK && !w) s = BF_NO_MEMORY;
    if (s == BF_OK) {
        memcpy(w, depth, (size_t)n * 2);
        for (uint32_t i = 0; i < n; i++) {
            const uint8_t *c = rgb + 3 * (size_t)i;
            w[words + i / 2] |= fusion_rgb565(c[0], c[1], c[2]) << (16 * (i & 1u));
        }
        s = gpu_buffer_upload(*out, 0, w, 2 * words * 4);
    }
    free(w);
    *colour_off = words * 4;
    return s;
}

/* The reference made with frame f (in `slot`) at T, as recon/ makes it:
 * the frame preprocessed, its half-resolution depth standing in for the
 * map's ray-cast, its intensity kept for the photometric term unless
 * with_frame is false (as a relocalising candidate's: no intensity). */
static bf_status reference_of_slot_as(gpu_context *ctx, track_tracker *t, gpu_buffer *slot, uint64_t colour_off,
                                      const bf_se3 *T, bool with_frame)
{
    gpu_buffer *target, *fd;
    uint64_t target_px, fd_px;
    bf_status s = track_set_frame_colour(t, slot, colour_off);
    if (s == BF_OK) s = track_reference_target(t, &target, &target_px);
    if (s == BF_OK) s = gpu_begin(ctx);
    if (s == BF_OK) s = track_cmd_frame(t, slot, 0, 0);
    if (s == BF_OK) s = track_frame_depth_gpu(t, 1, &fd, &fd_px);
    if (s != BF_OK) return s;
    gpu_cmd_barrier(ctx, GPU_BARRIER_COMPUTE_TO_TRANSFER);
    gpu_cmd_copy(ctx, fd, fd_px * 4, target, target_px * 4, (uint64_t)(K_MID.width / 2) * (K_MID.height / 2) * 4);
    gpu_cmd_barrier(ctx, GPU_BARRIER_TRANSFER_TO_COMPUTE);
    if ((s = track_cmd_reference(t, T, with_frame)) != BF_OK) return s;
    gpu_cmd_barrier(ctx, GPU_BARRIER_HOST);
    if ((s = gpu_submit_wait(ctx)) != BF_OK) return s;
    return track_finish_reference(t);
}

static bf_status reference_of_slot(gpu_context *ctx, track_tracker *t, gpu_buffer *slot, uint64_t colour_off,
                                   const bf_se3 *T)
{
    return reference_of_slot_as(ctx, t, slot, colour_off, T, true);
}

/* A horizontal box blur of odd length len, RGB8, clamped at the edges. */
static void box_blur_rows(const uint8_t *src, uint8_t *dst, uint32_t w, uint32_t h, int len)
{
    for (uint32_t y = 0; y < h; y++) {
        for (uint32_t x = 0; x < w; x++) {
            for (int c = 0; c < 3; c++) {
                int sum = 0;
                for (int k = -len / 2; k <= len / 2; k++) {
                    int xx = (int)x + k;
                    xx = xx < 0 ? 0 : xx >= (int)w ? (int)w - 1 : xx;
                    sum += src[3 * ((size_t)y * w + (size_t)xx) + (size_t)c];
                }
                dst[3 * ((size_t)y * w + x) + (size_t)c] = (uint8_t)((sum + len / 2) / len);
            }
        }
    }
}

/* A textured floor: its shape leaves the slides along it and the turn about
 * its normal to the guess (the test above); with the photometric term its
 * texture pins them. The "on" cases use the term at every level, as the 2 cm
 * step spans 3 pixels at the finest one; with the defaults the finest level
 * decides and alone uses it. (synth's wooden floor has gaps thinner than a
 * pixel, rendered without antialiasing: they flicker from view to view, and
 * the term followed them to a wrong pose.) */
BF_TEST(photometric_term_tracks_a_slide_along_a_textured_plane)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    synth_scene sc;
    bf_se3 T0;
    CHECK_OK(mosaic_scene(&sc, &T0));
    synth_renderer *rr;
    synth_render_config rc = {.K = K_MID, .noise = SYNTH_NOISE_KINECT1, .seed = 11};
    CHECK_OK(synth_renderer_create(&sc, &rc, &rr));
    /* Along the floor only: 2 cm and 2 degrees about its normal. */
    bf_se3 T0i = bf_se3_inverse(&T0);
    bf_vec3 n_c = bf_se3_rotate(&T0i, bf_v3(0, 0, 1));
    bf_vec3 slide = bf_se3_rotate(&T0i, bf_v3_normalize(bf_v3(1.0, 0.6, 0)));
    bf_se3 d = bf_se3_from_qt(bf_quat_from_axis_angle(n_c, 2.0 * M_PI / 180), bf_v3_scale(slide, 0.02));
    bf_se3 T1 = bf_se3_mul(&T0, &d);
    uint32_t n = K_MID.width * K_MID.height;
    uint16_t *d0 = malloc(n * 2), *d1 = malloc(n * 2);
    uint8_t *c0 = malloc(n * 3), *c1 = malloc(n * 3), *cb1 = malloc(n * 3);
    CHECK_OK(synth_render(rr, 0, &T0, d0, c0, NULL));
    CHECK_OK(synth_render(rr, 1, &T1, d1, c1, NULL));
    /* The second frame smeared as a camera turning during the exposure
     * smears it: a 9-pixel horizontal box. */
    box_blur_rows(c1, cb1, K_MID.width, K_MID.height, 9);
    gpu_buffer *s0, *s1, *sb1;
    uint64_t off0, off1, offb1;
    CHECK_OK(slot_of(ctx, d0, c0, n, &s0, &off0));
    CHECK_OK(slot_of(ctx, d1, c1, n, &s1, &off1));
    CHECK_OK(slot_of(ctx, d1, cb1, n, &sb1, &offb1));
    enum { N_CASES = 9 };
    double err[N_CASES][2];
    bf_se3 est[N_CASES];
    uint32_t iters[N_CASES];
    /* Off, on, on through a colour camera that is the depth camera (the
     * distortion path, no distortion): as registered colour, and on with
     * the second frame's colour blurred: the term is dropped. Then with the
     * defaults (weight 0.3, only where the depth leaves a direction weak),
     * which a plane does: the term is brought in at the finest level; the
     * same with the frame blurred: brought in, then dropped; and the same
     * against a reference made without a frame's intensity (a relocalising
     * candidate's): nothing to compare, so depth alone. A reference cast
     * from the map alone at exactly the pose of the last frame that made
     * one keeps that frame's intensity (the term comes in); 1 cm away it
     * has none. */
    for (int photo = 0; photo < N_CASES; photo++) {
        bool weak = photo >= 4;
        track_config cfg = test_config(&K_MID);
        if (!weak) {
            cfg.photo_weight = photo ? 1.0f : 0.0f;
            cfg.photo_weak_ratio = 0;
        }
        /* The drop and the weak test are decided at the finest level
         * (photo_levels 1, the default): coarser levels keep what the term
         * did there. */
        if (!weak) cfg.photo_levels = photo == 3 ? 1 : 3;
        track_tracker *t;
        CHECK_OK(track_create(ctx, &cfg, &K_MID, &t));
        if (photo == 2) {
            double no_dist[5] = {0, 0, 0, 0, 0};
            bf_se3 I = bf_se3_identity();
            CHECK_OK(track_set_colour_camera(t, &K_MID, no_dist, &I));
        }
        if (photo >= 7) {
            /* The frame fused at T0 first, then the map alone cast again. */
            CHECK_OK(reference_of_slot(ctx, t, s0, off0, &T0));
            bf_se3 T_cast = T0;
            if (photo == 8) T_cast.t.x += 0.01;
            CHECK_OK(reference_of_slot_as(ctx, t, s0, off0, &T_cast, false));
        } else {
            CHECK_OK(reference_of_slot_as(ctx, t, s0, off0, &T0, photo != 6));
        }
        bool blurred = photo == 3 || photo == 5;
        gpu_buffer *f1 = blurred ? sb1 : s1;
        CHECK_OK(track_set_frame_colour(t, f1, blurred ? offb1 : off1));
        track_result r;
        CHECK_OK(track_frame_gpu(t, f1, 0, 1, &T0, &r));
        est[photo] = r.T_wc;
        iters[photo] = r.iterations;
        /* The error along the floor (world z is its normal): the camera's
         * position in x, y and its heading about z. */
        bf_se3 T1i = bf_se3_inverse(&T1), e = bf_se3_mul(&r.T_wc, &T1i);
        double xi[6];
        bf_se3_log(&e, xi);
        err[photo][0] = hypot(r.T_wc.t.x - T1.t.x, r.T_wc.t.y - T1.t.y);
        err[photo][1] = fabs(xi[5]) * 180 / M_PI;
        static const char *what[N_CASES] = {"off",          "on", "on (colour camera)", "on, frame blurred",
                                            "where weak", "where weak, frame blurred",
                                            "where weak, reference without intensity",
                                            "where weak, cast again at the kept pose",
                                            "where weak, cast 1 cm from the kept pose"};
        fprintf(stderr, "  textured floor, photometric %s: %s, degenerate %d, eig ratio %.3g, along the floor %.2f mm, "
                        "about its normal %.3f deg, sharpness %.3f%s%s\n",
                what[photo], track_outcome_name(r.outcome), r.degenerate, r.eig_min / r.eig_max, 1e3 * err[photo][0],
                err[photo][1], r.photo_sharpness, r.photo_dropped ? " (term dropped)" : "",
                r.photo_weak ? " (brought in: weak)" : "");
        CHECK_EQ_INT(r.outcome, TRACK_OK);
        CHECK_EQ_INT(r.degenerate, photo == 0 || photo == 3 || photo == 5 || photo == 6 || photo == 8);
        /* The same texture seen 2 cm further: the gradient energies agree
         * (sharpness about 1); a 9-pixel box keeps well under half of the
         * mosaic's edge energy. */
        CHECK_EQ_INT(r.photo_dropped, blurred);
        CHECK_EQ_INT(r.photo_weak, photo == 4 || photo == 5 || photo == 7);
        if (photo == 1 || photo == 2 || photo == 4 || photo == 7)
            CHECK(r.photo_sharpness > 0.8 && r.photo_sharpness < 1.25);
        if (blurred) CHECK(r.photo_sharpness > 0 && r.photo_sharpness < 0.5);
        if (photo == 6 || photo == 8) CHECK(r.photo_sharpness == 0);
        track_destroy(t);
    }
    /* Off: the guess's 2 cm and 2 degrees stay (degenerate). On: a tenth
     * of a pixel (1.8 m away at 262 px a pixel is 7 mm), measured 0.55 mm
     * and 0.005 degrees. */
    CHECK(err[0][0] > 0.015 && err[0][1] > 1.5);
    CHECK_LE(err[1][0], 0.0015);
    CHECK_LE(err[1][1], 0.05);
    /* Brought in at the finest level alone and at the default weight, it
     * reaches the same bounds. */
    CHECK_LE(err[4][0], 0.0015);
    CHECK_LE(err[4][1], 0.05);
    double dt, da;
    pose_error(&est[1], &est[2], &dt, &da);
    CHECK_LE(dt, 5e-5);
    CHECK_LE(da, 0.002);
    /* Dropped, the term leaves the depth-only pose. Brought in and dropped,
     * or with no intensity to compare, the frame is tracked as without the
     * term: the same pose, bit for bit. */
    pose_error(&est[0], &est[3], &dt, &da);
    CHECK_LE(dt, 5e-5);
    CHECK_LE(da, 0.002);
    CHECK(memcmp(&est[0], &est[5], sizeof est[0]) == 0);
    CHECK(memcmp(&est[0], &est[6], sizeof est[0]) == 0);
    /* Brought in and dropped, the depth-only first iteration is taken back,
     * not run a third time. */
    CHECK_EQ_INT(iters[5], iters[0] + 1);
    /* Cast again at the kept pose: the same as the frame's own reference. */
    CHECK(memcmp(&est[4], &est[7], sizeof est[0]) == 0);
    /* Settings out of range are refused at create. */
    track_tracker *bad;
    track_config cb = test_config(&K_MID);
    cb.photo_weight = -1;
    CHECK_STATUS(track_create(ctx, &cb, &K_MID, &bad), BF_INVALID_ARG);
    cb = test_config(&K_MID);
    cb.photo_levels = TRACK_MAX_LEVELS + 1;
    CHECK_STATUS(track_create(ctx, &cb, &K_MID, &bad), BF_INVALID_ARG);
    cb = test_config(&K_MID);
    cb.photo_sigma = 0;
    CHECK_STATUS(track_create(ctx, &cb, &K_MID, &bad), BF_INVALID_ARG);
    cb = test_config(&K_MID);
    cb.photo_sharpness_min = 1.5f;
    CHECK_STATUS(track_create(ctx, &cb, &K_MID, &bad), BF_INVALID_ARG);
    cb = test_config(&K_MID);
    cb.photo_weak_ratio = 1.0f;
    CHECK_STATUS(track_create(ctx, &cb, &K_MID, &bad), BF_INVALID_ARG);
    gpu_buffer_destroy(s0);
    gpu_buffer_destroy(s1);
    gpu_buffer_destroy(sb1);
    free(d0), free(d1), free(c0), free(c1), free(cb1);
    synth_renderer_destroy(rr);
    synth_scene_free(&sc);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

/* The room constrains every direction by its depth alone: with the term
 * kept for weak geometry (the default) it stays out, and the pose is the
 * depth-only one bit for bit; asked for in every frame, it runs. */
BF_TEST(photometric_term_stays_out_where_the_depth_constrains_every_direction)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    room rm;
    CHECK_OK(room_open(&rm, &K_MID, SYNTH_NOISE_KINECT1));
    bf_se3 T0 = rm.scene.T_wc_view, d = small_motion();
    bf_se3 T1 = bf_se3_mul(&T0, &d);
    uint32_t n = K_MID.width * K_MID.height;
    uint16_t *d0 = malloc(n * 2), *d1 = malloc(n * 2);
    uint8_t *c0 = malloc(n * 3), *c1 = malloc(n * 3);
    CHECK_OK(synth_render(rm.r, 0, &T0, d0, c0, NULL));
    CHECK_OK(synth_render(rm.r, 1, &T1, d1, c1, NULL));
    gpu_buffer *s0, *s1;
    uint64_t off0, off1;
    CHECK_OK(slot_of(ctx, d0, c0, n, &s0, &off0));
    CHECK_OK(slot_of(ctx, d1, c1, n, &s1, &off1));
    track_result r[3];
    for (int mode = 0; mode < 3; mode++) {
        /* 0: the defaults (the term where weak); 1: off; 2: every frame. */
        track_config cfg = test_config(&K_MID);
        if (mode == 0) CHECK(cfg.photo_weight > 0 && cfg.photo_weak_ratio > 0);
        if (mode == 1) cfg.photo_weight = 0;
        if (mode == 2) cfg.photo_weak_ratio = 0;
        track_tracker *t;
        CHECK_OK(track_create(ctx, &cfg, &K_MID, &t));
        CHECK_OK(reference_of_slot(ctx, t, s0, off0, &T0));
        CHECK_OK(track_set_frame_colour(t, s1, off1));
        CHECK_OK(track_frame_gpu(t, s1, 0, 1, &T0, &r[mode]));
        double dt, da;
        pose_error(&r[mode].T_wc, &T1, &dt, &da);
        fprintf(stderr, "  room, photometric %s: %s, eig ratio %.3g, %.2f mm, %.3f deg, sharpness %.3f%s\n",
                mode == 0 ? "where weak" : mode == 1 ? "off" : "every frame", track_outcome_name(r[mode].outcome),
                r[mode].eig_min / r[mode].eig_max, 1e3 * dt, da, r[mode].photo_sharpness,
                r[mode].photo_weak ? " (brought in)" : "");
        CHECK_EQ_INT(r[mode].outcome, TRACK_OK);
        CHECK(!r[mode].degenerate && !r[mode].photo_weak);
        /* Against one noisy frame's half-resolution depth (the full one of
         * icp_recovers_2cm_2deg_noisy_room keeps to 4 mm): 7.2-7.3 mm. */
        CHECK_LE(dt, 0.01);
        CHECK_LE(da, 0.5);
        track_destroy(t);
    }
    /* Well above the weak ratio, so the term never ran: the same pose. */
    CHECK(r[0].eig_min > 0.01 * r[0].eig_max);
    CHECK(r[0].photo_sharpness == 0 && r[2].photo_sharpness > 0);
    CHECK(memcmp(&r[0].T_wc, &r[1].T_wc, sizeof r[0].T_wc) == 0);
    gpu_buffer_destroy(s0);
    gpu_buffer_destroy(s1);
    free(d0), free(d1), free(c0), free(c1);
    room_close(&rm);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

BF_TEST(empty_saturated_and_nan_depth_are_reported_and_tracking_resumes)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    room rm;
    CHECK_OK(room_open(&rm, &K_SMALL, SYNTH_NOISE_KINECT1));
    uint32_t n = K_SMALL.width * K_SMALL.height;
    bf_se3 T0 = rm.scene.T_wc_view, d = small_motion();
    bf_se3 T1 = bf_se3_mul(&T0, &d);
    uint16_t *d0 = render(&rm, 0, &T0), *d1 = render(&rm, 1, &T1);
    uint16_t *zero = calloc(n, 2), *far = malloc(n * 2);
    for (uint32_t i = 0; i < n; i++) far[i] = 65535; /* 13.1 m: beyond max_depth_m */
    track_config cfg = test_config(&K_SMALL);
    cfg.ref_level = 0; /* the GPU references below are full-resolution images */
    /* At 160x120 a quarter of the pixels (4,800 samples) leaves 10.7 mm of
     * noise; this test is about resuming, at the bound of the checkerboard. */
    cfg.finest_sample_step = 2;
    track_tracker *t;
    CHECK_OK(track_create(ctx, &cfg, &K_SMALL, &t));
    track_result r;
    bf_frame f0 = frame_of(&K_SMALL, d0, 0), f1 = frame_of(&K_SMALL, d1, 1);
    bf_frame fz = frame_of(&K_SMALL, zero, 2), ff = frame_of(&K_SMALL, far, 3);
    /* No reference yet. */
    CHECK_OK(track_frame(t, &f1, &T0, &r));
    CHECK_EQ_INT(r.outcome, TRACK_NO_REFERENCE);
    CHECK_OK(track_set_reference_frame(t, &f0, &T0));
    CHECK_OK(track_frame(t, &fz, &T0, &r));
    CHECK_EQ_INT(r.outcome, TRACK_NO_DEPTH);
    CHECK(memcmp(&r.T_wc, &T0, sizeof T0) == 0);
    CHECK_OK(track_frame(t, &ff, &T0, &r));
    CHECK_EQ_INT(r.outcome, TRACK_NO_DEPTH);
    /* The next good frame tracks. */
    CHECK_OK(track_frame(t, &f1, &T0, &r));
    CHECK_EQ_INT(r.outcome, TRACK_OK);
    double dt, da;
    pose_error(&T1, &r.T_wc, &dt, &da);
    CHECK_LE(dt, 0.01);
    /* A reference of NaN (a broken ray-cast): no reference, no crash. */
    float *nan_img = malloc(n * 4), *mixed = malloc(n * 4);
    for (uint32_t i = 0; i < n; i++) nan_img[i] = NAN;
    gpu_buffer *buf;
    CHECK_OK(upload_float(ctx, nan_img, n, &buf));
    CHECK_OK(track_set_reference_gpu(t, buf, &T0));
    CHECK_OK(track_frame(t, &f1, &T0, &r));
    CHECK_EQ_INT(r.outcome, TRACK_NO_REFERENCE);
    gpu_buffer_destroy(buf);
    /* A reference with NaN and infinity sprinkled in: those pixels are
     * dropped, no NaN reaches the smoothing or the pose. */
    for (uint32_t i = 0; i < n; i++) {
        mixed[i] = (float)(d0[i] / K_SMALL.depth_scale);
        if (i % 7 == 3) mixed[i] = NAN;
        if (i % 11 == 5) mixed[i] = INFINITY;
        if (i % 13 == 6) mixed[i] = -1.0f;
    }
    CHECK_OK(upload_float(ctx, mixed, n, &buf));
    CHECK_OK(track_set_reference_gpu(t, buf, &T0));
    CHECK_OK(track_download_reference(t, nan_img));
    for (uint32_t i = 0; i < n; i++) CHECK(isfinite(nan_img[i]) && nan_img[i] >= 0);
    CHECK_OK(track_frame(t, &f1, &T0, &r));
    fprintf(stderr, "  after NaN-sprinkled reference: %s, %u/%u inliers\n", track_outcome_name(r.outcome), r.n_inliers,
            r.n_valid);
    CHECK(bf_se3_is_finite(&r.T_wc));
    gpu_buffer_destroy(buf);
    /* Bad arguments are statuses. */
    bf_frame wrong = frame_of(&K_MID, d0, 9);
    CHECK_STATUS(track_frame(t, &wrong, &T0, &r), BF_INVALID_ARG);
    track_config bad = cfg;
    bad.levels = 4;
    track_tracker *t2 = NULL;
    CHECK_STATUS(track_create(ctx, &bad, &K_SMALL, &t2), BF_INVALID_ARG);
    CHECK(t2 == NULL);
    track_destroy(NULL);
    track_destroy(t);
    free(d0), free(d1), free(zero), free(far), free(nan_img), free(mixed);
    room_close(&rm);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

BF_TEST(sudden_jump_of_30cm_20deg_is_a_failure)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    room rm;
    CHECK_OK(room_open(&rm, &K_SMALL, SYNTH_NOISE_KINECT1));
    bf_se3 T0 = rm.scene.T_wc_view;
    track_config cfg = test_config(&K_SMALL);
    track_tracker *t;
    CHECK_OK(track_create(ctx, &cfg, &K_SMALL, &t));
    uint16_t *d0 = render(&rm, 0, &T0);
    bf_frame f0 = frame_of(&K_SMALL, d0, 0);
    CHECK_OK(track_set_reference_frame(t, &f0, &T0));
    /* Several directions of the jump: each must fail, whatever the reason. */
    bf_vec3 axes[3] = {bf_v3(0, 1, 0), bf_v3(1, 0, 0), bf_v3(0.3, -1, 0.5)};
    bf_vec3 dirs[3] = {bf_v3(1, 0, 0), bf_v3(0, 1, 0.5), bf_v3(-1, 0.2, -0.6)};
    for (int k = 0; k < 3; k++) {
        bf_se3 j = bf_se3_from_qt(bf_quat_from_axis_angle(axes[k], 20 * M_PI / 180), bf_v3_scale(bf_v3_normalize(dirs[k]), 0.3));
        bf_se3 T1 = bf_se3_mul(&T0, &j);
        uint16_t *d1 = render(&rm, 1, &T1);
        bf_frame f1 = frame_of(&K_SMALL, d1, 1);
        track_result r;
        CHECK_OK(track_frame(t, &f1, &T0, &r));
        fprintf(stderr, "  jump %d: %s (%u/%u inliers, rms %.1f mm)\n", k, track_outcome_name(r.outcome), r.n_inliers,
                r.n_valid, 1e3 * r.residual_m);
        CHECK(r.outcome != TRACK_OK);
        CHECK(memcmp(&r.T_wc, &T0, sizeof T0) == 0);
        free(d1);
    }
    track_destroy(t);
    free(d0);
    room_close(&rm);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}
