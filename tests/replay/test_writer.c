/* replay: the TUM-folder writer. */
#include <stdio.h>

#include "replay/replay.h"
#include "replay_test.h"
#include "test.h"

/* A TUM writer (*w) into a fresh folder named name (its path in *dir) for
 * K's camera; the checks fail the test otherwise. */
static void fresh_writer(const char *name, const bf_intrinsics *K, const char **dir, replay_tum_writer **w)
{
    *w = NULL;
    *dir = rt_fresh_dir(name);
    CHECK(*dir);
    CHECK_OK(replay_tum_writer_create(*dir, K, w));
}

BF_TEST(writer_writes_index_files_only_at_finish)
{
    const char *dir;
    bf_intrinsics K = {0, 0, 500, 500, 3.5, 2.5, 5000};
    replay_tum_writer *w;
    fresh_writer("writer_atomic", &K, &dir, &w);
    CHECK(w);
    uint16_t d[4 * 3] = {1, 2, 3};
    uint8_t c[4 * 3 * 3] = {9};
    bf_frame f = {.index = 0, .width = 4, .height = 3, .t_depth_s = 1.0, .t_rgb_s = 1.01, .depth = d, .rgb = c};
    CHECK_OK(replay_tum_writer_add(w, &f));
    char p[1024];
    snprintf(p, sizeof p, "%s/depth.txt", dir);
    CHECK(!bf_file_exists(p));
    snprintf(p, sizeof p, "%s/depth/1.000000.png", dir);
    CHECK(bf_file_exists(p));
    /* Time must advance (depth and colour); size must stay. */
    CHECK_STATUS(replay_tum_writer_add(w, &f), BF_INVALID_ARG);
    f.t_depth_s = 2;
    CHECK_STATUS(replay_tum_writer_add(w, &f), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("colour time");
    f.t_depth_s = 2;
    f.width = 3;
    CHECK_STATUS(replay_tum_writer_add(w, &f), BF_INVALID_ARG);
    CHECK_OK(replay_tum_writer_finish(w));
    snprintf(p, sizeof p, "%s/depth.txt", dir);
    CHECK(bf_file_exists(p));
    snprintf(p, sizeof p, "%s/camera.txt", dir);
    char *cam;
    CHECK_OK(bf_read_file(p, &cam, NULL));
    double v[5];
    CHECK_EQ_INT(sscanf(cam, "%lf %lf %lf %lf %lf", &v[0], &v[1], &v[2], &v[3], &v[4]), 5);
    free(cam);
    CHECK(v[0] == 500 && v[2] == 3.5 && v[3] == 2.5 && v[4] == 5000);
    snprintf(p, sizeof p, "%s/groundtruth.txt", dir);
    CHECK(!bf_file_exists(p)); /* no frame had a pose */
    replay_tum_writer_destroy(w);
    replay_tum_writer_destroy(NULL);
}

BF_TEST(a_depth_only_folder_reads_back)
{
    /* No frame with colour: no rgb.txt, and the folder reads as depth only
     * (an empty rgb.txt is refused by the reader, "no frames listed"). */
    const char *dir;
    bf_intrinsics K = {4, 3, 500, 500, 1.5, 1, 5000};
    replay_tum_writer *w;
    fresh_writer("writer_depth_only", &K, &dir, &w);
    CHECK(w);
    uint16_t d[4 * 3] = {1000, 2000, 3000};
    for (int k = 0; k < 2; k++) {
        bf_frame f = {.index = (uint32_t)k, .width = 4, .height = 3, .t_depth_s = 1.0 + k, .t_rgb_s = 1.0 + k, .depth = d};
        CHECK_OK(replay_tum_writer_add(w, &f));
    }
    CHECK_OK(replay_tum_writer_finish(w));
    replay_tum_writer_destroy(w);
    char p[1024];
    snprintf(p, sizeof p, "%s/rgb.txt", dir);
    CHECK(!bf_file_exists(p));
    rgbd_source *src;
    CHECK_OK(replay_open(dir, NULL, &src));
    bf_frame f;
    uint32_t n = 0;
    while (rgbd_source_next(src, &f) == BF_OK) {
        CHECK(f.rgb == NULL);
        CHECK(f.depth[1] == 2000);
        n++;
    }
    CHECK_EQ_INT(n, 2);
    rgbd_source_close(src);
}

BF_TEST(writer_then_reader_round_trip_is_bit_exact)
{
    const char *data = bf_test_data("tum/frames");
    if (!data) BF_SKIP("tum/frames absent");
    char src_dir[1024];
    snprintf(src_dir, sizeof src_dir, "%s", data);
    char dir[1024];
    snprintf(dir, sizeof dir, "%s", rt_fresh_dir("writer_rt"));
    bf_intrinsics K = {0, 0, 520.9, 521.0, 325.1, 249.7, 5000};
    replay_tum_writer *w;
    CHECK_OK(replay_tum_writer_create(dir, &K, &w));
    const char *v[3] = {"a", "b1", "b2"};
    uint16_t *dep[3];
    uint8_t *col[3];
    for (int k = 0; k < 3; k++) {
        char p[1200];
        uint32_t ww, hh;
        snprintf(p, sizeof p, "%s/fr2_desk_%s_depth.png", src_dir, v[k]);
        CHECK(rt_png_read_u16(p, &dep[k], &ww, &hh));
        snprintf(p, sizeof p, "%s/fr2_desk_%s_rgb.png", src_dir, v[k]);
        CHECK(rt_png_read_rgb8(p, &col[k], &ww, &hh));
        bf_frame f = {.index = (uint32_t)k, .width = ww, .height = hh, .t_depth_s = 1305031102.175304 + k / 30.0,
                      .depth = dep[k], .rgb = col[k], .has_pose = k != 1};
        f.t_rgb_s = f.t_depth_s + 0.004;
        f.T_wc = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0, 0, 1), 3.0 + k), bf_v3(k, 2, 3));
        CHECK_OK(replay_tum_writer_add(w, &f));
    }
    CHECK_OK(replay_tum_writer_finish(w));
    replay_tum_writer_destroy(w);

    rgbd_source *src;
    CHECK_OK(replay_open(dir, NULL, &src));
    CHECK_EQ_INT(src->n_frames, 3);
    CHECK(src->has_groundtruth);
    /* camera.txt carries the intrinsics exactly. */
    CHECK(src->intrinsics.fx_px == 520.9 && src->intrinsics.fy_px == 521.0 && src->intrinsics.cx_px == 325.1 &&
          src->intrinsics.cy_px == 249.7 && src->intrinsics.depth_scale == 5000);
    for (int k = 0; k < 3; k++) {
        bf_frame f;
        CHECK_OK(rgbd_source_next(src, &f));
        CHECK(memcmp(f.depth, dep[k], 640 * 480 * 2) == 0);
        CHECK(memcmp(f.rgb, col[k], 640 * 480 * 3) == 0);
        /* Times go through 6 decimals, as TUM writes them. */
        CHECK_NEAR(f.t_depth_s, 1305031102.175304 + k / 30.0, 1e-6);
        CHECK_NEAR(f.t_rgb_s - f.t_depth_s, 0.004, 2e-6);
        /* Frame 1 has no pose of its own, but lies between frames 0 and 2
         * of groundtruth.txt, so it gets the interpolated one. */
        CHECK(f.has_pose);
        if (k != 1) {
            bf_se3 T = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0, 0, 1), 3.0 + k), bf_v3(k, 2, 3));
            bf_se3 Ti = bf_se3_inverse(&T);
            bf_se3 D = bf_se3_mul(&Ti, &f.T_wc);
            CHECK_LE(bf_se3_angle(&D), 1e-8);
            CHECK_LE(bf_v3_norm(D.t), 1e-8);
        }
        free(dep[k]);
        free(col[k]);
    }
    rgbd_source_close(src);
}

