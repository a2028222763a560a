/* Tracking every frame, fusing fewer (recon_config.fuse_every and
 * fuse_every_behind): which frames are fused, that the poses of the frames
 * tracked only still hold, and that the runner fuses fewer only while
 * frames wait in a queue that drops. Validation is on. */
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <time.h>

#include "capture/capture.h"
#include "gpu_fixture.h"
#include "recon_fixture.h"
#include "recon/recon.h"

#define N_ROOM 40

BF_TEST(every_third_frame_fused_and_every_frame_tracked_within_a_centimetre)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    synth_scene sc;
    bf_se3 truth[N_ROOM];
    CHECK_OK(room_sweep(&sc, truth, N_ROOM));
    static run_out o, all;
    memset(&o, 0, sizeof o);
    memset(&all, 0, sizeof all);
    recon_run_config cfg = fixture_run_config();
    bf_se3 I = bf_se3_identity();
    CHECK_OK(run_loop_with(ctx, &cfg, &sc, truth, N_ROOM, &I, NULL, &all));
    cfg.loop.fuse_every = 3;
    CHECK_OK(run_loop_with(ctx, &cfg, &sc, truth, N_ROOM, &I, NULL, &o));
    double rms = run_rms_error(&o, truth, N_ROOM), rms_all = run_rms_error(&all, truth, N_ROOM);
    fprintf(stderr, "  fuse every 3rd: %u tracked, %u tracked only, %u lost, trajectory RMS %.2f mm (every frame fused: "
            "%.2f mm)\n", o.counts.tracked, o.counts.unfused, o.counts.lost, 1e3 * rms, 1e3 * rms_all);
    CHECK_EQ_INT(o.counts.tracked, N_ROOM);
    /* The first frame, then every third: 0, 3, ..., 39. */
    for (uint32_t k = 0; k < N_ROOM; k++) CHECK_EQ_INT(o.fr[k].fused, k % 3 == 0);
    CHECK_EQ_INT(o.counts.unfused, N_ROOM - (N_ROOM + 2) / 3);
    CHECK_EQ_INT(o.counts.behind, 0);
    /* The bounds of every frame fused (test_recon_room): issue 4's ATE,
     * and the surface of a third of the frames. A frame tracked against a
     * reference one or two frames older sees the same surfaces: the
     * trajectory within twice every frame fused's error (plus 2 mm, the
     * spread of two runs of the same frames on lavapipe). */
    CHECK_LE(rms, 0.015);
    CHECK_LE(rms, 2 * rms_all + 0.002);
    CHECK_LE(surface_p90(&sc, &o.points), 0.02);
    mesh_free(&o.points);
    mesh_free(&all.points);

    /* Fused at known poses (the tracker's one-step error): every frame is
     * fused, whatever the cadence. */
    memset(&o, 0, sizeof o);
    cfg.poses = RECON_POSES_TRACK_FUSE_GT;
    CHECK_OK(run_loop_with(ctx, &cfg, &sc, truth, 12, &I, NULL, &o));
    CHECK_EQ_INT(o.counts.unfused, 0);
    for (uint32_t k = 0; k < 12; k++) CHECK(o.fr[k].fused);
    mesh_free(&o.points);
    synth_scene_free(&sc);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

#define N_QUEUED 12

static bf_status keep(void *user, recon_run *run, const bf_frame *f, const recon_frame_result *fr)
{
    (void)run;
    run_out *o = user;
    if (f->index < 64) o->fr[f->index] = *fr, o->est[f->index] = fr->T_wc;
    return BF_OK;
}

/* All N_QUEUED frames captured into the queue before the loop takes the
 * first: frame k finds N_QUEUED - 1 - k frames waiting behind it. */
