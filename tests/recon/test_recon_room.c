/* Issue 4's accuracy check at test size: a noisy room tracked over 40
 * frames (320x240) within 1.5 cm, and the same run 10 km from the origin
 * with the same accuracy. (bench/ and docs/bench_replay.md have the
 * 600-frame 640x480 run.) Validation is on. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mesh/mesh.h"
#include "synth/synth.h"
#include "gpu_fixture.h"
#include "recon_fixture.h"
#include "recon/recon.h"
#include "replay/replay.h"
#include "export/export.h"

#define N_ROOM 40

BF_TEST(room_is_tracked_within_a_centimetre_and_10km_away_alike)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    synth_scene sc;
    bf_se3 truth[N_ROOM];
    CHECK_OK(room_sweep(&sc, truth, N_ROOM));
    static run_out a, b;
    memset(&a, 0, sizeof a);
    memset(&b, 0, sizeof b);
    bf_se3 I = bf_se3_identity();
    CHECK_OK(run_loop(ctx, &sc, truth, N_ROOM, &I, NULL, &a));
    double rms = run_rms_error(&a, truth, N_ROOM);
    fprintf(stderr, "  room: %u tracked, %u lost, trajectory RMS %.2f mm, end %.2f mm / %.3f deg\n", a.counts.tracked,
            a.counts.lost, 1e3 * rms, 1e3 * trans_dist(&a.est[N_ROOM - 1], &truth[N_ROOM - 1]),
            rot_dist_deg(&a.est[N_ROOM - 1], &truth[N_ROOM - 1]));
    CHECK_EQ_INT(a.counts.tracked, N_ROOM);
    /* The map covers these views: no fit to it is weak enough to consult
     * the frame before (recon_reloc_config.last_frame_below). */
    CHECK_EQ_INT(a.counts.last_frame, 0);
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
    /* Frame by frame the two runs part by what the nondeterministic slot
     * order starts and the closed loop carries on: 0.4-5.6 mm in the runs
     * of this test while the ICP weights were tuned (2026-12-01), with the
     * RMS of both runs within 1.3 mm. Float precision lost 10 km out would
     * show as centimetres
     * (1 mm float spacing per coordinate, growing with every frame fused)
     * and in the RMS above. */
    CHECK_LE(worst, 0.01);
    mesh_free(&a.points);
    mesh_free(&b.points);
    synth_scene_free(&sc);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

/* ICL-NUIM's camera has its y axis up (fy < 0): the same rays as a y-down
 * camera with the rows flipped, so the loop must track it as well, colour
 * (the photometric term, the keyframes' keypoints) included. Until the
 * thirty-fifth session the tracker refused it. */
BF_TEST(a_camera_with_y_up_is_tracked_as_well)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    synth_scene sc;
    enum { N = 30 };
    bf_se3 truth[N];
    CHECK_OK(room_sweep(&sc, truth, N));
    static run_out o;
    memset(&o, 0, sizeof o);
    bf_se3 I = bf_se3_identity();
    recon_run_config cfg = fixture_run_config();
    fixture_set_y_up(true);
    CHECK(test_K().fy_px < 0);
    bf_status s = run_loop_colour(ctx, &cfg, &sc, truth, N, &I, NULL, &o);
    fixture_set_y_up(false);
    CHECK_OK(s);
    double rms = run_rms_error(&o, truth, N);
    fprintf(stderr, "  y up: %u tracked, %u lost, trajectory RMS %.2f mm, surface p90 %.2f mm\n", o.counts.tracked,
            o.counts.lost, 1e3 * rms, 1e3 * surface_p90(&sc, &o.points));
    CHECK_EQ_INT(o.counts.tracked, N);
    CHECK_LE(rms, 0.015); /* the y-down room's bound above */
    CHECK_LE(surface_p90(&sc, &o.points), 0.02);
    mesh_free(&o.points);
    synth_scene_free(&sc);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

/* The tracking reference (recon_config.reference_confident): every sign
 * bit until the map's first window has been integrated, the confident
 * voxels alone after it. With the fixture's window of 10 the first window
 * closes at frame 4 and its five slices end at frame 8 or 9, so the two
 * loops are the same loop bit for bit up to there and part after it; both
 * keep the room within the accuracy bound above. */
BF_TEST(the_reference_is_the_confident_map_once_a_window_has_closed)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    synth_scene sc;
    enum { N = 30 };
    bf_se3 truth[N];
    CHECK_OK(room_sweep(&sc, truth, N));
    static run_out conf, all;
    bf_se3 I = bf_se3_identity();
    for (int with = 0; with < 2; with++) {
        run_out *o = with ? &conf : &all;
        memset(o, 0, sizeof *o);
        recon_run_config cfg = fixture_run_config();
        cfg.loop.reference_confident = with;
        CHECK_OK(run_loop_with(ctx, &cfg, &sc, truth, N, &I, NULL, o));
        CHECK_EQ_INT(o->counts.tracked, N);
        fprintf(stderr, "  reference from %s: trajectory RMS %.2f mm\n", with ? "confident voxels" : "every sign bit",
                1e3 * run_rms_error(o, truth, N));
        CHECK_LE(run_rms_error(o, truth, N), 0.015);
        mesh_free(&o->points);
    }
    uint32_t first = N;
    for (uint32_t k = 0; k < N && first == N; k++)
        if (memcmp(&conf.est[k], &all.est[k], sizeof conf.est[k]) != 0) first = k;
    fprintf(stderr, "  the two loops part at frame %u\n", first);
    CHECK(first >= 9);
    CHECK(first < N);
    synth_scene_free(&sc);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}