BF_TEST(writer_failed_add_leaves_the_index_files_as_they_were)
{
    const char *dir;
    bf_intrinsics K = {0, 0, 500, 500, 3.5, 2.5, 5000};
    replay_tum_writer *w;
    fresh_writer("writer_failed_add", &K, &dir, &w);
    CHECK(w);
    uint16_t d[4 * 3] = {1, 2, 3};
    uint8_t c[4 * 3 * 3] = {9};
    bf_frame f = {.index = 0, .width = 4, .height = 3, .t_depth_s = 1.0, .t_rgb_s = 1.0, .depth = d, .rgb = c,
                  .has_pose = true, .T_wc = bf_se3_identity()};
    /* A folder where frame 0's colour PNG should go: the depth PNG is
     * written, the colour PNG fails. */
    char p[1024];
    snprintf(p, sizeof p, "%s/rgb/1.000000.png", dir);
    CHECK_OK(bf_mkdir_p(p));
    CHECK(replay_tum_writer_add(w, &f) != BF_OK);
    CHECK_ERROR_MENTIONS("1.000000.png");
    /* The frame is retried later and the folder finished: one line each. */
    f.t_depth_s = f.t_rgb_s = 2.0;
    CHECK_OK(replay_tum_writer_add(w, &f));
    CHECK_OK(replay_tum_writer_finish(w));
    replay_tum_writer_destroy(w);
    static const char *const index[3] = {"depth.txt", "rgb.txt", "groundtruth.txt"};
    for (int k = 0; k < 3; k++) {
        snprintf(p, sizeof p, "%s/%s", dir, index[k]);
        char *txt;
        CHECK_OK(bf_read_file(p, &txt, NULL));
        bool has_failed = strstr(txt, "1.000000 ") != NULL, has_retry = strstr(txt, "2.000000 ") != NULL;
        free(txt);
        CHECK(!has_failed);
        CHECK(has_retry);
    }
}
