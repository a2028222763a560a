/* eval: trajectory error (association, Horn alignment, ATE, RPE). */
#include "eval/eval.h"
#include "replay/replay.h"
#include "test.h"

static double det3(const double R[3][3])
{
    return R[0][0] * (R[1][1] * R[2][2] - R[1][2] * R[2][1]) - R[0][1] * (R[1][0] * R[2][2] - R[1][2] * R[2][0]) +
           R[0][2] * (R[1][0] * R[2][1] - R[1][1] * R[2][0]);
}

static double max_abs_diff_se3(const bf_se3 *A, const bf_se3 *B)
{
    double m = 0;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) m = fmax(m, fabs(A->R[i][j] - B->R[i][j]));
    m = fmax(m, fabs(A->t.x - B->t.x));
    m = fmax(m, fabs(A->t.y - B->t.y));
    return fmax(m, fabs(A->t.z - B->t.z));
}

/* A smooth, non-planar camera path with a turning camera: 30 Hz. */
static bf_se3 path_pose(double t)
{
    bf_quat q = bf_quat_from_axis_angle(bf_v3(0.2, 1, 0.1), 0.3 * t);
    return bf_se3_from_qt(q, bf_v3(cos(t), sin(0.7 * t), 0.2 * t + 0.1 * sin(2 * t)));
}

/* ------------------------------------------------------------ real data */

/* Expected values from tests/eval/tum_oracle.py, an independent numpy
 * re-implementation of TUM's associate.py (|dt| < 0.02 s), evaluate_ate.py
 * (Horn via SVD, U diag(1,1,det) V^T) and evaluate_rpe.py (--fixed_delta,
 * all pairs), run with Debian's python3-numpy 1.24.2 as
 *   python3 tests/eval/tum_oracle.py groundtruth.txt rgbdslam_estimate.txt
 * The oracle uses the SVD, traj.c the quaternion eigenvector: both are
 * exact up to rounding, so 1e-9 (relative) is far above the double-precision
 * disagreement (~1e-13) and far below any real change of rule. */
/* fr1_xyz's ground truth and RGBD-SLAM's estimate of it (shared data). */
static bf_status read_fr1_xyz(const char *dir, bf_traj *gt, bf_traj *est)
{
    char p_gt[4200], p_est[4200];
    snprintf(p_gt, sizeof p_gt, "%s/groundtruth.txt", dir);
    snprintf(p_est, sizeof p_est, "%s/rgbdslam_estimate.txt", dir);
    bf_status s = replay_traj_read_tum(p_gt, gt);
    return s == BF_OK ? replay_traj_read_tum(p_est, est) : s;
}

