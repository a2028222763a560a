/* Point-to-plane ICP, coarse to fine (KinectFusion, Newcombe et al. 2011,
 * sec. 3.5; linearisation of Low 2004): host side of shaders/track_icp.comp
 * and track_icp_sg.comp. Each iteration is one dispatch (association,
 * residuals and workgroup sums fused) and one submission; the CPU adds the
 * partial sums in double, solves the 6x6 system in double and composes the
 * relative pose in double. Failure and degeneracy checks are at the end. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bf_shaders_spv.h"
#include "tracking_int.h"

bf_status track__icp_create(track_tracker *t)
{
    const gpu_limits *lim = gpu_device_limits(t->ctx);
    /* The configured shape (track_config.icp_local, icp_px_per_thread),
     * narrowed to what the device allows. */
    uint32_t local = t->cfg.icp_local;
    while (local > lim->max_compute_workgroup_invocations || local > lim->max_compute_workgroup_size[0]) local /= 2;
    t->icp_local = local;
    t->icp_px_per_thread = t->cfg.icp_px_per_thread;
    uint64_t n0 = (uint64_t)t->geom.w[0] * t->geom.h[0];
    t->icp_groups_max = (uint32_t)((n0 + (uint64_t)local * t->icp_px_per_thread - 1) / ((uint64_t)local * t->icp_px_per_thread));
    if (t->icp_groups_max > lim->max_compute_workgroup_count[0]) {
        t->icp_groups_max = lim->max_compute_workgroup_count[0];
    }
    /* Subgroup additions where the device has them; the shared-memory
     * kernel otherwise (and with icp_subgroup false, so tests exercise both). */
    uint32_t need = VK_SUBGROUP_FEATURE_BASIC_BIT | VK_SUBGROUP_FEATURE_ARITHMETIC_BIT;
    t->icp_subgroup = (lim->subgroup_ops & need) == need && t->cfg.icp_subgroup;
    gpu_pipeline_desc d = {
        .name = t->icp_subgroup ? "track.icp_sg" : "track.icp",
        .spirv = t->icp_subgroup ? bf_spv_track_icp_sg : bf_spv_track_icp,
        .spirv_bytes = t->icp_subgroup ? bf_spv_track_icp_sg_size : bf_spv_track_icp_size,
        .n_buffers = TRACK_ICP_BUFFERS,
        .push_bytes = sizeof(track_icp_push),
        .local_size = {local, 1, 1},
    };
    bf_status s = gpu_pipeline_create(t->ctx, &d, &t->p_icp);
    if (s != BF_OK) return s;
    uint64_t bytes = (uint64_t)t->icp_groups_max * TRACK_PARTIAL_WORDS * 4;
    gpu_buffer_desc bd = {.name = "track.partials", .size_bytes = bytes, .memory = GPU_MEMORY_READBACK};
    if ((s = gpu_buffer_create(t->ctx, &bd, &t->partials)) != BF_OK) return s;
    if ((s = gpu_buffer_zero(t->partials)) != BF_OK) return s;
    t->partial_host = malloc(bytes);
    if (!t->partial_host) return bf_fail(BF_NO_MEMORY, "tracking: partial sums");
    if ((s = gpu_bindings_create(t->ctx, TRACK_ICP_BUFFERS, "track.icp", &t->b_icp)) != BF_OK) return s;
    gpu_buffer *bufs[TRACK_ICP_BUFFERS] = {t->addresses, t->partials};
    for (uint32_t i = 0; i < TRACK_ICP_BUFFERS && s == BF_OK; i++) s = gpu_bindings_set(t->b_icp, i, bufs[i], 0, GPU_WHOLE_SIZE);
    if (s != BF_OK) return s;
    /* Zero push constants: an empty level, the workgroup writes zeros. */
    return gpu_pipeline_warm_up(t->ctx, &t->p_icp, 1);
}

void track__icp_destroy(track_tracker *t)
{
    gpu_bindings_destroy(t->b_icp);
    gpu_buffer_destroy(t->partials);
    gpu_pipeline_destroy(t->p_icp);
    free(t->partial_host);
    t->b_icp = NULL;
    t->partials = NULL;
    t->p_icp = NULL;
    t->partial_host = NULL;
}

