/* The tracker: configuration, buffers, references and the per-frame entry
 * point (DESIGN.md section 6). The stages live in pyramid.c (depth,
 * pyramids, ROF) and icp.c (ICP and its checks); docs/tracking.md explains
 * the defaults. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "tracking_int.h"

track_config track_config_default(void)
{
    track_config c = {
        .levels = 3,
        /* KinectFusion's 10, 5 and 4 (Newcombe et al. 2011, sec. 3.5), the
         * finest level on a checkerboard of its pixels (finest_sample_step):
         * the weighted iterations there move the pose by millimetres each on
         * real frames, and 5 of them stopped short along the weak directions
         * (real dev frames 69 -> 37 mm ATE at 10; docs/real_frames.md). 15
         * on a quarter of the pixels since: better than 10 on half of them
         * (real 21.1 -> 20.7 mm) for 0.77x the tracking time. With the
         * convergence test below a level may stop earlier. */
        .iterations = {15, 5, 4},
        .dist_m = 0.1f,
        /* KinectFusion uses 20; Kinect v1 depth is quantised in disparity,
         * so even smoothed normals of real frames disagree by more than 20
         * degrees on about a third of the pixels at the right pose, and
         * narrow gates stop the real TUM fr2_desk pair in a wrong minimum
         * where 45 finds the consistent pose (docs/tracking.md). */
        .angle_deg = 45.0f,
        /* Once the plain iteration has found the basin, the weighted ones
         * refine with 30: on the real dev frames ATE 24.9 -> 21.5-21.8 mm
         * as the only gate (20: 22.5, 25: 21.9; 35 with Huber 3: 20.7), as
         * good on the synthetic room; as the only gate it lost the wide
         * fr2_desk pair above (docs/real_frames.md). */
        .fine_angle_deg = 30.0f,
        .sensor = bf_sensor_kinect1(),
        /* A quarter of the frame's samples must find a partner: frame to
         * frame at 30 Hz over 90% do; a lost or jumped camera leaves a few
         * percent (tests: 0.3 m / 20 degrees gives < 10%). */
        .min_inlier_frac = 0.25f,
        /* RMS point-to-plane residual of the inliers: the Kinect v1 noise
         * (Nguyen et al. 2012) is 2-6 mm at 1-2 m, 14 mm at 3 m for one
         * image; against a smoothed reference the residual is about that
         * of the frame. A wrong pose spreads inliers over the whole 0.1 m
         * gate (RMS ~ 3-5 cm). 2 cm separates the two for desk-sized
         * scenes; a scene mostly beyond 3.5 m needs more. */
        .max_residual_m = 0.02f,
        /* A correct pose on real Kinect v1 frames leaves an RMS of r /
         * sigma_z of 1.2-2.6 (the 500 dev frames: median 1.84, p95 2.28),
         * while its metric RMS follows the depth: 7 mm where the camera
         * looks at a table, 18-21 mm where the view is mostly beyond 2 m
         * (dev frames 460-480), which the 2 cm gate alone would soon count
         * as lost. A wrong pose within the 0.1 m association gate leaves
         * 3-5 cm, 3.5 sigma or more for views nearer than about 2.4 m;
         * beyond, the inlier fraction and the motion gate catch it. So 2 cm
         * fails a frame only where that is also 3.5 sigma. */
        .max_residual_sigma = 3.5f,
        /* Per frame at 30 Hz: 0.15 m is 4.5 m/s and 15 degrees 450 deg/s,
         * about twice the fastest hand-held motion, so one dropped frame
         * still passes; anything beyond is a jump (a 0.3 m / 20 degree jump
         * fails here if ICP follows it at all). */
        .max_motion_m = 0.15f,
        .max_motion_deg = 15.0f,
        /* Eigenvalues of the system with rotation columns scaled by the
         * mean depth, smallest over largest, measured at the finest level:
         * the noisy room 2e-2, the TUM fr2_desk pair 7e-3, and a single
         * noisy plane (320x240 Kinect v1 model) 3.5e-4, 2.8e-3 and 4.1e-3
         * for its three weak directions against 5.6e-2 and more for the
         * constrained ones. 4.5e-3 drops all three weak ones; the margin to
         * the desk is thin: with the loop's quarter-resolution reference
         * its coarsest level's system sat at 4.6e-3 on the way to the right
         * pose, and 5e-3 (the default until then) held that direction and
         * ended in a wrong minimum (docs/tracking.md). */
        .degenerate_ratio = 4.5e-3,
        /* Off: with the finest level converged, the ray-cast reference is
         * better unsmoothed, on real frames (ATE 37 -> 34 mm) and on the
         * synthetic room (2.9 -> 2.3 mm), and the loop saves ROF's 10-15 ms
         * (docs/real_frames.md); 10 iterations is the smoothing's design. */
        .rof_iterations = 0,
        .rof_lambda0 = 100.0f,
        /* Half resolution: a quarter of the cost for the same tracking
         * error (bench_tracking, docs/tracking.md); the normals come from
         * level 1 anyway. */
        .rof_level = 1,
        .ref_level = 1,
        .min_valid_frac = 0.01f,
        /* A level stops once an update moves less than 50 um and turns less than 0.003 deg: against
           10 um and 0.001 deg, 11.5% fewer iterations on the real dev frames (18.40 -> 16.28 a frame) for
           20.65 -> 20.68 mm ATE, 14% on the synthetic room (12.15 -> 10.44) for 1.211 -> 1.217 mm
           (docs/real_frames.md, ninth session). */
        .converged_m = 5e-5f,
        .converged_deg = 3e-3f,
        /* Every fourth pixel (the 2x2 blocks' corners on a checkerboard):
         * the reference is a ray-cast at half resolution (ref_level 1, the
         * tracker's default; a quarter in recon's loop), so denser frame
         * samples mostly repeat its pixels. Side by side with every second
         * one (the previous default): real dev frames 21.1 mm ATE with
         * 10 iterations against 20.7 mm with 15 at step 4, tracking 0.77x,
         * frame 0.94x; synthetic room 1.22 against 1.21 mm, 0.79x and
         * 0.95x (docs/tracking.md). */
        .finest_sample_step = 4,
        /* At the finest level: together they halve the loop's error on the
         * synthetic room (docs/tracking.md). Real residuals are about twice
         * the Gaussian model (residual_sigma), so k = 3 bends fewer good
         * samples: real dev frames 21.5-21.8 -> 20.2 mm with the 30 degree
         * gate, synthetic room 2.0 -> 1.5 mm (docs/real_frames.md); k = 4
         * gives the same 20.2 mm. */
        .huber_k = 3.0f,
        .weight_noise = true,
        /* Real frames: 2 -> 37 mm ATE, 3 -> 25 mm; the synthetic room 2.3 ->
         * 2.0 mm (docs/real_frames.md: the near surfaces are the less
         * distorted ones). */
        .noise_weight_exp = 3.0f,
        /* With 10 finest iterations the scaled unit changes nothing on real
         * frames (37.1 against 37.3 mm) and costs the synthetic room 0.3 mm;
         * at 5 it is what converges (69 -> 43 mm). */
        .huber_scaled = false,
        .huber_knee = 1.3f,
        /* bench/bench_tracking.c measured the ICP shapes on lavapipe (docs/tracking.md). */
        .icp_local = 64,
        .icp_px_per_thread = 16,
        .icp_subgroup = true,
        /* Level 1's normals at the finest level: less noisy, and as accurate (docs/tracking.md). */
        .parent_normals = true,
        /* Kept for frames whose depth leaves a direction weak: there the
         * colour holds what ICP would leave to the guess, and where the
         * depth constrains everything the term cost more than it gave
         * (docs/real_frames.md, "The photometric term where the depth is
         * weak"). */
        .photo_weight = 0.3f,
        .photo_sigma = 0.03f,
        .photo_levels = 1,
        .photo_sharpness_min = 0.6f,
        .photo_weak_ratio = 0.01f,
    };
    return c;
}