BF_TEST(ate_and_rpe_of_rgbdslam_on_fr1_xyz_match_the_tum_oracle)
{
    const char *dir = bf_test_data("tum/fr1_xyz");
    if (!dir) BF_SKIP("shared data absent");
    bf_traj gt = {0}, est = {0};
    CHECK_OK(read_fr1_xyz(dir, &gt, &est));

    eval_ate_result ate;
    eval_rpe_result rs, rf;
    bf_status s1 = eval_ate(&gt, &est, 0.02, &ate);
    bf_status s2 = eval_rpe(&gt, &est, 0, false, 1.0, &rs);
    bf_status s3 = eval_rpe(&gt, &est, 0, true, 0, &rf);
    bf_traj_free(&gt);
    bf_traj_free(&est);
    CHECK_OK(s1);
    CHECK_OK(s2);
    CHECK_OK(s3);
#define REL(x) (1e-9 * fabs(x))
    CHECK_EQ_INT(ate.n_matched, 786);
    CHECK_NEAR(ate.trans.rmse, 0.0134734677699, REL(0.0134734677699) + 1e-13);
    CHECK_NEAR(ate.trans.mean, 0.012029476392, REL(0.012029476392) + 1e-13);
    CHECK_NEAR(ate.trans.median, 0.0111757511333, REL(0.0111757511333) + 1e-13);
    CHECK_NEAR(ate.trans.std, 0.00606844555718, REL(0.00606844555718) + 1e-13);
    CHECK_NEAR(ate.trans.min, 0.000938702720662, 1e-12);
    CHECK_NEAR(ate.trans.max, 0.0347272016811, REL(0.0347272016811) + 1e-13);
    /* The alignment itself (oracle's rot and trans). */
    const double R[3][3] = {{0.9995289339037357, -0.025556512467789262, -0.016993379880015647},
                            {0.025922282215500303, 0.9994291876936816, 0.021664119430254758},
                            {0.01643002051133091, -0.022094421387130553, 0.9996208736163751}};
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) CHECK_NEAR(ate.T_gt_est.R[i][j], R[i][j], 1e-9);
    CHECK_NEAR(ate.T_gt_est.t.x, 0.05514887223796139, 1e-9);
    CHECK_NEAR(ate.T_gt_est.t.y, -0.06462044550667712, 1e-9);
    CHECK_NEAR(ate.T_gt_est.t.z, -0.0013055199633258407, 1e-9);

    CHECK_EQ_INT(rs.n_pairs, 753);
    CHECK_NEAR(rs.trans.rmse, 0.0212174440791, REL(0.0212174440791) + 1e-13);
    CHECK_NEAR(rs.trans.mean, 0.0195236639524, REL(0.0195236639524) + 1e-13);
    CHECK_NEAR(rs.trans.median, 0.0193085925867, REL(0.0193085925867) + 1e-13);
    CHECK_NEAR(rs.trans.std, 0.00830701385115, REL(0.00830701385115) + 1e-13);
    CHECK_NEAR(rs.trans.max, 0.048152004435, REL(0.048152004435) + 1e-13);
    CHECK_NEAR(rs.rot.rmse, 0.934480459417, REL(0.934480459417) + 1e-11);
    CHECK_NEAR(rs.rot.mean, 0.84147232844, REL(0.84147232844) + 1e-11);
    CHECK_NEAR(rs.rot.median, 0.801085322109, REL(0.801085322109) + 1e-11);
    CHECK_NEAR(rs.rot.max, 2.29598544512, REL(2.29598544512) + 1e-11);

    CHECK_EQ_INT(rf.n_pairs, 783);
    CHECK_NEAR(rf.trans.rmse, 0.00576344630998, REL(0.00576344630998) + 1e-13);
    CHECK_NEAR(rf.trans.mean, 0.00481646152778, REL(0.00481646152778) + 1e-13);
    CHECK_NEAR(rf.trans.median, 0.00412328299051, REL(0.00412328299051) + 1e-13);
    CHECK_NEAR(rf.rot.rmse, 0.352968960967, REL(0.352968960967) + 1e-11);
    CHECK_NEAR(rf.rot.mean, 0.300080291019, REL(0.300080291019) + 1e-11);
    CHECK_NEAR(rf.rot.median, 0.262954972396, REL(0.262954972396) + 1e-11);
#undef REL
}

/* ------------------------------------------------------------ ATE */

BF_TEST(ate_of_a_rigidly_moved_copy_is_zero_and_recovers_the_inverse)
{
    bf_traj gt = {0}, est = {0};
    bf_se3 T = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(1, -2, 0.5), 2.5), bf_v3(3, -1, 7));
    for (int i = 0; i < 300; i++) {
        double t = i / 30.0;
        bf_se3 P = path_pose(t), Q = bf_se3_mul(&T, &P);
        CHECK_OK(bf_traj_push(&gt, 1000 + t, &P));
        /* est stamps 3 ms late: still associated one to one. */
        CHECK_OK(bf_traj_push(&est, 1000 + t + 0.003, &Q));
    }
    eval_ate_result r;
    CHECK_OK(eval_ate(&gt, &est, 0.02, &r));
    bf_traj_free(&gt);
    bf_traj_free(&est);
    CHECK_EQ_INT(r.n_matched, 300);
    /* Coordinates of size ~10 m: rounding leaves ~1e-15 m per point. */
    CHECK_LE(r.trans.rmse, 1e-12);
    bf_se3 Tinv = bf_se3_inverse(&T);
    CHECK_LE(max_abs_diff_se3(&r.T_gt_est, &Tinv), 1e-12);
}

/* Points on a circle in z = 0 at angles 2 pi i / N, est displaced along z
 * by e_i = a_(i mod 4) (-1)^(i div 4) with N / 4 even. Each residue class
 * r sums (-1)^m e^{2 pi i (4m + r) / N} over m, a full geometric series of
 * ratio -e^{8 pi i / N} != 1 whose N/4-th power is 1: zero. So the
 * displacements have zero mean and zero cross-covariance with the circle,
 * the optimal alignment is the identity (uniquely: the circle fixes the
 * rotation) and each error is exactly |e_i|. */
