/* Relocalisation: finding the map again after tracking failed or the
 * depth went away for a while (recon_int.h, DESIGN.md section 6).
 *
 * A frame that cannot be tracked from its guess is tried from a few
 * candidate poses: where the colour's keypoints, matched to a keyframe's,
 * put the camera (PnP with RANSAC), the last good pose, the last tracked
 * motion continued over the frames elapsed, both turned by 10 or 20
 * degrees, and keyframes (poses kept while tracking, one per 0.1 m or 10
 * degrees of the path).
 * Each candidate costs a ray-cast of the map at its pose (the tracking
 * reference, not fused) and an ICP from it; the best one is taken only when
 * it passes the tracker's gates with a margin, agrees with the map where the
 * map predicts a surface (agreement_of), and no other candidate found a
 * different pose. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "recon_int.h"
#include "shaders/bf_common.glsl.h"

/* Two candidates that pass but end this far apart found two different
 * minima (a repetitive scene): tracking's own error from two starts on the
 * same frame is millimetres, so neither is trusted. */
#define RELOC_AMBIGUOUS_M 0.05
#define RELOC_AMBIGUOUS_DEG 5.0
/* reloc.feature_candidates at most: the search's lists are this long. */
#define FEATURE_MAX_CANDIDATES 8u

/* The turns tried around the last pose and the continued motion: yaw
 * (about the camera's y axis) and pitch (x), 10 degrees first. Hand-held
 * cameras turn faster than they move: a 30-frame gap turned the real
 * camera 20 degrees while it moved 13 cm (docs/tracking.md). */
static const double turn_axis_deg[8][2] = {{1, 10}, {1, -10}, {0, 10}, {0, -10},
                                           {1, 20}, {1, -20}, {0, 20}, {0, -20}};
#define N_TURNS 8u

bf_status recon__reloc_create(recon *r)
{
    const recon_reloc_config *c = &r->cfg.reloc;
    r->V_step = bf_se3_identity();
    if (!c->enabled) return BF_OK;
    if (c->max_candidates < 1 || c->max_keyframes < 1 || !(c->max_gate_intervals >= 1) ||
        !(c->keyframe_m > 0) || !(c->keyframe_deg > 0) || !(c->min_inlier_frac > 0 && c->min_inlier_frac <= 1) ||
        !(c->max_residual_m > 0) || !(c->max_residual_sigma >= 0) || c->check_step < 1 || !(c->check_band_m >= 0) ||
        !(c->max_front_frac >= 0 && c->max_front_frac <= 1) || c->feature_candidates > FEATURE_MAX_CANDIDATES ||
        !(c->last_frame_below >= 0 && c->last_frame_below <= 1))
        return bf_fail(BF_INVALID_ARG,
                       "recon: reloc needs candidates %u >= 1, keyframes %u >= 1, gate intervals %g >= 1, keyframe "
                       "spacing %g m / %g deg > 0, inliers %g in (0, 1], residual %g m > 0 (%g sigma >= 0), check "
                       "step %u >= 1, band %g m >= 0, in front %g in [0, 1], colour candidates %u <= 8, weak fit "
                       "below %g in [0, 1]",
                       c->max_candidates, c->max_keyframes, c->max_gate_intervals, c->keyframe_m, c->keyframe_deg,
                       c->min_inlier_frac, c->max_residual_m, c->max_residual_sigma, c->check_step, c->check_band_m,
                       c->max_front_frac, c->feature_candidates, c->last_frame_below);
    r->keyframes = calloc(c->max_keyframes, sizeof *r->keyframes);
    r->kf_features = calloc(c->max_keyframes, sizeof *r->kf_features);
    if (!r->keyframes || !r->kf_features) return bf_fail(BF_NO_MEMORY, "recon: %u keyframes", c->max_keyframes);
    r->ref_host = malloc((size_t)r->K_ref.width * r->K_ref.height * sizeof *r->ref_host);
    if (!r->ref_host) return bf_fail(BF_NO_MEMORY, "recon: the reference's depth on the host");
    if (c->last_frame && !(r->good_depth = malloc((size_t)r->K.width * r->K.height * sizeof *r->good_depth)))
        return bf_fail(BF_NO_MEMORY, "recon: the last good frame's depth");
    return BF_OK;
}

void recon__reloc_destroy(recon *r)
{
    for (uint32_t i = 0; r->kf_features && i < r->cfg.reloc.max_keyframes; i++) features_free(r->kf_features[i]);
    free(r->kf_features);
    free(r->keyframes);
    free(r->ref_host);
    free(r->good_depth);
    r->good_depth = NULL;
    r->kf_features = NULL;
    r->keyframes = NULL;
    r->ref_host = NULL;
}