const char *track_outcome_name(track_outcome o)
{
    switch (o) {
    case TRACK_OK: return "ok";
    case TRACK_NO_DEPTH: return "no-depth";
    case TRACK_NO_REFERENCE: return "no-reference";
    case TRACK_FEW_INLIERS: return "few-inliers";
    case TRACK_HIGH_RESIDUAL: return "high-residual";
    case TRACK_LARGE_MOTION: return "large-motion";
    case TRACK_NUMERIC: return "numeric";
    }
    return "unknown";
}

void track__level_intrinsics(const bf_intrinsics *K, uint32_t l, float *fx, float *fy, float *cx, float *cy)
{
    bf_intrinsics L = bf_intrinsics_level(K, l);
    *fx = (float)L.fx_px;
    *fy = (float)L.fy_px;
    *cx = (float)L.cx_px;
    *cy = (float)L.cy_px;
}

bf_status track_config_check(const track_config *c)
{
    if (!c) return bf_fail(BF_INVALID_ARG, "tracking: NULL config");
    if (c->levels < 1 || c->levels > TRACK_MAX_LEVELS)
        return bf_fail(BF_INVALID_ARG, "tracking: %u levels (1..%u)", c->levels, TRACK_MAX_LEVELS);
    if (!(c->fine_angle_deg >= 0 && c->fine_angle_deg <= 180))
        return bf_fail(BF_INVALID_ARG, "tracking: fine_angle_deg %g must be in [0, 180] (0: angle_deg)", c->fine_angle_deg);
    if (!(c->dist_m > 0) || !(c->angle_deg > 0 && c->angle_deg <= 180) || !(c->sensor.max_depth_m > 0) ||
        !(c->sensor.sigma_a > 0) || !(c->sensor.sigma_b >= 0))
        return bf_fail(BF_INVALID_ARG,
                       "tracking: gates and sensor must be positive (dist %g m, angle %g deg, depth %g m, sigma %g)",
                       c->dist_m, c->angle_deg, c->sensor.max_depth_m, c->sensor.sigma_a);
    /* ROF's level matters only when it runs (off by default). */
    if (c->rof_iterations > 0 && (c->rof_level > 1 || c->rof_level >= c->levels))
        return bf_fail(BF_INVALID_ARG, "tracking: rof_level %u (0 or 1, below levels %u)", c->rof_level, c->levels);
    if (!(c->max_residual_sigma >= 0))
        return bf_fail(BF_INVALID_ARG, "tracking: max_residual_sigma %g (0 or more)", c->max_residual_sigma);
    if (c->ref_level >= c->levels)
        return bf_fail(BF_INVALID_ARG, "tracking: ref_level %u (below levels %u)", c->ref_level, c->levels);
    if (c->finest_sample_step != 1 && c->finest_sample_step != 2 && c->finest_sample_step != 4)
        return bf_fail(BF_INVALID_ARG, "tracking: finest_sample_step %u (1, 2 or 4)", c->finest_sample_step);
    if (c->icp_local < 1 || c->icp_local > TRACK_ICP_LOCAL_MAX || (c->icp_local & (c->icp_local - 1)))
        return bf_fail(BF_INVALID_ARG, "tracking: icp_local %u (a power of two up to %u)", c->icp_local,
                       TRACK_ICP_LOCAL_MAX);
    if (c->icp_px_per_thread < 1 || c->icp_px_per_thread > 4096)
        return bf_fail(BF_INVALID_ARG, "tracking: icp_px_per_thread %u (1..4096)", c->icp_px_per_thread);
    if (c->iterations[0] < 1) return bf_fail(BF_INVALID_ARG, "tracking: the finest level needs an iteration");
    if (!(c->huber_knee >= 1) || !isfinite(c->huber_knee))
        return bf_fail(BF_INVALID_ARG, "tracking: huber_knee %g must be >= 1", c->huber_knee);
    if (!(c->huber_k >= 0) || !isfinite(c->huber_k))
        return bf_fail(BF_INVALID_ARG, "tracking: huber_k %g must be >= 0 (0: off)", c->huber_k);
    if (c->weight_noise && !(c->noise_weight_exp > 0 && c->noise_weight_exp <= 4))
        return bf_fail(BF_INVALID_ARG, "tracking: noise_weight_exp %g not in (0, 4]", c->noise_weight_exp);
    if (!(c->photo_weight >= 0) || !isfinite(c->photo_weight) || !(c->photo_sigma > 0) || !isfinite(c->photo_sigma))
        return bf_fail(BF_INVALID_ARG, "tracking: photo_weight %g (>= 0) or photo_sigma %g (> 0) out of range",
                       c->photo_weight, c->photo_sigma);
    if (!(c->photo_weak_ratio >= 0 && c->photo_weak_ratio < 1))
        return bf_fail(BF_INVALID_ARG, "tracking: photo_weak_ratio %g not in [0, 1)", c->photo_weak_ratio);
    if (!(c->photo_sharpness_min >= 0 && c->photo_sharpness_min <= 1))
        return bf_fail(BF_INVALID_ARG, "tracking: photo_sharpness_min %g (0..1)", c->photo_sharpness_min);
    if (c->photo_levels < 1 || c->photo_levels > TRACK_MAX_LEVELS)
        return bf_fail(BF_INVALID_ARG, "tracking: photo_levels %u (1..%u)", c->photo_levels, TRACK_MAX_LEVELS);
    if (!(c->rof_lambda0 > 0)) return bf_fail(BF_INVALID_ARG, "tracking: rof_lambda0 %g must be positive", c->rof_lambda0);
    if (!(c->degenerate_ratio >= 0 && c->degenerate_ratio < 1))
        return bf_fail(BF_INVALID_ARG, "tracking: degenerate_ratio %g not in [0, 1)", c->degenerate_ratio);
    return BF_OK;
}

