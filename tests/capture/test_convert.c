/* Pure helpers of the live backends: pixel formats, the Kinect v1
 * disparity model, the device clock unwrapping. */
#include "capture/live_int.h"
#include "test.h"

BF_TEST(yuyv_grey_and_colours)
{
    /* Y=128 with neutral chroma is grey (128-16)*1.164 = 130.4; pure BT.601
     * red (Y 81, U 90, V 240) decodes to about (255, 0, 0). */
    const uint8_t yuyv[2 * 4] = {128, 128, 128, 128, 81, 90, 81, 240};
    uint8_t rgb[4 * 3];
    capture__yuyv_to_rgb(yuyv, 8, 4, 1, rgb);
    for (int i = 0; i < 6; i++) CHECK_NEAR(rgb[i], 130, 1);
    CHECK_NEAR(rgb[6], 255, 2);
    CHECK_NEAR(rgb[7], 0, 2);
    CHECK_NEAR(rgb[8], 0, 2);
    CHECK_NEAR(rgb[9], 255, 2);
    /* UYVY is the same samples in another order. */
    const uint8_t uyvy[2 * 4] = {128, 128, 128, 128, 90, 81, 240, 81};
    uint8_t rgb2[4 * 3];
    capture__uyvy_to_rgb(uyvy, 8, 4, 1, rgb2);
    CHECK(!memcmp(rgb, rgb2, sizeof rgb));
}

BF_TEST(strided_rows_and_bgr)
{
    /* Two rows of 2 BGR pixels with 2 bytes of padding per row. */
    const uint8_t bgr[2 * 8] = {1, 2, 3, 4, 5, 6, 99, 99, 7, 8, 9, 10, 11, 12, 99, 99};
    uint8_t rgb[12];
    capture__bgr_to_rgb(bgr, 8, 2, 2, rgb);
    const uint8_t want[12] = {3, 2, 1, 6, 5, 4, 9, 8, 7, 12, 11, 10};
    CHECK(!memcmp(rgb, want, 12));
    uint8_t packed[12];
    capture__copy_rows(bgr, 8, 6, 2, packed);
    CHECK(!memcmp(packed, bgr, 6) && !memcmp(packed + 6, bgr + 8, 6));
}

BF_TEST(nearest_resize_maps_corners)
{
    uint8_t src[2 * 2 * 3] = {10, 10, 10, 20, 20, 20, 30, 30, 30, 40, 40, 40};
    uint8_t dst[4 * 4 * 3];
    capture__resize_rgb_nearest(src, 2, 2, dst, 4, 4);
    CHECK_EQ_INT(dst[0], 10);
    CHECK_EQ_INT(dst[(0 * 4 + 3) * 3], 20);
    CHECK_EQ_INT(dst[(3 * 4 + 0) * 3], 30);
    CHECK_EQ_INT(dst[(3 * 4 + 3) * 3], 40);
}

BF_TEST(clock_unwrap_crosses_the_32_bit_wrap)
{
    capture__unwrap32 u = {0};
    CHECK_EQ_INT(capture__unwrap32_push(&u, 0xFFFFFF00u), 0xFFFFFF00ull);
    /* Colour stamped a little before the depth it pairs with: no wrap. */
    CHECK_EQ_INT(capture__unwrap32_push(&u, 0xFFFFFE00u), 0xFFFFFE00ull);
    CHECK_EQ_INT(capture__unwrap32_push(&u, 0x00000100u), 0x100000100ull);
    CHECK_EQ_INT(capture__unwrap32_push(&u, 0x00200000u), 0x100200000ull);
}

BF_TEST(kinect_model_matches_an_independent_fit)
{
    /* Magnenat's fit to measured Kinect v1 depth (OpenKinect wiki, "Imaging
     * Information"): z = 0.1236 m * tan(raw / 2842.5 + 1.1863). Its own
     * error against measurements is about a percent in the working range,
     * so the model with libfreenect's default parameters must agree with
     * it within 1.5 % for 0.5-3 m (raw 400-950). */
    capture__kinect_params p = capture__kinect_default_params();
    double prev = 0;
    for (int raw = 400; raw <= 950; raw += 10) {
        double mm = capture__kinect_raw_to_mm((uint16_t)raw, &p);
        double fit = 123.6 * tan(raw / 2842.5 + 1.1863);
        CHECK_LE(fabs(mm - fit) / fit, 0.015);
        CHECK(mm > prev); /* depth grows with disparity value */
        prev = mm;
    }
    CHECK(isnan(capture__kinect_raw_to_mm(2047, &p)));
    /* Beyond 10 m the model is outside the sensor's range. */
    CHECK(isnan(capture__kinect_raw_to_mm(1084, &p)));
    /* IR camera focal length at 640x480: 120 / (2 * 0.1042) = 575.8 px,
     * the value Kinect calibrations report (about 580). */
    CHECK_NEAR(capture__kinect_ir_focal_px(&p), 575.816, 0.001);
}

BF_TEST(focal_from_fov)
{
    /* 90 degrees over 640 px: f = 320 px. */
    CHECK_NEAR(capture__focal_from_fov(640, M_PI / 2), 320.0, 1e-9);
    CHECK(isnan(capture__focal_from_fov(640, 0)));
    CHECK(isnan(capture__focal_from_fov(640, M_PI)));
}