static void run_queued_skipping(gpu_context *ctx, const synth_scene *sc, const bf_se3 *truth, bool drops,
                                uint32_t every, const bool *skipped, uint32_t n_skipped, run_out *o)
{
    fixture_render fr;
    rgbd_source *src = NULL, *q = NULL;
    bf_se3 I = bf_se3_identity();
    CHECK_OK(fixture_render_open(sc, truth, N_QUEUED, &I, NULL, &fr, &src));
    fr.dropped = skipped;
    CHECK_OK(drops ? capture_threaded(src, N_QUEUED + 4, &q) : capture_threaded_lossless(src, N_QUEUED + 4, &q));
    CHECK_OK(capture_threaded_start(q));
    for (int i = 0; i < 3000 && !capture_threaded_stats(q).is_ended; i++)
        nanosleep(&(struct timespec){.tv_nsec = 10000000}, NULL);
    CHECK(capture_threaded_stats(q).is_ended);
    CHECK_EQ_INT(capture_threaded_stats(q).queued, N_QUEUED - n_skipped);
    recon_run_config cfg = fixture_run_config();
    cfg.loop.fuse_every = every;
    recon_run run;
    CHECK_OK(recon_run_sequence(ctx, q, &cfg, keep, o, &run));
    o->counts = run.counts;
    recon_run_free(&run);
    /* q owns src now. */
    rgbd_source_close(q);
    fixture_render_close(&fr, NULL);
}

static void run_queued(gpu_context *ctx, const synth_scene *sc, const bf_se3 *truth, bool drops, uint32_t every,
                       run_out *o)
{
    run_queued_skipping(ctx, sc, truth, drops, every, NULL, 0, o);
}

BF_TEST(frames_waiting_in_a_queue_that_drops_are_fused_every_fourth)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    synth_scene sc;
    bf_se3 truth[N_QUEUED];
    CHECK_OK(room_sweep(&sc, truth, N_QUEUED));
    static run_out o;
    /* A camera's queue (drops when full): frames 0-10 come with frames
     * behind them, so after the first, every fourth is fused (4, 8); the
     * last finds none waiting and is fused as every frame is by default. */
    memset(&o, 0, sizeof o);
    run_queued(ctx, &sc, truth, true, 1, &o);
    fprintf(stderr, "  camera's queue: %u tracked, %u tracked only, %u behind:", o.counts.tracked, o.counts.unfused,
            o.counts.behind);
    for (uint32_t k = 0; k < N_QUEUED; k++) fprintf(stderr, " %u:%s", k, o.fr[k].fused ? "fused" : "tracked");
    fprintf(stderr, "\n");
    CHECK_EQ_INT(o.counts.tracked, N_QUEUED);
    CHECK_EQ_INT(o.counts.behind, N_QUEUED - 1);
    for (uint32_t k = 0; k < N_QUEUED; k++) CHECK_EQ_INT(o.fr[k].fused, k == 0 || k == 4 || k == 8 || k == N_QUEUED - 1);
    CHECK_EQ_INT(o.counts.unfused, N_QUEUED - 4);
    for (uint32_t k = 0; k < N_QUEUED; k++) CHECK_LE(trans_dist(&o.est[k], &truth[k]), 0.015);
    mesh_free(&o.points);

    /* A file read ahead (lossless: waits, never drops): the frames queued
     * are no camera the loop is behind, and every frame is fused. */
    memset(&o, 0, sizeof o);
    run_queued(ctx, &sc, truth, false, 1, &o);
    CHECK_EQ_INT(o.counts.tracked, N_QUEUED);
    CHECK_EQ_INT(o.counts.behind, 0);
    CHECK_EQ_INT(o.counts.unfused, 0);
    for (uint32_t k = 0; k < N_QUEUED; k++) CHECK(o.fr[k].fused);
    mesh_free(&o.points);

    /* fuse_every above fuse_every_behind: the larger applies, behind or
     * not (0 and 6 fused; the last, not behind, is the 5th since). */
    memset(&o, 0, sizeof o);
    run_queued(ctx, &sc, truth, true, 6, &o);
    CHECK_EQ_INT(o.counts.tracked, N_QUEUED);
    for (uint32_t k = 0; k < N_QUEUED; k++) CHECK_EQ_INT(o.fr[k].fused, k == 0 || k == 6);
    synth_scene_free(&sc);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