static bf_status check_config(const track_config *c, const bf_intrinsics *K)
{
    bf_status s = track_config_check(c);
    if (s != BF_OK) return s;
    uint32_t min_side = track_min_image_side(c);
    if (K->width < min_side || K->height < min_side)
        return bf_fail(BF_INVALID_ARG, "tracking: images of %ux%u are too small for %u pyramid levels (at least %ux%u)",
                       K->width, K->height, c->levels, min_side, min_side);
    /* A negative fy (ICL-NUIM's y-up camera) is a camera like any other:
     * projection, back-projection and the normals' orientation toward the
     * camera all hold with it. */
    if (!(K->fx_px > 0) || !(fabs(K->fy_px) > 0) || !isfinite(K->fy_px) || !(K->depth_scale > 0) ||
        !isfinite(K->depth_scale))
        return bf_fail(BF_INVALID_ARG, "tracking: intrinsics need a positive fx and depth_scale and a non-zero fy (%g, %g, %g)",
                       K->fx_px, K->fy_px, K->depth_scale);
    return BF_OK;
}

static bf_status buffer(track_tracker *t, const char *name, uint64_t bytes, gpu_memory mem, gpu_buffer **out)
{
    gpu_buffer_desc d = {.name = name, .size_bytes = bytes, .memory = mem};
    return gpu_buffer_create(t->ctx, &d, out);
}