/* One iteration's system, summed in double. */
typedef struct icp_sums {
    double s[TRACK_SUMS];
} icp_sums;

/* One iteration: one submission, one dispatch, 36 floats per workgroup
 * read back. with_frame records the frame's preprocessing in front of it
 * (the first iteration of a frame: one submission and wait fewer);
 * photo_unit 0 leaves the photometric term out. */
static bf_status run_iteration(track_tracker *t, uint32_t l, const bf_se3 *T_rc, bool with_frame, bool weighted,
                               double huber_unit, double photo_unit, icp_sums *out, track_result *res)
{
    uint32_t sub = l == 0 ? t->cfg.finest_sample_step : 1u;
    uint32_t n = t->geom.w[l] * t->geom.h[l] / sub;
    uint32_t per_group = t->icp_local * t->icp_px_per_thread;
    uint32_t g = (n + per_group - 1) / per_group;
    if (g > t->icp_groups_max) g = t->icp_groups_max;
    if (g < 1) g = 1;
    track_icp_push pc = {
        .size = track_icp_size(t->geom.w[l], t->geom.h[l]),
        .off = t->geom.off[l],
        .n_threads = g * t->icp_local,
        /* The distance gate widens with the level (dist_m at the finest,
         * 4 dist_m at level 2): coarse levels are there to catch the larger
         * part of the motion, and their pixels are 2^l times wider. Whatever
         * ICP then finds beyond max_motion is reported as a failure. */
        .dist_m = t->cfg.dist_m * (float)(1u << l),
        /* The weighted iterations refine within the basin the wide gate
         * found: there the narrower fine gate (track_config.fine_angle_deg). */
        .cos_angle = (float)cos((weighted && t->cfg.fine_angle_deg > 0 ? t->cfg.fine_angle_deg : t->cfg.angle_deg) *
                                M_PI / 180.0),
        .sub = sub,
        .huber_k = weighted ? (float)(t->cfg.huber_k * huber_unit) : 0.0f,
        .noise_exp = weighted && t->cfg.weight_noise ? t->cfg.noise_weight_exp : 0.0f,
        .sigma_a = t->cfg.sensor.sigma_a,
        .sigma_b = t->cfg.sensor.sigma_b,
        .sigma_c = t->cfg.sensor.sigma_c,
    };
    /* Frame levels below the reference's finest are associated with it. */
    uint32_t rl = l > t->ref_first ? l : t->ref_first;
    pc.ref_off = t->geom.off[rl];
    pc.ref_size = track_icp_size(t->geom.w[rl], t->geom.h[rl]);
    pc.ref_shift = rl - l;
    if (photo_unit > 0 && l < t->cfg.photo_levels && t->frame_has_int && t->ref_has_int) {
        /* Relative to a depth residual at 1 m, as the noise weights are. In
         * the plain iteration too, so that texture constrains what the
         * geometry alone leaves weak (a textured floor or wall: icp_subspace). */
        double s1 = bf_sensor_sigma(1.0f, t->cfg.sensor.sigma_a, t->cfg.sensor.sigma_b, t->cfg.sensor.sigma_c);
        double si = t->cfg.photo_sigma * photo_unit;
        pc.photo_w = (float)(t->cfg.photo_weight * (s1 / si) * (s1 / si));
        pc.photo_huber = t->cfg.huber_k > 0 ? (float)(t->cfg.huber_k * si) : 1e30f;
    }
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 3; j++) pc.R[3 * i + j] = (float)T_rc->R[i][j];
    }
    pc.t[0] = (float)T_rc->t.x, pc.t[1] = (float)T_rc->t.y, pc.t[2] = (float)T_rc->t.z;
    track__level_intrinsics(&t->K, l, &pc.fx, &pc.fy, &pc.cx, &pc.cy);
    bf_status s = gpu_begin(t->ctx);
    if (s != BF_OK) return s;
    if (with_frame) track__cmd_frame_pyramid(t);
    gpu_cmd_stage_begin(t->ctx, "track.icp");
    gpu_cmd_dispatch(t->ctx, t->p_icp, t->b_icp, &pc, g, 1, 1);
    /* The partial sums -> the host's read after the fence. */
    gpu_cmd_barrier(t->ctx, GPU_BARRIER_HOST);
    gpu_cmd_stage_end(t->ctx);
    if ((s = gpu_submit_wait(t->ctx)) != BF_OK) return s;
    char what[32];
    snprintf(what, sizeof what, "icp level %u", l);
    track__profile_print(t, what);
    const gpu_stage_time *st;
    uint32_t n_st = gpu_stage_times(t->ctx, &st);
    for (uint32_t i = 0; i < n_st; i++) {
        res->ms_gpu += st[i].ms;
        if (strcmp(st[i].name, "track.icp")) res->ms_frame += st[i].ms;
    }
    if ((s = gpu_buffer_download(t->partials, 0, t->partial_host, (uint64_t)g * TRACK_PARTIAL_WORDS * 4)) != BF_OK)
        return s;
    memset(out, 0, sizeof *out);
    for (uint32_t k = 0; k < g; k++) {
        const float *p = t->partial_host + (size_t)k * TRACK_PARTIAL_WORDS;
        for (uint32_t i = 0; i < TRACK_SUMS; i++) out->s[i] += p[i];
    }
    return BF_OK;
}

