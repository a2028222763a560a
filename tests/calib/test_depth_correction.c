/* calib: the depth correction. A camera moving inside a box room sees depth
 * made exactly (ray against the box's six planes) and then spoiled by a
 * known pattern fixed in the image (bands along x, a bowl): the estimate
 * from the true poses must find that pattern's inverse, up to the image's
 * mean, which pairs of frames cannot see. Also the file written and read
 * back bit for bit, malformed files refused by field, and the apply's
 * edge cases. */
#include <math.h>

#include "calib/calib.h"
#include "test.h"

enum { W = 160, H = 120, N_FRAMES = 61 };

/* The box room: x in [-2, 2], y in [-1.3, 1.3], z in [-2.5, 2.5]. */
static double box_depth(const bf_se3 *T_wc, const bf_intrinsics *K, uint32_t u, uint32_t v)
{
    bf_vec3 d_c = bf_v3((u - K->cx_px) / K->fx_px, (v - K->cy_px) / K->fy_px, 1.0);
    bf_vec3 d = bf_v3(T_wc->R[0][0] * d_c.x + T_wc->R[0][1] * d_c.y + T_wc->R[0][2] * d_c.z,
                      T_wc->R[1][0] * d_c.x + T_wc->R[1][1] * d_c.y + T_wc->R[1][2] * d_c.z,
                      T_wc->R[2][0] * d_c.x + T_wc->R[2][1] * d_c.y + T_wc->R[2][2] * d_c.z);
    const double lo[3] = {-2, -1.3, -2.5}, hi[3] = {2, 1.3, 2.5};
    const double o[3] = {T_wc->t.x, T_wc->t.y, T_wc->t.z}, dv[3] = {d.x, d.y, d.z};
    double s = INFINITY;
    for (int a = 0; a < 3; a++) {
        if (dv[a] == 0) continue;
        double t = ((dv[a] > 0 ? hi[a] : lo[a]) - o[a]) / dv[a];
        if (t > 0 && t < s) s = t;
    }
    return s; /* the ray's parameter at d_c's z = 1: the camera depth */
}

/* The sensor's pattern at pixel (u, v): what it multiplies the true depth by. */
static double pattern(uint32_t u, uint32_t v)
{
    double x = (u + 0.5) / W - 0.5, y = (v + 0.5) / H - 0.5;
    return 1.0 + 0.006 * sin(2 * M_PI * 3 * x) + 0.01 * (x * x + y * y - 1.0 / 6);
}

static bf_se3 pose(uint32_t i)
{
    double s = i / (double)(N_FRAMES - 1);
    bf_quat q = bf_quat_mul(bf_quat_from_axis_angle(bf_v3(0, 1, 0), -0.9 + 1.8 * s),
                            bf_quat_from_axis_angle(bf_v3(1, 0, 0), 0.25 * sin(6 * s)));
    return bf_se3_from_qt(q, bf_v3(-0.6 + 1.2 * s, 0.2 * sin(9 * s), 0.4 * cos(5 * s)));
}

typedef struct scene {
    bf_intrinsics K;
    uint16_t *depth[N_FRAMES];
    const uint16_t *cdepth[N_FRAMES];
    uint32_t index[N_FRAMES];
    bf_se3 T[N_FRAMES];
} scene;

static void make_scene(scene *sc, bool spoiled)
{
    sc->K = (bf_intrinsics){.width = W, .height = H, .fx_px = 130, .fy_px = 130, .cx_px = 79.5, .cy_px = 59.5,
                            .depth_scale = 5000};
    for (uint32_t i = 0; i < N_FRAMES; i++) {
        sc->T[i] = pose(i);
        sc->index[i] = i;
        sc->depth[i] = malloc(W * H * sizeof(uint16_t));
        for (uint32_t v = 0; v < H; v++)
            for (uint32_t u = 0; u < W; u++) {
                double z = box_depth(&sc->T[i], &sc->K, u, v) * (spoiled ? pattern(u, v) : 1.0);
                sc->depth[i][v * W + u] = z < 6.0 ? (uint16_t)lround(z * 5000) : 0;
            }
        sc->cdepth[i] = sc->depth[i];
    }
}

static void free_scene(scene *sc)
{
    for (uint32_t i = 0; i < N_FRAMES; i++) free(sc->depth[i]);
}

static calib_depth_config small_config(void)
{
    calib_depth_config c = calib_depth_config_default();
    c.cell_px = 8;
    c.max_depth_m = 6.0f;
    c.min_samples = 20;
    return c;
}