/* A pyramid: bound to some kernels, read and written by others through its
 * address (shaders/track.glsl.h). */
static bf_status pyramid(track_tracker *t, const char *name, uint64_t bytes, gpu_buffer **out)
{
    gpu_buffer_desc d = {.name = name, .size_bytes = bytes, .memory = GPU_MEMORY_DEVICE,
                         .usage = GPU_USAGE_STORAGE | GPU_USAGE_TRANSFER | GPU_USAGE_ADDRESS};
    return gpu_buffer_create(t->ctx, &d, out);
}

/* The ICP's address table (TRACK_ADDR_*). */
static bf_status address_table(track_tracker *t)
{
    gpu_buffer *a[TRACK_ADDRS];
    a[TRACK_ADDR_FRAME_DEPTH] = t->frame_depth;
    a[TRACK_ADDR_FRAME_NORMAL] = t->frame_normal;
    a[TRACK_ADDR_REF_DEPTH] = t->ref_depth;
    a[TRACK_ADDR_REF_NORMAL] = t->ref_normal;
    a[TRACK_ADDR_FRAME_INT] = t->frame_int;
    a[TRACK_ADDR_REF_INT] = t->ref_int;
    return gpu_address_table_create(t->ctx, "track.addresses", a, TRACK_ADDRS, &t->addresses);
}

bf_status track_create(gpu_context *ctx, const track_config *cfg, const bf_intrinsics *K, track_tracker **out)
{
    if (!ctx || !cfg || !K || !out) return bf_fail(BF_INVALID_ARG, "tracking: NULL argument");
    bf_status s = check_config(cfg, K);
    if (s != BF_OK) return s;
    track_tracker *t = calloc(1, sizeof *t);
    if (!t) return bf_fail(BF_NO_MEMORY, "tracking: tracker");
    t->ctx = ctx;
    t->cfg = *cfg;
    t->K = *K;
    t->motion_scale = 1.0;
    t->colour_registered = true;
    /* Every pyramid has all TRACK_LEVELS levels, whatever cfg.levels uses. */
    uint32_t off = 0;
    for (uint32_t l = 0; l < TRACK_LEVELS; l++) {
        t->geom.w[l] = K->width >> l;
        t->geom.h[l] = K->height >> l;
        t->geom.off[l] = off;
        off += t->geom.w[l] * t->geom.h[l];
    }
    t->geom.n_pix = off;
    uint64_t n0 = (uint64_t)K->width * K->height, np = t->geom.n_pix;
    if ((s = buffer(t, "track.upload", (n0 + 1) / 2 * 4, GPU_MEMORY_UPLOAD, &t->upload)) != BF_OK) goto fail;
    if ((s = pyramid(t, "track.frame_depth", np * 4, &t->frame_depth)) != BF_OK) goto fail;
    if ((s = pyramid(t, "track.frame_normal", np * 4, &t->frame_normal)) != BF_OK) goto fail;
    if ((s = pyramid(t, "track.ref_depth", np * 4, &t->ref_depth)) != BF_OK) goto fail;
    if ((s = pyramid(t, "track.ref_normal", np * 4, &t->ref_normal)) != BF_OK) goto fail;
    if ((s = pyramid(t, "track.rof_p[0]", n0 * 8, &t->rof_p[0])) != BF_OK) goto fail;
    if ((s = pyramid(t, "track.rof_p[1]", n0 * 8, &t->rof_p[1])) != BF_OK) goto fail;
    if ((s = buffer(t, "track.counters", TRACK_CNT_WORDS * 4, GPU_MEMORY_READBACK, &t->counters)) != BF_OK) goto fail;
    /* The intensity pyramids: a word each while the photometric term is off. */
    uint64_t ni = cfg->photo_weight > 0 ? np * 4 : 4;
    if ((s = pyramid(t, "track.frame_intensity", ni, &t->frame_int)) != BF_OK) goto fail;
    if ((s = pyramid(t, "track.ref_intensity", ni, &t->ref_int)) != BF_OK) goto fail;
    /* Defined contents before any kernel reads them (validation, and a
     * reference pyramid level a smaller config never writes). */
    gpu_buffer *zero[] = {t->upload, t->frame_depth, t->frame_normal, t->ref_depth, t->ref_normal,
                          t->rof_p[0], t->rof_p[1], t->counters, t->frame_int, t->ref_int};
    for (size_t i = 0; i < sizeof zero / sizeof zero[0] && s == BF_OK; i++) s = gpu_buffer_zero(zero[i]);
    if (s == BF_OK) s = address_table(t);
    if (s != BF_OK) goto fail;
    if ((s = track__pyramid_create(t)) != BF_OK) goto fail;
    if ((s = track__icp_create(t)) != BF_OK) goto fail;
    *out = t;
    return BF_OK;
fail:
    track_destroy(t);
    return s;
}