double recon__intervals(const recon *r, const bf_frame *f)
{
    double n = f->index > r->good_index ? (double)(f->index - r->good_index) : 1.0;
    /* Timestamps jitter by a few milliseconds at 33: rounded, one frame
     * later is one interval, a frame the capture dropped is two. */
    if (r->dt_s > 0 && f->t_depth_s > r->good_t_s) n = floor((f->t_depth_s - r->good_t_s) / r->dt_s + 0.5);
    return n < 1 ? 1.0 : n;
}

bf_status recon__set_gate(recon *r, double n)
{
    double cap = r->cfg.reloc.max_gate_intervals;
    return track_set_motion_scale(r->tracker, n < cap ? n : cap);
}

static double angle_deg(const bf_se3 *A, const bf_se3 *B)
{
    bf_se3 Ai = bf_se3_inverse(A), D = bf_se3_mul(&Ai, B);
    return bf_se3_angle(&D) * 180.0 / M_PI;
}

static double dist_m(const bf_se3 *A, const bf_se3 *B) { return bf_v3_norm(bf_v3_sub(A->t, B->t)); }

/* Whether p repeats q: within the distance two passing candidates may end
 * apart and still be one pose (two colour poses that close are one). */
static bool same_pose(const bf_se3 *p, const bf_se3 *q)
{
    return dist_m(p, q) <= RELOC_AMBIGUOUS_M && angle_deg(p, q) <= RELOC_AMBIGUOUS_DEG;
}

/* Within a keyframe spacing of T: close enough that ICP from one reaches the other. */
static bool is_near(const recon *r, const bf_se3 *A, const bf_se3 *B)
{
    return dist_m(A, B) <= r->cfg.reloc.keyframe_m && angle_deg(A, B) <= r->cfg.reloc.keyframe_deg;
}

/* How far apart two poses are in keyframe spacings: the larger of the
 * distance over keyframe_m and the angle over keyframe_deg (is_near: <= 1). */
static double spacing_of(const recon *r, const bf_se3 *A, const bf_se3 *B)
{
    double d = dist_m(A, B) / r->cfg.reloc.keyframe_m, a = angle_deg(A, B) / r->cfg.reloc.keyframe_deg;
    return d > a ? d : a;
}

/* The keyframe that the store misses least, with T about to join it: the
 * one whose two nearest others (T among them) are nearest together. The
 * nearest alone ties along an evenly spaced path, and the ends then went
 * first; with the second nearest an end (one neighbour) outlasts the
 * keyframes between, so a long scan keeps where it began. */
static uint32_t most_redundant(const recon *r, const bf_se3 *T)
{
    uint32_t best = 0;
    double best_score = INFINITY;
    for (uint32_t i = 0; i < r->n_keyframes; i++) {
        double d1 = spacing_of(r, &r->keyframes[i], T), d2 = INFINITY;
        for (uint32_t j = 0; j < r->n_keyframes; j++) {
            if (j == i) continue;
            double d = spacing_of(r, &r->keyframes[i], &r->keyframes[j]);
            if (d < d1) d2 = d1, d1 = d;
            else if (d < d2) d2 = d;
        }
        if (d1 + d2 < best_score) best_score = d1 + d2, best = i;
    }
    return best;
}

/* Whether frames' colour gives candidates. */
static bool uses_features(const recon *r)
{
    return r->cfg.reloc.features > 0 && r->cfg.reloc.feature_candidates > 0;
}

/* f's colour keypoints, each with the point the depth puts there, in the
 * depth camera's frame: read at the keypoint's own pixel where the colour
 * is registered, else found through the colour camera
 * (calib_points_on_colour), so the keypoints come from the colour camera's
 * own image, not a resampling of it. */
static bf_status lift_keypoints(const recon *r, const bf_frame *f, const features_set *all, features_set **lifted)
{
    bf_se3 T_cd;
    const calib_camera *cam = recon__colour_rig(&r->cfg, &T_cd);
    float lo = 1e-3f, hi = r->cfg.sensor.max_depth_m;
    if (!cam) return features_lift(all, f->depth, &r->K, lo, hi, false, lifted);
    float *xyz = malloc((size_t)f->width * f->height * 3 * sizeof *xyz);
    if (!xyz) return bf_fail(BF_NO_MEMORY, "recon: frame %u: the depth's points on the colour", f->index);
    bf_status s = calib_points_on_colour(cam, &T_cd, &r->K, f->depth, f->width, f->height, xyz);
    if (s == BF_OK) s = features_lift_points(all, xyz, f->width, f->height, lo, hi, false, lifted);
    free(xyz);
    return s;
}

/* The lifted keypoints of f's colour, or NULL (no colour, or OpenCV
 * failed: the keyframe is kept without them, with a warning). */
