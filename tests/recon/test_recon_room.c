/* Issue 4's accuracy check at test size: a noisy room tracked over 40
 * frames (320x240) within 1.5 cm, and the same run 10 km from the origin
 * with the same accuracy. (bench/ and docs/bench_replay.md have the
 * 600-frame 640x480 run.) Validation is on. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "eval/eval.h"
#include "gpu_fixture.h"
#include "recon/recon.h"
#include "replay/replay.h"
#include "stream/stream.h"

#define W 320
#define H 240

static bf_intrinsics test_K(void) { return (bf_intrinsics){W, H, 262.5, 262.5, 159.5, 119.5, 5000}; }

/* A hand-held sideways sweep with a little yaw and bob at 30 Hz, relative
 * to the scene's first view (the motion of tests/fusion's room test). */
static bf_se3 sweep_pose(const eval_scene *sc, uint32_t k)
{
    double s = k / 30.0;
    bf_se3 M = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0, 1, 0), -0.15 * sin(s)),
                              bf_v3(0.25 * sin(s), 0.02 * sin(3 * s), 0.05 * (1 - cos(s))));
    return bf_se3_mul(&sc->T_wc_view, &M);
}

static double trans_dist(const bf_se3 *A, const bf_se3 *B) { return bf_v3_norm(bf_v3_sub(A->t, B->t)); }

static double rot_dist_deg(const bf_se3 *A, const bf_se3 *B)
{
    bf_se3 Ai = bf_se3_inverse(A), D = bf_se3_mul(&Ai, B);
    double c = (D.R[0][0] + D.R[1][1] + D.R[2][2] - 1) / 2;
    return acos(c > 1 ? 1 : (c < -1 ? -1 : c)) * 180 / M_PI;
}

/* One run of the loop over n frames rendered at true_pose[k]; the loop
 * starts at offset * true_pose[0] (offset moves the whole world) and
 * est[k] receives each frame's pose. mutate (may be NULL) edits frame k's
 * depth before it goes in. */
typedef void (*mutate_fn)(uint32_t k, uint16_t *depth);

typedef struct run_out {
    bf_se3 est[64];
    recon_frame_result fr[64];
    recon_counts counts;
    fusion_stats map;
    eval_mesh points; /* surface voxels, world frame */
} run_out;

static bf_status run_loop(gpu_context *ctx, const eval_scene *sc, const bf_se3 *true_pose, uint32_t n,
                          const bf_se3 *offset, mutate_fn mutate, run_out *out)
{
    bf_intrinsics K = test_K();
    eval_render_config rc = {.K = K, .noise = EVAL_NOISE_KINECT1, .seed = 7};
    eval_renderer *ren = NULL;
    recon *r = NULL;
    uint16_t *depth = malloc((size_t)W * H * sizeof *depth);
    recon_config cfg = recon_config_default();
    cfg.fusion.brick_cap = 1u << 17;
    cfg.fusion.window = 10;
    cfg.fusion.subcache = 4;
    if (getenv("BF_ROF")) cfg.track.rof_iterations = (uint32_t)atoi(getenv("BF_ROF"));
    if (getenv("BF_RATIO")) cfg.fusion.voxel_ratio = (float)atof(getenv("BF_RATIO"));
    bf_se3 T0 = bf_se3_mul(offset, &true_pose[0]);
    bf_status s = depth ? eval_renderer_create(sc, &rc, &ren) : BF_NO_MEMORY;
    if (s == BF_OK) s = recon_create(ctx, &cfg, &K, &T0, &r);
    for (uint32_t k = 0; s == BF_OK && k < n; k++) {
        s = eval_render(ren, k, &true_pose[k], depth, NULL, NULL);
        if (s != BF_OK) break;
        if (mutate) mutate(k, depth);
        bf_frame f = {.index = k, .width = W, .height = H, .t_depth_s = 100 + k / 30.0, .depth = depth};
        f.t_rgb_s = f.t_depth_s;
        s = recon_add_frame(r, &f, &out->fr[k]);
        out->est[k] = out->fr[k].T_wc;
    }
    if (s == BF_OK) s = recon_flush(r);
    if (s == BF_OK) s = fusion_check(recon_map(r));
    if (s == BF_OK) s = fusion_get_stats(recon_map(r), &out->map);
    fusion_snapshot snap = {0};
    if (s == BF_OK) s = fusion_snapshot_take(recon_map(r), &snap);
    if (s == BF_OK) s = stream_export_points(&snap, &out->points, NULL);
    fusion_snapshot_free(&snap);
    if (r) out->counts = recon_get_counts(r);
    recon_destroy(r);
    eval_renderer_destroy(ren);
    free(depth);
    return s;
}

