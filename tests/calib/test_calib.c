/* calib: calib.json written and read back bit for bit, every malformed
 * field refused by name, the camera model against its inverse, and the
 * estimate from exact corners (projected analytically, no images)
 * recovering the cameras and the transform that made them. */
#include <math.h>

#include "calib/calib.h"
#include "shaders/fusion.glsl.h"
#include "synth/synth.h"
#include "test.h"

static calib_result sample_result(void)
{
    calib_result r = {0};
    r.colour = (calib_camera){.width = 640, .height = 480, .fx_px = 525.123456789012345, .fy_px = 524.9876543210987,
                              .cx_px = 319.5 + 1.0 / 3, .cy_px = 239.5 - 1.0 / 7,
                              .dist = {0.1234567890123, -0.2, 1e-4 / 3, -2e-4, 0.05}, .rms_px = 0.1 / 3};
    r.depth = (calib_camera){.width = 640, .height = 480, .fx_px = 580.0 + 1.0 / 9, .fy_px = 580.5,
                             .cx_px = 314.25, .cy_px = 245.0 / 1.1, .rms_px = 0.07};
    bf_quat q = bf_quat_from_axis_angle(bf_v3(0.2, 1, -0.3), 0.6 * M_PI / 180);
    r.T_colour_depth = bf_se3_from_qt(q, bf_v3(-0.025 + 1e-5 / 3, 0.002, -1.0 / 3000));
    r.has_depth = true;
    r.rms_px = 0.123;
    r.n_views = 14;
    return r;
}

BF_TEST(calib_json_round_trip_is_exact)
{
    char path[600];
    snprintf(path, sizeof path, "%s/calib.json", bf_test_tmpdir());
    calib_result r = sample_result(), back;
    CHECK_OK(calib_write(path, &r));
    CHECK_OK(calib_read(path, &back));
    CHECK(back.has_depth);
    CHECK_EQ_INT(back.n_views, 14);
    /* Bit for bit: 17 significant digits read back as the same double. */
    CHECK(memcmp(&back.colour, &r.colour, sizeof r.colour) == 0);
    CHECK(memcmp(&back.depth, &r.depth, sizeof r.depth) == 0);
    CHECK(memcmp(&back.T_colour_depth, &r.T_colour_depth, sizeof r.T_colour_depth) == 0);
    CHECK(back.rms_px == r.rms_px);

    /* Colour alone: no depth, no transform. */
    r.has_depth = false;
    CHECK_OK(calib_write(path, &r));
    CHECK_OK(calib_read(path, &back));
    CHECK(!back.has_depth);
    CHECK(memcmp(&back.colour, &r.colour, sizeof r.colour) == 0);
}

/* A minimal hand-written file: dist, rms_px, views and format may be left out. */
BF_TEST(calib_minimal_file_is_accepted)
{
    const char *t = "{\"colour\": {\"width\": 640, \"height\": 480, \"fx\": 525, \"fy\": 525, \"cx\": 319.5, "
                    "\"cy\": 239.5}, \"extra\": [1, 2]}";
    calib_result r;
    CHECK_OK(calib_parse("hand.json", t, strlen(t), &r));
    CHECK(!r.has_depth);
    CHECK(r.colour.fx_px == 525 && r.colour.dist[0] == 0 && r.colour.dist[4] == 0);
}