static features_set *keyframe_features(const recon *r, const bf_frame *f)
{
    if (!f || !f->rgb || !f->depth || !uses_features(r)) return NULL;
    features_set *all = NULL, *lifted = NULL;
    double t0 = bf_time_s();
    bf_status s = features_detect_rgb(f->rgb, f->width, f->height, r->cfg.reloc.features, false, &all);
    if (s == BF_OK) s = lift_keypoints(r, f, all, &lifted);
    features_free(all);
    if (s != BF_OK) bf_warn("recon: frame %u: a keyframe without colour keypoints: %s", f->index, bf_last_error());
    else bf_debug("recon: frame %u: keyframe colour: %u keypoints, %zu bytes, %.1f ms", f->index,
                  features_count(lifted), features_bytes(lifted), 1e3 * (bf_time_s() - t0));
    return lifted;
}

/* T becomes a keyframe with feat (owned; NULL: none) unless one is near. */
static void add_keyframe_with(recon *r, const bf_se3 *T, features_set *feat)
{
    for (uint32_t i = 0; i < r->n_keyframes; i++)
        if (is_near(r, &r->keyframes[i], T)) {
            features_free(feat);
            return;
        }
    /* Bounded: once all are held the most redundant one is replaced, so the
     * store keeps its spread over the scan (a search over 64 poses, only
     * when a new one comes). */
    uint32_t i = r->n_keyframes < r->cfg.reloc.max_keyframes ? r->n_keyframes++ : most_redundant(r, T);
    r->keyframes[i] = *T;
    features_free(r->kf_features[i]);
    r->kf_features[i] = feat;
    r->counts.keyframes = r->n_keyframes;
    r->kf_generation++;
}

void recon__add_keyframe(recon *r, const bf_se3 *T, const bf_frame *f)
{
    for (uint32_t i = 0; i < r->n_keyframes; i++)
        if (is_near(r, &r->keyframes[i], T)) return; /* before an ORB pass it would not need */
    add_keyframe_with(r, T, keyframe_features(r, f));
}

bf_status recon__keyframes_export(const recon *r, store_keyframes *out)
{
    memset(out, 0, sizeof *out);
    if (!r->keyframes || !r->n_keyframes) return BF_OK;
    /* Within what the file holds: the first STORE_MAX_KEYFRAMES, each with
     * at most STORE_MAX_KEYPOINTS (ORB may keep a few more than asked when
     * responses tie). */
    uint32_t n = r->n_keyframes < STORE_MAX_KEYFRAMES ? r->n_keyframes : STORE_MAX_KEYFRAMES;
    store_keyframes k = {.kf = bf_calloc(n, sizeof *k.kf)};
    if (!k.kf) return bf_fail(BF_NO_MEMORY, "recon: %u keyframes", n);
    bf_status s = BF_OK;
    for (uint32_t i = 0; i < n && s == BF_OK; i++) {
        k.n = i + 1;
        k.kf[i].T_wc = r->keyframes[i];
        if (r->kf_features[i])
            s = features_export_lifted(r->kf_features[i], &k.kf[i].n, &k.kf[i].desc, &k.kf[i].xyz);
        if (k.kf[i].n > STORE_MAX_KEYPOINTS) k.kf[i].n = STORE_MAX_KEYPOINTS;
    }
    if (s != BF_OK) {
        store_keyframes_free(&k);
        return s;
    }
    *out = k;
    return BF_OK;
}

void recon__keyframes_import(recon *r, const store_keyframes *k)
{
    for (uint32_t i = 0; r->keyframes && k && i < k->n; i++) {
        const store_keyframe *f = &k->kf[i];
        features_set *feat = NULL;
        if (f->n && uses_features(r) && features_import_lifted(f->n, f->desc, f->xyz, &feat) != BF_OK) {
            bf_warn("recon: stored keyframe %u without its colour keypoints: %s", i, bf_last_error());
            feat = NULL;
        }
        add_keyframe_with(r, &f->T_wc, feat);
    }
}

/* The motion of D spread evenly over n intervals: D^(1/n) (the twist divided). */
static bf_se3 per_interval(const bf_se3 *D, double n)
{
    double xi[6];
    bf_se3_log(D, xi);
    for (int i = 0; i < 6; i++) xi[i] /= n;
    return bf_se3_exp(xi);
}

