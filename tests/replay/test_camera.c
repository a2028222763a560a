/* replay: camera presets and --camera specifications. */
#include "replay/replay.h"
#include "replay_test.h"
#include "test.h"

BF_TEST(camera_presets_are_tums_published_calibration)
{
    bf_intrinsics K = {.width = 7, .height = 9, .depth_scale = 123};
    CHECK_OK(replay_parse_camera("fr1", &K));
    CHECK(K.fx_px == 517.3 && K.fy_px == 516.5 && K.cx_px == 318.6 && K.cy_px == 255.3);
    CHECK_OK(replay_parse_camera("fr2", &K));
    CHECK(K.fx_px == 520.9 && K.fy_px == 521.0 && K.cx_px == 325.1 && K.cy_px == 249.7);
    CHECK_OK(replay_parse_camera("fr3", &K));
    CHECK(K.fx_px == 535.4 && K.fy_px == 539.2 && K.cx_px == 320.1 && K.cy_px == 247.6);
    CHECK_OK(replay_parse_camera("icl", &K));
    CHECK(K.fx_px == 481.2 && K.fy_px == -480.0);
    CHECK_OK(replay_parse_camera("481.2,-480,319.5,239.5", &K));
    CHECK(K.fy_px == -480.0 && K.cy_px == 239.5);
    /* Size and depth scale are left alone. */
    CHECK(K.width == 7 && K.height == 9 && K.depth_scale == 123);
    CHECK_STATUS(replay_parse_camera("FR1", &K), BF_INVALID_ARG);
    CHECK_STATUS(replay_parse_camera("", &K), BF_INVALID_ARG);
    CHECK_STATUS(replay_parse_camera("1,,2,3", &K), BF_INVALID_ARG);
}

/* The lens that goes with a camera: TUM's published distortion for fr1 and
 * fr2, none for fr3 (undistorted before publishing) and ICL-NUIM; nine
 * numbers give it; replay_parse_camera (a pinhole's commands) drops a
 * preset's and refuses numbers with one. */
BF_TEST(camera_presets_carry_their_lens)
{
    bf_intrinsics K = {0};
    double dist[CALIB_DIST_N];
    CHECK_OK(replay_parse_camera_lens("fr1", &K, dist));
    CHECK(dist[0] == 0.2624 && dist[1] == -0.9531 && dist[2] == -0.0054 && dist[3] == 0.0026 && dist[4] == 1.1633);
    CHECK(K.fx_px == 517.3);
    CHECK_OK(replay_parse_camera_lens("fr2", &K, dist));
    CHECK(dist[0] == 0.2312 && dist[1] == -0.7849 && dist[2] == -0.0033 && dist[3] == -0.0001 && dist[4] == 0.9172);
    CHECK_OK(replay_parse_camera_lens("fr3", &K, dist));
    CHECK(!calib_has_distortion(dist));
    CHECK_OK(replay_parse_camera_lens("icl", &K, dist));
    CHECK(!calib_has_distortion(dist));
    CHECK_OK(replay_parse_camera_lens("500,501,300,200", &K, dist));
    CHECK(!calib_has_distortion(dist) && K.fx_px == 500 && K.cy_px == 200);
    CHECK_OK(replay_parse_camera_lens("500,501,300,200,0.1,-0.2,0.001,-0.002,0.3", &K, dist));
    CHECK(dist[0] == 0.1 && dist[1] == -0.2 && dist[2] == 0.001 && dist[3] == -0.002 && dist[4] == 0.3);
    CHECK_STATUS(replay_parse_camera_lens("500,501,300,200,0.1", &K, dist), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("k1,k2,p1,p2,k3");
    CHECK_STATUS(replay_parse_camera_lens("500,501,300,200,0.1,0,0,0,0,7", &K, dist), BF_INVALID_ARG);
    /* The pinhole's parser. */
    K = (bf_intrinsics){0};
    CHECK_OK(replay_parse_camera("fr1", &K));
    CHECK(K.fx_px == 517.3);
    CHECK_OK(replay_parse_camera("500,501,300,200,0,0,0,0,0", &K));
    CHECK_STATUS(replay_parse_camera("500,501,300,200,0.1,0,0,0,0", &K), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("a lens (distortion coefficients) is not applied here");
}
