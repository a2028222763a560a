/* Relocalisation in the loop (recon/reloc.c): a covered lens while the
 * camera moves on, a jump away and back to where the map was made, and a
 * jump to a place the map has never seen, which must stay lost. Synthetic
 * frames of the noisy room at 320x240 (recon_fixture.h); validation is on. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gpu_fixture.h"
#include "mosaic_scene.h"
#include "recon_fixture.h"
#include "recon/recon.h"

/* The camera slid x_m along its own x axis and turned yaw_deg about its
 * own y axis (vertical in the image), from the room's first view. */
static bf_se3 view_pose(const synth_scene *sc, double x_m, double yaw_deg)
{
    bf_se3 M = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0, 1, 0), yaw_deg * M_PI / 180), bf_v3(x_m, 0, 0));
    return bf_se3_mul(&sc->T_wc_view, &M);
}

static bool is_good(const recon_frame_result *fr)
{
    return fr->state == RECON_TRACKED || fr->state == RECON_RELOCALISED || fr->state == RECON_FIRST;
}

/* Tracking's own accuracy on these frames, the bound every pose the loop
 * fuses must keep: the 40-frame room run stays within 15 mm RMS
 * (test_recon_room) and a frame after three frames without depth within
 * 2 cm (test_recon); a relocalised pose is ICP's minimum against the same
 * map, so it has the same bound. A wrong minimum is off by the candidate's
 * own distance from the truth (5-40 cm here). */
#define POSE_TOL_M 0.02
#define POSE_TOL_DEG 1.0

/* A lost frame is reported at the last good pose and leaves the map alone. */
static void check_lost_frame(const run_out *o, uint32_t k, uint32_t last_good)
{
    CHECK_EQ_INT(o->fr[k].state, RECON_LOST);
    CHECK(!o->fr[k].fused);
    CHECK_NEAR(trans_dist(&o->est[k], &o->est[last_good]), 0, 1e-12);
}

/* Frames [from, to) good, fused at the cadence every (from fused, then
 * every every-th: recon_config.fuse_every), and within tracking's own
 * bound of the truth. */
static void check_found_frames_every(const run_out *o, const bf_se3 *truth, uint32_t from, uint32_t to,
                                     uint32_t every)
{
    for (uint32_t k = from; k < to; k++) {
        CHECK(is_good(&o->fr[k]));
        CHECK_EQ_INT(o->fr[k].fused, (k - from) % every == 0);
        CHECK_LE(trans_dist(&o->est[k], &truth[k]), POSE_TOL_M);
        CHECK_LE(rot_dist_deg(&o->est[k], &truth[k]), POSE_TOL_DEG);
    }
}

static void check_found_frames(const run_out *o, const bf_se3 *truth, uint32_t from, uint32_t to)
{
    check_found_frames_every(o, truth, from, to, 1);
}

/* Covered lens: 24 frames without depth while the camera keeps turning
 * and sliding, slowing down to half its speed meanwhile (134 mm and 20
 * degrees in the gap): the continued motion overshoots by 44 mm and 6.6
 * degrees, the last pose is 134 mm and 20 degrees off. */
enum { COV_BEFORE = 10, COV_GAP = 24, COV_AFTER = 8, COV_N = COV_BEFORE + COV_GAP + COV_AFTER };

static void cover_lens(uint32_t k, uint16_t *depth)
{
    if (k >= COV_BEFORE && k < COV_BEFORE + COV_GAP) memset(depth, 0, (size_t)W * H * sizeof *depth);
}

static void covered_truth(const synth_scene *sc, bf_se3 truth[COV_N])
{
    /* Per frame before the gap: sliding right while turning left keeps
     * the table in view, as a hand-held camera looking at it does. */
    const double v_m = 0.0074, v_deg = -1.1;
    double x = 0, yaw = 0;
    for (uint32_t k = 0; k < COV_N; k++) {
        truth[k] = view_pose(sc, x, yaw);
        double slow = 1.0;
        if (k >= COV_BEFORE) slow = k < COV_BEFORE + COV_GAP ? 1 - 0.5 * (k - COV_BEFORE) / COV_GAP : 0.5;
        x += v_m * slow;
        yaw += v_deg * slow;
    }
}

