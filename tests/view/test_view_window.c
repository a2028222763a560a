/* view: the window shows the headless ray-cast byte for byte. A torus is
 * voxelised into a map (render_voxelise_mesh), ray-cast at a pose, shown
 * in the window for a few frames, and the last frame read back from the
 * swapchain is compared with render_download's image of the same cast;
 * then a cast of half the window's size, which the blit stretches (each
 * window pixel the cast pixel under it). Runs under Xvfb (with_xvfb.sh);
 * skips without a display or a device that presents. Validation is on. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "gpu_fixture.h"
#include "mesh_shapes.h"
#include "mesh/mesh.h"
#include "render/render.h"
#include "view/view.h"

enum { W = 200, H = 150 };

/* Shows caster's image for 3 frames and reads the last back into rgb. */
static bf_status show_three(view_window *w, render_caster *rc, fusion_map *map, const bf_intrinsics *K, uint8_t *rgb)
{
    render_options ro = render_options_display();
    bf_status s = BF_OK;
    for (int i = 0, shown = 0; s == BF_OK && shown < 3 && i < 20; i++) {
        bool is_shown = false;
        if (!view_poll(w)) return BF_IO;
        bf_se3 T = view_pose(w);
        s = render_raycast(rc, map, K, &T, &ro);
        if (s == BF_OK) s = view_show(w, render_get_targets(rc), shown == 2 ? rgb : NULL, &is_shown);
        shown += is_shown;
    }
    return s;
}

