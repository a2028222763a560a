/* replay: TUM RGB-D folders built in the temporary folder around the real
 * fr2 desk frames, with timestamps chosen to exercise association. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "replay/replay.h"
#include "replay_test.h"
#include "test.h"

/* Depth and colour index files (fake times, real images):
 *  depth 10.000 a  <-> rgb 10.015 a    |dt| 0.015 < 0.02: paired
 *  depth 10.100 b1 <-> rgb 10.092 b1   |dt| 0.008: paired
 *  depth 10.200 b2  -  rgb 10.225 b2   |dt| 0.025 > 0.02: depth dropped
 *  depth 10.300 a   -  rgb 10.309 a    |dt| 0.009, but depth 10.3105 is
 *  depth 10.3105 b1 <-> rgb 10.309 a   closer (0.0015): greedy one-to-one
 *                                      pairing leaves 10.300 without colour
 *  depth 10.500 b2 <-> rgb 10.500 b2   paired, beyond the ground truth
 * Ground truth at 9.9 (A), 10.1 (B), 10.295 (C): 10.0 interpolates A-B
 * halfway, 10.1 is B, 10.3105 is 0.0155 past C (within 0.02: gets C), 10.5
 * gets no pose. */
static const char *const depth_txt = "# depth maps\n# timestamp filename\n"
                                     "10.000 depth/a.png\n10.100 depth/b1.png\n10.200 depth/b2.png\n"
                                     "10.300 depth/a2.png\n10.3105 depth/b1_2.png\n10.500 depth/b2.png\n";
static const char *const rgb_txt = "# colour\n10.015 rgb/a.png\n10.092 rgb/b1.png\n10.225 rgb/b2.png\n"
                                   "10.309 rgb/a.png\n10.500 rgb/b2.png\n";

static bf_se3 gt_pose(int k)
{
    return bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(0, 1, 0.2), 0.2 * k), bf_v3(k, 0.5 * k, -k));
}

static bool write_gt(const char *dir)
{
    bf_traj tr = {0};
    const double t[3] = {9.9, 10.1, 10.295};
    for (int k = 0; k < 3; k++) {
        bf_se3 T = gt_pose(k);
        if (bf_traj_push(&tr, t[k], &T)) return false;
    }
    bool ok = replay_traj_write_tum(rt_join(dir, "groundtruth.txt"), &tr) == BF_OK;
    bf_traj_free(&tr);
    return ok;
}

/* Makes tmp/name as a TUM folder over the real frames; NULL if data absent. */
static const char *make_tum(const char *name)
{
    const char *data = bf_test_data("tum/frames");
    if (!data) return NULL;
    const char *dir = rt_fresh_dir(name);
    char d[1024];
    snprintf(d, sizeof d, "%s", dir);
    static char keep[1024];
    snprintf(keep, sizeof keep, "%s", d);
    const char *v[3] = {"a", "b1", "b2"};
    for (int i = 0; i < 3; i++) {
        char src[1024], n[64];
        snprintf(src, sizeof src, "%s/fr2_desk_%s_depth.png", data, v[i]);
        snprintf(n, sizeof n, "depth/%s.png", v[i]);
        if (!rt_link(src, keep, n)) return NULL;
        snprintf(src, sizeof src, "%s/fr2_desk_%s_rgb.png", data, v[i]);
        snprintf(n, sizeof n, "rgb/%s.png", v[i]);
        if (!rt_link(src, keep, n)) return NULL;
    }
    char src[1024];
    snprintf(src, sizeof src, "%s/fr2_desk_a_depth.png", data);
    if (!rt_link(src, keep, "depth/a2.png")) return NULL;
    snprintf(src, sizeof src, "%s/fr2_desk_b1_depth.png", data);
    if (!rt_link(src, keep, "depth/b1_2.png")) return NULL;
    if (!rt_write_text(rt_join(keep, "depth.txt"), depth_txt) || !rt_write_text(rt_join(keep, "rgb.txt"), rgb_txt) ||
        !write_gt(keep))
        return NULL;
    return keep;
}

