/* replay: ICL-NUIM in its numbered layout (the real shared frames) and its
 * TUM-like layout with the negative-fy camera. */
#include <stdio.h>
#include <unistd.h>

#include "replay/replay.h"
#include "replay_test.h"
#include "test.h"

/* pose.txt of the shared data, second line (frame index 1). */
static const double pose1[7] = {-0.101611, 0.08215, -2.33163, -0.0231916, -0.376659, -0.17448, 0.909476};

BF_TEST(icl_numbered_layout_reads_real_frames_poses_and_negative_fy)
{
    const char *p = bf_test_data("icl_nuim");
    if (!p) BF_SKIP("icl_nuim absent");
    char dir[1024];
    snprintf(dir, sizeof dir, "%s", p);
    rgbd_source *src;
    CHECK_OK(replay_open(dir, NULL, &src));
    CHECK(!strcmp(src->kind, "icl-nuim"));
    CHECK_EQ_INT(src->n_frames, 5);
    CHECK(src->has_groundtruth);
    const bf_intrinsics *K = rgbd_source_intrinsics(src);
    CHECK(K->fx_px == 481.2 && K->fy_px == -480.0 && K->cx_px == 319.5 && K->cy_px == 239.5);
    CHECK(K->depth_scale == 5000 && K->width == 640 && K->height == 480);
    bf_frame f;
    for (uint32_t i = 0; i < 5; i++) {
        CHECK_OK(rgbd_source_next(src, &f));
        CHECK_EQ_INT(f.index, i);
        CHECK_NEAR(f.t_depth_s, i / 30.0, 1e-12);
        CHECK(f.has_pose);
        if (i == 1) {
            bf_quat q = bf_quat_normalize((bf_quat){pose1[6], pose1[3], pose1[4], pose1[5]});
            bf_se3 T = bf_se3_from_qt(q, bf_v3(pose1[0], pose1[1], pose1[2]));
            CHECK_NEAR(f.T_wc.t.x, pose1[0], 0);
            CHECK_NEAR(f.T_wc.t.y, pose1[1], 0);
            CHECK_NEAR(f.T_wc.t.z, pose1[2], 0);
            bf_se3 Ti = bf_se3_inverse(&T);
            bf_se3 D = bf_se3_mul(&Ti, &f.T_wc);
            CHECK_LE(bf_se3_angle(&D), 1e-12);
            /* Pixels equal an independent decode of depth/2.png, color/2.png. */
            uint16_t *d;
            uint8_t *c;
            uint32_t w, h;
            CHECK(rt_png_read_u16(rt_join(dir, "depth/2.png"), &d, &w, &h));
            CHECK(w == 640 && h == 480 && memcmp(d, f.depth, (size_t)w * h * 2) == 0);
            free(d);
            CHECK(rt_png_read_rgb8(rt_join(dir, "color/2.png"), &c, &w, &h));
            CHECK(f.rgb && memcmp(c, f.rgb, (size_t)w * h * 3) == 0);
            free(c);
        }
    }
    CHECK_STATUS(rgbd_source_next(src, &f), BF_END);
    rgbd_source_close(src);
}

/* A copy of the ICL folder with links to the images and our own pose.txt. */
static const char *icl_copy(const char *name, const char *pose_txt)
{
    const char *data = bf_test_data("icl_nuim");
    if (!data) return NULL;
    char src[1024];
    snprintf(src, sizeof src, "%s", data);
    static char d[1024];
    snprintf(d, sizeof d, "%s", rt_fresh_dir(name));
    for (int k = 1; k <= 5; k++) {
        char a[1200], b[64];
        snprintf(a, sizeof a, "%s/depth/%d.png", src, k);
        snprintf(b, sizeof b, "depth/%d.png", k);
        if (!rt_link(a, d, b)) return NULL;
        snprintf(a, sizeof a, "%s/color/%d.png", src, k);
        snprintf(b, sizeof b, "color/%d.png", k);
        if (!rt_link(a, d, b)) return NULL;
    }
    if (pose_txt && !rt_write_text(rt_join(d, "pose.txt"), pose_txt)) return NULL;
    return d;
}

BF_TEST(icl_bad_pose_file_names_file_and_line)
{
    const char *d = icl_copy("icl_bad", "0 0 0 0 0 0 1\n0 0 0 0 0 0 1\n0 0 0 0 0 0 1\n0 0 0 0 0 0 1\n");
    if (!d) BF_SKIP("icl_nuim absent");
    char dir[1024];
    snprintf(dir, sizeof dir, "%s", d);
    rgbd_source *src = NULL;
    CHECK_STATUS(replay_open(dir, NULL, &src), BF_FORMAT);
    CHECK_ERROR_MENTIONS("pose.txt");
    CHECK_ERROR_MENTIONS("4 poses for 5");
    CHECK(rt_write_text(rt_join(dir, "pose.txt"),
                        "0 0 0 0 0 0 1\n0 0 0 0 0 0 1\n0 nan 0 0 0 0 1\n0 0 0 0 0 0 1\n0 0 0 0 0 0 1\n"));
    CHECK_STATUS(replay_open(dir, NULL, &src), BF_FORMAT);
    CHECK_ERROR_MENTIONS("pose.txt:3");
    CHECK(rt_write_text(rt_join(dir, "pose.txt"), "0 0 0 0 0 0 1\n0 0 0 0 0 1\n"));
    CHECK_STATUS(replay_open(dir, NULL, &src), BF_FORMAT);
    CHECK_ERROR_MENTIONS("pose.txt:2");
    CHECK(rt_write_text(rt_join(dir, "pose.txt"), "0 0 0 0 0 0 1\n0 0 0 0 0 0 1\n0 0 0 0 0 0 1\n"
                                                  "0 0 0 0 0 0 1\n0 0 0 0 0 0 1\n0 0 0 0 0 0 1\n"));
    CHECK_STATUS(replay_open(dir, NULL, &src), BF_FORMAT);
    CHECK_ERROR_MENTIONS("pose.txt:6");
    /* Without pose.txt the frames simply have no ground truth. */
    CHECK(unlink(rt_join(dir, "pose.txt")) == 0);
    CHECK_OK(replay_open(dir, NULL, &src));
    CHECK(!src->has_groundtruth);
    bf_frame f;
    CHECK_OK(rgbd_source_next(src, &f));
    CHECK(!f.has_pose);
    rgbd_source_close(src);
}

BF_TEST(icl_tum_like_layout_with_icl_camera)
{
    const char *d = icl_copy("icl_tum", NULL);
    if (!d) BF_SKIP("icl_nuim absent");
    char dir[1024];
    snprintf(dir, sizeof dir, "%s", d);
    CHECK(rt_write_text(rt_join(dir, "depth.txt"), "0 depth/1.png\n1 depth/2.png\n2 depth/3.png\n"));
    CHECK(rt_write_text(rt_join(dir, "rgb.txt"), "0 color/1.png\n1 color/2.png\n2 color/3.png\n"));
    replay_options opt = {.camera = "icl"};
    rgbd_source *src;
    CHECK_OK(replay_open(dir, &opt, &src));
    CHECK(!strcmp(src->kind, "tum"));
    CHECK_EQ_INT(src->n_frames, 3);
    CHECK(src->intrinsics.fy_px == -480.0 && src->intrinsics.fx_px == 481.2);
    rgbd_source_close(src);
    opt.camera = "481.2,-480,319.5,239.5";
    CHECK_OK(replay_open(dir, &opt, &src));
    CHECK(src->intrinsics.fy_px == -480.0);
    rgbd_source_close(src);
}
