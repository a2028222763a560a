/* Trajectory error: absolute trajectory error (ATE) after Horn alignment and
 * relative pose error (RPE), as the TUM RGB-D benchmark tools define them
 * (Sturm et al., "A Benchmark for the Evaluation of RGB-D SLAM Systems",
 * IROS 2012; scripts associate.py, evaluate_ate.py and evaluate_rpe.py by
 * Juergen Sturm, TUM, BSD licence). This is an independent C implementation
 * of the same rules; where a rule is a quirk of the scripts it is kept and
 * marked "TUM:" so the numbers agree with theirs. */
#include "eval/eval.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define EVAL_TUM_MAX_DT_S 0.02 /* associate.py's default --max_difference */

/* ------------------------------------------------------------ statistics */

bf_status eval_err_stats_compute(const double *v, size_t n, eval_err_stats *out)
{
    if (n == 0) return bf_fail(BF_INVALID_ARG, "error statistics of an empty set");
    double *tmp = bf_malloc(n * sizeof *tmp);
    if (!tmp) return bf_fail(BF_NO_MEMORY, "out of memory for %zu errors", n);
    double sum = 0, sum2 = 0, lo = INFINITY, hi = -INFINITY;
    for (size_t i = 0; i < n; i++) {
        tmp[i] = v[i];
        sum += v[i];
        sum2 += v[i] * v[i];
        lo = fmin(lo, v[i]);
        hi = fmax(hi, v[i]);
    }
    eval_err_stats s;
    s.mean = sum / (double)n;
    s.rmse = sqrt(sum2 / (double)n);
    /* numpy.std: population standard deviation, computed about the mean. */
    double var = 0;
    for (size_t i = 0; i < n; i++) var += (v[i] - s.mean) * (v[i] - s.mean);
    s.std = sqrt(var / (double)n);
    /* numpy.median: the mean of the two middle values for even n, which is
     * the linearly interpolated 50th percentile. */
    s.median = bf_percentile_inplace(tmp, n, 50.0);
    s.min = lo;
    s.max = hi;
    free(tmp);
    *out = s;
    return BF_OK;
}

/* ------------------------------------------------------------ Horn */

bf_status eval_horn_align(const bf_vec3 *model, const bf_vec3 *data, size_t n, bf_se3 *T_data_model)
{
    if (n == 0) return bf_fail(BF_INVALID_ARG, "Horn alignment of an empty point set");
    bf_vec3 cm = {0, 0, 0}, cd = {0, 0, 0};
    for (size_t i = 0; i < n; i++) {
        cm = bf_v3_add(cm, model[i]);
        cd = bf_v3_add(cd, data[i]);
    }
    cm = bf_v3_scale(cm, 1.0 / (double)n);
    cd = bf_v3_scale(cd, 1.0 / (double)n);
    /* Cross-covariance S[a][b] = sum over points of model_a * data_b, both
     * centred (Horn 1987, "Closed-form solution of absolute orientation using
     * unit quaternions", JOSA A 4(4), section 4). */
    double S[3][3] = {{0}};
    for (size_t i = 0; i < n; i++) {
        bf_vec3 m = bf_v3_sub(model[i], cm), d = bf_v3_sub(data[i], cd);
        double ma[3] = {m.x, m.y, m.z}, da[3] = {d.x, d.y, d.z};
        for (int a = 0; a < 3; a++)
            for (int b = 0; b < 3; b++) S[a][b] += ma[a] * da[b];
    }
    double sxx = S[0][0], sxy = S[0][1], sxz = S[0][2];
    double syx = S[1][0], syy = S[1][1], syz = S[1][2];
    double szx = S[2][0], szy = S[2][1], szz = S[2][2];
    /* The unit quaternion (w, x, y, z) maximising q^T N q is the rotation
     * taking model to data. A quaternion is always a proper rotation, so
     * unlike a bare SVD solution this can never return a reflection; for
     * planar or collinear sets the top eigenvalue repeats and any vector of
     * its eigenspace is an optimal rotation. */
    double N[16] = {
        sxx + syy + szz, syz - szy,        szx - sxz,        sxy - syx,
        syz - szy,       sxx - syy - szz,  sxy + syx,        szx + sxz,
        szx - sxz,       sxy + syx,        -sxx + syy - szz, syz + szy,
        sxy - syx,       szx + sxz,        syz + szy,        -sxx - syy + szz,
    };
    double norm2 = 0;
    for (int k = 0; k < 16; k++) {
        if (!isfinite(N[k])) return bf_fail(BF_NUMERIC, "Horn alignment: non-finite coordinates");
        norm2 += N[k] * N[k];
    }
    bf_quat q = bf_quat_identity();
    if (norm2 > 0) {
        /* Scale for the Jacobi threshold; eigenvectors are unchanged. */
        double inv = 1.0 / sqrt(norm2);
        for (int k = 0; k < 16; k++) N[k] *= inv;
        double w[4], V[16];
        bf_sym_eigen(4, N, w, V);
        /* Eigenvalues ascend: the last column belongs to the largest. */
        q = bf_quat_normalize((bf_quat){V[0 * 4 + 3], V[1 * 4 + 3], V[2 * 4 + 3], V[3 * 4 + 3]});
    }
    /* All points coincide (norm2 == 0): every rotation is optimal, keep
     * the identity. */
    bf_se3 T = bf_se3_from_qt(q, bf_v3(0, 0, 0));
    T.t = bf_v3_sub(cd, bf_se3_rotate(&T, cm));
    *T_data_model = T;
    return BF_OK;
}