BF_TEST(ate_of_known_noise_gives_its_rmse)
{
    bf_traj gt = {0}, est = {0};
    const int N = 400;
    double sum2 = 0, sum = 0;
    for (int i = 0; i < N; i++) {
        double a = 2 * M_PI * i / N;
        double sigma = 0.001 * (1 + (i % 4)); /* 1, 2, 3, 4 mm */
        double e = ((i / 4) % 2 ? -1 : 1) * sigma;
        sum2 += e * e;
        sum += sigma;
        bf_se3 P = bf_se3_from_qt(bf_quat_identity(), bf_v3(2 * cos(a), 2 * sin(a), 0));
        bf_se3 Q = P;
        Q.t.z += e;
        CHECK_OK(bf_traj_push(&gt, i * 0.01, &P));
        CHECK_OK(bf_traj_push(&est, i * 0.01, &Q));
    }
    eval_ate_result r;
    CHECK_OK(eval_ate(&gt, &est, 0.005, &r));
    bf_traj_free(&gt);
    bf_traj_free(&est);
    CHECK_EQ_INT(r.n_matched, N);
    CHECK_NEAR(r.trans.rmse, sqrt(sum2 / N), 1e-12);
    CHECK_NEAR(r.trans.mean, sum / N, 1e-12);
    CHECK_NEAR(r.trans.median, 0.0025, 1e-12); /* 1,2 | 3,4 mm: middle two are 2 and 3 */
    CHECK_NEAR(r.trans.min, 0.001, 1e-12);
    CHECK_NEAR(r.trans.max, 0.004, 1e-12);
    CHECK_NEAR(r.trans.std, sqrt(sum2 / N - (sum / N) * (sum / N)), 1e-12);
    bf_se3 I = bf_se3_identity();
    CHECK_LE(max_abs_diff_se3(&r.T_gt_est, &I), 1e-12);
}

BF_TEST(horn_never_returns_a_reflection)
{
    /* A mirrored point set: the best orthogonal map is the mirror (det -1);
     * an SVD solution without the det correction returns it. */
    bf_vec3 a[50], b[50];
    unsigned s = 7;
    for (int i = 0; i < 50; i++) {
        s = s * 1103515245u + 12345u;
        double x = (s >> 8) % 1000 / 1000.0;
        s = s * 1103515245u + 12345u;
        double y = (s >> 8) % 1000 / 1000.0;
        s = s * 1103515245u + 12345u;
        double z = (s >> 8) % 1000 / 1000.0;
        a[i] = bf_v3(x, y, z);
        b[i] = bf_v3(x, y, -z);
    }
    bf_se3 T;
    CHECK_OK(eval_horn_align(a, b, 50, &T));
    CHECK_NEAR(det3(T.R), 1.0, 1e-12);

    /* Collinear points along a line: the rotation about the line is free,
     * any choice must still be proper and map the line onto its image. */
    bf_se3 M = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0.3, 0.2, 1), 1.2), bf_v3(1, 2, 3));
    for (int i = 0; i < 50; i++) {
        a[i] = bf_v3(0.1 * i, 0, 0);
        b[i] = bf_se3_apply(&M, a[i]);
    }
    CHECK_OK(eval_horn_align(a, b, 50, &T));
    CHECK_NEAR(det3(T.R), 1.0, 1e-12);
    for (int i = 0; i < 50; i++) CHECK_LE(bf_v3_norm(bf_v3_sub(bf_se3_apply(&T, a[i]), b[i])), 1e-12);

    /* A collinear trajectory mirrored through a plane containing the line
     * is still fitted exactly by a proper rotation. */
    for (int i = 0; i < 50; i++) b[i] = bf_v3(0.1 * i, 0, 0);
    CHECK_OK(eval_horn_align(a, b, 50, &T));
    CHECK_NEAR(det3(T.R), 1.0, 1e-12);

    /* All points at one place: identity rotation, translation between them. */
    for (int i = 0; i < 5; i++) {
        a[i] = bf_v3(1, 1, 1);
        b[i] = bf_v3(2, 1, 1);
    }
    CHECK_OK(eval_horn_align(a, b, 5, &T));
    CHECK_NEAR(T.R[0][0] + T.R[1][1] + T.R[2][2], 3, 1e-15);
    CHECK_NEAR(T.t.x, 1, 1e-15);
    CHECK_STATUS(eval_horn_align(a, b, 0, &T), BF_INVALID_ARG);
}