static bool frame_matches_files(const bf_frame *f, const char *depth_png, const char *rgb_png)
{
    uint16_t *d;
    uint8_t *c;
    uint32_t w, h;
    if (!rt_png_read_u16(depth_png, &d, &w, &h)) return false;
    bool ok = w == f->width && h == f->height && memcmp(d, f->depth, (size_t)w * h * 2) == 0;
    free(d);
    if (!rt_png_read_rgb8(rgb_png, &c, &w, &h)) return false;
    ok = ok && f->rgb && w == f->width && memcmp(c, f->rgb, (size_t)w * h * 3) == 0;
    free(c);
    return ok;
}

static double rot_diff(const bf_se3 *A, const bf_se3 *B)
{
    bf_se3 Ai = bf_se3_inverse(A);
    bf_se3 D = bf_se3_mul(&Ai, B);
    return bf_se3_angle(&D) + bf_v3_norm(D.t);
}

BF_TEST(tum_associates_like_associate_py_and_reads_real_pixels)
{
    const char *dir = make_tum("tum_main");
    if (!dir) BF_SKIP("tum/frames absent");
    const char *data = bf_test_data("tum/frames");
    char data_dir[1024];
    snprintf(data_dir, sizeof data_dir, "%s", data);
    rgbd_source *src;
    CHECK_OK(replay_open(dir, NULL, &src));
    CHECK(!strcmp(src->kind, "tum"));
    CHECK_EQ_INT(src->n_frames, 4);
    CHECK(src->has_groundtruth);
    const bf_intrinsics *K = rgbd_source_intrinsics(src);
    CHECK(K->width == 640 && K->height == 480);
    CHECK(K->fx_px == 525 && K->fy_px == 525 && K->cx_px == 319.5 && K->cy_px == 239.5);
    CHECK(K->depth_scale == 5000);

    const double want_td[4] = {10.0, 10.1, 10.3105, 10.5};
    const double want_tr[4] = {10.015, 10.092, 10.309, 10.5};
    const char *want_d[4] = {"a", "b1", "b1", "b2"}, *want_c[4] = {"a", "b1", "a", "b2"};
    bf_frame f;
    for (int i = 0; i < 4; i++) {
        CHECK_OK(rgbd_source_next(src, &f));
        CHECK_EQ_INT(f.index, i);
        CHECK_NEAR(f.t_depth_s, want_td[i], 1e-12);
        CHECK_NEAR(f.t_rgb_s, want_tr[i], 1e-12);
        char pd[1200], pc[1200];
        snprintf(pd, sizeof pd, "%s/fr2_desk_%s_depth.png", data_dir, want_d[i]);
        snprintf(pc, sizeof pc, "%s/fr2_desk_%s_rgb.png", data_dir, want_c[i]);
        CHECK(frame_matches_files(&f, pd, pc));
        if (i == 0) {
            /* Halfway between A and B: written with 9 decimals. */
            bf_se3 A = gt_pose(0), B = gt_pose(1);
            bf_se3 mid = bf_se3_interpolate(&A, &B, 0.5);
            CHECK(f.has_pose);
            CHECK_LE(rot_diff(&f.T_wc, &mid), 1e-8);
        } else if (i == 1 || i == 2) {
            bf_se3 P = gt_pose(i == 1 ? 1 : 2);
            CHECK(f.has_pose);
            CHECK_LE(rot_diff(&f.T_wc, &P), 1e-8);
        } else {
            CHECK(!f.has_pose);
        }
    }
    /* Buffers are reused: every frame points into the same memory. */
    const uint16_t *d_last = f.depth;
    CHECK_STATUS(rgbd_source_next(src, &f), BF_END);
    CHECK_STATUS(rgbd_source_next(src, &f), BF_END);
    CHECK(d_last != NULL);
    CHECK_EQ_INT(replay_skipped_frames(src), 0);
    rgbd_source_close(src);
    rgbd_source_close(NULL);
}

