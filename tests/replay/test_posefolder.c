/* replay: pose-per-frame folders (7-Scenes / 3DMatch layout) built in the
 * temporary folder from the real fr2 frames, converted to millimetres. */
#include <stdio.h>
#include <unistd.h>

#include "replay/replay.h"
#include "replay_test.h"
#include "test.h"

static bf_se3 frame_pose(int k)
{
    return bf_se3_from_qt(bf_quat_from_axis_angle(bf_v3(1, 2, 3), 0.4 * k + 0.1), bf_v3(0.1 * k, -0.2, 1.5));
}

static bool write_pose(const char *dir, int k, const bf_se3 *T)
{
    char name[64], text[1024];
    snprintf(name, sizeof name, "frame-%06d.pose.txt", k);
    int n = 0;
    /* 7-Scenes style: tab separated, 8 decimals, trailing tab. */
    for (int i = 0; i < 3; i++)
        n += snprintf(text + n, sizeof text - (size_t)n, "%.8e\t%.8e\t%.8e\t%.8e\t\n", T->R[i][0], T->R[i][1],
                      T->R[i][2], i == 0 ? T->t.x : i == 1 ? T->t.y : T->t.z);
    snprintf(text + n, sizeof text - (size_t)n, "0.0\t0.0\t0.0\t1.0\t\n");
    return rt_write_text(rt_join(dir, name), text);
}

/* Frames 0..2 from fr2 desk a, b1, b2: depth in mm (fr2 units / 5, rounded
 * down), one pixel set to 7-Scenes' 65535 "no depth", colour as PNG or JPEG.
 * Keeps the mm depth of frame 0 in *mm0 for the comparison. */
static const char *make_posefolder(const char *name, bool jpeg, uint16_t **mm0)
{
    const char *data = bf_test_data("tum/frames");
    if (!data) return NULL;
    char src[1024];
    snprintf(src, sizeof src, "%s", data);
    static char d[1024];
    snprintf(d, sizeof d, "%s", rt_fresh_dir(name));
    const char *v[3] = {"a", "b1", "b2"};
    for (int k = 0; k < 3; k++) {
        char p[1200], n[64];
        snprintf(p, sizeof p, "%s/fr2_desk_%s_depth.png", src, v[k]);
        uint16_t *dep;
        uint32_t w, h;
        if (!rt_png_read_u16(p, &dep, &w, &h)) return NULL;
        for (size_t i = 0; i < (size_t)w * h; i++) dep[i] = (uint16_t)(dep[i] / 5);
        dep[7] = 65535;
        snprintf(n, sizeof n, "frame-%06d.depth.png", k);
        if (replay_png_write_u16(rt_join(d, n), dep, w, h)) return NULL;
        if (k == 0 && mm0)
            *mm0 = dep;
        else
            free(dep);
        snprintf(p, sizeof p, "%s/fr2_desk_%s_rgb.png", src, v[k]);
        if (jpeg) {
            uint8_t *c;
            if (!rt_png_read_rgb8(p, &c, &w, &h)) return NULL;
            snprintf(n, sizeof n, "frame-%06d.color.jpg", k);
            bool ok = rt_jpeg_write(rt_join(d, n), c, w, h, 90);
            free(c);
            if (!ok) return NULL;
        } else {
            snprintf(n, sizeof n, "frame-%06d.color.png", k);
            if (!rt_link(p, d, n)) return NULL;
        }
        bf_se3 T = frame_pose(k);
        if (!write_pose(d, k, &T)) return NULL;
    }
    if (!rt_write_text(rt_join(d, "camera-intrinsics.txt"), "520.9 0 325.1\n0 521.0 249.7\n0 0 1\n")) return NULL;
    return d;
}

BF_TEST(posefolder_reads_millimetre_depth_poses_and_intrinsics)
{
    uint16_t *mm0 = NULL;
    const char *d = make_posefolder("pf_main", false, &mm0);
    if (!d) BF_SKIP("tum/frames absent");
    char dir[1024];
    snprintf(dir, sizeof dir, "%s", d);
    rgbd_source *src;
    CHECK_OK(replay_open(dir, NULL, &src));
    CHECK(!strcmp(src->kind, "pose-folder"));
    CHECK_EQ_INT(src->n_frames, 3);
    CHECK(src->has_groundtruth);
    const bf_intrinsics *K = rgbd_source_intrinsics(src);
    CHECK(K->fx_px == 520.9 && K->fy_px == 521.0 && K->cx_px == 325.1 && K->cy_px == 249.7);
    CHECK(K->depth_scale == 1000 && K->width == 640 && K->height == 480);
    bf_frame f;
    for (int k = 0; k < 3; k++) {
        CHECK_OK(rgbd_source_next(src, &f));
        CHECK_EQ_INT(f.index, k);
        CHECK_NEAR(f.t_depth_s, k / 30.0, 1e-12);
        CHECK(f.has_pose);
        bf_se3 T = frame_pose(k);
        /* Written with 9 significant digits: within 1e-8. */
        bf_se3 Ti = bf_se3_inverse(&T);
        bf_se3 D = bf_se3_mul(&Ti, &f.T_wc);
        CHECK_LE(bf_se3_angle(&D), 1e-7);
        CHECK_LE(bf_v3_norm(D.t), 1e-7);
        CHECK(f.rgb != NULL);
        if (k == 0) {
            /* 65535 became "no depth"; everything else is bit-exact. */
            CHECK_EQ_INT(f.depth[7], 0);
            mm0[7] = 0;
            CHECK(memcmp(mm0, f.depth, 640 * 480 * 2) == 0);
        }
    }
    free(mm0);
    CHECK_STATUS(rgbd_source_next(src, &f), BF_END);
    rgbd_source_close(src);
}