void track_destroy(track_tracker *t)
{
    if (!t) return;
    track__icp_destroy(t);
    track__pyramid_destroy(t);
    gpu_buffer *bufs[] = {t->addresses, t->ref_int, t->frame_int, t->counters, t->rof_p[1], t->rof_p[0], t->ref_normal,
                          t->ref_depth, t->frame_normal, t->frame_depth, t->upload};
    for (size_t i = 0; i < sizeof bufs / sizeof bufs[0]; i++) gpu_buffer_destroy(bufs[i]);
    memset(t, 0xff, sizeof *t); /* poison: a use after destroy crashes early */
    free(t);
}

void track__set_rof_iterations(track_tracker *t, uint32_t n) { t->cfg.rof_iterations = n; }

/* Fewest valid pixels of level l (min_valid_frac of its pixels). */
static uint32_t min_valid(const track_tracker *t, uint32_t l)
{
    double n = ceil((double)t->cfg.min_valid_frac * t->geom.w[l] * t->geom.h[l]);
    return n < 1 ? 1u : (uint32_t)n;
}

static bf_status read_counter(track_tracker *t, uint32_t idx, uint32_t *v)
{
    return gpu_buffer_download(t->counters, idx * 4u, v, 4);
}

/* The nearest rigid motion: the rotation's polar factor (Higham's Newton
 * iteration X <- (X + X^-T) / 2, quadratic near a rotation; an exact
 * rotation comes back unchanged up to rounding). Every pose the tracker
 * keeps or composes goes through it. Without it the closed loop (reference
 * and guess at the last estimate) tripled the rotation's deviation from
 * orthonormality every frame: T_rc = T_wr^-1 guess is R^T R = I + E instead
 * of I, ICP carries E along, and T_wr T_rc returns R (I + E), whose Gram
 * matrix is I + 3E. From 1e-16 that reached 1e-3 after ~25 frames and the
 * "relative" pose the GPU saw depended on how the absolute one had been
 * reached (docs/tracking.md). det(R) must be positive. */
static bf_se3 nearest_rigid(const bf_se3 *T)
{
    bf_se3 out = *T;
    double (*X)[3] = out.R;
    for (int it = 0; it < 30; it++) {
        double C[3][3]; /* cofactors: X^-T = C / det */
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++) {
                int i1 = (i + 1) % 3, i2 = (i + 2) % 3, j1 = (j + 1) % 3, j2 = (j + 2) % 3;
                C[i][j] = X[i1][j1] * X[i2][j2] - X[i1][j2] * X[i2][j1];
            }
        double det = X[0][0] * C[0][0] + X[0][1] * C[0][1] + X[0][2] * C[0][2];
        if (!(det > 0) || !isfinite(det)) return *T;
        double change = 0;
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++) {
                double v = 0.5 * (X[i][j] + C[i][j] / det);
                change = fmax(change, fabs(v - X[i][j]));
                X[i][j] = v;
            }
        if (change < 1e-15) break;
    }
    return out;
}

static double det3(const double R[3][3])
{
    return R[0][0] * (R[1][1] * R[2][2] - R[1][2] * R[2][1]) - R[0][1] * (R[1][0] * R[2][2] - R[1][2] * R[2][0]) +
           R[0][2] * (R[1][0] * R[2][1] - R[1][1] * R[2][0]);
}

static bf_status check_pose(const bf_se3 *T_wc)
{
    if (!bf_se3_is_finite(T_wc) || !(det3(T_wc->R) > 0))
        return bf_fail(BF_INVALID_ARG, "tracking: reference pose is not finite or not a rotation");
    return BF_OK;
}

bf_status track_reference_target(track_tracker *t, gpu_buffer **buf, uint64_t *offset)
{
    if (!t || !buf || !offset) return bf_fail(BF_INVALID_ARG, "tracking: NULL argument");
    *buf = t->ref_depth;
    *offset = t->geom.off[t->cfg.ref_level];
    return BF_OK;
}

/* Records the preparation of the reference (in place: from its target;
 * else from the raw frame in the upload buffer). */
static void cmd_reference(track_tracker *t, bool in_place, const bf_se3 *T_wc)
{
    t->has_ref = false; /* the pyramids are being rewritten */
    t->ref_pending = true;
    t->ref_int_pending = false; /* track_cmd_reference sets it */
    t->int_kept_pending = t->int_kept; /* and changes what is kept */
    t->T_int_pending = t->T_int;
    t->ref_first = in_place ? t->cfg.ref_level : 0;
    t->T_wr_pending = *T_wc;
    track__cmd_reference(t, in_place);
}