/* Behind a camera the queue drops frames while the loop works, so the next
 * frame it takes may be more intervals on than the motion gate's cap (4),
 * past which a frame is searched for (a lens covered, a camera carried
 * off). A search costs several ray-casts and ICPs (400-600 ms on
 * lavapipe), behind which the queue drops a dozen frames more, so every
 * frame after one became a search (docs/tracking.md). Frames 4-8 here are
 * never captured (what the camera's queue had dropped before), and the
 * rest all wait in the queue: frame 9 comes 6 intervals after frame 3,
 * and from a camera with depth in every frame the loop took it is tracked
 * from the continued motion, the gate at its cap, and passes a search
 * candidate's test. From a file read ahead (a lossless queue: nothing
 * dropped, the gap is the recording's) it is searched for, as a gap beyond
 * the cap always was. */
BF_TEST(a_gap_behind_a_camera_is_tracked_from_the_guess_not_searched)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    synth_scene sc;
    CHECK_OK(synth_scene_room(NULL, &sc));
    bf_se3 truth[N_QUEUED];
    bool skipped[N_QUEUED] = {false};
    /* Turning 3 degrees a frame: 18 degrees across the gap, which the
     * continued turn reaches and an ICP from the last pose does not. */
    bf_se3 T0 = sweep_pose(&sc, 0);
    for (uint32_t k = 0; k < N_QUEUED; k++) truth[k] = panned(&T0, -3.0 * k);
    for (uint32_t k = 4; k <= 8; k++) skipped[k] = true;
    static run_out o;
    for (int drops = 1; drops >= 0; drops--) {
        memset(&o, 0, sizeof o);
        run_queued_skipping(ctx, &sc, truth, drops, 1, skipped, 5, &o);
        fprintf(stderr, "  %s: %u tracked, %u relocalised, %u behind:", drops ? "camera's queue" : "file read ahead",
                o.counts.tracked, o.counts.relocalised, o.counts.behind);
        for (uint32_t k = 0; k < N_QUEUED; k++)
            if (!skipped[k])
                fprintf(stderr, " %u:%s%s%s %.1f mm", k, recon_state_name(o.fr[k].state), o.fr[k].reloc ? "/" : "",
                        recon_reloc_kind_name(o.fr[k].reloc), 1e3 * trans_dist(&o.est[k], &truth[k]));
        fprintf(stderr, "\n");
        CHECK_EQ_INT(o.counts.tracked, N_QUEUED - 5);
        CHECK_EQ_INT(o.counts.lost, 0);
        CHECK_EQ_INT(o.fr[9].state, drops ? RECON_TRACKED : RECON_RELOCALISED);
        if (drops) {
            CHECK_EQ_INT(o.fr[9].reloc, RECON_RELOC_NONE);
            CHECK(o.fr[9].track.inlier_frac >= recon_config_default().reloc.min_inlier_frac);
        }
        for (uint32_t k = 0; k < N_QUEUED; k++)
            if (!skipped[k]) CHECK_LE(trans_dist(&o.est[k], &truth[k]), 0.015);
        mesh_free(&o.points);
    }
    synth_scene_free(&sc);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}

BF_TEST(a_fusing_cadence_of_0_or_beyond_64_is_refused)
{
    gpu_context *ctx;
    GPU_FIXTURE_OPEN(ctx);
    bf_intrinsics K = test_K();
    bf_se3 I = bf_se3_identity();
    const uint32_t bad[][2] = {{0, 4}, {1, 0}, {RECON_MAX_FUSE_EVERY + 1, 4}, {1, RECON_MAX_FUSE_EVERY + 1}};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        recon_config cfg = fixture_run_config().loop;
        cfg.fuse_every = bad[i][0];
        cfg.fuse_every_behind = bad[i][1];
        recon *r = NULL;
        CHECK_STATUS(recon_create(ctx, &cfg, &K, &I, &r), BF_INVALID_ARG);
        CHECK(r == NULL);
        CHECK(strstr(bf_last_error(), "fuse_every") != NULL);
    }
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    gpu_context_destroy(ctx);
}