/* RMS of the translation error without alignment: the loop starts at the
 * true first pose, so the trajectories share a frame. */
static double rms_error(const run_out *o, const bf_se3 *true_pose, uint32_t n)
{
    double sum = 0;
    for (uint32_t k = 0; k < n; k++) sum += pow(trans_dist(&o->est[k], &true_pose[k]), 2);
    return sqrt(sum / n);
}

static double surface_p90(const eval_scene *sc, const eval_mesh *pts)
{
    eval_surface_config ec = eval_surface_config_default();
    eval_surface_result er;
    if (eval_surface(&sc->mesh, pts, NULL, &ec, &er) != BF_OK) return INFINITY;
    fprintf(stderr, "  surface: %u points, median %.2f mm, p90 %.2f mm\n", pts->n_verts, 1e3 * er.accuracy.median,
            1e3 * er.accuracy.p90);
    return er.accuracy.p90;
}

#define N_ROOM 40

BF_TEST(room_is_tracked_within_a_centimetre_and_10km_away_alike)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    eval_scene sc;
    CHECK_OK(eval_scene_room(NULL, &sc));
    bf_se3 truth[N_ROOM];
    for (uint32_t k = 0; k < N_ROOM; k++) truth[k] = sweep_pose(&sc, k);
    static run_out a, b;
    memset(&a, 0, sizeof a);
    memset(&b, 0, sizeof b);
    bf_se3 I = bf_se3_identity();
    CHECK_OK(run_loop(ctx, &sc, truth, N_ROOM, &I, NULL, &a));
    double rms = rms_error(&a, truth, N_ROOM);
    for (uint32_t k = 0; k < N_ROOM; k++)
        if (getenv("BF_TEST_VERBOSE"))
            fprintf(stderr, "  %2u %-8s %-14s deg %d inl %.2f res %.2f mm err %.2f mm\n", k,
                    recon_state_name(a.fr[k].state), track_outcome_name(a.fr[k].track.outcome),
                    a.fr[k].track.degenerate, a.fr[k].track.inlier_frac, 1e3 * a.fr[k].track.residual_m,
                    1e3 * trans_dist(&a.est[k], &truth[k]));
    fprintf(stderr, "  room: %u tracked, %u lost, trajectory RMS %.2f mm, end %.2f mm / %.3f deg\n", a.counts.tracked,
            a.counts.lost, 1e3 * rms, 1e3 * trans_dist(&a.est[N_ROOM - 1], &truth[N_ROOM - 1]),
            rot_dist_deg(&a.est[N_ROOM - 1], &truth[N_ROOM - 1]));
    CHECK_EQ_INT(a.counts.tracked, N_ROOM);
    CHECK_LE(rms, 0.015); /* issue 4's ATE bound */
    CHECK_LE(surface_p90(&sc, &a.points), 0.02);

    /* The same frames with the whole world moved 10 km away: the map origin
     * follows the first camera and the GPU only sees relative poses, so the
     * run must be as accurate as at the origin. Not bit for bit: fusion on
     * lavapipe is not deterministic from run to run (the allocation's
     * atomics hand out brick slots in a different order, so the window
     * slices hold different bricks on a given frame); two runs at the same
     * origin part by ~0.2 mm after 8 frames. */
    bf_se3 far = bf_se3_from_qt(bf_quat_identity(), bf_v3(10000.0, -7000.0, 30.0));
    CHECK_OK(run_loop(ctx, &sc, truth, N_ROOM, &far, NULL, &b));
    CHECK_EQ_INT(b.counts.tracked, N_ROOM);
    double worst = 0, sum = 0;
    for (uint32_t k = 0; k < N_ROOM; k++) {
        bf_se3 moved = bf_se3_mul(&far, &a.est[k]), true_far = bf_se3_mul(&far, &truth[k]);
        double d = trans_dist(&moved, &b.est[k]);
        if (d > worst) worst = d;
        sum += pow(trans_dist(&b.est[k], &true_far), 2);
    }
    double rms_far = sqrt(sum / N_ROOM);
    fprintf(stderr, "  10 km away: trajectory RMS %.2f mm (at the origin %.2f mm), largest difference %.2f mm\n",
            1e3 * rms_far, 1e3 * rms, 1e3 * worst);
    CHECK_LE(rms_far, 0.015);
    CHECK_NEAR(rms_far, rms, 0.002);
    CHECK_LE(worst, 0.005);
    eval_mesh_free(&a.points);
    eval_mesh_free(&b.points);
    eval_scene_free(&sc);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