void recon__good_frame(recon *r, const bf_frame *f, const bf_se3 *T_new, bool may_keyframe)
{
    if (r->counts.tracked > 0) {
        /* Not the first good frame: the step from the last one. */
        double n = recon__intervals(r, f);
        bf_se3 Li = bf_se3_inverse(&r->T_last), D = bf_se3_mul(&Li, T_new);
        r->V_step = per_interval(&D, n);
        r->has_velocity = true;
        if (f->index == r->good_index + 1 && f->t_depth_s > r->good_t_s) {
            /* An average over a few steps: one step's jitter is a few ms. */
            double dt = f->t_depth_s - r->good_t_s;
            r->dt_s = r->dt_s > 0 ? 0.8 * r->dt_s + 0.2 * dt : dt;
        }
    }
    r->T_last = *T_new;
    r->good_index = f->index;
    r->good_t_s = f->t_depth_s;
    r->is_lost = false;
    r->depthless_since_good = false;
    if (r->keyframes && may_keyframe) recon__add_keyframe(r, T_new, f);
    if (r->good_depth) memcpy(r->good_depth, f->depth, (size_t)f->width * f->height * sizeof *r->good_depth);
    r->has_good_depth = r->good_depth != NULL;
}

/* The primary candidates, tried on every searching frame: 0 the last good
 * pose, 1 the motion continued over n intervals (with a velocity). */
static uint32_t n_primary(const recon *r) { return r->has_velocity ? 2u : 1u; }

bf_se3 recon__velocity_pose(const recon *r, double n)
{
    double xi[6];
    bf_se3_log(&r->V_step, xi);
    for (int i = 0; i < 6; i++) xi[i] *= n;
    bf_se3 M = bf_se3_exp(xi);
    return bf_se3_mul(&r->T_last, &M);
}

/* Entry i of the round robin: the turns of each primary, then the
 * keyframes. */
static uint32_t n_round(const recon *r) { return n_primary(r) * N_TURNS + r->n_keyframes; }

static recon_reloc_kind round_entry(const recon *r, uint32_t i, double n, bf_se3 *T)
{
    if (i >= n_primary(r) * N_TURNS) {
        *T = r->keyframes[i - n_primary(r) * N_TURNS];
        return RECON_RELOC_KEYFRAME;
    }
    bf_se3 base = i < N_TURNS ? r->T_last : recon__velocity_pose(r, n);
    const double *ta = turn_axis_deg[i % N_TURNS];
    bf_vec3 axis = ta[0] == 1 ? bf_v3(0, 1, 0) : bf_v3(1, 0, 0);
    bf_se3 turn = bf_se3_from_qt(bf_quat_from_axis_angle(axis, ta[1] * M_PI / 180.0), bf_v3(0, 0, 0));
    *T = bf_se3_mul(&base, &turn); /* turned about the camera's own centre */
    return RECON_RELOC_TURNED;
}

/* The map ray-cast at T_wc as the tracking reference, in a submission of
 * its own (nothing is fused). No frame was fused there: the intensity the
 * photometric term compares with is kept only at the last fused frame's
 * own pose (track_cmd_reference). */
bf_status recon__cast_reference(recon *r, const bf_se3 *T_wc, recon_frame_result *out)
{
    render_options ro = r->cfg.raycast;
    ro.no_shade = true;
    bf_status s = track_reference_target(r->tracker, &ro.depth_out, &ro.depth_offset);
    if (s != BF_OK) return s;
    if ((s = gpu_begin(r->ctx)) != BF_OK) return s;
    r->ref_is_map = false; /* a candidate's view, not the last fused pose's */
    s = render_cmd_raycast(r->ref_caster, r->map, &r->K_ref, T_wc, &ro);
    if (s == BF_OK) s = track_cmd_reference(r->tracker, T_wc, false);
    /* The reference's count of valid pixels -> the host. */
    gpu_cmd_barrier(r->ctx, GPU_BARRIER_HOST);
    bf_status sw = gpu_submit_wait(r->ctx);
    if (s == BF_OK) s = sw;
    if (s != BF_OK) return s;
    render_finish_raycast(r->ref_caster);
    out->ms_raycast += render_last_ms(r->ref_caster);
    return track_finish_reference(r->tracker);
}

/* How a candidate's pose agrees with the map where the map predicts a
 * surface: the frame's samples moved into the reference camera (cast at
 * T_ref) and compared with the reference depth at the pixel they land on.
 * Inliers and residual count samples where the map has nothing; a pose that
 * slid along a partly mapped wall fits the wall as well as the right pose
 * fits its view, but puts some of the frame where the map saw free space
 * (docs/tracking.md, the agreement check). On the host, for the candidates
 * that pass the tracker's gates only: the per-frame ICP is unchanged. */
typedef struct agreement {
    uint32_t n_samples; /* frame samples with depth in range */
    uint32_t n_covered; /* of those, landing on a reference pixel with depth */
    uint32_t n_agree;   /* covered, within the band of the predicted depth */
    uint32_t n_front;   /* covered, in front of it: something where the map saw free space */
    uint32_t n_behind;  /* covered, behind it: seen through a surface the map holds */
} agreement;