BF_TEST(covered_lens_while_moving_is_found_again_after_the_gap)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    synth_scene sc;
    CHECK_OK(synth_scene_room(NULL, &sc));
    bf_se3 truth[COV_N];
    covered_truth(&sc, truth);
    const uint32_t back = COV_BEFORE + COV_GAP; /* the first frame with depth again */
    fprintf(stderr, "  in the gap: %.0f mm, %.1f deg\n", 1e3 * trans_dist(&truth[COV_BEFORE - 1], &truth[back]),
            rot_dist_deg(&truth[COV_BEFORE - 1], &truth[back]));
    bf_se3 I = bf_se3_identity();
    static run_out o;
    /* with: 0 reloc off, 1 on, 2 on with every third frame fused
     * (recon_config.fuse_every): the frame a search finds is fused. */
    for (int with = 0; with < 3; with++) {
        memset(&o, 0, sizeof o);
        recon_run_config cfg = fixture_run_config();
        cfg.loop.reloc.enabled = with >= 1;
        cfg.loop.fuse_every = with == 2 ? 3 : 1;
        /* Without reloc, from the last pose: the continued motion (the
         * default guess) carries this camera across the gap, since it
         * kept turning the same way, which a lens covered while the
         * camera is carried elsewhere would not. */
        if (!with) cfg.loop.constant_velocity = false;
        CHECK_OK(run_loop_with(ctx, &cfg, &sc, truth, COV_N, &I, cover_lens, &o));
        fprintf(stderr, "  reloc %s%s: %u tracked (%u only), %u relocalised, %u lost;", with ? "on" : "off",
                with == 2 ? ", every 3rd fused" : "", o.counts.tracked, o.counts.unfused, o.counts.relocalised,
                o.counts.lost);
        for (uint32_t k = back; k < COV_N; k++)
            fprintf(stderr, " %u:%s%s%s (%.0f mm)", k, recon_state_name(o.fr[k].state), o.fr[k].reloc ? "/" : "",
                    recon_reloc_kind_name(o.fr[k].reloc), 1e3 * trans_dist(&o.est[k], &truth[k]));
        fprintf(stderr, "\n");
        for (uint32_t k = COV_BEFORE; k < back; k++) CHECK_EQ_INT(o.fr[k].state, RECON_NO_DEPTH);
        if (!with) {
            /* The scenario is beyond plain tracking from the last pose
             * with the per-frame gate: the frame after the gap is lost. */
            CHECK_EQ_INT(o.fr[back].state, RECON_LOST);
            mesh_free(&o.points);
            continue;
        }
        /* Found within two frames (the continued motion is a primary
         * candidate), then tracked on. */
        uint32_t found = back;
        while (found < COV_N && !is_good(&o.fr[found])) check_lost_frame(&o, found++, COV_BEFORE - 1);
        CHECK_LE(found, back + 1);
        CHECK_EQ_INT(o.fr[found].state, RECON_RELOCALISED);
        if (with == 2) CHECK(o.counts.unfused > 0);
        check_found_frames_every(&o, truth, found, COV_N, cfg.loop.fuse_every);
        fprintf(stderr, "  after the gap: frame %u off by %.1f mm, %.2f deg; last by %.1f mm\n", found,
                1e3 * trans_dist(&o.est[found], &truth[found]), rot_dist_deg(&o.est[found], &truth[found]),
                1e3 * trans_dist(&o.est[COV_N - 1], &truth[COV_N - 1]));
        CHECK_LE(surface_p90(&sc, &o.points), 0.02);
        mesh_free(&o.points);
    }
    synth_scene_free(&sc);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

/* Away and back: the camera slides 38 cm and turns 28.5 degrees over 20
 * frames (keyframes every 10 cm or 10 degrees), turns round to the unmapped
 * back of the room for 6 frames, then comes back near its second frame:
 * 35 cm and 27 degrees from the last good pose, beyond where ICP from it
 * or its turns converges, 2 cm from the first keyframe. */
enum { AB_OUT = 20, AB_AWAY = 6, AB_BACK = 8, AB_N = AB_OUT + AB_AWAY + AB_BACK };

static void away_and_back_truth(const synth_scene *sc, bf_se3 truth[AB_N])
{
    for (uint32_t k = 0; k < AB_N; k++) {
        if (k < AB_OUT) truth[k] = view_pose(sc, 0.02 * k, 1.5 * k);
        else if (k < AB_OUT + AB_AWAY) truth[k] = view_pose(sc, 0.38, 180 + 3.0 * (k - AB_OUT));
        else truth[k] = view_pose(sc, 0.02 + 0.003 * (k - AB_OUT - AB_AWAY), 1.5 + 0.2 * (k - AB_OUT - AB_AWAY));
    }
}