/* RMS over the image of the product of multiplier and pattern, each
 * divided by its mean: 0 when the estimate undoes the pattern exactly. */
static double residual_rms(const calib_depth_correction *c)
{
    float *map = malloc(W * H * sizeof *map);
    calib_depth_map(c, map);
    double m = 0, mm = 0;
    for (uint32_t v = 0; v < H; v++)
        for (uint32_t u = 0; u < W; u++) m += map[v * W + u] * pattern(u, v);
    m /= W * H;
    for (uint32_t v = 0; v < H; v++)
        for (uint32_t u = 0; u < W; u++) {
            double e = map[v * W + u] * pattern(u, v) / m - 1;
            mm += e * e;
        }
    free(map);
    return sqrt(mm / (W * H));
}

static double pattern_rms(void)
{
    double m = 0, mm = 0;
    for (uint32_t v = 0; v < H; v++)
        for (uint32_t u = 0; u < W; u++) m += pattern(u, v);
    m /= W * H;
    for (uint32_t v = 0; v < H; v++)
        for (uint32_t u = 0; u < W; u++) mm += (pattern(u, v) / m - 1) * (pattern(u, v) / m - 1);
    return sqrt(mm / (W * H));
}

BF_TEST(depth_correction_finds_a_known_pattern)
{
    scene sc;
    make_scene(&sc, true);
    calib_depth_config cfg = small_config();
    calib_depth_frames in = {.n = N_FRAMES, .depth = sc.cdepth, .index = sc.index, .T_wc = sc.T, .K = sc.K};
    calib_depth_correction *c = malloc(sizeof *c);
    CHECK_OK(calib_depth_estimate(&cfg, &in, c));
    CHECK_EQ_INT(c->grid_w, 20);
    CHECK_EQ_INT(c->grid_h, 15);
    /* Pairs 15 and 30 frames apart, a first frame every 3: 16 + 11. */
    CHECK_EQ_INT(c->n_pairs, 27);
    double before = pattern_rms(), after = residual_rms(c);
    printf("  pattern RMS %.2f per mille, left after the correction %.2f (measured %.2f -> %.2f)\n", 1000 * before,
           1000 * after, 1000 * c->rms_before, 1000 * c->rms_after);
    /* The pattern is 5 per mille RMS; a cell's multiplier is one value for
     * 8 x 8 pixels of a pattern that moves up to 0.7 per mille across a
     * cell, and depth is rounded to 0.2 mm (0.1 per mille at 2 m): what is
     * left must be under a fifth of the pattern. */
    CHECK(before > 0.004);
    CHECK(after < 0.2 * before);
    CHECK(c->rms_after < 0.2 * c->rms_before);
    free(c);
    free_scene(&sc);
}

BF_TEST(depth_correction_of_clean_depth_is_flat)
{
    scene sc;
    make_scene(&sc, false);
    calib_depth_config cfg = small_config();
    calib_depth_frames in = {.n = N_FRAMES, .depth = sc.cdepth, .index = sc.index, .T_wc = sc.T, .K = sc.K};
    calib_depth_correction *c = malloc(sizeof *c);
    CHECK_OK(calib_depth_estimate(&cfg, &in, c));
    float lo = 2, hi = 0;
    for (uint32_t i = 0; i < c->grid_w * c->grid_h; i++) {
        lo = fminf(lo, c->mult[i]);
        hi = fmaxf(hi, c->mult[i]);
    }
    printf("  clean depth: multipliers %.5f..%.5f\n", lo, hi);
    /* Only the rounding to 0.2 mm is left to find. */
    CHECK(lo > 0.9995 && hi < 1.0005);
    free(c);
    free_scene(&sc);
}

BF_TEST(depth_correction_needs_pairs)
{
    scene sc;
    make_scene(&sc, false);
    calib_depth_config cfg = small_config();
    calib_depth_frames in = {.n = 10, .depth = sc.cdepth, .index = sc.index, .T_wc = sc.T, .K = sc.K};
    calib_depth_correction *c = malloc(sizeof *c);
    CHECK_STATUS(calib_depth_estimate(&cfg, &in, c), BF_FORMAT);
    CHECK(strstr(bf_last_error(), "no pair"));
    uint32_t back[2] = {5, 4};
    in.n = 2;
    in.index = back;
    CHECK_STATUS(calib_depth_estimate(&cfg, &in, c), BF_INVALID_ARG);
    free(c);
    free_scene(&sc);
}