/* The solve of one system: the update and the spectrum. */
typedef struct icp_step {
    double xi[6];        /* translation, then rotation vector (reference camera) */
    double eig_min, eig_max;
    bool degenerate;
    bool ok;             /* finite and solvable */
} icp_step;

/* The directions the geometry constrains: eigenvectors (columns of B, in
 * the depth-scaled coordinates below) of an unweighted system whose
 * eigenvalue is >= ratio times the largest. A single plane constrains 3 of
 * 6; the rest keep the guess instead of following noise. The ratio is a
 * property of the scene's shape, so it is taken from a plain least-squares
 * system (with the photometric term when it is on: the texture of a plane
 * constrains the slides its shape leaves free): robust and noise weights shift the spectrum (on the synthetic
 * room the median ratio fell from 1.3e-2 to 6e-3, below the 5e-3 gate on a
 * third of the frames) without making the geometry any weaker. */
typedef struct icp_subspace {
    double B[36];        /* 6 x k, column-major: column c is B[6 c .. 6 c + 5] */
    int k;
    double zbar;         /* the depth scale B was taken in (the plain system's) */
    double eig_min, eig_max;
    bool degenerate;
} icp_subspace;

/* The system's matrix and vector with rotation columns divided by the
 * inliers' mean depth (a rotation of w radians moves a point at depth z by
 * about w z metres), so eigenvalues compare metres with metres: with x =
 * (t, w zbar), H'_ij = H_ij / (scale_i scale_j), g'_i = g_i / scale_i.
 * zbar > 0 is used as given (a subspace's), else it is the system's own.
 * False when there is nothing to solve. */
static bool scaled_system(const icp_sums *s, double zbar, double H[36], double g[6], double scale[6])
{
    double n_in = s->s[TRACK_SUM_INLIERS];
    for (uint32_t i = 0; i < TRACK_SUMS; i++)
        if (!isfinite(s->s[i])) return false;
    if (n_in < 6) return false;
    if (!(zbar > 0)) zbar = s->s[TRACK_SUM_Z] / n_in;
    if (!(zbar > 0)) return false;
    for (int i = 0; i < 6; i++) scale[i] = i < 3 ? 1.0 : zbar;
    uint32_t e = TRACK_SUM_ATA;
    for (int i = 0; i < 6; i++)
        for (int j = i; j < 6; j++) {
            double v = s->s[e++] / (scale[i] * scale[j]);
            H[6 * i + j] = H[6 * j + i] = v;
        }
    for (int i = 0; i < 6; i++) g[i] = s->s[TRACK_SUM_ATR + i] / scale[i];
    return true;
}