/* ------------------------------------------------------------ association */

static bf_status check_traj(const bf_traj *t, const char *what)
{
    if (!t || t->n == 0) return bf_fail(BF_INVALID_ARG, "%s trajectory is empty", what);
    for (size_t i = 1; i < t->n; i++)
        if (!(t->t_s[i] > t->t_s[i - 1]))
            return bf_fail(BF_INVALID_ARG, "%s trajectory: timestamps not increasing at pose %zu", what, i);
    return BF_OK;
}

bf_status eval_associate(const bf_traj *gt, const bf_traj *est, double max_dt_s,
                         eval_match **out, size_t *n_out)
{
    bf_status s;
    if ((s = check_traj(gt, "ground-truth")) || (s = check_traj(est, "estimated"))) return s;
    if (max_dt_s <= 0) max_dt_s = EVAL_TUM_MAX_DT_S;
    /* TUM associate.py (bf_associate_stamps); matches are returned in
     * the order of the first stamp, as the script returns them. */
    size_t *est_of = bf_malloc(gt->n * sizeof *est_of);
    eval_match *m = bf_malloc(gt->n * sizeof *m);
    if (!est_of || !m) {
        free(est_of);
        free(m);
        return bf_fail(BF_NO_MEMORY, "out of memory associating trajectories");
    }
    if ((s = bf_associate_stamps(gt->t_s, gt->n, est->t_s, est->n, max_dt_s, est_of))) {
        free(est_of);
        free(m);
        return s;
    }
    size_t n = 0;
    for (size_t i = 0; i < gt->n; i++)
        if (est_of[i] != SIZE_MAX) m[n++] = (eval_match){i, est_of[i]};
    free(est_of);
    *out = m;
    *n_out = n;
    return BF_OK;
}

/* ------------------------------------------------------------ ATE */

bf_status eval_ate(const bf_traj *gt, const bf_traj *est, double max_dt_s, eval_ate_result *out)
{
    eval_match *m;
    size_t n;
    bf_status s = eval_associate(gt, est, max_dt_s, &m, &n);
    if (s != BF_OK) return s;
    if (n < 2) {
        free(m);
        return bf_fail(BF_FORMAT, "ATE: only %zu pose pair%s timestamps within %g s; "
                                  "are these the same sequence?",
                       n, n == 1 ? " has" : "s have", max_dt_s > 0 ? max_dt_s : EVAL_TUM_MAX_DT_S);
    }
    bf_vec3 *p_est = bf_malloc(n * sizeof *p_est), *p_gt = bf_malloc(n * sizeof *p_gt);
    double *err = bf_malloc(n * sizeof *err);
    if (!p_est || !p_gt || !err) {
        s = bf_fail(BF_NO_MEMORY, "out of memory for %zu pose pairs", n);
        goto done;
    }
    for (size_t k = 0; k < n; k++) {
        p_gt[k] = gt->T_wc[m[k].i_gt].t;
        p_est[k] = est->T_wc[m[k].i_est].t;
    }
    /* TUM evaluate_ate.py: only positions are aligned and compared. */
    bf_se3 T_gt_est;
    s = eval_horn_align(p_est, p_gt, n, &T_gt_est);
    if (s != BF_OK) goto done;
    for (size_t k = 0; k < n; k++) err[k] = bf_v3_norm(bf_v3_sub(bf_se3_apply(&T_gt_est, p_est[k]), p_gt[k]));
    eval_ate_result r = {.n_matched = n, .T_gt_est = T_gt_est};
    s = eval_err_stats_compute(err, n, &r.trans);
    if (s == BF_OK) *out = r;
done:
    free(m);
    free(p_est);
    free(p_gt);
    free(err);
    return s;
}

/* ------------------------------------------------------------ RPE */

/* TUM evaluate_rpe.py's find_closest_index: a binary search that keeps the
 * closest element among those it visits (which include both neighbours of t,
 * so it is the true nearest; on an exact tie the first visited wins). */
static size_t tum_closest_index(const double *L, size_t n, double t)
{
    size_t lo = 0, hi = n, best = 0;
    double diff = fabs(L[0] - t);
    while (lo < hi) {
        size_t mid = (lo + hi) / 2;
        double d = fabs(L[mid] - t);
        if (d < diff) {
            diff = d;
            best = mid;
        }
        if (t == L[mid]) return mid;
        if (L[mid] > t)
            hi = mid;
        else
            lo = mid + 1;
    }
    return best;
}