BF_TEST(a_camera_back_from_elsewhere_is_found_at_a_keyframe)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    synth_scene sc;
    CHECK_OK(synth_scene_room(NULL, &sc));
    bf_se3 truth[AB_N];
    away_and_back_truth(&sc, truth);
    const uint32_t back = AB_OUT + AB_AWAY;
    fprintf(stderr, "  the return from the last good pose: %.0f mm, %.1f deg\n",
            1e3 * trans_dist(&truth[AB_OUT - 1], &truth[back]), rot_dist_deg(&truth[AB_OUT - 1], &truth[back]));
    static run_out o;
    memset(&o, 0, sizeof o);
    bf_se3 I = bf_se3_identity();
    recon_run_config cfg = fixture_run_config();
    CHECK_OK(run_loop_with(ctx, &cfg, &sc, truth, AB_N, &I, NULL, &o));
    fprintf(stderr, "  %u tracked, %u relocalised, %u lost, %u keyframes;", o.counts.tracked, o.counts.relocalised,
            o.counts.lost, o.counts.keyframes);
    for (uint32_t k = AB_OUT; k < AB_N; k++)
        fprintf(stderr, " %u:%s%s%s", k, recon_state_name(o.fr[k].state), o.fr[k].reloc ? "/" : "",
                recon_reloc_kind_name(o.fr[k].reloc));
    fprintf(stderr, "\n");
    for (uint32_t k = 0; k < AB_OUT; k++) CHECK(is_good(&o.fr[k]));
    CHECK(o.counts.keyframes >= 4); /* 38 cm and 28.5 degrees of path */
    for (uint32_t k = AB_OUT; k < back; k++) check_lost_frame(&o, k, AB_OUT - 1);
    /* Found from a keyframe within the frames the round robin needs to
     * reach the keyframes: 16 turns and the keyframes at two a frame. */
    uint32_t found = back, reach = (16 + o.counts.keyframes + 1) / 2;
    while (found < AB_N && !is_good(&o.fr[found])) check_lost_frame(&o, found++, AB_OUT - 1);
    CHECK_LE(found, back + reach);
    CHECK(found < AB_N);
    if (found < AB_N) {
        CHECK_EQ_INT(o.fr[found].state, RECON_RELOCALISED);
        CHECK_EQ_INT(o.fr[found].reloc, RECON_RELOC_KEYFRAME);
        fprintf(stderr, "  found at frame %u (%u after the return) off by %.1f mm, %.2f deg\n", found, found - back,
                1e3 * trans_dist(&o.est[found], &truth[found]), rot_dist_deg(&o.est[found], &truth[found]));
    }
    check_found_frames(&o, truth, found, AB_N);
    CHECK_LE(surface_p90(&sc, &o.points), 0.02);
    mesh_free(&o.points);
    synth_scene_free(&sc);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

/* Carried away: the sweep of the test above, then in one frame the camera
 * is 0.36 m behind and above the middle of its path, looking down 12
 * degrees more: 0.35 m or more from every pose of the path, so
 * ICP from none of them reaches it (the per-frame gate is 0.15 m), but it
 * sees what the keyframes saw. The frames carry colour: the lost frame's
 * ORB keypoints matched to a keyframe's, lifted by its depth, give the
 * pose by PnP, which ICP then refines. Without colour candidates the
 * camera stays lost. */
enum { CA_OUT = 20, CA_AFTER = 6, CA_N = CA_OUT + CA_AFTER };

static void carried_away_truth(const synth_scene *sc, bf_se3 truth[CA_N])
{
    for (uint32_t k = 0; k < CA_N; k++) {
        if (k < CA_OUT) {
            truth[k] = view_pose(sc, 0.02 * k, 1.5 * k);
            continue;
        }
        bf_se3 mid = view_pose(sc, 0.19 + 0.004 * (k - CA_OUT), 14.0 + 0.3 * (k - CA_OUT));
        bf_se3 M = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(1, 0, 0), -12.0 * M_PI / 180), bf_v3(0, -0.1, -0.35));
        truth[k] = bf_se3_mul(&mid, &M);
    }
}

/* The carried-away run: with colour candidates (with) or without; cal,
 * when not NULL, is a calibration whose colour camera sees the colour. */