recon__agreement_class recon__classify_sample(const float *ref, uint32_t w, uint32_t h, double x, double y,
                                              double z, const bf_sensor *sn, double band_m)
{
    if (!(x > -0.5 && y > -0.5 && x < w - 0.5 && y < h - 0.5)) return RECON_SAMPLE_OFF;
    float zq = ref[(size_t)(uint32_t)(y + 0.5) * w + (uint32_t)(x + 0.5)];
    if (!(zq > 0)) return RECON_SAMPLE_OFF;
    /* The four reference pixels around the landing point (fewer at the
     * border), the nearest surface and the farthest among them: at a
     * silhouette of the reference (at the default track.ref_level a
     * quarter of the frame's resolution, so a reference pixel spans 4 x 4
     * of the frame's) the nearest pixel may be the background beside the
     * foreground the sample belongs to. Right poses put 0.5-1.7% of their
     * samples in front by the nearest pixel alone on the synthetic room
     * and 3.4-7.2% on fr1/rpy's far floor; free space where a wrong pose
     * puts the frame is wider than a pixel (docs/tracking.md, the
     * agreement check). */
    double fx = floor(x), fy = floor(y); /* -1 left of the first pixel's centre */
    uint32_t x0 = fx < 0 ? 0 : (uint32_t)fx, y0 = fy < 0 ? 0 : (uint32_t)fy;
    uint32_t x1 = fx >= 0 && x0 + 1 < w ? x0 + 1 : x0, y1 = fy >= 0 && y0 + 1 < h ? y0 + 1 : y0;
    const float around[4] = {ref[(size_t)y0 * w + x0], ref[(size_t)y0 * w + x1], ref[(size_t)y1 * w + x0],
                             ref[(size_t)y1 * w + x1]};
    float z_near = zq, z_far = zq;
    for (int k = 0; k < 4; k++) {
        if (!(around[k] > 0)) continue;
        if (around[k] < z_near) z_near = around[k];
        if (around[k] > z_far) z_far = around[k];
    }
    double zm = z > zq ? z : zq;
    double band = band_m + 3.0 * bf_sensor_sigma((float)zm, sn->sigma_a, sn->sigma_b, sn->sigma_c);
    if (z < z_near - band) return RECON_SAMPLE_FRONT;
    if (z > z_far + band) return RECON_SAMPLE_BEHIND;
    return RECON_SAMPLE_AGREE;
}

static bf_status agreement_of(recon *r, const bf_frame *f, const bf_se3 *T_ref, const bf_se3 *T_wc, agreement *a)
{
    bf_status s = track_download_reference(r->tracker, r->ref_host);
    if (s != BF_OK) return s;
    memset(a, 0, sizeof *a);
    bf_se3 Ri = bf_se3_inverse(T_ref), T_rc = bf_se3_mul(&Ri, T_wc);
    const bf_sensor *sn = &r->cfg.sensor;
    uint32_t step = r->cfg.reloc.check_step;
    for (uint32_t v = 0; v < f->height; v += step)
        for (uint32_t u = 0; u < f->width; u += step) {
            double z = f->depth[(size_t)v * f->width + u] / r->K.depth_scale;
            if (!(z > 0) || z > sn->max_depth_m) continue;
            a->n_samples++;
            bf_vec3 p = bf_se3_apply(&T_rc, bf_intrinsics_unproject(&r->K, u, v, z));
            double x, y;
            if (!bf_intrinsics_project(&r->K_ref, p, &x, &y)) continue;
            recon__agreement_class c = recon__classify_sample(r->ref_host, r->K_ref.width, r->K_ref.height, x, y,
                                                              p.z, sn, r->cfg.reloc.check_band_m);
            if (c == RECON_SAMPLE_OFF) continue;
            a->n_covered++;
            if (c == RECON_SAMPLE_FRONT) a->n_front++;
            else if (c == RECON_SAMPLE_BEHIND) a->n_behind++;
            else a->n_agree++;
        }
    return BF_OK;
}

bool recon__passes(const recon *r, const track_result *t)
{
    /* Degenerate systems fit anywhere along their weak directions. The
     * residual as the tracker gates it: metric, or in units of the
     * sensor's noise, which at 2.5-3.5 m is 10-20 mm alone. */
    const recon_reloc_config *c = &r->cfg.reloc;
    bool fits = t->residual_m <= c->max_residual_m ||
                (c->max_residual_sigma > 0 && r->cfg.track.max_residual_sigma > 0 &&
                 t->residual_sigma <= c->max_residual_sigma);
    return t->outcome == TRACK_OK && !t->degenerate && t->inlier_frac >= c->min_inlier_frac && fits;
}