bf_status track_cmd_reference(track_tracker *t, const bf_se3 *T_wc, bool with_frame)
{
    if (!t || !T_wc) return bf_fail(BF_INVALID_ARG, "tracking: NULL argument");
    bf_status s = check_pose(T_wc);
    if (s != BF_OK) return s;
    cmd_reference(t, true, T_wc);
    if (!with_frame) {
        /* The image kept is what a camera at its pose saw: a reference cast
         * there again (the last pose, after frames that failed) keeps it;
         * anywhere else there is nothing to compare with. */
        t->ref_int_pending = t->int_kept && memcmp(T_wc, &t->T_int, sizeof *T_wc) == 0;
        return BF_OK;
    }
    t->ref_int_pending = t->frame_has_int;
    if (t->ref_int_pending) {
        t->int_kept_pending = true;
        t->T_int_pending = *T_wc;
        /* ICP's reads of both pyramids -> the copy. */
        gpu_cmd_barrier(t->ctx, GPU_BARRIER_COMPUTE_TO_TRANSFER);
        uint32_t nl = track__int_levels(t);
        uint64_t px = (uint64_t)t->geom.off[nl - 1] + (uint64_t)t->geom.w[nl - 1] * t->geom.h[nl - 1];
        gpu_cmd_copy(t->ctx, t->frame_int, 0, t->ref_int, 0, px * 4);
        /* The copy -> the next frame's ICP. */
        gpu_cmd_barrier(t->ctx, GPU_BARRIER_TRANSFER_TO_COMPUTE);
    }
    return BF_OK;
}

bf_status track_finish_reference(track_tracker *t)
{
    if (!t || !t->ref_pending) return bf_fail(BF_INVALID_ARG, "tracking: no reference recorded to finish");
    t->ref_pending = false;
    track__profile_print(t, "reference");
    t->ms_rof = gpu_stage_ms(t->ctx, "track.rof");
    t->ms_ref = t->ms_rof + gpu_stage_ms(t->ctx, "track.ref");
    uint32_t n = 0;
    bf_status s = read_counter(t, TRACK_CNT_REF_VALID, &n);
    if (s != BF_OK) return s;
    t->ref_valid = n;
    t->has_ref = n >= min_valid(t, t->ref_first);
    t->ref_has_int = t->ref_int_pending;
    t->ref_int_pending = false;
    t->int_kept = t->int_kept_pending;
    t->T_int = t->T_int_pending;
    t->T_wr = nearest_rigid(&t->T_wr_pending);
    return BF_OK;
}

/* One submission of its own: the reference from depth (a GPU float image,
 * copied to the target) or raw (a frame's u16 depth). */
static bf_status set_reference(track_tracker *t, gpu_buffer *depth, const uint16_t *raw, const bf_se3 *T_wc)
{
    bf_status s = raw ? track__upload_depth(t, raw) : BF_OK;
    if (s == BF_OK) s = gpu_begin(t->ctx);
    if (s != BF_OK) return s;
    if (depth) {
        uint32_t l = t->cfg.ref_level;
        /* The previous reference's readers -> the copy over it. */
        gpu_cmd_barrier(t->ctx, GPU_BARRIER_COMPUTE_TO_TRANSFER);
        gpu_cmd_copy(t->ctx, depth, 0, t->ref_depth, (uint64_t)t->geom.off[l] * 4,
                     (uint64_t)t->geom.w[l] * t->geom.h[l] * 4);
        /* The copy into the target -> the depth pass reading it in place. */
        gpu_cmd_barrier(t->ctx, GPU_BARRIER_TRANSFER_TO_COMPUTE);
    }
    cmd_reference(t, depth != NULL, T_wc);
    /* The count of valid pixels -> the host's read. */
    gpu_cmd_barrier(t->ctx, GPU_BARRIER_HOST);
    if ((s = gpu_submit_wait(t->ctx)) != BF_OK) {
        t->ref_pending = false;
        return s;
    }
    return track_finish_reference(t);
}

bf_status track_set_reference_gpu(track_tracker *t, gpu_buffer *depth, const bf_se3 *T_wc)
{
    if (!t || !depth || !T_wc) return bf_fail(BF_INVALID_ARG, "tracking: NULL argument");
    uint32_t l = t->cfg.ref_level;
    uint64_t need = (uint64_t)t->geom.w[l] * t->geom.h[l] * 4;
    if (gpu_buffer_size(depth) < need)
        return bf_fail(BF_INVALID_ARG, "tracking: reference %s holds %llu bytes, %ux%u floats need %llu",
                       gpu_buffer_name(depth), (unsigned long long)gpu_buffer_size(depth), t->geom.w[l], t->geom.h[l],
                       (unsigned long long)need);
    bf_status s = check_pose(T_wc);
    if (s != BF_OK) return s;
    return set_reference(t, depth, NULL, T_wc);
}