static void check_carried_away(gpu_context *ctx, const synth_scene *sc, const bf_se3 *truth, bool with,
                               const calib_result *cal)
{
    bf_se3 I = bf_se3_identity();
    static run_out o;
    memset(&o, 0, sizeof o);
    recon_run_config cfg = fixture_run_config();
    if (!with) cfg.loop.reloc.features = 0;
    if (cal) cfg.loop.has_calibration = true, cfg.loop.calibration = *cal;
    CHECK_OK(run_loop_colour(ctx, &cfg, sc, truth, CA_N, &I, NULL, &o));
    fprintf(stderr, "  colour candidates %s%s: %u tracked, %u relocalised, %u lost, %u keyframes;", with ? "on" : "off",
            cal ? " (a colour camera of its own)" : "", o.counts.tracked, o.counts.relocalised, o.counts.lost,
            o.counts.keyframes);
    for (uint32_t k = CA_OUT; k < CA_N; k++)
        fprintf(stderr, " %u:%s%s%s (%.0f mm)", k, recon_state_name(o.fr[k].state), o.fr[k].reloc ? "/" : "",
                recon_reloc_kind_name(o.fr[k].reloc), 1e3 * trans_dist(&o.est[k], &truth[k]));
    fprintf(stderr, "\n");
    for (uint32_t k = 0; k < CA_OUT; k++) CHECK(is_good(&o.fr[k]));
    if (!with) {
        /* Beyond the depth-only candidates: lost, and nothing fused. */
        for (uint32_t k = CA_OUT; k < CA_N; k++) check_lost_frame(&o, k, CA_OUT - 1);
    } else {
        /* Found on the first frame after the jump, from colour, then
         * tracked on within tracking's own bound; the jump is no motion
         * to continue, so the next frame is tracked from the found pose
         * without a search. */
        CHECK_EQ_INT(o.fr[CA_OUT].state, RECON_RELOCALISED);
        CHECK_EQ_INT(o.fr[CA_OUT].reloc, RECON_RELOC_FEATURES);
        CHECK_EQ_INT(o.fr[CA_OUT + 1].state, RECON_TRACKED);
        CHECK_EQ_INT(o.fr[CA_OUT + 1].reloc, RECON_RELOC_NONE);
        check_found_frames(&o, truth, CA_OUT, CA_N);
    }
    CHECK_LE(surface_p90(sc, &o.points), 0.02);
    mesh_free(&o.points);
}

/* A colour camera of its own (--calibration): its own focal length (fx 236
 * against the depth's 262.5), centre and barrel lens (k1 -0.2, k2 0.1: the
 * corners 18 pixels in), set 15 cm beside the depth camera and turned 10
 * degrees, further than a Kinect's 2.5 cm, so that a colour pose taken for
 * the depth camera's, keypoints lifted as if the colour were registered,
 * or PnP run with the depth camera's intrinsics all leave the candidate
 * beyond ICP's reach (each of the three makes the camera stay lost for two
 * frames or more). The fixture renders the colour from where this camera
 * sits and puts it through the lens. (PnP without the lens still lands
 * within ICP's reach here: tests/features checks it.) */
static calib_result colour_camera_of_its_own(void)
{
    bf_intrinsics K = test_K();
    calib_result cal = {.colour = {.width = W, .height = H, .fx_px = 236.0, .fy_px = 235.0, .cx_px = 163.0,
                                   .cy_px = 117.5, .dist = {-0.2, 0.1, 0.001, -0.001, 0}},
                        .has_depth = true,
                        .depth = {.width = W, .height = H, .fx_px = K.fx_px, .fy_px = K.fy_px, .cx_px = K.cx_px,
                                  .cy_px = K.cy_px}};
    cal.T_colour_depth =
        bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0.3, 1, 0.2), 10.0 * M_PI / 180), bf_v3(-0.15, 0.02, 0.01));
    return cal;
}

/* Without colour candidates, with them, and with them through a colour
 * camera of its own: the keyframes' keypoints found in that camera's own
 * image and lifted by the depth it sees (calib_points_on_colour), PnP
 * giving that camera's pose and the rig the depth camera's. */
