/* The runner's policies (recon_run_sequence): first pose, a source that
 * fails mid-scan, the stop flag, fusion at known poses, fusing at ground
 * truth without it. Frames are the fixture's 320x240 room. */
#include <string.h>

#include "gpu_fixture.h"
#include "recon_fixture.h"
#include "recon/recon.h"
#include "test.h"

enum { N = 8, FAIL_AT = 5 };

/* The fixture's frames; frame FAIL_AT fails like an unplugged device, or
 * frame 2 loses its ground truth. */
typedef struct faulty {
    rgbd_source *inner;
    bool fail, drop_pose;
} faulty;

static bf_status faulty_frame(void *user, uint32_t k, bf_frame *f)
{
    faulty *fy = user;
    if (fy->fail && k == FAIL_AT) return bf_fail(BF_IO, "camera: frame %u: device went away", k);
    bf_status s = rgbd_source_next(fy->inner, f);
    if (s == BF_OK && fy->drop_pose && k == 2) f->has_pose = false;
    return s;
}

static volatile sig_atomic_t g_stop;

/* The device (the test skips without one) and the room every test runs in. */
#define OPEN_ROOM(ctx, sc)                                                                                   \
    GPU_FIXTURE_OPEN(ctx);                                                                                 \
    CHECK_OK(synth_scene_room(NULL, &(sc)))

static bf_status stop_after_3(void *user, recon_run *run, const bf_frame *f, const recon_frame_result *fr)
{
    (void)user, (void)run, (void)fr;
    if (f->index == 3) g_stop = 1;
    return BF_OK;
}

/* Runs N frames of the sweep through the runner with cfg. */
static bf_status run(gpu_context *ctx, const synth_scene *sc, faulty fy, const recon_run_config *cfg,
                     recon_frame_fn on_frame, recon_run *out)
{
    bf_se3 truth[N], I = bf_se3_identity();
    for (uint32_t k = 0; k < N; k++) truth[k] = sweep_pose(sc, k);
    fixture_render fr;
    rgbd_source *src = NULL;
    bf_intrinsics K = test_K();
    bf_status s = fixture_render_open(sc, truth, N, &I, NULL, &fr, &fy.inner);
    if (s == BF_OK) s = capture_source_from_fn(&K, N, true, faulty_frame, &fy, &src);
    if (s == BF_OK) s = recon_run_sequence(ctx, src, cfg, on_frame, NULL, out);
    rgbd_source_close(src);
    if (fy.inner) fixture_render_close(&fr, fy.inner);
    return s;
}

BF_TEST(runner_keeps_the_map_of_a_source_that_fails_mid_scan)
{
    gpu_context *ctx;
    synth_scene sc;
    OPEN_ROOM(ctx, sc);
    recon_run_config cfg = fixture_run_config();
    recon_run r;
    CHECK_STATUS(run(ctx, &sc, (faulty){.fail = true}, &cfg, NULL, &r), BF_IO);
    recon_run_free(&r);
    cfg.keep_on_source_error = true;
    CHECK_OK(run(ctx, &sc, (faulty){.fail = true}, &cfg, NULL, &r));
    CHECK_EQ_INT(r.source_status, BF_IO);
    CHECK(strstr(r.source_error, "device went away"));
    CHECK_EQ_INT(r.est.n, FAIL_AT);
    CHECK(r.map != NULL);
    CHECK_OK(fusion_check(r.map));
    /* The first pose is the first frame's ground truth. */
    CHECK_NEAR(trans_dist(&r.est.T_wc[0], &r.gt.T_wc[0]), 0, 1e-12);
    recon_run_free(&r);
    synth_scene_free(&sc);
    gpu_context_destroy(ctx);
}

BF_TEST(runner_stops_at_the_flag_and_starts_at_identity_when_asked)
{
    gpu_context *ctx;
    synth_scene sc;
    OPEN_ROOM(ctx, sc);
    recon_run_config cfg = fixture_run_config();
    cfg.stop = &g_stop;
    cfg.init_identity = true;
    g_stop = 0;
    recon_run r;
    CHECK_OK(run(ctx, &sc, (faulty){0}, &cfg, stop_after_3, &r));
    CHECK(r.is_interrupted);
    CHECK_EQ_INT(r.est.n, 4);
    bf_se3 I = bf_se3_identity();
    CHECK_NEAR(trans_dist(&r.est.T_wc[0], &I), 0, 1e-12);
    recon_run_free(&r);
    synth_scene_free(&sc);
    gpu_context_destroy(ctx);
}

BF_TEST(runner_fuses_at_known_poses_and_skips_frames_without_one)
{
    gpu_context *ctx;
    synth_scene sc;
    OPEN_ROOM(ctx, sc);
    recon_run_config cfg = fixture_run_config();
    cfg.poses = RECON_POSES_KNOWN;
    recon_run r;
    CHECK_OK(run(ctx, &sc, (faulty){.drop_pose = true}, &cfg, NULL, &r));
    CHECK(r.loop == NULL && r.map != NULL);
    CHECK_EQ_INT(r.n_fused, N - 1);
    CHECK_EQ_INT(r.n_skipped, 1);
    CHECK_EQ_INT(r.est.n, N - 1);
    for (size_t i = 0; i < r.est.n; i++) CHECK_NEAR(trans_dist(&r.est.T_wc[i], &r.gt.T_wc[i]), 0, 1e-12);
    CHECK_OK(fusion_check(r.map));
    recon_run_free(&r);
    /* Fusing at ground truth passes over a frame without it, as the known
     * poses do: counted, no estimate, the rest tracked (not the end of the run). */
    cfg.poses = RECON_POSES_TRACK_FUSE_GT;
    cfg.name = "room";
    CHECK_OK(run(ctx, &sc, (faulty){.drop_pose = true}, &cfg, NULL, &r));
    CHECK_EQ_INT(r.n_skipped, 1);
    CHECK_EQ_INT(r.est.n, N - 1);
    CHECK_EQ_INT(r.counts.frames, N - 1);
    recon_run_free(&r);
    synth_scene_free(&sc);
    gpu_context_destroy(ctx);
}