BF_TEST(ate_on_a_straight_line_trajectory_is_zero_without_reflection)
{
    bf_traj gt = {0}, est = {0};
    bf_se3 T = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0, 1, 0), 0.5), bf_v3(0, 0, 1));
    for (int i = 0; i < 100; i++) {
        bf_se3 P = bf_se3_from_qt(bf_quat_identity(), bf_v3(0.01 * i, 0, 0)), Q = bf_se3_mul(&T, &P);
        CHECK_OK(bf_traj_push(&gt, i * 0.1, &P));
        CHECK_OK(bf_traj_push(&est, i * 0.1, &Q));
    }
    eval_ate_result r;
    CHECK_OK(eval_ate(&gt, &est, 0, &r));
    bf_traj_free(&gt);
    bf_traj_free(&est);
    CHECK_LE(r.trans.rmse, 1e-13);
    CHECK_NEAR(det3(r.T_gt_est.R), 1.0, 1e-12);
}

BF_TEST(association_is_greedy_one_to_one_and_strict)
{
    bf_traj gt = {0}, est = {0};
    bf_se3 I = bf_se3_identity();
    /* gt 0.00 and 1.00; est 0.005 and 0.008 both nearest to gt 0.00: only
     * the closer is taken. est 1.02 is exactly 0.02 away: not a candidate
     * (associate.py uses a strict <). */
    double tg[] = {0.0, 1.0}, te[] = {0.005, 0.008, 1.02};
    for (int i = 0; i < 2; i++) CHECK_OK(bf_traj_push(&gt, tg[i], &I));
    for (int i = 0; i < 3; i++) CHECK_OK(bf_traj_push(&est, te[i], &I));
    eval_match *m;
    size_t n;
    CHECK_OK(eval_associate(&gt, &est, 0.0200001, &m, &n));
    CHECK_EQ_INT(n, 2);
    CHECK_EQ_INT(m[0].i_est, 0);
    CHECK_EQ_INT(m[1].i_est, 2);
    free(m);
    CHECK_OK(eval_associate(&gt, &est, 0.02, &m, &n));
    CHECK_EQ_INT(n, 1);
    free(m);
    /* Fewer than two pairs: ATE refuses, naming the reason. */
    eval_ate_result r;
    CHECK_STATUS(eval_ate(&gt, &est, 0.02, &r), BF_FORMAT);
    CHECK_ERROR_MENTIONS("pose pair");
    bf_traj_free(&gt);
    bf_traj_free(&est);
}

/* ------------------------------------------------------------ RPE */

BF_TEST(rpe_of_a_constant_drift_is_the_drift_per_delta)
{
    /* gt moves along x at 1 m/s, est at 1.02 m/s, neither turns: for poses
     * dt apart the error is a pure translation of 0.02 dt m. A second pair
     * checks rotation drift: gt static, est turning 3 deg/s about z in
     * place, so the error is a pure rotation of 3 dt deg. 10 s at 30 Hz. */
    bf_traj gt = {0}, est = {0}, spin = {0};
    for (int i = 0; i <= 300; i++) {
        double t = i / 30.0;
        bf_se3 G = bf_se3_from_qt(bf_quat_identity(), bf_v3(t, 0, 0));
        bf_se3 E = bf_se3_from_qt(bf_quat_identity(), bf_v3(1.02 * t, 0, 0));
        bf_se3 S = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0, 0, 1), 3 * M_PI / 180 * t), bf_v3(0, 0, 0));
        CHECK_OK(bf_traj_push(&gt, 50 + t, &G));
        CHECK_OK(bf_traj_push(&est, 50 + t, &E));
        CHECK_OK(bf_traj_push(&spin, 50 + t, &S));
    }
    eval_rpe_result r;
    CHECK_OK(eval_rpe(&gt, &est, 0, false, 1.0, &r));
    /* TUM's pair rule: j = pose nearest t_i + 1 s, dropped when j is the
     * last pose, so i = 0..269 (j = i + 30 <= 299): 270 pairs. */
    CHECK_EQ_INT(r.n_pairs, 270);
    CHECK_NEAR(r.max_dt_s, 2 / 30.0, 1e-9); /* TUM's default: twice the median ground-truth interval */
    CHECK_NEAR(r.trans.mean, 0.02, 1e-12);
    CHECK_NEAR(r.trans.max, 0.02, 1e-12);
    CHECK_NEAR(r.rot.max, 0, 1e-12);
    CHECK_OK(eval_rpe(&gt, &est, 0, true, 0, &r));
    /* Per frame: j = i + 1, and the pair ending at the last pose is dropped:
     * 299 pairs of 1/30 s, error 0.02/30 m each. */
    CHECK_EQ_INT(r.n_pairs, 299);
    CHECK_NEAR(r.trans.median, 0.02 / 30, 1e-12);
    CHECK_OK(eval_rpe(&gt, &est, 0.01, true, 0, &r));
    CHECK(r.max_dt_s == 0.01); /* the caller's */

    /* Rotation drift over 2 s: 6 deg; pairs i = 0..239 (j = i + 60 < 300). */
    bf_traj still = {0};
    for (size_t i = 0; i < spin.n; i++) {
        bf_se3 I = bf_se3_identity();
        CHECK_OK(bf_traj_push(&still, spin.t_s[i], &I));
    }
    CHECK_OK(eval_rpe(&still, &spin, 0, false, 2.0, &r));
    CHECK_EQ_INT(r.n_pairs, 240);
    CHECK_NEAR(r.rot.mean, 6.0, 1e-9);
    CHECK_NEAR(r.rot.std, 0, 1e-9);
    CHECK_NEAR(r.trans.max, 0, 1e-12);
    bf_traj_free(&gt);
    bf_traj_free(&est);
    bf_traj_free(&spin);
    bf_traj_free(&still);
}