BF_TEST(depth_correction_file_round_trip_is_exact)
{
    calib_depth_correction *c = calloc(1, sizeof *c), *back = malloc(sizeof *back);
    *c = (calib_depth_correction){.width = 640, .height = 480, .cell_px = 16, .grid_w = 40, .grid_h = 30,
                                  .n_frames = 167, .n_pairs = 319, .n_cells_measured = 1200, .rms_before = 0.0026,
                                  .rms_after = 0.00024};
    for (uint32_t i = 0; i < 1200; i++) c->mult[i] = 1.0f + (float)sin(i * 0.37) / 77.0f;
    char path[600];
    snprintf(path, sizeof path, "%s/depth_correction.json", bf_test_tmpdir());
    CHECK_OK(calib_depth_write(path, c));
    CHECK_OK(calib_depth_read(path, back));
    CHECK(memcmp(back->mult, c->mult, 1200 * sizeof(float)) == 0);
    CHECK_EQ_INT(back->grid_w, 40);
    CHECK_EQ_INT(back->n_pairs, 319);
    CHECK(fabs(back->rms_before - 0.0026) < 1e-9);
    /* Where the pattern lies: a lens, bit for bit; none; or (not written)
     * unknown. */
    const double fr1[CALIB_DIST_N] = {0.2624, -0.9531, -0.0054, 0.0026, 1.1633};
    c->is_lens_known = true;
    memcpy(c->lens, fr1, sizeof fr1);
    CHECK_OK(calib_depth_write(path, c));
    CHECK_OK(calib_depth_read(path, back));
    CHECK(back->is_lens_known && memcmp(back->lens, fr1, sizeof fr1) == 0);
    memset(c->lens, 0, sizeof c->lens);
    CHECK_OK(calib_depth_write(path, c));
    CHECK_OK(calib_depth_read(path, back));
    CHECK(back->is_lens_known && !calib_has_distortion(back->lens));
    c->is_lens_known = false;
    CHECK_OK(calib_depth_write(path, c));
    CHECK_OK(calib_depth_read(path, back));
    CHECK(!back->is_lens_known);
    free(c);
    free(back);
}

BF_TEST(depth_correction_knows_the_pixels_it_was_made_in)
{
    const double fr1[CALIB_DIST_N] = {0.2624, -0.9531, -0.0054, 0.0026, 1.1633}, none[CALIB_DIST_N] = {0};
    calib_depth_correction *c = calloc(1, sizeof *c);
    /* A file that does not say fits any frames. */
    CHECK(calib_depth_same_lens(c, fr1) && calib_depth_same_lens(c, NULL));
    /* Made as a pinhole: frames read as a pinhole only. */
    c->is_lens_known = true;
    CHECK(calib_depth_same_lens(c, NULL) && calib_depth_same_lens(c, none));
    CHECK(!calib_depth_same_lens(c, fr1));
    /* Made through fr1's lens: that lens only. */
    memcpy(c->lens, fr1, sizeof fr1);
    CHECK(calib_depth_same_lens(c, fr1));
    CHECK(!calib_depth_same_lens(c, NULL));
    double other[CALIB_DIST_N];
    memcpy(other, fr1, sizeof fr1);
    other[0] += 1e-6;
    CHECK(!calib_depth_same_lens(c, other));
    free(c);
}