BF_TEST(window_shows_the_headless_raycast_byte_for_byte_and_stretches_a_smaller_one)
{
    if (!getenv("DISPLAY")) BF_SKIP("no display (run under Xvfb: tests/view/with_xvfb.sh)");
    view_config vc = view_config_default();
    vc.width = W, vc.height = H, vc.overlay = false;
    gpu_config gcfg = gpu_fixture_config();
    view_window *w = NULL;
    bf_status s = view_open(&vc, &gcfg, &w);
    if (s == BF_NO_DEVICE) BF_SKIP(bf_last_error());
    CHECK_OK(s);
    gpu_context *ctx = NULL;
    s = gpu_context_create(&gcfg, &ctx);
    if (s == BF_NO_DEVICE || s == BF_UNSUPPORTED) {
        view_destroy(w);
        BF_SKIP(bf_last_error());
    }
    CHECK_OK(s);
    /* Every fault point of view_attach (swapchain, semaphores, fence,
     * pipeline, buffers, binding set) in turn: a refusal leaves nothing
     * behind, or the next attach could not make a swapchain on the same
     * window (VK_ERROR_NATIVE_WINDOW_IN_USE_KHR) and validation would name
     * the leaked objects at the device's destruction. */
    uint32_t n_faults = 0;
    for (uint32_t n = 1; n < 200; n++) {
        bf_fault_arm(n);
        s = view_attach(w, ctx);
        if (bf_fault_arm(0) != 0) { /* the countdown never reached 0: past the last point */
            CHECK_OK(s);
            break;
        }
        CHECK(s != BF_OK);
        n_faults++;
    }
    CHECK(n_faults >= 5);
    printf("  %u fault points of view_attach walked\n", n_faults);
    uint32_t vw, vh;
    view_size(w, &vw, &vh);
    CHECK_EQ_INT(vw, W); /* Xvfb has no window manager to resize it */
    CHECK_EQ_INT(vh, H);

    mesh_data m = test_torus(0.3, 0.1, 96, 48);
    render_voxelise_config cfg = render_voxelise_config_default();
    cfg.level = 5; /* 7.8 mm voxels: a few thousand bricks */
    hostmap hm;
    CHECK_OK(render_voxelise_mesh(ctx, &m, NULL, &cfg, &hm, NULL));
    fusion_config fc = fusion_config_default();
    fc.brick_cap = hm.n_bricks + 64;
    fc.node_cap = 16 * hm.n_bricks + 1024;
    const bf_intrinsics K = {W, H, 170.0, 170.0, 99.5, 74.5, 5000};
    fusion_map *map;
    CHECK_OK(fusion_create(ctx, &fc, &K, hm.origin_w, &map));
    CHECK_OK(fusion_load(map, &hm));

    /* Looking at the torus from 1.2 m, turned so its hole shows. */
    bf_quat q = bf_quat_mul(bf_quat_from_axis_angle(bf_v3(0, 1, 0), 0.4), bf_quat_from_axis_angle(bf_v3(1, 0, 0), -0.6));
    bf_se3 T = bf_se3_from_qt(q, bf_v3_scale(bf_quat_rotate(q, bf_v3(0, 0, 1)), -1.2));
    view_set_pose(w, &T, 1.2);
    bf_se3 T_view = view_pose(w);
    CHECK(memcmp(&T_view, &T, sizeof T) == 0);
    CHECK(!view_is_following(w));

    /* Same size: the bytes of the cast. */
    render_caster *rc;
    CHECK_OK(render_create(ctx, NULL, W, H, &rc));
    uint8_t *shot = malloc(3 * W * H);
    CHECK_OK(show_three(w, rc, map, &K, shot));
    render_images im;
    CHECK_OK(render_download(rc, &im));
    uint32_t n_lit = 0, n_diff = 0;
    for (uint32_t i = 0; i < W * H; i++) {
        n_lit += im.rgb[3 * i] || im.rgb[3 * i + 1] || im.rgb[3 * i + 2];
        n_diff += memcmp(im.rgb + 3 * i, shot + 3 * i, 3) != 0;
    }
    CHECK(n_lit > W * H / 10); /* the torus is in view */
    CHECK_EQ_INT(n_diff, 0);
    render_images_free(&im);
    render_destroy(rc);

    /* The overlay (on by default; off above): the status line changes the
     * band's 2 + 5 + 2 = 9 rows (scale 1 below 640 px) and nothing below. */
    view_set_overlay(w, true);
    view_status st = {.has_frame = true, .frame = 7, .state = "tracked", .n_bricks = hm.n_bricks};
    view_set_status(w, &st);
    CHECK_OK(render_create(ctx, NULL, W, H, &rc));
    CHECK_OK(show_three(w, rc, map, &K, shot));
    CHECK_OK(render_download(rc, &im));
    uint32_t n_band = 0;
    n_diff = 0;
    for (uint32_t i = 0; i < W * H; i++) {
        bool differs = memcmp(im.rgb + 3 * i, shot + 3 * i, 3) != 0;
        if (i / W < 9) n_band += differs;
        else n_diff += differs;
    }
    CHECK(n_band > 100); /* about 30 characters of up to 15 pixels, and the darkened band */
    CHECK_EQ_INT(n_diff, 0);
    render_images_free(&im);
    render_destroy(rc);
    view_set_overlay(w, false);

    /* Half the size: window pixel (x, y) shows cast pixel (x / 2, y / 2). */
    const bf_intrinsics K2 = {W / 2, H / 2, 85.0, 85.0, 49.75, 37.25, 5000};
    CHECK_OK(render_create(ctx, NULL, W / 2, H / 2, &rc));
    CHECK_OK(show_three(w, rc, map, &K2, shot));
    CHECK_OK(render_download(rc, &im));
    n_diff = 0;
    for (uint32_t y = 0; y < H; y++)
        for (uint32_t x = 0; x < W; x++)
            n_diff += memcmp(im.rgb + 3 * ((y / 2) * (W / 2) + x / 2), shot + 3 * (y * W + x), 3) != 0;
    CHECK_EQ_INT(n_diff, 0);
    render_images_free(&im);
    render_destroy(rc);

    free(shot);
    fusion_destroy(map);
    hostmap_free(&hm);
    mesh_free(&m);
    GPU_FIXTURE_CHECK_CLEAN(ctx);
    view_detach(w);
    gpu_context_destroy(ctx);
    view_destroy(w);
}