BF_TEST(calib_malformed_fields_are_named)
{
    static const char cam[] = "\"width\": 640, \"height\": 480, \"fx\": 525, \"fy\": 525, \"cx\": 319.5, \"cy\": 239.5";
    static const char T[] = "\"T_colour_depth\": {\"R\": [1,0,0, 0,1,0, 0,0,1], \"t\": [0.025, 0, 0]}";
    struct {
        const char *text, *mention;
        bf_status want;
    } cases[] = {
        {"{\"colour\": {", "not JSON", BF_FORMAT},
        {"[1, 2]", "not a JSON object", BF_FORMAT},
        {"{\"version\": 1}\n<<<<<<< HEAD", "text after the JSON value at byte 15", BF_FORMAT},
        /* Behind a byte-order mark the bytes named are still the file's. */
        {"\xEF\xBB\xBF{\"version\": 1}\n<<<<<<< HEAD", "text after the JSON value at byte 18", BF_FORMAT},
        {"\xEF\xBB\xBF{\"version\": 1,}", "not JSON (near byte 17)", BF_FORMAT},
        {"{\"depth\": {}}", "colour: missing", BF_FORMAT},
        {"{\"colour\": {\"width\": 640, \"height\": 480, \"fy\": 525, \"cx\": 319.5, \"cy\": 239.5}}", "colour.fx: missing",
         BF_FORMAT},
        {"{\"colour\": {\"width\": 640, \"height\": 480, \"fx\": -525, \"fy\": 525, \"cx\": 319.5, \"cy\": 239.5}}",
         "colour.fx: -525 is not positive", BF_FORMAT},
        {"{\"colour\": {\"width\": 640, \"height\": 480, \"fx\": 0, \"fy\": 525, \"cx\": 319.5, \"cy\": 239.5}}",
         "colour.fx: 0 is not positive", BF_FORMAT},
        {"{\"colour\": {\"width\": 640, \"height\": 480, \"fx\": 1e999, \"fy\": 525, \"cx\": 319.5, \"cy\": 239.5}}",
         "colour.fx: not finite", BF_FORMAT},
        {"{\"colour\": {\"width\": 640, \"height\": 480, \"fx\": \"525\", \"fy\": 525, \"cx\": 319.5, \"cy\": 239.5}}",
         "colour.fx: not a number", BF_FORMAT},
        {"{\"colour\": {\"width\": 640, \"height\": 480, \"fx\": 525, \"fy\": 525, \"cx\": 700, \"cy\": 239.5}}",
         "colour.cx: 700 is outside", BF_FORMAT},
        {"{\"colour\": {\"width\": 0, \"height\": 480, \"fx\": 525, \"fy\": 525, \"cx\": 0, \"cy\": 239.5}}",
         "colour.width", BF_FORMAT},
        {"{\"colour\": {\"width\": 640, \"height\": 480, \"fx\": 525, \"fy\": 525, \"cx\": 319.5, \"cy\": 239.5, "
         "\"dist\": [0.1, 0, 0, 0]}}",
         "colour.dist: not a list of 5 numbers", BF_FORMAT},
        {"{\"colour\": {\"width\": 640, \"height\": 480, \"fx\": 525, \"fy\": 525, \"cx\": 319.5, \"cy\": 239.5, "
         "\"coverage\": 2}}",
         "colour.coverage: 2 is not a fraction in 0..1", BF_FORMAT},
        {"{\"colour\": {\"width\": 640, \"height\": 480, \"fx\": 525, \"fy\": 525, \"cx\": 319.5, \"cy\": 239.5, "
         "\"extrapolation_px\": -5}}",
         "colour.extrapolation_px: -5 is negative", BF_FORMAT},
        {NULL, "T_colour_depth: missing", BF_FORMAT},   /* depth without T */
        {NULL, "depth: missing", BF_FORMAT},            /* T without depth */
        {NULL, "T_colour_depth.R: not a rotation", BF_FORMAT},
        {NULL, "depth.fy: missing", BF_FORMAT},
        {NULL, "version 2 is newer", BF_UNSUPPORTED},
    };
    char built[6][1024];
    snprintf(built[0], sizeof built[0], "{\"colour\": {%s}, \"depth\": {%s}}", cam, cam);
    snprintf(built[1], sizeof built[1], "{\"colour\": {%s}, %s}", cam, T);
    snprintf(built[2], sizeof built[2],
             "{\"colour\": {%s}, \"depth\": {%s}, \"T_colour_depth\": {\"R\": [1,0,0, 0,1,0, 0,0,-1], \"t\": [0,0,0]}}",
             cam, cam);
    snprintf(built[3], sizeof built[3],
             "{\"colour\": {%s}, \"depth\": {\"width\": 640, \"height\": 480, \"fx\": 580, \"cx\": 320, \"cy\": 240}, %s}",
             cam, T);
    snprintf(built[4], sizeof built[4], "{\"version\": 2, \"colour\": {%s}}", cam);
    size_t n_cases = sizeof cases / sizeof cases[0];
    for (size_t i = 0, b = 0; i < n_cases; i++) {
        const char *text = cases[i].text ? cases[i].text : built[b++];
        calib_result r;
        memset(&r, 0x5a, sizeof r);
        calib_result before = r;
        bf_clear_error();
        CHECK_STATUS(calib_parse("bad.json", text, strlen(text), &r), cases[i].want);
        CHECK_ERROR_MENTIONS("bad.json: ");
        CHECK_ERROR_MENTIONS(cases[i].mention);
        CHECK(memcmp(&r, &before, sizeof r) == 0); /* untouched on failure */
    }
    calib_result r;
    CHECK_STATUS(calib_read("/nonexistent/calib.json", &r), BF_IO);
    CHECK_ERROR_MENTIONS("/nonexistent/calib.json");
}