bf_status eval_rpe(const bf_traj *gt, const bf_traj *est, double max_dt_s, bool per_frame,
                   double delta_s, eval_rpe_result *out)
{
    bf_status s;
    if ((s = check_traj(gt, "ground-truth")) || (s = check_traj(est, "estimated"))) return s;
    if (!per_frame && !(delta_s > 0 && isfinite(delta_s)))
        return bf_fail(BF_INVALID_ARG, "RPE: delta must be a positive number of seconds (got %g)", delta_s);
    if (gt->n < 2 || est->n < 2)
        return bf_fail(BF_FORMAT, "RPE: needs at least two poses in each trajectory");
    size_t n = est->n;
    double *index = bf_malloc(n * sizeof *index);
    double *gap = bf_malloc((gt->n - 1) * sizeof *gap);
    double *e_t = bf_malloc(n * sizeof *e_t), *e_r = bf_malloc(n * sizeof *e_r);
    if (!index || !gap || !e_t || !e_r) {
        s = bf_fail(BF_NO_MEMORY, "out of memory for RPE over %zu poses", n);
        goto done;
    }
    /* TUM: the gt stamp matched to an est stamp may be at most twice the
     * median gt sampling interval away (a caller's max_dt_s overrides). */
    double max_dt = max_dt_s;
    if (!(max_dt > 0)) {
        for (size_t i = 0; i + 1 < gt->n; i++) gap[i] = gt->t_s[i + 1] - gt->t_s[i];
        max_dt = 2 * bf_percentile_inplace(gap, gt->n - 1, 50.0);
    }
    /* The pairs: TUM's "fixed delta" mode, unit "s" (stamps) or "f" (frame
     * numbers, delta 1). */
    double delta = per_frame ? 1.0 : delta_s;
    for (size_t i = 0; i < n; i++) index[i] = per_frame ? (double)i : est->t_s[i];
    size_t n_pairs = 0, n_candidates = 0; /* pairs with ground truth near both ends; pairs at all */
    for (size_t i = 0; i < n; i++) {
        size_t j = tum_closest_index(index, n, index[i] + delta);
        /* TUM: a pair ending at the last pose is dropped (the script's
         * guard against running past the end drops the last real pair too). */
        if (j == n - 1) continue;
        n_candidates++;
        double te0 = est->t_s[i], te1 = est->t_s[j];
        size_t g0 = tum_closest_index(gt->t_s, gt->n, te0);
        size_t g1 = tum_closest_index(gt->t_s, gt->n, te1);
        if (fabs(gt->t_s[g0] - te0) > max_dt || fabs(gt->t_s[g1] - te1) > max_dt) continue;
        /* TUM: ominus(a, b) = a^-1 b, and
         * error = ominus(ominus(est_j, est_i), ominus(gt_j, gt_i))
         *       = (est_j^-1 est_i)^-1 (gt_j^-1 gt_i). */
        bf_se3 inv_e1 = bf_se3_inverse(&est->T_wc[j]);
        bf_se3 inv_g1 = bf_se3_inverse(&gt->T_wc[g1]);
        bf_se3 rel_e = bf_se3_mul(&inv_e1, &est->T_wc[i]);
        bf_se3 rel_g = bf_se3_mul(&inv_g1, &gt->T_wc[g0]);
        bf_se3 inv_rel_e = bf_se3_inverse(&rel_e);
        bf_se3 err = bf_se3_mul(&inv_rel_e, &rel_g);
        e_t[n_pairs] = bf_v3_norm(err.t);
        e_r[n_pairs] = bf_se3_angle(&err) * 180.0 / M_PI;
        n_pairs++;
    }
    if (n_candidates < 2 && !per_frame) {
        /* Too short whatever the ground truth (TUM drops a pair that ends at the last pose). */
        s = bf_fail(BF_FORMAT, "RPE: the trajectory spans %.3f s: too short for two pairs %g s apart that do "
                    "not end at its last pose (TUM's rule drops a pair ending there)",
                    est->t_s[n - 1] - est->t_s[0], delta);
        goto done;
    }
    if (n_pairs < 2) {
        s = bf_fail(BF_FORMAT, "RPE: only %zu pose pair%s %s apart with ground truth within %g s", n_pairs,
                    n_pairs == 1 ? "" : "s", per_frame ? "one frame" : "delta", max_dt);
        goto done;
    }
    eval_rpe_result r = {.n_pairs = n_pairs, .max_dt_s = max_dt};
    if (!(s = eval_err_stats_compute(e_t, n_pairs, &r.trans)) &&
        !(s = eval_err_stats_compute(e_r, n_pairs, &r.rot)))
        *out = r;
done:
    free(index);
    free(gap);
    free(e_t);
    free(e_r);
    return s;
}