static bf_status check_frame(const track_tracker *t, const bf_frame *f)
{
    if (f->width != t->K.width || f->height != t->K.height)
        return bf_fail(BF_INVALID_ARG, "tracking: frame %u is %ux%u, the tracker %ux%u", f->index, f->width,
                       f->height, t->K.width, t->K.height);
    if (!f->depth) return bf_fail(BF_INVALID_ARG, "tracking: frame %u has no depth image", f->index);
    return BF_OK;
}

bf_status track_set_reference_frame(track_tracker *t, const bf_frame *f, const bf_se3 *T_wc)
{
    if (!t || !f || !T_wc) return bf_fail(BF_INVALID_ARG, "tracking: NULL argument");
    bf_status s = check_frame(t, f);
    if (s == BF_OK) s = check_pose(T_wc);
    if (s != BF_OK) return s;
    return set_reference(t, NULL, f->depth, T_wc);
}

/* The frame's colour into the intensity kernel's bindings (a host-side
 * descriptor write, every frame as for the depth). */
static bf_status bind_colour(track_tracker *t)
{
    if (!t->colour || !(t->cfg.photo_weight > 0)) return BF_OK;
    return gpu_bindings_set(t->b_int, 0, t->colour, 0, GPU_WHOLE_SIZE);
}

bf_status track_set_colour_camera(track_tracker *t, const bf_intrinsics *Kc, const double *dist,
                                  const bf_se3 *T_colour_depth)
{
    if (!t) return bf_fail(BF_INVALID_ARG, "tracking: NULL argument");
    if (!Kc) {
        t->colour_registered = true;
        return BF_OK;
    }
    bool ok = T_colour_depth && bf_se3_is_finite(T_colour_depth) && det3(T_colour_depth->R) > 0 && Kc->fx_px > 0 &&
              fabs(Kc->fy_px) > 0 && isfinite(Kc->fx_px) && isfinite(Kc->fy_px) && isfinite(Kc->cx_px) && isfinite(Kc->cy_px);
    for (int i = 0; dist && i < 5; i++) ok = ok && isfinite(dist[i]);
    if (!ok) return bf_fail(BF_INVALID_ARG, "tracking: colour camera (fx %g, fy %g), its distortion or T_colour_depth is not usable",
                            Kc->fx_px, Kc->fy_px);
    t->Kc = *Kc;
    for (int i = 0; i < 5; i++) t->colour_dist[i] = dist ? dist[i] : 0.0;
    t->T_colour_depth = *T_colour_depth;
    t->colour_registered = false;
    return BF_OK;
}

bf_status track_set_frame_colour(track_tracker *t, gpu_buffer *buf, uint64_t offset)
{
    if (!t) return bf_fail(BF_INVALID_ARG, "tracking: NULL argument");
    if (buf) {
        uint64_t words = ((uint64_t)t->K.width * t->K.height + 1) / 2;
        if (offset % 4 || offset / 4 > UINT32_MAX || gpu_buffer_size(buf) < offset + words * 4)
            return bf_fail(BF_INVALID_ARG, "tracking: colour: %s holds %llu bytes, %llu words of colour from byte %llu",
                           gpu_buffer_name(buf), (unsigned long long)gpu_buffer_size(buf), (unsigned long long)words,
                           (unsigned long long)offset);
    }
    t->colour = buf;
    t->colour_off = (uint32_t)(offset / 4);
    return BF_OK;
}

/* Tracks the frame whose raw depth is at word raw_off of raw. */
static bf_status frame_from(track_tracker *t, gpu_buffer *raw, uint32_t raw_off, uint32_t index,
                            const bf_se3 *guess_wc, track_result *out)
{
    if (!bf_se3_is_finite(guess_wc) || !(det3(guess_wc->R) > 0))
        return bf_fail(BF_INVALID_ARG, "tracking: frame %u: guess is not finite or not a rotation", index);
    track_result r = {.outcome = TRACK_OK, .T_wc = *guess_wc, .ms_rof = t->ms_rof, .ms_ref = t->ms_ref};
    if (!t->has_ref) {
        r.outcome = TRACK_NO_REFERENCE;
        *out = r;
        return BF_OK;
    }
    /* Bound every frame (a host-side descriptor write): a buffer pointer
     * seen before may be a new buffer at a freed one's address. */
    bf_status s = gpu_bindings_set(t->b_frame, 0, raw, 0, GPU_WHOLE_SIZE);
    if (s == BF_OK) s = bind_colour(t);
    if (s != BF_OK) return s;
    t->frame_raw_off = raw_off;
    if ((s = gpu_buffer_fill(t->counters, TRACK_CNT_FRAME_VALID * 4u, 4, 0)) != BF_OK) return s;
    /* Everything the GPU sees is relative to the reference camera, and
     * rigid (nearest_rigid: a guess that is not quite orthonormal must not
     * make its error part of the relative pose). */
    bf_se3 T_rw = bf_se3_inverse(&t->T_wr);
    bf_se3 T_rc = bf_se3_mul(&T_rw, guess_wc);
    T_rc = nearest_rigid(&T_rc);
    double t0 = bf_time_s();
    t->has_frame = false;
    if ((s = track__icp_run(t, &T_rc, min_valid(t, 0), &r)) != BF_OK) return s;
    t->has_frame = true;
    r.ms_wall = 1e3 * (bf_time_s() - t0);
    if (r.outcome == TRACK_OK) {
        T_rc = nearest_rigid(&T_rc);
        bf_se3 T_wc = bf_se3_mul(&t->T_wr, &T_rc);
        r.T_wc = nearest_rigid(&T_wc);
    } else {
        r.T_wc = *guess_wc;
    }
    *out = r;
    return BF_OK;
}