BF_TEST(a_camera_carried_away_is_found_from_its_colour)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    synth_scene sc;
    CHECK_OK(synth_scene_room(NULL, &sc));
    bf_se3 truth[CA_N];
    carried_away_truth(&sc, truth);
    double nearest = INFINITY;
    for (uint32_t k = 0; k < CA_OUT; k++) {
        double d = trans_dist(&truth[k], &truth[CA_OUT]);
        if (d < nearest) nearest = d;
    }
    fprintf(stderr, "  the jump: %.0f mm from the nearest pose of the path, %.0f mm and %.1f deg from the last\n",
            1e3 * nearest, 1e3 * trans_dist(&truth[CA_OUT - 1], &truth[CA_OUT]),
            rot_dist_deg(&truth[CA_OUT - 1], &truth[CA_OUT]));
    CHECK(nearest > 0.3); /* beyond ICP's reach from any keyframe */
    for (int with = 0; with < 2; with++) check_carried_away(ctx, &sc, truth, with, NULL);
    calib_result cal = colour_camera_of_its_own();
    check_carried_away(ctx, &sc, truth, true, &cal);
    synth_scene_free(&sc);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

/* A new place: after 12 frames of the sweep the camera turns round to the
 * back of the room, which the map has never seen, and looks about there.
 * Every frame after the jump is lost, says so, and is not fused; the map
 * holds no ghost of the back wall. The frames carry colour, so the
 * keyframes' keypoints are matched too and must not place it either. */
BF_TEST(a_camera_in_an_unmapped_place_stays_lost)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    synth_scene sc;
    CHECK_OK(synth_scene_room(NULL, &sc));
    enum { JUMP = 12, N = 24 };
    bf_se3 truth[N];
    for (uint32_t k = 0; k < N; k++)
        truth[k] = k < JUMP ? view_pose(&sc, 0.01 * k, 0.5 * k) : view_pose(&sc, 0.12, 170 + 2.0 * (k - JUMP));
    static run_out o;
    memset(&o, 0, sizeof o);
    bf_se3 I = bf_se3_identity();
    recon_run_config cfg = fixture_run_config();
    CHECK_OK(run_loop_colour(ctx, &cfg, &sc, truth, N, &I, NULL, &o));
    uint32_t tried = 0;
    double best_inliers = 0;
    for (uint32_t k = JUMP; k < N; k++) {
        check_lost_frame(&o, k, JUMP - 1);
        CHECK_EQ_INT(o.fr[k].reloc, RECON_RELOC_NONE);
        tried += o.fr[k].reloc_tried;
        if (o.fr[k].track.inlier_frac > best_inliers) best_inliers = o.fr[k].track.inlier_frac;
    }
    fprintf(stderr, "  %u lost, %u relocalised, %u candidates tried, best inliers %.1f%%\n", o.counts.lost,
            o.counts.relocalised, tried, 100 * best_inliers);
    CHECK_EQ_INT(o.counts.relocalised, 0);
    CHECK_EQ_INT(o.counts.lost, N - JUMP);
    /* Each lost frame searched with its whole budget, and colour's on top
     * where PnP found a pose. */
    CHECK(tried >= (N - JUMP) * cfg.loop.reloc.max_candidates);
    /* The first frame after the jump is also tried against the frame before it (reloc.last_frame). */
    CHECK(tried <= (N - JUMP) * (cfg.loop.reloc.max_candidates + cfg.loop.reloc.feature_candidates) + 1);
    CHECK_LE(surface_p90(&sc, &o.points), 0.02);
    mesh_free(&o.points);
    synth_scene_free(&sc);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

/* Turned away in the gap: as the covered lens above, but in the gap the
 * camera turns the other way, to the right by 0.9 degrees a frame (22
 * degrees from the last good pose, 124 mm), so the view after the gap is
 * mostly the unmapped part of the room beside a partly mapped wall. ICP
 * from the candidate turned 20 degrees slides 21 cm along that wall and
 * passes the tracker's gates with a margin (57% inliers at 13.6 mm; the
 * right pose in the test above had 57% at 16.6 mm); the agreement check
 * rejects it: a fifth of the covered samples off the predicted surface,
 * 5% in front of it, against at most 9% and 1.2% at right poses. The loop
 * must find the right pose or stay lost, never take a wrong one. */