static bool subspace_of(const icp_sums *s, double ratio, icp_subspace *out)
{
    double H[36], g[6], scale[6], w[6], V[36];
    if (!scaled_system(s, 0, H, g, scale)) return false;
    out->zbar = scale[3];
    bf_sym_eigen(6, H, w, V);
    if (!(w[5] > 0) || !isfinite(w[0])) return false;
    out->eig_min = w[0];
    out->eig_max = w[5];
    out->degenerate = w[0] < ratio * w[5];
    out->k = 0;
    for (int c = 0; c < 6; c++) {
        if (w[c] < ratio * w[5] || !(w[c] > 0)) continue;
        for (int i = 0; i < 6; i++) out->B[6 * out->k + i] = V[6 * i + c];
        out->k++;
    }
    return out->k > 0;
}

/* Solves H xi = -g in double within the subspace: xi = B (B^T H B)^-1
 * B^T (-g), so directions outside it keep the guess. */
static icp_step solve(const icp_sums *s, const icp_subspace *S)
{
    icp_step st = {.ok = false, .eig_min = S->eig_min, .eig_max = S->eig_max, .degenerate = S->degenerate};
    double H[36], g[6], scale[6];
    if (!scaled_system(s, S->zbar, H, g, scale)) return st;
    int k = S->k;
    double Hk[36], gk[6], wk[6], Vk[36];
    for (int a = 0; a < k; a++) {
        gk[a] = 0;
        for (int i = 0; i < 6; i++) gk[a] += S->B[6 * a + i] * g[i];
        for (int b = 0; b < k; b++) {
            double v = 0;
            for (int i = 0; i < 6; i++)
                for (int j = 0; j < 6; j++) v += S->B[6 * a + i] * H[6 * i + j] * S->B[6 * b + j];
            Hk[k * a + b] = v;
        }
    }
    bf_sym_eigen(k, Hk, wk, Vk);
    if (!(wk[k - 1] > 0)) return st;
    double y[6] = {0}, x[6] = {0};
    for (int c = 0; c < k; c++) {
        if (!(wk[c] > 1e-12 * wk[k - 1])) continue;
        double d = 0;
        for (int a = 0; a < k; a++) d += Vk[k * a + c] * gk[a];
        d /= wk[c];
        for (int a = 0; a < k; a++) y[a] -= d * Vk[k * a + c];
    }
    for (int a = 0; a < k; a++)
        for (int i = 0; i < 6; i++) x[i] += S->B[6 * a + i] * y[a];
    for (int i = 0; i < 6; i++) {
        st.xi[i] = x[i] / scale[i];
        if (!isfinite(st.xi[i])) return st;
    }
    st.ok = true;
    return st;
}

/* T_rc <- (R(w), t) T_rc: the linearised motion p + w x p + t of Low 2004
 * applied as a rotation about the reference camera's origin plus a shift,
 * so a step in the translation alone never turns the camera. */
static void apply(bf_se3 *T_rc, const double xi[6])
{
    double rot[6] = {0, 0, 0, xi[3], xi[4], xi[5]};
    bf_se3 inc = bf_se3_exp(rot);
    inc.t = bf_v3(xi[0], xi[1], xi[2]);
    *T_rc = bf_se3_mul(&inc, T_rc);
}

/* The unit of the next iteration's Huber threshold in sigma_z(z): the
 * inliers' RMS of r / sigma_z over huber_knee (what a frame that fits the
 * model leaves against the map) when that is above 1. Real Kinect v1 depth
 * against the map leaves residuals 2-4 times the Gaussian model's (its
 * disparity quantisation and lens distortion; docs/real_frames.md): with the
 * model's unit Huber's weight then bends nearly every sample, the finest
 * level converges like an L1 fit, several millimetres per iteration, and
 * stops short in the weakly constrained directions. Scaled, it again bends
 * only the tail. On frames that fit the model the unit stays 1. */
/* The photometric term's unit: photo_sigma, or the RMS of the level's last
 * intensity residuals when larger. Frames whose colour does not fit their
 * depth's motion (motion blur, rolling shutter, the exposure) then count
 * less, as DVO's scale estimate does (Kerl, Sturm and Cremers 2013). */
static double photo_unit_of(const track_config *c, const icp_sums *s)
{
    double n = s->s[TRACK_SUM_PHOTO_N], rr = s->s[TRACK_SUM_PHOTO_RR];
    if (!(n > 0) || !isfinite(rr)) return 1.0;
    double u = sqrt(rr / n) / c->photo_sigma;
    return u > 1.0 ? u : 1.0;
}