BF_TEST(tum_frames_reuse_the_same_buffers)
{
    const char *dir = make_tum("tum_buffers");
    if (!dir) BF_SKIP("tum/frames absent");
    rgbd_source *src;
    CHECK_OK(replay_open(dir, NULL, &src));
    bf_frame f;
    CHECK_OK(rgbd_source_next(src, &f));
    const uint16_t *d0 = f.depth;
    const uint8_t *c0 = f.rgb;
    while (rgbd_source_next(src, &f) == BF_OK) {
        CHECK(f.depth == d0);
        CHECK(f.rgb == c0);
    }
    rgbd_source_close(src);
}

BF_TEST(tum_camera_precedence_options_over_camera_txt_over_default)
{
    const char *dir = make_tum("tum_camera");
    if (!dir) BF_SKIP("tum/frames absent");
    char d[1024];
    snprintf(d, sizeof d, "%s", dir);
    rgbd_source *src;
    replay_options opt = {.camera = "fr2"};
    CHECK_OK(replay_open(d, &opt, &src));
    const bf_intrinsics *K = rgbd_source_intrinsics(src);
    CHECK(K->fx_px == 520.9 && K->fy_px == 521.0 && K->cx_px == 325.1 && K->cy_px == 249.7);
    CHECK(K->depth_scale == 5000);
    rgbd_source_close(src);

    CHECK(rt_write_text(rt_join(d, "camera.txt"), "500 501 300.5 200.5 1000\n"));
    CHECK_OK(replay_open(d, NULL, &src));
    K = rgbd_source_intrinsics(src);
    CHECK(K->fx_px == 500 && K->fy_px == 501 && K->cx_px == 300.5 && K->cy_px == 200.5 && K->depth_scale == 1000);
    rgbd_source_close(src);

    opt = (replay_options){.camera = "fr1", .depth_scale = 4000};
    CHECK_OK(replay_open(d, &opt, &src));
    K = rgbd_source_intrinsics(src);
    CHECK(K->fx_px == 517.3 && K->fy_px == 516.5 && K->cx_px == 318.6 && K->cy_px == 255.3);
    CHECK(K->depth_scale == 4000);
    rgbd_source_close(src);

    opt = (replay_options){.camera = "600,-601,320,240", .max_frames = 2};
    CHECK_OK(replay_open(d, &opt, &src));
    K = rgbd_source_intrinsics(src);
    CHECK(K->fx_px == 600 && K->fy_px == -601 && K->depth_scale == 1000);
    CHECK_EQ_INT(src->n_frames, 2);
    bf_frame f;
    CHECK_OK(rgbd_source_next(src, &f));
    CHECK_OK(rgbd_source_next(src, &f));
    CHECK_STATUS(rgbd_source_next(src, &f), BF_END);
    rgbd_source_close(src);

    CHECK(rt_write_text(rt_join(d, "camera.txt"), "500 501 300.5\n"));
    CHECK_STATUS(replay_open(d, NULL, &src), BF_FORMAT);
    CHECK_ERROR_MENTIONS("camera.txt:1");
    CHECK(rt_write_text(rt_join(d, "camera.txt"), "500 0 300.5 200 5000\n"));
    CHECK_STATUS(replay_open(d, NULL, &src), BF_FORMAT);
    CHECK_ERROR_MENTIONS("camera.txt:1");
    /* A mirrored image (fx < 0) and a depth scale beyond --depth-scale's
     * range are refused by the file's name; a y-up camera (fy < 0) is not. */
    CHECK(rt_write_text(rt_join(d, "camera.txt"), "-500 501 300.5 200 5000\n"));
    CHECK_STATUS(replay_open(d, NULL, &src), BF_FORMAT);
    CHECK_ERROR_MENTIONS("camera.txt:1: fx must be positive");
    CHECK(rt_write_text(rt_join(d, "camera.txt"), "500 501 300.5 200 1e-30\n"));
    CHECK_STATUS(replay_open(d, NULL, &src), BF_FORMAT);
    CHECK_ERROR_MENTIONS("depth_scale 1e-30 is not between 1 and 1e6");
    CHECK(rt_write_text(rt_join(d, "camera.txt"), "500 -501 300.5 200 5000\n"));
    CHECK_OK(replay_open(d, NULL, &src));
    CHECK(rgbd_source_intrinsics(src)->fy_px == -501);
    rgbd_source_close(src);
}