static void turned_away_truth(const synth_scene *sc, bf_se3 truth[COV_N])
{
    double x = 0, yaw = 0;
    for (uint32_t k = 0; k < COV_N; k++) {
        truth[k] = view_pose(sc, x, yaw);
        bool is_gap = k + 1 >= COV_BEFORE && k + 1 < COV_BEFORE + COV_GAP; /* the step to frame k + 1 */
        x += k + 1 < COV_BEFORE ? 0.0074 : is_gap ? 0.005 : 0.0037;
        yaw += k + 1 < COV_BEFORE ? -1.1 : is_gap ? 0.9 : 0.5;
    }
}

/* A wrong minimum is off by the distance ICP slid (21 cm here); anything
 * past 5 cm is not tracking's own error (2 cm, POSE_TOL_M). */
#define WRONG_POSE_M 0.05

BF_TEST(a_camera_turned_away_in_the_gap_is_never_placed_wrong)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    synth_scene sc;
    CHECK_OK(synth_scene_room(NULL, &sc));
    bf_se3 truth[COV_N];
    turned_away_truth(&sc, truth);
    const uint32_t back = COV_BEFORE + COV_GAP;
    fprintf(stderr, "  in the gap: %.0f mm, %.1f deg\n", 1e3 * trans_dist(&truth[COV_BEFORE - 1], &truth[back]),
            rot_dist_deg(&truth[COV_BEFORE - 1], &truth[back]));
    bf_se3 I = bf_se3_identity();
    static run_out o;
    memset(&o, 0, sizeof o);
    recon_run_config cfg = fixture_run_config();
    /* The tracker of 2026-12-02's first relocalisation (5 iterations on
     * every finest pixel, the smoothed reference, the noise weight's
     * exponent 2): from the turned candidate it slid to the wrong minimum
     * this test is about (213 mm off) in the normal build, so the free-space
     * check had to turn it down. Today's tracker finds the right pose from
     * it (4 mm off); the assertions on the poses hold for both. */
    cfg.loop.track.iterations[0] = 5;
    cfg.loop.track.finest_sample_step = 1;
    cfg.loop.track.rof_iterations = 10;
    cfg.loop.track.noise_weight_exp = 2.0f;
    CHECK_OK(run_loop_with(ctx, &cfg, &sc, truth, COV_N, &I, cover_lens, &o));
    uint32_t rejected = 0, good = 0;
    for (uint32_t k = back; k < COV_N; k++) {
        fprintf(stderr, "  %u: %s%s%s, %u rejected (%.0f mm, %.1f deg off)\n", k, recon_state_name(o.fr[k].state),
                o.fr[k].reloc ? "/" : "", recon_reloc_kind_name(o.fr[k].reloc), o.fr[k].reloc_rejected,
                1e3 * trans_dist(&o.est[k], &truth[k]), rot_dist_deg(&o.est[k], &truth[k]));
        rejected += o.fr[k].reloc_rejected;
        if (!is_good(&o.fr[k])) {
            check_lost_frame(&o, k, COV_BEFORE - 1);
            continue;
        }
        good++;
        CHECK_LE(trans_dist(&o.est[k], &truth[k]), WRONG_POSE_M);
        CHECK_LE(trans_dist(&o.est[k], &truth[k]), POSE_TOL_M);
        CHECK_LE(rot_dist_deg(&o.est[k], &truth[k]), POSE_TOL_DEG);
    }
    /* Whether ICP slides into the wrong minimum from the turned candidate
     * depends on the run (the loop is not bit-reproducible; under ASan the
     * right pose was found directly, 10 mm off): the property is the poses
     * above, either way. The check's counts on the run that did slide are in
     * docs/tracking.md. */
    fprintf(stderr, "  %u good after the gap, %u candidates rejected by the check%s\n", good, rejected,
            rejected ? " (the wrong minimum was reached and turned down)" : "");
    CHECK_LE(surface_p90(&sc, &o.points), 0.02);
    mesh_free(&o.points);
    synth_scene_free(&sc);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

/* Frames 6-10 of the textured floor lose their depth (a covered lens):
 * six intervals, more than the motion gate's cap of four, so the frame
 * after the gap is searched for from candidate poses. */
static void floor_gap(uint32_t k, uint16_t *depth)
{
    if (k >= 6 && k <= 10) memset(depth, 0, (size_t)W * H * 2);
}