/* What a search has seen so far. */
typedef struct search_state {
    bool has_best, is_ambiguous;
    track_result best;       /* the passing candidate with most inliers */
    recon_reloc_kind best_kind;
    bool has_any;
    track_result any;        /* the candidate with most inliers (reported when none passes) */
    bool is_no_depth;        /* the frame has no depth the tracker can use: no candidate will do */
} search_state;

static bf_status try_candidate(recon *r, const bf_frame *f, const fusion_frame_slot *slot, const bf_se3 *T_c,
                               recon_reloc_kind kind, search_state *st, recon_frame_result *out)
{
    track_result t;
    bf_status s = recon__cast_reference(r, T_c, out);
    if (s == BF_OK) s = track_frame_gpu(r->tracker, slot->depth, slot->offset, f->index, T_c, &t);
    if (s != BF_OK) return s;
    out->reloc_tried++;
    out->ms_track += t.ms_gpu;
    st->is_no_depth = t.outcome == TRACK_NO_DEPTH;
    bf_debug("recon: frame %u: candidate %s: %s, inliers %.1f%%, residual %.1f mm", f->index,
             recon_reloc_kind_name(kind), track_outcome_name(t.outcome), 100 * t.inlier_frac, 1e3 * t.residual_m);
    if (!st->has_any || t.inlier_frac > st->any.inlier_frac) st->any = t;
    st->has_any = true;
    if (!recon__passes(r, &t)) return BF_OK;
    /* The tracker's gates passed: the candidate is checked against the
     * map's prediction before it may count. */
    agreement a;
    double t0 = bf_time_s();
    if ((s = agreement_of(r, f, T_c, &t.T_wc, &a)) != BF_OK) return s;
    double ms_check = 1e3 * (bf_time_s() - t0);
    double agree = a.n_covered ? (double)a.n_agree / a.n_covered : 0;
    double front = a.n_covered ? (double)a.n_front / a.n_covered : 1;
    /* Only the samples in front decide: right poses leave up to 15% behind
     * the predicted surface on real frames (holes and edges of the map's
     * ray-cast, docs/tracking.md), but next to none in front of it. */
    bool is_agreeing = front <= r->cfg.reloc.max_front_frac;
    bf_debug("recon: frame %u: candidate %s: %u of %u samples covered, %.1f%% agree, %.1f%% in front, %.1f%% behind "
             "(%.1f ms): %s",
             f->index, recon_reloc_kind_name(kind), a.n_covered, a.n_samples, 100 * agree, 100 * front,
             a.n_covered ? 100.0 * a.n_behind / a.n_covered : 0.0, ms_check, is_agreeing ? "agrees" : "rejected");
    if (!is_agreeing) {
        out->reloc_rejected++;
        return BF_OK;
    }
    if (st->has_best && !same_pose(&st->best.T_wc, &t.T_wc)) st->is_ambiguous = true;
    if (!st->has_best || t.inlier_frac > st->best.inlier_frac) {
        st->best = t;
        st->best_kind = kind;
    }
    st->has_best = true;
    return BF_OK;
}

/* RANSAC for a keyframe's pose: from the distinctive matches a frame that
 * sees what a keyframe saw keeps about half as inliers (45-84% measured),
 * where 1000 draws miss every all-inlier five-point sample with a
 * probability of 1e-14; a 3 px threshold takes Kinect v1's depth-to-colour
 * offset (7-Scenes registers neither) and ORB's one-pixel placement. */
#define FEATURE_RANSAC_PX 3.0
#define FEATURE_RANSAC_ITERATIONS 1000u
/* Matches further apart than 64 of ORB's 256 bits are dropped (ORB-SLAM
 * takes 50-100): what is left is more often right, so RANSAC's adaptive
 * count stops sooner. */
#define FEATURE_MAX_HAMMING 64u
/* PnP runs on the keyframes with most such matches only, this many per
 * pose asked for: PnP costs about ten times the matching. */
#define FEATURE_PNP_PER_CANDIDATE 2u

void recon__keep_pose(recon__colour_pose *best, uint32_t *n, uint32_t cap, const recon__colour_pose *p)
{
    for (uint32_t j = 0; j < *n; j++)
        if (best[j].n_inliers >= p->n_inliers && same_pose(&best[j].T_wc, &p->T_wc)) return;
    uint32_t m = 0;
    for (uint32_t j = 0; j < *n; j++)
        if (!same_pose(&best[j].T_wc, &p->T_wc)) best[m++] = best[j];
    uint32_t k = 0;
    while (k < m && best[k].n_inliers >= p->n_inliers) k++;
    if (k >= cap) {
        *n = m;
        return;
    }
    uint32_t keep = m < cap ? m : cap - 1; /* the poses kept after p's place */
    memmove(&best[k + 1], &best[k], (keep - k) * sizeof *best);
    best[k] = *p;
    *n = keep + 1;
}