BF_TEST(calib_undistort_inverts_distort)
{
    const double dist[CALIB_DIST_N] = {0.12, -0.25, 1e-3, -5e-4, 0.08};
    double worst = 0;
    for (double y = -0.5; y <= 0.5; y += 0.05)
        for (double x = -0.65; x <= 0.65; x += 0.05) {
            double xd, yd, xu, yu;
            calib_distort(dist, x, y, &xd, &yd);
            CHECK(calib_undistort(dist, xd, yd, &xu, &yu));
            worst = fmax(worst, fmax(fabs(xu - x), fabs(yu - y)));
        }
    CHECK_LE(worst, 1e-11);
}

/* The colour pass distorts in float with the shared GLSL/C functions of
 * shaders/fusion.glsl.h: the same model as calib's, to float precision
 * (1e-6 of a normalised coordinate is 5e-4 px at fx 525). */
BF_TEST(fusion_colour_distortion_matches_calib)
{
    const double dist[CALIB_DIST_N] = {0.12, -0.25, 1e-3, -5e-4, 0.08};
    double worst = 0;
    for (double y = -0.5; y <= 0.5; y += 0.05)
        for (double x = -0.65; x <= 0.65; x += 0.05) {
            double xd, yd;
            calib_distort(dist, x, y, &xd, &yd);
            float k1 = (float)dist[0], k2 = (float)dist[1], p1 = (float)dist[2], p2 = (float)dist[3];
            float k3 = (float)dist[4];
            float fx = bf_distort_x((float)x, (float)y, k1, k2, p1, p2, k3);
            float fy = bf_distort_y((float)x, (float)y, k1, k2, p1, p2, k3);
            worst = fmax(worst, fmax(fabs(fx - xd), fabs(fy - yd)));
        }
    CHECK(worst > 0); /* float, not a copy of the double result */
    CHECK_LE(worst, 1e-6);
}

