/* capture_open: URI schemes, options and the errors for absent devices. */
#include <dlfcn.h>

#include "capture/live_int.h"
#include "test.h"

static bool has_backend(const char *name)
{
    for (const char *const *n = capture_backend_names(); *n; n++)
        if (!strcmp(*n, name)) return true;
    return false;
}

BF_TEST(unknown_scheme_is_invalid_arg)
{
    rgbd_source *src = NULL;
    CHECK_STATUS(capture_open("kinect2:0", &src), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("kinect2");
    CHECK(src == NULL);
    CHECK_STATUS(capture_open("/dev/video0", &src), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("/dev/video0");
    CHECK_STATUS(capture_open(":0", &src), BF_INVALID_ARG);
}

BF_TEST(backend_names_list_what_was_compiled)
{
    const char *const *names = capture_backend_names();
    int n = 0;
    while (names[n]) n++;
#ifdef BF_HAVE_V4L2
    CHECK(has_backend("v4l2"));
#endif
#ifdef BF_HAVE_FREENECT
    CHECK(has_backend("freenect"));
#else
    CHECK(!has_backend("freenect"));
#endif
#ifdef BF_HAVE_OPENNI2
    CHECK(has_backend("openni2"));
#else
    CHECK(!has_backend("openni2"));
#endif
    CHECK(n <= 3);
}

/* A backend left out of the build names the package that brings it. */
BF_TEST(backend_not_compiled_names_the_package)
{
    rgbd_source *src = NULL;
    int n_checked = 0;
#ifndef BF_HAVE_FREENECT
    CHECK_STATUS(capture_open("freenect:0", &src), BF_UNSUPPORTED);
    CHECK_ERROR_MENTIONS("libfreenect-dev");
    n_checked++;
#endif
#ifndef BF_HAVE_OPENNI2
    CHECK_STATUS(capture_open("openni2:", &src), BF_UNSUPPORTED);
    CHECK_ERROR_MENTIONS("libopenni2-dev");
    n_checked++;
#endif
    (void)src;
    if (!n_checked) BF_SKIP("every backend is compiled in");
}

BF_TEST(uri_options_parse_and_apply)
{
    char target[64];
    capture__uri_options o;
    CHECK_OK(capture__uri_split("freenect:1?depth=disparity&camera=500,501.5,320,240&depth_scale=5000",
                                "1?depth=disparity&camera=500,501.5,320,240&depth_scale=5000", target, sizeof target,
                                &o));
    CHECK(!strcmp(target, "1"));
    CHECK(!strcmp(o.depth_mode, "disparity"));
    CHECK(o.has_camera && o.has_depth_scale);
    bf_intrinsics K = {.width = 640, .height = 480, .fx_px = 1, .fy_px = 1, .depth_scale = 1000};
    capture__apply_options(&o, &K);
    CHECK_NEAR(K.fx_px, 500, 0);
    CHECK_NEAR(K.fy_px, 501.5, 0);
    CHECK_NEAR(K.cx_px, 320, 0);
    CHECK_NEAR(K.cy_px, 240, 0);
    CHECK_NEAR(K.depth_scale, 5000, 0);
    CHECK_EQ_INT(K.width, 640);

    CHECK_OK(capture__uri_split("v4l2:/dev/video2,/dev/video4", "/dev/video2,/dev/video4", target, sizeof target, &o));
    CHECK(!strcmp(target, "/dev/video2,/dev/video4"));
    CHECK(!o.has_camera && !o.has_depth_scale && !o.depth_mode[0]);

    CHECK_STATUS(capture__uri_split("v4l2:x?fps=30", "x?fps=30", target, sizeof target, &o), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("fps");
    CHECK_STATUS(capture__uri_split("v4l2:x?camera=1,2,3", "x?camera=1,2,3", target, sizeof target, &o),
                 BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("fx,fy,cx,cy");
    /* Decimal only, every value whole, the message naming all of it. */
    CHECK_STATUS(capture__uri_split("v4l2:x?camera=0x10,2,3,4", "x?camera=0x10,2,3,4", target, sizeof target, &o),
                 BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("camera=0x10,2,3,4");
    CHECK_STATUS(capture__uri_split("v4l2:x?camera=1,2,3,4,5", "x?camera=1,2,3,4,5", target, sizeof target, &o),
                 BF_INVALID_ARG);
    CHECK_STATUS(capture__uri_split("v4l2:x?camera=1,,3,4", "x?camera=1,,3,4", target, sizeof target, &o),
                 BF_INVALID_ARG);
    CHECK_STATUS(capture__uri_split("v4l2:x?depth_scale=-1", "x?depth_scale=-1", target, sizeof target, &o),
                 BF_INVALID_ARG);
    CHECK_STATUS(capture__uri_split("v4l2:x?depth", "x?depth", target, sizeof target, &o), BF_INVALID_ARG);
    CHECK_STATUS(capture__uri_split("f:x?depth=mm", "x?depth=mm", target, sizeof target, &o), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("registered or disparity");
}

BF_TEST(v4l2_missing_node_is_no_device)
{
    if (!has_backend("v4l2")) BF_SKIP("no V4L2 backend");
    rgbd_source *src = NULL;
    CHECK_STATUS(capture_open("v4l2:/dev/bitfuse-no-such-video", &src), BF_NO_DEVICE);
    CHECK_ERROR_MENTIONS("v4l2:/dev/bitfuse-no-such-video");
    CHECK(src == NULL);
    CHECK_STATUS(capture_open("v4l2:", &src), BF_INVALID_ARG);
    CHECK_STATUS(capture_open("v4l2:/dev/null", &src), BF_NO_DEVICE);
    CHECK_ERROR_MENTIONS("not a V4L2 device");
}

BF_TEST(freenect_missing_device_is_no_device)
{
#ifdef BF_HAVE_FREENECT
    rgbd_source *src = NULL;
    CHECK_STATUS(capture_open("freenect:abc", &src), BF_INVALID_ARG);
    /* Index 7: no machine running these tests has eight Kinects. */
    CHECK_STATUS(capture_open("freenect:7", &src), BF_NO_DEVICE);
    CHECK_ERROR_MENTIONS("freenect:7");
    CHECK(src == NULL);
    if (dlsym(RTLD_DEFAULT, "freenect_copy_registration") == NULL) BF_SKIP("fakenect is loaded");
    bf_status s = capture_open("freenect:0", &src);
    if (s == BF_OK) {
        rgbd_source_close(src);
        BF_SKIP("a Kinect is plugged in");
    }
    CHECK_STATUS(s, BF_NO_DEVICE);
    CHECK_ERROR_MENTIONS("freenect:0");
#else
    BF_SKIP("built without libfreenect");
#endif
}

BF_TEST(list_devices_does_not_fail_without_devices)
{
    capture_device_info d[8];
    uint32_t n = capture_list_devices(d, 8);
    for (uint32_t i = 0; i < n && i < 8; i++) CHECK(strchr(d[i].uri, ':') != NULL);
    CHECK(capture_list_devices(NULL, 0) == n);
}

BF_TEST(device_uris_are_told_from_recordings_by_scheme)
{
    CHECK(capture_is_device_uri("freenect:0"));
    CHECK(capture_is_device_uri("openni2:"));
    CHECK(capture_is_device_uri("v4l2:/dev/video0"));
    CHECK(!capture_is_device_uri("freenectx:0"));
    CHECK(!capture_is_device_uri("seq_fr2"));
    CHECK(!capture_is_device_uri("/data/run:2/desk.bflog"));
    CHECK(!capture_is_device_uri("v4l2"));
    /* A device URI naming a recording keeps the recording's times (a resumed store passes over
     * what it has); a camera's are its own. */
    CHECK(capture_is_recording_uri("openni2:/data/desk.oni"));
    CHECK(capture_is_recording_uri("openni2:desk.ONI"));
    CHECK(!capture_is_recording_uri("openni2:"));
    CHECK(!capture_is_recording_uri("openni2:Dummy"));
    CHECK(!capture_is_recording_uri("/data/desk.oni"));
    CHECK(!capture_is_recording_uri("freenect:0"));
    /* Without an opener for recordings, a path is refused, not read. */
    rgbd_source *src = NULL;
    bool is_live = true;
    CHECK_STATUS(capture_open_device("seq_fr2", NULL, NULL, false, 4, &is_live, &src), BF_INVALID_ARG);
    CHECK(src == NULL);
}

/* Three 8x8 frames 50 ms apart. */
static bf_status three_frames(void *user, uint32_t k, bf_frame *f)
{
    static uint16_t depth[64];
    (void)user;
    *f = (bf_frame){.index = k, .width = 8, .height = 8, .t_depth_s = 7 + 0.05 * k, .depth = depth};
    return BF_OK;
}

static bf_status open_three(void *user, const char *path, rgbd_source **out)
{
    (void)path;
    return capture_source_from_fn(user, 3, false, three_frames, NULL, out);
}

/* Five frames at 20 Hz with an hour's break after the second. */
static bf_status five_with_a_break(void *user, uint32_t k, bf_frame *f)
{
    (void)user;
    static uint16_t depth[64];
    *f = (bf_frame){.index = k, .width = 8, .height = 8, .t_depth_s = 7 + 0.05 * k + (k >= 2 ? 3600 : 0), .depth = depth};
    return BF_OK;
}

static bf_status open_five(void *user, const char *path, rgbd_source **out)
{
    (void)path;
    return capture_source_from_fn(user, 5, false, five_with_a_break, NULL, out);
}

/* A recording opened through capture_open_device with --realtime, read to
 * its end: the frames delivered and the seconds it took. */
static double paced_read(const char *uri, capture_open_fn open, uint32_t *n, bool *is_live)
{
    bf_intrinsics K = {8, 8, 10, 10, 3.5, 3.5, 1000};
    rgbd_source *src = NULL;
    double t0 = bf_time_s();
    *n = 0;
    if (capture_open_device(uri, open, &K, true, 4, is_live, &src) != BF_OK) return -1;
    bf_frame f;
    while (rgbd_source_next(src, &f) == BF_OK) ++*n;
    double dt = bf_time_s() - t0;
    rgbd_source_close(src);
    return dt;
}

BF_TEST(a_paced_recording_goes_on_at_its_pace_after_a_break)
{
    /* The break is not waited for (over 10 s), and the frames after it keep
     * their 50 ms steps: 50 ms before it and 100 ms after it, not a burst. */
    uint32_t n;
    bool is_live = true;
    double dt = paced_read("five", open_five, &n, &is_live);
    CHECK_EQ_INT(n, 5);
    CHECK(dt >= 0.145);
    CHECK(dt < 5);
}

BF_TEST(a_paced_recording_arrives_at_its_own_frame_rate)
{
    uint32_t n;
    bool is_live = true;
    double dt = paced_read("three", open_three, &n, &is_live);
    CHECK(!is_live);
    CHECK_EQ_INT(n, 3);
    CHECK(dt >= 0.095); /* the last frame is 100 ms after the first */
}