/* Whether the photometric term is to be dropped for this frame, from the
 * first finest-level system: brightness constancy assumes the frame and
 * the reference image the same texture the same way; a camera turning fast
 * smears one of them (Kinect v1's colour exposes for up to 1/30 s), which
 * removes gradient energy. On the real dev frames the term's steps were
 * 11-19 mm wrong exactly on such frames (docs/real_frames.md). The ratio of
 * the two energies at the same rows measures the smear without a model of
 * the scene's texture. */
static bool photo_dropped(const track_config *c, const icp_sums *s, track_result *res)
{
    double gr = s->s[TRACK_SUM_PHOTO_GREF], gf = s->s[TRACK_SUM_PHOTO_GFRAME];
    if (!(s->s[TRACK_SUM_PHOTO_N] > 0) || !(gr > 0) || !isfinite(gf)) return false;
    double ratio = gf / gr;
    res->photo_sharpness = ratio;
    double m = c->photo_sharpness_min;
    return m > 0 && (ratio < m || ratio * m > 1.0);
}

/* Whether a frame tracked with photo_weak_ratio needs the term: its
 * depth-only system leaves a direction weak, and both intensities exist. */
static bool photo_wanted(const track_tracker *t, const icp_sums *s)
{
    if (!(t->cfg.photo_weight > 0) || !t->frame_has_int || !t->ref_has_int) return false;
    double H[36], g[6], scale[6], w[6], V[36];
    if (!scaled_system(s, 0, H, g, scale)) return false;
    bf_sym_eigen(6, H, w, V);
    return w[5] > 0 && isfinite(w[0]) && w[0] < t->cfg.photo_weak_ratio * w[5];
}

static double huber_unit_of(const track_config *c, const icp_sums *s)
{
    double n = s->s[TRACK_SUM_INLIERS], rn = s->s[TRACK_SUM_RN];
    if (!c->huber_scaled || !(n > 0) || !isfinite(rn)) return 1.0;
    double u = sqrt(rn / n) / c->huber_knee;
    return u > 1.0 ? u : 1.0;
}