bf_status track_frame(track_tracker *t, const bf_frame *f, const bf_se3 *guess_wc, track_result *out)
{
    if (!t || !f || !guess_wc || !out) return bf_fail(BF_INVALID_ARG, "tracking: NULL argument");
    bf_status s = check_frame(t, f);
    if (s != BF_OK) return s;
    if (t->has_ref && (s = track__upload_depth(t, f->depth)) != BF_OK) return s;
    return frame_from(t, t->upload, 0, f->index, guess_wc, out);
}

/* A frame's raw depth on the GPU must fit its buffer from a word offset. */
static bf_status check_gpu_frame(const track_tracker *t, gpu_buffer *depth, uint64_t offset, uint32_t index)
{
    uint64_t words = ((uint64_t)t->K.width * t->K.height + 1) / 2;
    if (offset % 4 || offset / 4 > UINT32_MAX || gpu_buffer_size(depth) < offset + words * 4)
        return bf_fail(BF_INVALID_ARG, "tracking: frame %u: %s holds %llu bytes, %llu words of depth from byte %llu",
                       index, gpu_buffer_name(depth), (unsigned long long)gpu_buffer_size(depth),
                       (unsigned long long)words, (unsigned long long)offset);
    return BF_OK;
}

bf_status track_frame_gpu(track_tracker *t, gpu_buffer *depth, uint64_t offset, uint32_t index,
                          const bf_se3 *guess_wc, track_result *out)
{
    if (!t || !depth || !guess_wc || !out) return bf_fail(BF_INVALID_ARG, "tracking: NULL argument");
    bf_status s = check_gpu_frame(t, depth, offset, index);
    if (s != BF_OK) return s;
    return frame_from(t, depth, (uint32_t)(offset / 4), index, guess_wc, out);
}

bf_status track_set_motion_scale(track_tracker *t, double scale)
{
    if (!t) return bf_fail(BF_INVALID_ARG, "tracking: NULL argument");
    if (!(scale >= 1) || !isfinite(scale)) return bf_fail(BF_INVALID_ARG, "tracking: motion scale %g (>= 1)", scale);
    t->motion_scale = scale;
    return BF_OK;
}

bf_status track_cmd_frame(track_tracker *t, gpu_buffer *depth, uint64_t offset, uint32_t index)
{
    if (!t || !depth) return bf_fail(BF_INVALID_ARG, "tracking: NULL argument");
    bf_status s = check_gpu_frame(t, depth, offset, index);
    /* Bound before the recording uses it (a host-side descriptor write). */
    if (s == BF_OK) s = gpu_bindings_set(t->b_frame, 0, depth, 0, GPU_WHOLE_SIZE);
    if (s == BF_OK) s = bind_colour(t);
    if (s == BF_OK) s = gpu_buffer_fill(t->counters, TRACK_CNT_FRAME_VALID * 4u, 4, 0);
    if (s != BF_OK) return s;
    t->frame_raw_off = (uint32_t)(offset / 4);
    track__cmd_frame_pyramid(t);
    t->has_frame = true;
    return BF_OK;
}

bf_status track_frame_depth_gpu(track_tracker *t, uint32_t level, gpu_buffer **buf, uint64_t *offset)
{
    if (!t || !buf || !offset) return bf_fail(BF_INVALID_ARG, "tracking: NULL argument");
    if (!t->has_frame || level >= TRACK_LEVELS)
        return bf_fail(BF_INVALID_ARG, "tracking: no frame depth at level %u (%s)", level,
                       t->has_frame ? "beyond the pyramid" : "no frame tracked yet");
    *buf = t->frame_depth;
    *offset = t->geom.off[level];
    return BF_OK;
}

bf_status track_download_reference(track_tracker *t, float *depth)
{
    if (!t || !depth) return bf_fail(BF_INVALID_ARG, "tracking: NULL argument");
    uint32_t l = t->ref_first;
    return gpu_buffer_download(t->ref_depth, (uint64_t)t->geom.off[l] * 4, depth,
                               (uint64_t)t->geom.w[l] * t->geom.h[l] * 4);
}
