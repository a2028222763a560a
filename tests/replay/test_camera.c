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