/* The poses where the frame's colour keypoints, matched to each
 * keyframe's, put the camera: up to reloc.feature_candidates, most
 * inliers first, none within the ambiguity distance of one before. An
 * OpenCV failure gives none, with a warning: the other candidates remain. */
static uint32_t colour_poses(const recon *r, const bf_frame *f, recon__colour_pose *best, uint32_t cap)
{
    if (cap > FEATURE_MAX_CANDIDATES) cap = FEATURE_MAX_CANDIDATES;
    bool any = false;
    for (uint32_t i = 0; i < r->n_keyframes && !any; i++) any = r->kf_features[i] != NULL;
    if (!any || !f->rgb || !uses_features(r) || cap == 0) return 0;
    features_set *frame = NULL;
    double t0 = bf_time_s();
    bf_status s = features_detect_rgb(f->rgb, f->width, f->height, r->cfg.reloc.features, false, &frame);
    /* The frame's keypoints are where its colour camera saw them: PnP
     * gives that camera's pose, and the rig takes it to the depth
     * camera's. */
    bf_se3 T_cd = bf_se3_identity();
    const calib_camera *cam = recon__colour_rig(&r->cfg, &T_cd);
    bf_intrinsics K = cam ? calib_camera_intrinsics(cam) : r->K;
    bf_se3 T_dc = bf_se3_inverse(&T_cd);
    const features_pnp_config pc = {.ransac_px = FEATURE_RANSAC_PX, .ransac_iterations = FEATURE_RANSAC_ITERATIONS,
                                    .min_inliers = r->cfg.reloc.feature_min_inliers,
                                    .max_hamming = FEATURE_MAX_HAMMING, .fast = true};
    /* The keyframes ranked by matches, the best few kept (insertion into a
     * short list, ties to the earlier keyframe). */
    uint32_t top[FEATURE_MAX_CANDIDATES * FEATURE_PNP_PER_CANDIDATE];
    uint32_t top_m[FEATURE_MAX_CANDIDATES * FEATURE_PNP_PER_CANDIDATE], n_top = 0;
    uint32_t top_cap = cap * FEATURE_PNP_PER_CANDIDATE;
    for (uint32_t i = 0; i < r->n_keyframes && s == BF_OK; i++) {
        uint32_t m;
        if (!r->kf_features[i]) continue;
        if ((s = features_match_count(r->kf_features[i], frame, FEATURE_MAX_HAMMING, &m)) != BF_OK) break;
        if (m < r->cfg.reloc.feature_min_inliers) continue;
        uint32_t k = n_top < top_cap ? n_top++ : top_cap;
        while (k > 0 && top_m[k - 1] < m) {
            if (k < top_cap) top[k] = top[k - 1], top_m[k] = top_m[k - 1];
            k--;
        }
        if (k < top_cap) top[k] = i, top_m[k] = m;
    }
    uint32_t n = 0;
    for (uint32_t t = 0; t < n_top && s == BF_OK; t++) {
        uint32_t i = top[t];
        features_pnp_result pr;
        const double *dist = cam ? cam->dist : NULL;
        if ((s = features_pnp(r->kf_features[i], frame, &K, dist, &pc, &pr)) != BF_OK || !pr.ok) continue;
        /* PnP gives the keyframe's points (its depth camera's frame) in the
         * frame's colour camera, T_ba; in its depth camera they are T_dc
         * T_ba, and the frame's pose is the keyframe's times the inverse. */
        bf_se3 T_da = bf_se3_mul(&T_dc, &pr.T_ba), T_ab = bf_se3_inverse(&T_da);
        recon__colour_pose p = {.n_inliers = pr.n_inliers, .T_wc = bf_se3_mul(&r->keyframes[i], &T_ab)};
        bf_debug("recon: frame %u: keyframe %u: %u colour matches, %u inliers, %.2f px", f->index, i, pr.n_matches,
                 pr.n_inliers, pr.rms_px);
        recon__keep_pose(best, &n, cap, &p);
    }
    features_free(frame);
    if (s != BF_OK) {
        bf_warn("recon: frame %u: no candidates from colour: %s", f->index, bf_last_error());
        return 0;
    }
    bf_debug("recon: frame %u: colour against %u keyframes: %u poses, %.1f ms", f->index, r->n_keyframes, n,
             1e3 * (bf_time_s() - t0));
    return n;
}