/* A candidate is checked against the map cast at its pose. Only at the
 * last good pose is there an image to compare the frame's colour with (the
 * last fused frame's, kept with the reference); elsewhere the frame would
 * be compared with its own colour or another pose's, which fit anywhere
 * (test_tracking checks that contract). The camera slides along the
 * textured floor (8 mm a frame), loses its depth for frames 6-10 and stops
 * at frame 8's pose: the last pose is 24 mm short of it, the
 * constant-velocity candidate 24 mm past it, and on depth alone every
 * candidate is degenerate. Without colour candidates (features 0), the
 * last pose's candidate, compared with the kept colour, finds it. */
BF_TEST(after_a_gap_on_a_textured_floor_the_last_pose_keeps_its_colour)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    synth_scene sc;
    bf_se3 T0;
    CHECK_OK(mosaic_scene(&sc, &T0));
    enum { N = 16, GAP = 6, AFTER = 11, STOP = 8 };
    bf_se3 truth[N];
    for (uint32_t k = 0; k < N; k++) {
        uint32_t m = k < STOP ? k : STOP;
        bf_se3 D = bf_se3_from_qt(bf_quat_identity(), bf_v3(0.008 * m, 0, 0));
        truth[k] = bf_se3_mul(&D, &T0);
    }
    recon_run_config cfg = fixture_run_config();
    cfg.loop.reloc.features = 0;
    static run_out o;
    memset(&o, 0, sizeof o);
    bf_se3 I = bf_se3_identity();
    CHECK_OK(run_loop_colour(ctx, &cfg, &sc, truth, N, &I, floor_gap, &o));
    uint32_t tried = 0;
    fprintf(stderr, "  textured floor after the gap:");
    for (uint32_t k = AFTER; k < N; k++) {
        tried += o.fr[k].reloc_tried;
        fprintf(stderr, " %u:%s%s%s (%.0f mm)", k, recon_state_name(o.fr[k].state), o.fr[k].reloc ? "/" : "",
                recon_reloc_kind_name(o.fr[k].reloc), 1e3 * trans_dist(&o.est[k], &truth[k]));
        /* Placed only where it is: within tracking's bound of the truth. */
        if (is_good(&o.fr[k])) CHECK_LE(trans_dist(&o.est[k], &truth[k]), 0.005);
    }
    fprintf(stderr, "; %u candidates tried\n", tried);
    for (uint32_t k = 0; k < GAP; k++) CHECK(is_good(&o.fr[k]));
    /* Searched for (the gap is beyond the gate's cap) and found at once. */
    CHECK(tried >= 1);
    CHECK_EQ_INT(o.fr[AFTER].state, RECON_RELOCALISED);
    CHECK_EQ_INT(o.fr[AFTER].reloc, RECON_RELOC_LAST);
    for (uint32_t k = AFTER; k < N; k++) CHECK(is_good(&o.fr[k]));
    mesh_free(&o.points);
    synth_scene_free(&sc);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

/* A map that covers little of the view (a fast turn into what it has
 * barely seen: TUM fr1/rpy's frames 39-59, docs/tracking.md), made here by
 * casting the tracking reference only to 2.4 m while the frames see the
 * room to its far walls: each frame's fit to the map is weak (25-30% of
 * its samples) or fails, while the frame before, one interval away, sees
 * 92-93% of what it sees. On the map alone the weak fits pass the
 * tracker's gates and slide along what little it holds (21-152 mm off by
 * frame 7), then the camera is lost. With reloc.last_frame every frame is
 * tracked against the one before it and keeps tracking's own bound (the
 * steps' errors add up: 12 mm by frame 19), also across frames a live
 * queue dropped (two intervals apart) and with every third frame fused,
 * but not across a frame without depth. */
enum { THIN_N = 20, THIN_GAP = 10 };

/* A frame of the thin run without depth: the frame after it is two
 * intervals from the last good one, whose view it may no longer share. */
static void thin_gap(uint32_t k, uint16_t *depth)
{
    if (k == THIN_GAP) memset(depth, 0, (size_t)W * H * sizeof *depth);
}
#define THIN_FAR_M 2.4f

