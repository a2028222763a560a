/* replay: the shared sequence options and camera specifications. */
#include "replay/replay.h"
#include "replay_test.h"
#include "test.h"

BF_TEST(options_parse_good_values_in_both_spellings)
{
    char *argv[] = {"cmd", "seq", "--camera", "fr3", "--depth-scale=1000", "--frames", "25", "--skip-bad-frames",
                    "--json", "--frames=7", "--camera=1,2,3,4"};
    int argc = (int)(sizeof argv / sizeof argv[0]);
    replay_options opt = {0};
    int i = 1;
    CHECK_EQ_INT(replay_parse_option(argc, argv, &i, &opt), 0); /* "seq" is not an option */
    CHECK_EQ_INT(i, 1);
    i = 2;
    CHECK_EQ_INT(replay_parse_option(argc, argv, &i, &opt), 1);
    CHECK_EQ_INT(i, 4);
    CHECK(!strcmp(opt.camera, "fr3"));
    CHECK_EQ_INT(replay_parse_option(argc, argv, &i, &opt), 1);
    CHECK_EQ_INT(i, 5);
    CHECK(opt.depth_scale == 1000);
    CHECK_EQ_INT(replay_parse_option(argc, argv, &i, &opt), 1);
    CHECK_EQ_INT(opt.max_frames, 25);
    CHECK_EQ_INT(replay_parse_option(argc, argv, &i, &opt), 1);
    CHECK(opt.skip_bad_frames);
    CHECK_EQ_INT(i, 8);
    CHECK_EQ_INT(replay_parse_option(argc, argv, &i, &opt), 0); /* --json belongs to the command */
    i = 9;
    CHECK_EQ_INT(replay_parse_option(argc, argv, &i, &opt), 1);
    CHECK_EQ_INT(opt.max_frames, 7);
    CHECK_EQ_INT(replay_parse_option(argc, argv, &i, &opt), 1);
    CHECK(!strcmp(opt.camera, "1,2,3,4"));
    CHECK_EQ_INT(i, argc);
    CHECK_EQ_INT(replay_parse_option(argc, argv, &i, &opt), 0);
    CHECK(strstr(replay_options_help(), "--skip-bad-frames"));
}

/* Parses argv[0] (and its value) alone; returns the result. */
static int parse_one(char *a, char *b, replay_options *opt)
{
    char *argv[3] = {a, b, NULL};
    int i = 0;
    return replay_parse_option(b ? 2 : 1, argv, &i, opt);
}

BF_TEST(options_reject_bad_values_with_a_message)
{
    replay_options opt = {0};
    struct {
        char *a, *b, *mention;
    } bad[] = {
        {"--camera", "fr4", "fr4"},          {"--camera", "1,2,3", "1,2,3"},   {"--camera", "1,2,3,4,5", "1,2,3,4,5"},
        {"--camera", "0,500,320,240", "zero"}, {"--camera", "a,b,c,d", "a,b,c,d"}, {"--camera", NULL, "missing"},
        {"--depth-scale", "0", "'0'"},       {"--depth-scale", "-5", "'-5'"},  {"--depth-scale", "inf", "inf"},
        {"--depth-scale", "5000x", "5000x"}, {"--frames", "0", "'0'"},         {"--frames", "-3", "-3"},
        {"--frames", "2.5", "2.5"},          {"--frames", NULL, "missing"},    {"--frames=", NULL, "''"},
    };
    for (size_t k = 0; k < sizeof bad / sizeof bad[0]; k++) {
        bf_clear_error();
        int r = parse_one(bad[k].a, bad[k].b, &opt);
        if (r != -1) bf__test_fail(__FILE__, __LINE__, "case %zu (%s %s) gave %d", k, bad[k].a, bad[k].b, r);
        CHECK_EQ_INT(r, -1);
        CHECK_ERROR_MENTIONS(bad[k].mention);
    }
    /* Nothing was set by the failures. */
    CHECK(opt.camera == NULL && opt.depth_scale == 0 && opt.max_frames == 0 && !opt.skip_bad_frames);
    /* Prefixes of other options are not ours. */
    CHECK_EQ_INT(parse_one("--cameras", "x", &opt), 0);
    CHECK_EQ_INT(parse_one("--frames-per-second", "x", &opt), 0);
}

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