bf_status recon__search(recon *r, const bf_frame *f, const fusion_frame_slot *slot, double n, recon_reloc_kind skip,
                        recon_frame_result *out, bool *found)
{
    search_state st = {0};
    uint32_t budget = r->cfg.reloc.max_candidates;
    *found = false;
    /* From a candidate, ICP may move what it may from a frame's guess: the
     * candidates are spaced to leave one within a frame's motion of the
     * camera, and a pose ICP reaches further away slid there along weakly
     * constrained directions (tests/recon/test_reloc.c: 30 cm along a
     * partly mapped wall, 45% inliers at 14 mm, every candidate agreeing). */
    bf_status s = track_set_motion_scale(r->tracker, 1.0);
    /* Colour first: where it finds a pose, that pose is wherever the
     * camera went, which none of the others reaches beyond 20 degrees
     * or a keyframe's neighbourhood. Its candidates come on top of
     * max_candidates, so the depth-only search below goes on as it
     * would without them when colour finds wrong poses or none. */
    recon__colour_pose fp[FEATURE_MAX_CANDIDATES];
    uint32_t n_fp = s == BF_OK ? colour_poses(r, f, fp, r->cfg.reloc.feature_candidates) : 0;
    for (uint32_t i = 0; i < n_fp && s == BF_OK && !st.is_no_depth; i++)
        s = try_candidate(r, f, slot, &fp[i].T_wc, RECON_RELOC_FEATURES, &st, out);
    /* The primaries every time (the likeliest places), then the round
     * robin where the last frame's search stopped: at most max_candidates
     * ray-casts and ICPs per frame besides colour's, and every entry is
     * reached within n_round / (max_candidates - 2) frames. */
    for (uint32_t i = 0; i < n_primary(r) && budget > 0 && s == BF_OK && !st.is_no_depth; i++) {
        recon_reloc_kind kind = i == 0 ? RECON_RELOC_LAST : RECON_RELOC_VELOCITY;
        if (kind == skip) continue;
        bf_se3 T = i == 0 ? r->T_last : recon__velocity_pose(r, n);
        s = try_candidate(r, f, slot, &T, kind, &st, out);
        budget--;
    }
    uint32_t len = n_round(r);
    for (uint32_t k = 0; k < len && budget > 0 && s == BF_OK && !st.is_no_depth; k++) {
        bf_se3 T;
        uint32_t i = r->reloc_cursor % len;
        r->reloc_cursor = (i + 1) % len;
        recon_reloc_kind kind = round_entry(r, i, n, &T);
        /* A keyframe where the last pose is: that one was just tried. */
        if (kind == RECON_RELOC_KEYFRAME && is_near(r, &T, &r->T_last)) continue;
        s = try_candidate(r, f, slot, &T, kind, &st, out);
        budget--;
    }
    if (s != BF_OK) return s;
    if (st.has_best && !st.is_ambiguous) {
        out->track = st.best;
        out->reloc = st.best_kind;
        *found = true;
    } else if (st.has_any) {
        out->track = st.any;
    }
    return BF_OK;
}

/* Frame-to-frame where the map is thin: a camera turning fast into what the
 * map has barely seen (TUM fr1/rpy's frames 39-59: most of the view at
 * 2.5-4.5 m, 13-30% of it associating with the map's ray-cast) fails
 * against the map from every candidate, while the frame before it, one
 * interval away, sees most of the same. Its pose is then the last good
 * one, its depth the reference, and the candidates' gates decide, with the
 * motion gate of the intervals between them: a live queue on lavapipe
 * drops two or three frames between the ones the loop takes. Not after a
 * loss, a frame without depth or a gap beyond the gate's cap: the frame
 * kept is then not the camera's last view. */
bf_status recon__track_last_frame(recon *r, const bf_frame *f, const fusion_frame_slot *slot, double n,
                                  recon_frame_result *out, bool *found)
{
    *found = false;
    if (!r->has_good_depth || r->is_lost || r->depthless_since_good || n > r->cfg.reloc.max_gate_intervals)
        return BF_OK;
    bf_frame g = {.index = r->good_index, .width = r->K.width, .height = r->K.height, .t_depth_s = r->good_t_s,
                  .t_rgb_s = r->good_t_s, .depth = r->good_depth};
    track_result t;
    bf_status s = recon__set_gate(r, n); /* a search before this left it at one interval's */
    r->ref_is_map = false;
    if (s == BF_OK) s = track_set_reference_frame(r->tracker, &g, &r->T_last);
    if (s == BF_OK) s = track_frame_gpu(r->tracker, slot->depth, slot->offset, f->index, &r->T_last, &t);
    if (s != BF_OK) return s;
    out->reloc_tried++;
    out->ms_track += t.ms_gpu + t.ms_ref; /* the frame before made into a reference, then the ICP */
    bf_debug("recon: frame %u: against frame %u: %s, inliers %.1f%%, residual %.1f mm", f->index, r->good_index,
             track_outcome_name(t.outcome), 100 * t.inlier_frac, 1e3 * t.residual_m);
    if (!recon__passes(r, &t)) return BF_OK;
    out->track = t;
    out->reloc = RECON_RELOC_FRAME;
    *found = true;
    return BF_OK;
}