BF_TEST(a_frame_the_map_barely_covers_is_tracked_against_the_frame_before)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    synth_scene sc;
    CHECK_OK(synth_scene_room(NULL, &sc));
    bf_se3 truth[THIN_N];
    for (uint32_t k = 0; k < THIN_N; k++) truth[k] = view_pose(&sc, 0.006 * k, -1.5 * k);
    bf_se3 I = bf_se3_identity();
    static run_out o;
    /* A live queue dropping every other frame over frames 7-13. */
    bool dropped[THIN_N] = {false};
    for (uint32_t k = 7; k <= 13; k += 2) dropped[k] = true;
    for (int with = 0; with < 5; with++) {
        memset(&o, 0, sizeof o);
        recon_run_config cfg = fixture_run_config();
        cfg.loop.raycast.far_m = THIN_FAR_M;
        cfg.loop.reloc.last_frame = with >= 1;
        /* Every third frame fused: a frame found on the frame before is
         * fused all the same, so the next one's map holds what it saw. */
        if (with == 4) cfg.loop.fuse_every = 3;
        if (with == 3) CHECK_OK(run_loop_dropping(ctx, &cfg, &sc, truth, THIN_N, dropped, &o));
        else CHECK_OK(run_loop_with(ctx, &cfg, &sc, truth, THIN_N, &I, with == 2 ? thin_gap : NULL, &o));
        fprintf(stderr, "  last frame %s: %u tracked (%u on the frame before), %u lost:",
                with == 4   ? "on, every third fused"
                : with == 3 ? "on, frames dropped"
                : with == 2 ? "on, a frame without depth"
                : with      ? "on"
                            : "off",
                o.counts.tracked, o.counts.last_frame, o.counts.lost);
        for (uint32_t k = 1; k < THIN_N; k++) {
            if (with == 3 && dropped[k]) continue;
            fprintf(stderr, " %u:%s%s%s %.0f%% (%.1f mm)", k, recon_state_name(o.fr[k].state), o.fr[k].reloc ? "/" : "",
                    recon_reloc_kind_name(o.fr[k].reloc), 100 * o.fr[k].track.inlier_frac,
                    1e3 * trans_dist(&o.est[k], &truth[k]));
        }
        fprintf(stderr, "\n");
        uint32_t right = 0, n_dropped = with == 3 ? 4 : 0;
        for (uint32_t k = 1; k < THIN_N; k++)
            right += (with != 3 || !dropped[k]) && is_good(&o.fr[k]) && trans_dist(&o.est[k], &truth[k]) <= POSE_TOL_M &&
                     rot_dist_deg(&o.est[k], &truth[k]) <= POSE_TOL_DEG;
        if (!with) {
            /* Beyond the map alone: placed wrong, or lost. */
            CHECK_LE(right, THIN_N / 2);
            mesh_free(&o.points);
            continue;
        }
        if (with == 2) {
            /* Not against a frame two intervals back; before the gap as
             * without it. */
            CHECK_EQ_INT(o.fr[THIN_GAP].state, RECON_NO_DEPTH);
            CHECK(o.fr[THIN_GAP + 1].reloc != RECON_RELOC_FRAME);
            for (uint32_t k = 1; k < THIN_GAP; k++) CHECK_EQ_INT(o.fr[k].reloc, RECON_RELOC_FRAME);
            mesh_free(&o.points);
            continue;
        }
        CHECK_EQ_INT(right, THIN_N - 1 - n_dropped);
        CHECK_EQ_INT(o.counts.lost, 0);
        CHECK(o.counts.last_frame >= THIN_N / 2);
        for (uint32_t k = 1; k < THIN_N; k++)
            if (with != 3 || !dropped[k]) CHECK(o.fr[k].fused);
        /* Two intervals after the frame before, with nothing lost between:
         * still tracked against it. */
        if (with == 3)
            for (uint32_t k = 8; k <= 14; k += 2) CHECK_EQ_INT(o.fr[k].reloc, RECON_RELOC_FRAME);
        mesh_free(&o.points);
    }
    synth_scene_free(&sc);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

/* The weak fit's bound is a fraction: outside [0, 1], or NaN, the loop is
 * refused with the reloc settings named, before anything is made. */
BF_TEST(a_weak_fit_bound_outside_0_to_1_is_refused)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    bf_intrinsics K = {W, H, 260, 260, W / 2.0, H / 2.0, 1000};
    bf_se3 I = bf_se3_identity();
    const float bad[] = {-0.1f, 1.5f, NAN};
    for (int i = 0; i < 3; i++) {
        recon_config cfg = recon_config_default();
        cfg.reloc.last_frame_below = bad[i];
        recon *r = NULL;
        CHECK_STATUS(recon_create(ctx, &cfg, &K, &I, &r), BF_INVALID_ARG);
        CHECK(r == NULL);
        CHECK(strstr(bf_last_error(), "weak fit below") != NULL);
    }
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}