/* A lens's distortion in the camera (TUM's fr2 preset, or the five numbers
 * of camera.txt): every frame comes undistorted, depth and colour by one
 * map, which is calib's (tests/calib/test_undistort.c checks it against
 * the geometry); without one the files come as they are. */
BF_TEST(tum_camera_with_a_lens_delivers_undistorted_frames)
{
    const char *dir = make_tum("tum_lens");
    if (!dir) BF_SKIP("tum/frames absent");
    char d[1024];
    snprintf(d, sizeof d, "%s", dir);
    const char *data = bf_test_data("tum/frames");
    char depth_png[1024], rgb_png[1024];
    snprintf(depth_png, sizeof depth_png, "%s/fr2_desk_a_depth.png", data);
    snprintf(rgb_png, sizeof rgb_png, "%s/fr2_desk_a_rgb.png", data);
    uint16_t *raw;
    uint8_t *raw_rgb;
    uint32_t w, h;
    CHECK(rt_png_read_u16(depth_png, &raw, &w, &h));
    CHECK(rt_png_read_rgb8(rgb_png, &raw_rgb, &w, &h));
    size_t n = (size_t)w * h;
    uint16_t *want = malloc(n * sizeof *want);
    uint8_t *want_rgb = malloc(3 * n);
    CHECK(want && want_rgb);
    const double fr2[CALIB_DIST_N] = {0.2312, -0.7849, -0.0033, -0.0001, 0.9172};
    const char *specs[2] = {"fr2", NULL};
    for (int k = 0; k < 2; k++) {
        if (!specs[k]) /* the same lens from camera.txt */
            CHECK(rt_write_text(rt_join(d, "camera.txt"),
                                "520.9 521.0 325.1 249.7 5000 0.2312 -0.7849 -0.0033 -0.0001 0.9172\n"));
        replay_options opt = {.camera = specs[k]};
        rgbd_source *src;
        CHECK_OK(replay_open(d, &opt, &src));
        double dist[CALIB_DIST_N], shift = 0;
        CHECK(replay_undistortion(src, dist, &shift));
        CHECK(memcmp(dist, fr2, sizeof dist) == 0);
        CHECK(shift > 19 && shift < 20); /* fr2's 19.4 px (pixels whose source is inside the image) */
        calib_camera lens = {.width = w, .height = h, .fx_px = 520.9, .fy_px = 521.0, .cx_px = 325.1, .cy_px = 249.7};
        memcpy(lens.dist, fr2, sizeof fr2);
        calib_undistort_map m;
        CHECK_OK(calib_undistort_map_make(&lens, &m));
        calib_undistort_u16(&m, raw, want);
        calib_undistort_rgb8(&m, raw_rgb, want_rgb);
        calib_undistort_map_free(&m);
        bf_frame f;
        CHECK_OK(rgbd_source_next(src, &f));
        CHECK(f.width == w && f.height == h);
        CHECK(memcmp(f.depth, want, n * sizeof *want) == 0);
        CHECK(f.rgb && memcmp(f.rgb, want_rgb, 3 * n) == 0);
        CHECK(memcmp(f.depth, raw, n * sizeof *raw) != 0); /* it did move pixels */
        rgbd_source_close(src);
    }
    /* Four numbers: a pinhole, the files as they are. */
    replay_options opt = {.camera = "520.9,521.0,325.1,249.7"};
    rgbd_source *src;
    CHECK_OK(replay_open(d, &opt, &src));
    double dist[CALIB_DIST_N];
    CHECK(!replay_undistortion(src, dist, NULL));
    bf_frame f;
    CHECK_OK(rgbd_source_next(src, &f));
    CHECK(memcmp(f.depth, raw, n * sizeof *raw) == 0);
    rgbd_source_close(src);
    /* A lens that folds the image is refused at open, naming where it came from. */
    CHECK(rt_write_text(rt_join(d, "camera.txt"), "520.9 521.0 325.1 249.7 5000 -0.9 0 0 0 0\n"));
    CHECK_STATUS(replay_open(d, NULL, &src), BF_FORMAT);
    CHECK_ERROR_MENTIONS("folds");
    CHECK_ERROR_MENTIONS("camera.txt");
    opt = (replay_options){.camera = "520.9,521.0,325.1,249.7,-0.9,0,0,0,0"};
    CHECK_STATUS(replay_open(d, &opt, &src), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("--camera");
    /* Six to nine fields are neither form. */
    CHECK(rt_write_text(rt_join(d, "camera.txt"), "520.9 521.0 325.1 249.7 5000 0.2\n"));
    CHECK_STATUS(replay_open(d, NULL, &src), BF_FORMAT);
    CHECK_ERROR_MENTIONS("camera.txt:1");
    free(raw);
    free(raw_rgb);
    free(want);
    free(want_rgb);
}

/* A folder named for its TUM sensor takes that sensor's calibration, lens
 * and all; its parents' names do not count; camera.txt and --camera still
 * come first. raw_colour (a calib.json registers the colour) leaves the
 * colour as captured while the depth is undistorted. */
BF_TEST(tum_folder_named_for_its_sensor_takes_its_calibration)
{
    const char *dir = make_tum("rgbd_dataset_freiburg2_lens");
    if (!dir) BF_SKIP("tum/frames absent");
    char d[1024];
    snprintf(d, sizeof d, "%s", dir);
    rgbd_source *src;
    double dist[CALIB_DIST_N];
    CHECK_OK(replay_open(d, NULL, &src));
    CHECK(rgbd_source_intrinsics(src)->fx_px == 520.9);
    CHECK(replay_undistortion(src, dist, NULL) && dist[0] == 0.2312);
    rgbd_source_close(src);
    char slash[1100];
    snprintf(slash, sizeof slash, "%s/", d); /* a trailing slash names the same folder */
    CHECK_OK(replay_open(slash, NULL, &src));
    CHECK(replay_undistortion(src, dist, NULL));
    rgbd_source_close(src);
    /* The colour as captured, the depth undistorted. */
    replay_options raw = {.raw_colour = true};
    CHECK_OK(replay_open(d, &raw, &src));
    bf_frame f;
    CHECK_OK(rgbd_source_next(src, &f));
    const char *data = bf_test_data("tum/frames");
    char depth_png[1024], rgb_png[1024];
    snprintf(depth_png, sizeof depth_png, "%s/fr2_desk_a_depth.png", data);
    snprintf(rgb_png, sizeof rgb_png, "%s/fr2_desk_a_rgb.png", data);
    uint8_t *c;
    uint16_t *z;
    uint32_t w, h;
    CHECK(rt_png_read_rgb8(rgb_png, &c, &w, &h) && rt_png_read_u16(depth_png, &z, &w, &h));
    CHECK(memcmp(f.rgb, c, (size_t)w * h * 3) == 0);
    CHECK(memcmp(f.depth, z, (size_t)w * h * 2) != 0);
    free(c);
    free(z);
    rgbd_source_close(src);
    /* camera.txt, then --camera, come first. */
    CHECK(rt_write_text(rt_join(d, "camera.txt"), "500 501 300.5 200.5 5000\n"));
    CHECK_OK(replay_open(d, NULL, &src));
    CHECK(rgbd_source_intrinsics(src)->fx_px == 500 && !replay_undistortion(src, dist, NULL));
    rgbd_source_close(src);
    replay_options opt = {.camera = "fr1"};
    CHECK_OK(replay_open(d, &opt, &src));
    CHECK(rgbd_source_intrinsics(src)->fx_px == 517.3 && replay_undistortion(src, dist, NULL) && dist[0] == 0.2624);
    rgbd_source_close(src);
    /* A parent's name is not the folder's. */
    const char *inner = make_tum("rgbd_dataset_freiburg1_parent/plain");
    CHECK(inner);
    snprintf(d, sizeof d, "%s", inner);
    CHECK_OK(replay_open(d, NULL, &src));
    CHECK(rgbd_source_intrinsics(src)->fx_px == 525.0 && !replay_undistortion(src, dist, NULL));
    rgbd_source_close(src);
}

/* Every allocation of a lens-carrying source, from open to the last frame,
 * fails in turn and is reported, never crashes or leaks. */
BF_TEST(tum_lens_reading_fails_cleanly_at_every_allocation)
{
    const char *dir = make_tum("rgbd_dataset_freiburg1_faults");
    if (!dir) BF_SKIP("tum/frames absent");
    int n = bf_test_fault_walk(rt_read_all, (void *)dir);
    CHECK(n >= 10);
    fprintf(stderr, "  sequence with a lens: %d allocations failed in turn\n", n);
}

/* Opens dir expecting status want and a message mentioning what. */
#define CHECK_OPEN_FAILS(dir, want, what)                                                        \
    do {                                                                                         \
        rgbd_source *_src = NULL;                                                                \
        CHECK_STATUS(replay_open((dir), NULL, &_src), (want));                                   \
        CHECK(_src == NULL);                                                                     \
        CHECK_ERROR_MENTIONS(what);                                                              \
    } while (0)

BF_TEST(tum_malformed_index_files_name_file_and_line)
{
    const char *dir = make_tum("tum_bad_index");
    if (!dir) BF_SKIP("tum/frames absent");
    char d[1024];
    snprintf(d, sizeof d, "%s", dir);
    const char *depth = rt_join(d, "depth.txt"), *rgb = rt_join(d, "rgb.txt"), *gt = rt_join(d, "groundtruth.txt");
    char depth_p[1024], rgb_p[1024], gt_p[1024];
    snprintf(depth_p, sizeof depth_p, "%s", depth);
    snprintf(rgb_p, sizeof rgb_p, "%s", rgb);
    snprintf(gt_p, sizeof gt_p, "%s", gt);

    CHECK(rt_write_text(depth_p, "10.0 depth/a.png\n10.2 depth/b1.png\n10.1 depth/b2.png\n"));
    CHECK_OPEN_FAILS(d, BF_FORMAT, "depth.txt:3");
    /* A repeated stamp is not an error (TUM's own files have them): the first line is kept. */
    CHECK(rt_write_text(depth_p, "10.0 depth/a.png\n10.0 depth/b1.png\n10.1 depth/b2.png\n"));
    rgbd_source *src = NULL;
    CHECK_OK(replay_open(d, NULL, &src));
    CHECK_EQ_INT(src->n_frames, 2);
    rgbd_source_close(src);
    CHECK(rt_write_text(depth_p, "10.0 depth/a.png\n10.1 depth/b1.png extra\n"));
    CHECK_OPEN_FAILS(d, BF_FORMAT, "depth.txt:2");
    CHECK_ERROR_MENTIONS("found 3");
    CHECK(rt_write_text(depth_p, "10.0 depth/a.png\nten depth/b1.png\n"));
    CHECK_OPEN_FAILS(d, BF_FORMAT, "depth.txt:2");
    CHECK(rt_write_text(depth_p, "# only comments\n"));
    CHECK_OPEN_FAILS(d, BF_FORMAT, "depth.txt");
    CHECK(rt_write_text(depth_p, depth_txt));

    CHECK(rt_write_text(rgb_p, "# c\n10.015 rgb/a.png\n10.015 rgb/b1.png\n10.092 rgb/b1.png\n"));
    CHECK_OK(replay_open(d, NULL, &src));
    rgbd_source_close(src);
    CHECK(rt_write_text(rgb_p, "# c\n10.015 rgb/a.png\n10.092 rgb/b1.png\n10.05 rgb/b2.png\n"));
    CHECK_OPEN_FAILS(d, BF_FORMAT, "rgb.txt:4");
    CHECK_ERROR_MENTIONS("before");
    CHECK(rt_write_text(rgb_p, "10.015\n"));
    CHECK_OPEN_FAILS(d, BF_FORMAT, "rgb.txt:1");
    CHECK(rt_write_text(rgb_p, "50 rgb/a.png\n"));
    CHECK_OPEN_FAILS(d, BF_FORMAT, "within 0.02 s");
    CHECK(rt_write_text(rgb_p, rgb_txt));

    CHECK(rt_write_text(gt_p, "9.9 0 0 0 0 0 0 1\n10.1 0 NaN 0 0 0 0 1\n"));
    CHECK_OPEN_FAILS(d, BF_FORMAT, "groundtruth.txt:2");
    CHECK(rt_write_text(gt_p, "9.9 0 0 0 0 0 0 1\n10.1 0 0 0 0 0 1\n"));
    CHECK_OPEN_FAILS(d, BF_FORMAT, "groundtruth.txt:2");
    CHECK(rt_write_text(gt_p, "10.1 0 0 0 0 0 0 1\n9.9 0 0 0 0 0 0 1\n"));
    CHECK_OPEN_FAILS(d, BF_FORMAT, "groundtruth.txt:2");
    CHECK(write_gt(d));

    CHECK(remove(depth_p) == 0);
    CHECK_OPEN_FAILS(d, BF_IO, "depth.txt");
    CHECK(remove(rgb_p) == 0);
    CHECK_OPEN_FAILS(d, BF_FORMAT, "not a recognised sequence");
    CHECK_OPEN_FAILS("/nonexistent/seq", BF_IO, "/nonexistent/seq");
    CHECK_OPEN_FAILS(gt_p, BF_FORMAT, "not a folder");
}

/* Replaces frame 1's depth image (b1.png) by the file at bad and returns
 * the folder. */
static const char *tum_with_bad_frame(const char *name, const char *bad_src, size_t n_bytes)
{
    const char *dir = make_tum(name);
    if (!dir) return NULL;
    static char d[1024];
    snprintf(d, sizeof d, "%s", dir);
    /* Frame 1 uses depth/b1.png, frame 2 depth/b1_2.png: break only b1. */
    const char *p = rt_join(d, "depth/b1.png");
    unlink(p);
    if (bad_src && !rt_copy_file(bad_src, p, n_bytes)) return NULL;
    return d;
}

static void check_bad_frame_1(const char *d, bf_status want, const char *what)
{
    rgbd_source *src;
    CHECK_OK(replay_open(d, NULL, &src));
    bf_frame f;
    CHECK_OK(rgbd_source_next(src, &f));
    CHECK_STATUS(rgbd_source_next(src, &f), want);
    CHECK_ERROR_MENTIONS("b1.png");
    CHECK_ERROR_MENTIONS("frame 1");
    CHECK_ERROR_MENTIONS(what);
    /* The caller may go on past the bad frame. */
    CHECK_OK(rgbd_source_next(src, &f));
    CHECK_EQ_INT(f.index, 2);
    rgbd_source_close(src);

    replay_options opt = {.skip_bad_frames = true};
    CHECK_OK(replay_open(d, &opt, &src));
    uint32_t seen[8], n = 0;
    bf_status s;
    while ((s = rgbd_source_next(src, &f)) == BF_OK && n < 8) seen[n++] = f.index;
    CHECK_STATUS(s, BF_END);
    CHECK_EQ_INT(n, 3);
    CHECK(seen[0] == 0 && seen[1] == 2 && seen[2] == 3);
    CHECK_EQ_INT(replay_skipped_frames(src), 1);
    rgbd_source_close(src);
}

BF_TEST(tum_truncated_depth_png_fails_its_frame_or_is_skipped)
{
    const char *data = bf_test_data("tum/frames/fr2_desk_b1_depth.png");
    if (!data) BF_SKIP("tum/frames absent");
    char src[1024];
    snprintf(src, sizeof src, "%s", data);
    const char *d = tum_with_bad_frame("tum_trunc", src, rt_file_size(src) / 2);
    CHECK(d);
    check_bad_frame_1(d, BF_FORMAT, "truncated");
}

BF_TEST(tum_missing_image_fails_its_frame_or_is_skipped)
{
    const char *d = tum_with_bad_frame("tum_missing", NULL, 0);
    if (!d) BF_SKIP("tum/frames absent");
    check_bad_frame_1(d, BF_IO, "cannot open");
}

BF_TEST(tum_8bit_depth_png_fails_its_frame_or_is_skipped)
{
    const char *d = tum_with_bad_frame("tum_8bit", NULL, 0);
    if (!d) BF_SKIP("tum/frames absent");
    static uint8_t g[640 * 480];
    CHECK(rt_png_write_gray8(rt_join(d, "depth/b1.png"), g, 640, 480));
    check_bad_frame_1(d, BF_FORMAT, "8-bit");
}

BF_TEST(tum_colour_depth_size_mismatch_fails_its_frame)
{
    const char *d = tum_with_bad_frame("tum_size", NULL, 0);
    if (!d) BF_SKIP("tum/frames absent");
    char dir[1024];
    snprintf(dir, sizeof dir, "%s", d);
    /* Depth of frame 1 back in place, its colour image replaced by 320x240. */
    const char *data = bf_test_data("tum/frames/fr2_desk_b1_depth.png");
    CHECK(rt_link(data, dir, "depth/b1.png"));
    static uint8_t c[320 * 240 * 3];
    unlink(rt_join(dir, "rgb/b1.png"));
    CHECK_OK(replay_png_write_rgb8(rt_join(dir, "rgb/b1.png"), c, 320, 240));
    rgbd_source *src;
    CHECK_OK(replay_open(dir, NULL, &src));
    bf_frame f;
    CHECK_OK(rgbd_source_next(src, &f));
    CHECK_STATUS(rgbd_source_next(src, &f), BF_FORMAT);
    CHECK_ERROR_MENTIONS("rgb/b1.png");
    CHECK_ERROR_MENTIONS("320x240");
    CHECK_ERROR_MENTIONS("frame 1");
    rgbd_source_close(src);
}

static bf_status read_groundtruth(void *arg)
{
    char path[1200];
    snprintf(path, sizeof path, "%s/groundtruth.txt", (const char *)arg);
    bf_traj t = {0};
    bf_status s = replay_traj_read_tum(path, &t);
    bf_traj_free(&t);
    return s;
}

/* Every host allocation of opening and reading a sequence fails in turn:
 * each is a clean BF_NO_MEMORY with a message, nothing leaks (ASan). */
BF_TEST(tum_reading_fails_cleanly_at_every_allocation)
{
    const char *dir = make_tum("tum_faults");
    if (!dir) BF_SKIP("tum/frames absent");
    int n = bf_test_fault_walk(rt_read_all, (void *)dir);
    CHECK(n >= 8);
    fprintf(stderr, "  sequence: %d allocations failed in turn\n", n);
    n = bf_test_fault_walk(read_groundtruth, (void *)dir);
    CHECK(n >= 1);
}