BF_TEST(depth_correction_malformed_files_are_named)
{
    struct {
        const char *text, *mention;
        bf_status want;
    } cases[] = {
        {"{", "not JSON", BF_FORMAT},
        {"{} {}", "text after the JSON value at byte 3", BF_FORMAT},
        {"{\"format\": \"bitfuse-calibration\", \"version\": 1}", "format", BF_FORMAT},
        {"{\"format\": \"bitfuse-depth-correction\", \"version\": 9}", "newer", BF_UNSUPPORTED},
        {"{\"format\": \"bitfuse-depth-correction\", \"version\": 1, \"width\": 16, \"height\": 8, \"cell_px\": 8, "
         "\"grid_w\": 2}",
         "grid_h: missing", BF_FORMAT},
        {"{\"format\": \"bitfuse-depth-correction\", \"version\": 1, \"width\": 16, \"height\": 8, \"cell_px\": 8, "
         "\"grid_w\": 3, \"grid_h\": 1, \"multipliers\": [[1, 1, 1]]}",
         "does not cover", BF_FORMAT},
        {"{\"format\": \"bitfuse-depth-correction\", \"version\": 1, \"width\": 16, \"height\": 8, \"cell_px\": 8, "
         "\"grid_w\": 2, \"grid_h\": 1, \"multipliers\": [[1, 1], [1, 1]]}",
         "multipliers: not a list of 1 rows", BF_FORMAT},
        {"{\"format\": \"bitfuse-depth-correction\", \"version\": 1, \"width\": 16, \"height\": 8, \"cell_px\": 8, "
         "\"grid_w\": 2, \"grid_h\": 1, \"multipliers\": [[1, 3]]}",
         "multipliers[0][1]", BF_FORMAT},
        {"{\"format\": \"bitfuse-depth-correction\", \"version\": 1, \"width\": 16, \"height\": 8, \"cell_px\": 8, "
         "\"grid_w\": 2, \"grid_h\": 1, \"multipliers\": [[1, 1]], \"pairs\": -1}",
         "pairs", BF_FORMAT},
        {"{\"format\": \"bitfuse-depth-correction\", \"version\": 1, \"width\": 16, \"height\": 8, \"cell_px\": 8, "
         "\"grid_w\": 2, \"grid_h\": 1, \"multipliers\": [[1, 1]], \"undistorted\": [0.1, 0]}",
         "undistorted: not null or a list of 5", BF_FORMAT},
        {"{\"format\": \"bitfuse-depth-correction\", \"version\": 1, \"width\": 16, \"height\": 8, \"cell_px\": 8, "
         "\"grid_w\": 2, \"grid_h\": 1, \"multipliers\": [[1, 1]], \"undistorted\": [0.1, 0, 0, \"x\", 0]}",
         "undistorted[3]", BF_FORMAT},
        /* Behind a byte-order mark the bytes named are still the file's. */
        {"\xEF\xBB\xBF{\"format\": 1} x", "text after the JSON value at byte 17", BF_FORMAT},
        {"\xEF\xBB\xBF{\"format\": }", "not JSON (near byte 14)", BF_FORMAT},
    };
    calib_depth_correction *c = malloc(sizeof *c);
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
        bf_status s = calib_depth_parse("dc.json", cases[k].text, strlen(cases[k].text), c);
        CHECK_STATUS(s, cases[k].want);
        CHECK(strstr(bf_last_error(), "dc.json") && strstr(bf_last_error(), cases[k].mention));
    }
    const char *ok = "{\"format\": \"bitfuse-depth-correction\", \"version\": 1, \"width\": 16, \"height\": 8, "
                     "\"cell_px\": 8, \"grid_w\": 2, \"grid_h\": 1, \"multipliers\": [[0.99, 1.01]]}";
    CHECK_OK(calib_depth_parse("dc.json", ok, strlen(ok), c));
    CHECK(c->mult[0] == 0.99f && c->mult[1] == 1.01f);
    free(c);
}

BF_TEST(depth_correction_apply_keeps_holes_and_range)
{
    calib_depth_correction *c = calloc(1, sizeof *c);
    *c = (calib_depth_correction){.width = 4, .height = 2, .cell_px = 2, .grid_w = 2, .grid_h = 1};
    c->mult[0] = 1.01f;
    c->mult[1] = 0.99f;
    float map[8];
    calib_depth_map(c, map);
    /* Cell centres at pixels 0.5 and 2.5: constant beyond them, linear between. */
    CHECK(map[0] == 1.01f && map[4] == 1.01f && map[3] == 0.99f && map[7] == 0.99f);
    CHECK(fabsf(map[1] - 1.005f) < 1e-6f && fabsf(map[2] - 0.995f) < 1e-6f);
    uint16_t src[8] = {65535, 1000, 0, 1000, 1, 0, 2000, 65535}, dst[8];
    calib_depth_apply(map, src, dst, 8);
    CHECK_EQ_INT(dst[0], 65535); /* 66190: clamped */
    CHECK_EQ_INT(dst[1], 1005);
    CHECK_EQ_INT(dst[2], 0); /* no depth stays none */
    CHECK_EQ_INT(dst[3], 990);
    CHECK_EQ_INT(dst[4], 1); /* 1.01 rounds to 1, and nothing measured becomes 0 */
    CHECK_EQ_INT(dst[5], 0);
    CHECK_EQ_INT(dst[6], 1990);
    CHECK_EQ_INT(dst[7], 64880); /* 65535 x 0.99 */
    /* In place. */
    calib_depth_apply(map, src, src, 8);
    CHECK(memcmp(src, dst, sizeof dst) == 0);
    free(c);
}