BF_TEST(rpe_skips_pairs_without_nearby_ground_truth)
{
    /* Ground truth with a 2 s hole: estimated poses inside the hole have no
     * gt within twice the median interval and their pairs are skipped. */
    bf_traj gt = {0}, est = {0};
    bf_se3 I = bf_se3_identity();
    for (int i = 0; i <= 300; i++) {
        double t = i / 30.0;
        if (t < 4 || t > 6) CHECK_OK(bf_traj_push(&gt, t, &I));
        CHECK_OK(bf_traj_push(&est, t, &I));
    }
    eval_rpe_result r;
    CHECK_OK(eval_rpe(&gt, &est, 0, true, 0, &r));
    /* 299 pairs without the hole; the pairs touching est poses with t in
     * (4 + 2/30, 6 - 2/30) exclusive are lost. */
    CHECK(r.n_pairs < 299 && r.n_pairs > 230);
    CHECK_NEAR(r.trans.max, 0, 0);
    CHECK_STATUS(eval_rpe(&gt, &est, 0, false, -1, &r), BF_INVALID_ARG);
    bf_traj_free(&gt);
    bf_traj_free(&est);
}

BF_TEST(rpe_of_a_trajectory_shorter_than_delta_says_so)
{
    /* 0.63 s of poses, pairs 1 s apart: none exist, and the message names
     * the span (not a timing mismatch with the ground truth). */
    bf_traj gt = {0}, est = {0};
    bf_se3 I = bf_se3_identity();
    for (int i = 0; i < 20; i++) {
        CHECK_OK(bf_traj_push(&gt, i / 30.0, &I));
        CHECK_OK(bf_traj_push(&est, i / 30.0, &I));
    }
    eval_rpe_result r;
    CHECK_STATUS(eval_rpe(&gt, &est, 0, false, 1.0, &r), BF_FORMAT);
    CHECK_ERROR_MENTIONS("the trajectory spans 0.633 s: too short for two pairs 1 s apart");
    /* Per frame, the same poses give pairs. */
    CHECK_OK(eval_rpe(&gt, &est, 0, true, 0, &r));
    CHECK(r.n_pairs == 18);
    /* 1.5 s long enough, but the ground truth 10 s away: its timing is named. */
    bf_traj_free(&gt);
    bf_traj_free(&est);
    for (int i = 0; i < 45; i++) {
        CHECK_OK(bf_traj_push(&gt, 10 + i / 30.0, &I));
        CHECK_OK(bf_traj_push(&est, i / 30.0, &I));
    }
    CHECK_STATUS(eval_rpe(&gt, &est, 0, false, 1.0, &r), BF_FORMAT);
    CHECK_ERROR_MENTIONS("only 0 pose pairs delta apart with ground truth within");
    bf_traj_free(&gt);
    bf_traj_free(&est);
}