BF_TEST(calib_parse_board_takes_cols_by_rows)
{
    calib_board b;
    CHECK_OK(calib_parse_board("9x6", &b));
    CHECK(b.cols == 9 && b.rows == 6);
    CHECK_STATUS(calib_parse_board("9x", &b), BF_INVALID_ARG);
    CHECK_STATUS(calib_parse_board("1x6", &b), BF_INVALID_ARG);
    CHECK_STATUS(calib_parse_board("9x6x2", &b), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("COLSxROWS");
}

/* The corners of view k seen by camera c at T_cb (board to camera). */
static void project_board(const calib_board *b, const calib_camera *c, const bf_se3 *T_cb, double *out)
{
    for (uint32_t j = 0; j < b->rows; j++)
        for (uint32_t i = 0; i < b->cols; i++) {
            bf_vec3 p = bf_se3_apply(T_cb, bf_v3(i * b->square_m, j * b->square_m, 0));
            size_t k = j * b->cols + i;
            calib_project(c, p, &out[2 * k], &out[2 * k + 1]);
        }
}

/* The corners of view k of n as the two cameras see them: the board's
 * centre 0.8-1 m ahead, tilted 20-41 degrees about a turning axis. */
static void board_view(const calib_board *b, const calib_result *truth, uint32_t k, uint32_t n, double *cc,
                       double *dc)
{
    double a = 2 * M_PI * k / n;
    bf_quat q = bf_quat_from_axis_angle(bf_v3(cos(a), sin(a), 0), (20 + 3 * k) * M_PI / 180);
    bf_se3 T_cb = bf_se3_from_qt(q, bf_v3(0, 0, 0));
    bf_vec3 centre_b = bf_v3(4 * b->square_m, 2.5 * b->square_m, 0);
    T_cb.t = bf_v3_sub(bf_v3(0.02 * k - 0.07, 0.01 * (k % 3), 0.8 + 0.025 * k), bf_se3_apply(&T_cb, centre_b));
    bf_se3 T_dc = bf_se3_inverse(&truth->T_colour_depth);
    bf_se3 T_db = bf_se3_mul(&T_dc, &T_cb);
    project_board(b, &truth->colour, &T_cb, cc);
    project_board(b, &truth->depth, &T_db, dc);
}

/* Exact corners give back the cameras and the transform: what is left is
 * OpenCV's float corners (2^-24 relative: 4e-5 px at 640) and its
 * stopping rule, far below the 0.5% and 2 mm the images are held to. */
BF_TEST(calib_estimate_recovers_exact_corners)
{
    const calib_board b = {.cols = 9, .rows = 6, .square_m = 0.04};
    calib_result truth = sample_result();
    truth.colour.dist[4] = 0; /* k3 and k2 trade off at these angles; keep the truth identifiable */
    const uint32_t n = 8;
    size_t nc = b.cols * b.rows;
    double *cc = calloc(n * nc * 2, sizeof *cc), *dc = calloc(n * nc * 2, sizeof *dc);
    bool found[8], not_found[8] = {false};
    for (uint32_t k = 0; k < n; k++) {
        board_view(&b, &truth, k, n, cc + 2 * nc * k, dc + 2 * nc * k);
        found[k] = true;
    }
    calib_views cv = {.n_views = n, .width = 640, .height = 480, .corners_px = cc, .is_found = found};
    calib_views dv = {.n_views = n, .width = 640, .height = 480, .corners_px = dc, .is_found = found};
    calib_result r, r_two;
    calib_config cfg = calib_config_default(), cfg2 = cfg;
    cfg2.radial_terms = 2;
    bf_status s = calib_estimate(&b, &cfg, &cv, &dv, &r);
    bf_status s_two = calib_estimate(&b, &cfg2, &cv, NULL, &r_two);
    calib_result r2;
    cfg2.radial_terms = 4;
    bf_status s4 = calib_estimate(&b, &cfg2, &cv, NULL, &r2);
    calib_views none = {.n_views = n, .width = 640, .height = 480, .corners_px = cc, .is_found = not_found};
    bf_status s2 = calib_estimate(&b, &cfg, &none, NULL, &r2); /* its message is checked last */
    /* How far out the corners reached, from the truth's camera. */
    double far = 0, reach = 0;
    for (int k = 0; k < 4; k++)
        far = fmax(far, hypot((((k & 1) ? 639.5 : -0.5) - truth.colour.cx_px) / truth.colour.fx_px,
                              (((k & 2) ? 479.5 : -0.5) - truth.colour.cy_px) / truth.colour.fy_px));
    for (size_t i = 0; i < n * nc; i++)
        reach = fmax(reach, hypot((cc[2 * i] - truth.colour.cx_px) / truth.colour.fx_px,
                                  (cc[2 * i + 1] - truth.colour.cy_px) / truth.colour.fy_px));
    free(cc);
    free(dc);
    CHECK_OK(s);
    /* Three radial terms by default; two hold k3 at 0. */
    CHECK_OK(s_two);
    CHECK(r_two.colour.dist[4] == 0);
    CHECK_NEAR(r_two.colour.dist[0], truth.colour.dist[0], 1e-4);
    /* Exact corners of a lens with k3 = 0: both fits are the truth, at the
     * image's edge too. */
    CHECK_LE(r.colour.extrapolation_px, 0.01);
    CHECK_LE(r_two.colour.extrapolation_px, 0.01);
    CHECK_STATUS(s4, BF_INVALID_ARG);
    CHECK_NEAR(r.colour.coverage, reach / far, 1e-3);
    CHECK(r.colour.coverage > 0.2 && r.colour.coverage < 1);
    CHECK(r.has_depth);
    CHECK_EQ_INT(r.n_views, n);
    CHECK_NEAR(r.colour.fx_px, truth.colour.fx_px, 0.01);
    CHECK_NEAR(r.colour.fy_px, truth.colour.fy_px, 0.01);
    CHECK_NEAR(r.colour.cx_px, truth.colour.cx_px, 0.01);
    CHECK_NEAR(r.colour.cy_px, truth.colour.cy_px, 0.01);
    CHECK_NEAR(r.colour.dist[0], truth.colour.dist[0], 1e-4);
    CHECK_NEAR(r.depth.fx_px, truth.depth.fx_px, 0.01);
    CHECK_NEAR(r.depth.cy_px, truth.depth.cy_px, 0.01);
    bf_se3 Tinv = bf_se3_inverse(&truth.T_colour_depth);
    bf_se3 E = bf_se3_mul(&Tinv, &r.T_colour_depth);
    CHECK_LE(bf_v3_norm(E.t), 1e-5);
    CHECK_LE(bf_se3_angle(&E) * 180 / M_PI, 1e-4);
    CHECK_LE(r.rms_px, 1e-3);
    /* No board anywhere: refused, saying how many were found. */
    CHECK_STATUS(s2, BF_FORMAT);
    CHECK_ERROR_MENTIONS("found in 0 of the 8 colour images");
}

/* TUM's fr1 lens (k3 1.16) seen by boards that stay in the middle of the
 * image: three radial terms give it back from exact corners, two cannot,
 * and the two fits, alike within the boards, part by pixels at the image's
 * edge: extrapolation_px says so, for either fit. */
BF_TEST(calib_estimate_says_how_uncertain_the_lens_is_beyond_the_boards)
{
    const calib_board b = {.cols = 9, .rows = 6, .square_m = 0.04};
    calib_result truth = sample_result();
    truth.colour = (calib_camera){.width = 640, .height = 480, .fx_px = 517.3, .fy_px = 516.5, .cx_px = 318.6,
                                  .cy_px = 255.3, .dist = {0.2624, -0.9531, 0, 0, 1.1633}};
    enum { N = 10 };
    size_t nc = b.cols * b.rows;
    double *cc = calloc(N * nc * 2, sizeof *cc), *dc = calloc(N * nc * 2, sizeof *dc);
    bool found[N];
    for (uint32_t k = 0; k < N; k++) {
        board_view(&b, &truth, k, N, cc + 2 * nc * k, dc + 2 * nc * k);
        found[k] = true;
    }
    calib_views cv = {.n_views = N, .width = 640, .height = 480, .corners_px = cc, .is_found = found};
    calib_config cfg = calib_config_default(), cfg2 = cfg;
    cfg2.radial_terms = 2;
    calib_result r3, r2;
    bf_status s3 = calib_estimate(&b, &cfg, &cv, NULL, &r3), s2 = calib_estimate(&b, &cfg2, &cv, NULL, &r2);
    free(cc);
    free(dc);
    CHECK_OK(s3);
    CHECK_OK(s2);
    CHECK_LE(r3.colour.rms_px, 1e-3);
    CHECK_NEAR(r3.colour.dist[4], truth.colour.dist[4], 1e-3);
    CHECK_LE(r3.colour.coverage, 0.7);
    CHECK_LE(1.0, r3.colour.extrapolation_px);
    CHECK_NEAR(r2.colour.extrapolation_px, r3.colour.extrapolation_px, 0.5);
    printf("  coverage %.2f, two and three terms differ by %.1f px at the edge\n", r3.colour.coverage,
           r3.colour.extrapolation_px);
}

/* A board rendered by synth (box-filtered, 1 grey level of noise) turned
 * by 0 and by 180 degrees in its plane: the corners found are the
 * projected truth in the board's own order (the dark outer square first),
 * within 0.15 px each and 0.06 px on average. cornerSubPix on a
 * box-filtered edge with this noise localises to a few hundredths of a
 * pixel (the calibrations of docs/calibration.md leave 0.05-0.06 px RMS,
 * corner error and model together); the worst corner may have three times
 * that. */
BF_TEST(calib_finds_rendered_corners_in_board_order)
{
    synth_board_config cfg = synth_board_config_default();
    cfg.colour.dist[0] = 0.1;
    cfg.colour.dist[1] = -0.2;
    const calib_camera *c = &cfg.colour;
    size_t nc = cfg.board.cols * cfg.board.rows;
    uint8_t *grey = malloc((size_t)c->width * c->height);
    double *found_px = malloc(2 * nc * sizeof *found_px), *true_px = malloc(2 * nc * sizeof *true_px);
    CHECK(grey && found_px && true_px);
    for (int turn = 0; turn < 2; turn++) {
        bf_se3 T_cb;
        CHECK_OK(synth_board_pose(&cfg, 3, &T_cb));
        if (turn) {
            /* Turn the board by 180 degrees about its centre's normal. */
            double s = cfg.board.square_m;
            bf_vec3 mid = bf_v3((cfg.board.cols - 1) * s / 2, (cfg.board.rows - 1) * s / 2, 0);
            bf_se3 Rz = bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0, 0, 1), M_PI), bf_v3(0, 0, 0));
            Rz.t = bf_v3_sub(mid, bf_se3_apply(&Rz, mid));
            T_cb = bf_se3_mul(&T_cb, &Rz);
        }
        CHECK_OK(synth_board_render(&cfg, c, &T_cb, 0, grey));
        bool is_found = false;
        CHECK_OK(calib_find_corners(&cfg.board, grey, c->width, c->height, &is_found, found_px));
        CHECK(is_found);
        project_board(&cfg.board, c, &T_cb, true_px);
        double worst = 0, sum = 0;
        for (size_t k = 0; k < nc; k++) {
            double e = hypot(found_px[2 * k] - true_px[2 * k], found_px[2 * k + 1] - true_px[2 * k + 1]);
            worst = fmax(worst, e);
            sum += e;
        }
        CHECK_LE(worst, 0.15);
        CHECK_LE(sum / nc, 0.06);
    }
    free(grey);
    free(found_px);
    free(true_px);
}