BF_TEST(posefolder_jpeg_colour_and_other_intrinsics_forms)
{
    const char *d = make_posefolder("pf_jpeg", true, NULL);
    if (!d) BF_SKIP("tum/frames absent");
    char dir[1024];
    snprintf(dir, sizeof dir, "%s", d);
    const char *ki = rt_join(dir, "camera-intrinsics.txt");
    char kpath[1024];
    snprintf(kpath, sizeof kpath, "%s", ki);
    /* 3DMatch's form with a fourth column and row. */
    CHECK(rt_write_text(kpath, "585 0 320 0\n0 585 240 0\n0 0 1 0\n0 0 0 1\n"));
    rgbd_source *src;
    CHECK_OK(replay_open(dir, NULL, &src));
    CHECK(src->intrinsics.fx_px == 585 && src->intrinsics.cy_px == 240);
    bf_frame f;
    CHECK_OK(rgbd_source_next(src, &f));
    /* Compare with an independent decode of the PNG it came from: JPEG at
     * quality 90 keeps the mean absolute error within a few levels. */
    uint8_t *c;
    uint32_t w, h;
    CHECK(rt_png_read_rgb8(bf_test_data("tum/frames/fr2_desk_a_rgb.png"), &c, &w, &h));
    double err = 0;
    for (size_t i = 0; i < (size_t)w * h * 3; i++) err += abs((int)c[i] - (int)f.rgb[i]);
    free(c);
    CHECK_LE(err / (w * h * 3.0), 4.0);
    rgbd_source_close(src);
    CHECK(rt_write_text(kpath, "500 0 300 0 501 200 0 0 1\n"));
    CHECK_OK(replay_open(dir, NULL, &src));
    CHECK(src->intrinsics.fy_px == 501 && src->intrinsics.cx_px == 300);
    rgbd_source_close(src);
    CHECK(rt_write_text(kpath, "# K\n585 0 320\n0 585\n0 0 1\n"));
    CHECK_STATUS(replay_open(dir, NULL, &src), BF_FORMAT);
    CHECK_ERROR_MENTIONS("camera-intrinsics.txt:2");
    CHECK(rt_write_text(kpath, "585 0 320\n0 585 240\n1 0 1\n"));
    CHECK_STATUS(replay_open(dir, NULL, &src), BF_FORMAT);
    CHECK_ERROR_MENTIONS("camera-intrinsics.txt:1");
    /* No intrinsics file: 7-Scenes' camera. */
    CHECK(unlink(kpath) == 0);
    CHECK_OK(replay_open(dir, NULL, &src));
    CHECK(src->intrinsics.fx_px == 585 && src->intrinsics.cx_px == 320 && src->intrinsics.depth_scale == 1000);
    rgbd_source_close(src);
}

BF_TEST(posefolder_bad_pose_fails_its_frame_or_is_skipped)
{
    const char *d = make_posefolder("pf_bad", false, NULL);
    if (!d) BF_SKIP("tum/frames absent");
    char dir[1024];
    snprintf(dir, sizeof dir, "%s", d);
    const char *pose = rt_join(dir, "frame-000001.pose.txt");
    char p[1024];
    snprintf(p, sizeof p, "%s", pose);
    const char *bad[] = {
        "1 0 0 0\n0 1 0 nan\n0 0 1 0\n0 0 0 1\n",   /* NaN */
        "1 0 0 0\n0 1 0 0\n0 0 1\n0 0 0 1\n",       /* 3 numbers on a row */
        "1 0 0 0\n0 1 0 0\n0 0 1 0\n1 0 0 1\n",     /* not rigid */
        "2 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n",     /* not a rotation */
    };
    const char *what[] = {"frame-000001.pose.txt:2", "frame-000001.pose.txt:3", "frame-000001.pose.txt:4",
                          "not a rotation"};
    for (int k = 0; k < 4; k++) {
        CHECK(rt_write_text(p, bad[k]));
        rgbd_source *src;
        CHECK_OK(replay_open(dir, NULL, &src));
        bf_frame f;
        CHECK_OK(rgbd_source_next(src, &f));
        CHECK_STATUS(rgbd_source_next(src, &f), BF_FORMAT);
        CHECK_ERROR_MENTIONS(what[k]);
        CHECK_ERROR_MENTIONS("frame 1");
        rgbd_source_close(src);
    }
    replay_options opt = {.skip_bad_frames = true};
    rgbd_source *src;
    CHECK_OK(replay_open(dir, &opt, &src));
    bf_frame f;
    CHECK_OK(rgbd_source_next(src, &f));
    CHECK_EQ_INT(f.index, 0);
    CHECK_OK(rgbd_source_next(src, &f));
    CHECK_EQ_INT(f.index, 2);
    CHECK_STATUS(rgbd_source_next(src, &f), BF_END);
    CHECK_EQ_INT(replay_skipped_frames(src), 1);
    rgbd_source_close(src);
}