BF_TEST(error_stats_follow_numpy)
{
    const double v[] = {4, 1, 3, 2};
    eval_err_stats s;
    CHECK_OK(eval_err_stats_compute(v, 4, &s));
    CHECK_NEAR(s.mean, 2.5, 0);
    CHECK_NEAR(s.median, 2.5, 0);
    CHECK_NEAR(s.rmse, sqrt(30.0 / 4), 1e-15);
    CHECK_NEAR(s.std, sqrt(1.25), 1e-15);
    CHECK_NEAR(s.min, 1, 0);
    CHECK_NEAR(s.max, 4, 0);
    CHECK_STATUS(eval_err_stats_compute(v, 0, &s), BF_INVALID_ARG);
}

/* The sliding-window candidate search of eval_associate against the
 * literal n x m loop of associate.py, on jittered stamps of two rates. */
BF_TEST(association_matches_the_brute_force_greedy_rule)
{
    unsigned st = 99;
    for (int round = 0; round < 20; round++) {
        bf_traj gt = {0}, est = {0};
        bf_se3 I = bf_se3_identity();
        double t = 0;
        for (int i = 0; i < 200; i++) {
            st = st * 1103515245u + 12345u;
            t += 0.005 + 0.01 * ((st >> 8) % 1000) / 1000.0;
            CHECK_OK(bf_traj_push(&gt, t, &I));
        }
        t = 0.003 * round;
        for (int i = 0; i < 120; i++) {
            st = st * 1103515245u + 12345u;
            t += 0.01 + 0.03 * ((st >> 8) % 1000) / 1000.0;
            CHECK_OK(bf_traj_push(&est, t, &I));
        }
        double max_dt = 0.004 + 0.002 * round;
        /* Brute force: repeatedly take the globally closest free pair. */
        bool *ua = calloc(gt.n, 1), *ub = calloc(est.n, 1);
        size_t n_bf = 0;
        size_t *pair_of_gt = malloc(gt.n * sizeof *pair_of_gt);
        for (size_t a = 0; a < gt.n; a++) pair_of_gt[a] = SIZE_MAX;
        for (;;) {
            double best = INFINITY;
            size_t ba = 0, bb = 0;
            for (size_t a = 0; a < gt.n; a++)
                for (size_t b = 0; b < est.n; b++) {
                    double dt = fabs(gt.t_s[a] - est.t_s[b]);
                    if (ua[a] || ub[b] || !(dt < max_dt) || !(dt < best)) continue;
                    best = dt;
                    ba = a;
                    bb = b;
                }
            if (best == INFINITY) break;
            ua[ba] = ub[bb] = true;
            pair_of_gt[ba] = bb;
            n_bf++;
        }
        eval_match *m;
        size_t n;
        CHECK_OK(eval_associate(&gt, &est, max_dt, &m, &n));
        bool same = n == n_bf;
        for (size_t k = 0; same && k < n; k++) {
            same = pair_of_gt[m[k].i_gt] == m[k].i_est;
            if (k > 0) same = same && m[k].i_gt > m[k - 1].i_gt;
        }
        free(m);
        free(ua);
        free(ub);
        free(pair_of_gt);
        bf_traj_free(&gt);
        bf_traj_free(&est);
        CHECK(same);
        CHECK(n_bf > 0);
    }
}

typedef struct traj_pair {
    bf_traj gt, est;
} traj_pair;

static bf_status run_ate_rpe(void *arg)
{
    const traj_pair *p = arg;
    eval_ate_result ate;
    eval_rpe_result rpe;
    bf_status s = eval_ate(&p->gt, &p->est, 0.02, &ate);
    if (s == BF_OK) s = eval_rpe(&p->gt, &p->est, 0, false, 1.0, &rpe);
    if (s == BF_OK) s = eval_rpe(&p->gt, &p->est, 0, true, 0, &rpe);
    return s;
}

/* Every host allocation of ATE and RPE fails in turn: each is a clean
 * BF_NO_MEMORY with a message, nothing leaks (ASan). */
BF_TEST(ate_and_rpe_fail_cleanly_at_every_allocation)
{
    const char *dir = bf_test_data("tum/fr1_xyz");
    if (!dir) BF_SKIP("shared data absent");
    traj_pair p = {{0}, {0}};
    bf_status s = read_fr1_xyz(dir, &p.gt, &p.est);
    int n = s == BF_OK ? bf_test_fault_walk(run_ate_rpe, &p) : -1;
    bf_traj_free(&p.gt);
    bf_traj_free(&p.est);
    CHECK_OK(s);
    CHECK(n >= 3);
    fprintf(stderr, "  ATE and RPE: %d allocations failed in turn\n", n);
}