bf_status track__icp_run(track_tracker *t, bf_se3 *T_rc, uint32_t min_valid, track_result *res)
{
    const track_config *c = &t->cfg;
    bf_se3 guess_rc = *T_rc;
    icp_sums sums = {0};
    icp_step step = {.ok = false};
    icp_subspace S = {.k = 0};
    bool have_finest = false;
    double huber_unit = 1.0;
    bool robust = c->huber_k > 0 || c->weight_noise;
    /* With a weak ratio the finest level starts on depth alone and the
     * term comes in only where that leaves a direction weak. */
    bool weak_only = c->photo_weak_ratio > 0;
    bool photo = !weak_only, photo_decided = !weak_only;
    icp_sums plain = {0}; /* the depth-only first finest iteration of a weak frame */
    res->photo_sharpness = 0;
    res->photo_dropped = false;
    res->photo_weak = false;
    for (int l = (int)c->levels - 1; l >= 0; l--) {
        double photo_unit = 1.0; /* residuals of a coarser level are smoother */
        for (uint32_t it = 0; it < c->iterations[l]; it++) {
            bool first = res->iterations == 0;
            /* Robust weights at the finest level only, after its first
             * iteration: coarse levels catch the bulk of a motion, when every
             * residual is large and down-weighting them stops ICP early (the
             * real TUM pair then stopped at 48 mm and 1.9 degrees instead of
             * 131 mm and 3.3, docs/tracking.md); the first, plain iteration
             * gives the constrained directions (icp_subspace) that the
             * weighted ones keep. */
            bool weighted = robust && l == 0 && it > 0 && S.k > 0;
            bf_status s = run_iteration(t, (uint32_t)l, T_rc, first, weighted, huber_unit, photo ? photo_unit : 0,
                                        &sums, res);
            if (s != BF_OK) return s;
            if (first) {
                uint32_t n_depth = 0;
                if ((s = gpu_buffer_download(t->counters, TRACK_CNT_FRAME_VALID * 4u, &n_depth, 4)) != BF_OK) return s;
                if (n_depth < min_valid) {
                    res->n_valid = n_depth;
                    res->outcome = TRACK_NO_DEPTH;
                    return BF_OK;
                }
            }
            res->iterations++;
            if (!photo_decided && l == 0 && it == 0) {
                photo_decided = true;
                if (photo_wanted(t, &sums)) {
                    plain = sums;
                    photo = true;
                    res->photo_weak = true;
                    it--;
                    continue;
                }
            }
            if (photo && l == 0 && it == 0 && photo_dropped(c, &sums, res)) {
                /* The plain iteration without the term: its system also
                 * gives the directions the weighted ones keep. A weak
                 * frame's was run first and is taken back as it was. */
                photo = false;
                res->photo_dropped = true;
                if (!res->photo_weak) {
                    it--;
                    continue;
                }
                sums = plain;
            }
            huber_unit = huber_unit_of(c, &sums);
            photo_unit = photo_unit_of(c, &sums);
            if (!weighted && !subspace_of(&sums, c->degenerate_ratio, &S)) S.k = 0;
            step = S.k > 0 ? solve(&sums, &S) : (icp_step){.ok = false};
            if (l == 0) have_finest = true;
            double dt = sqrt(step.xi[0] * step.xi[0] + step.xi[1] * step.xi[1] + step.xi[2] * step.xi[2]);
            double dw = sqrt(step.xi[3] * step.xi[3] + step.xi[4] * step.xi[4] + step.xi[5] * step.xi[5]);
            bf_debug("tracking: level %d iteration %u: %.0f/%.0f inliers, rms %.2f mm, eig %.3g/%.3g%s, step %.3f mm "
                     "%.4f deg",
                     l, it, sums.s[TRACK_SUM_INLIERS], sums.s[TRACK_SUM_VALID],
                     1e3 * sqrt(sums.s[TRACK_SUM_RR] / fmax(sums.s[TRACK_SUM_INLIERS], 1)), step.eig_min, step.eig_max,
                     step.degenerate ? " degenerate" : "", step.ok ? 1e3 * dt : 0.0, step.ok ? dw * 180.0 / M_PI : 0.0);
            if (!step.ok) break; /* nothing to solve at this level: go finer */
            apply(T_rc, step.xi);
            if (dt < c->converged_m && dw * 180.0 / M_PI < c->converged_deg) break;
        }
    }
    /* The checks use the last system of the finest level (DESIGN.md
     * section 6): the pose before its (tiny, once converged) update. */
    double n_valid = sums.s[TRACK_SUM_VALID], n_in = sums.s[TRACK_SUM_INLIERS];
    res->n_valid = (uint32_t)n_valid;
    res->n_inliers = (uint32_t)n_in;
    res->inlier_frac = n_valid > 0 ? n_in / n_valid : 0;
    res->residual_m = n_in > 0 ? sqrt(sums.s[TRACK_SUM_RR] / n_in) : 0;
    res->residual_sigma = n_in > 0 ? sqrt(sums.s[TRACK_SUM_RN] / n_in) : 0;
    res->eig_min = step.eig_min;
    res->eig_max = step.eig_max;
    res->degenerate = step.ok && step.degenerate;
    bf_se3 motion_inv = bf_se3_inverse(&guess_rc);
    bf_se3 motion = bf_se3_mul(&motion_inv, T_rc);
    if (!have_finest || n_valid < 1) res->outcome = TRACK_NO_DEPTH;
    else if (!bf_se3_is_finite(T_rc)) res->outcome = TRACK_NUMERIC;
    else if (res->inlier_frac < c->min_inlier_frac) res->outcome = TRACK_FEW_INLIERS;
    else if (!step.ok) res->outcome = TRACK_NUMERIC;
    else if (res->residual_m > c->max_residual_m &&
             !(c->max_residual_sigma > 0 && res->residual_sigma <= c->max_residual_sigma))
        res->outcome = TRACK_HIGH_RESIDUAL;
    else if (bf_v3_norm(motion.t) > c->max_motion_m * t->motion_scale ||
             bf_se3_angle(&motion) * 180.0 / M_PI > c->max_motion_deg * t->motion_scale)
        res->outcome = TRACK_LARGE_MOTION;
    else res->outcome = TRACK_OK;
    return BF_OK;
}
