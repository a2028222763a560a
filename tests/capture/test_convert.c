/* Pure helpers of the live backends: pixel formats, the Kinect v1
 * disparity model, the device clock unwrapping. */
#include "capture/live_int.h"
#include "test.h"

#include <stdlib.h>
#include <string.h>

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

/* A ramp v = 20 + gx * x + gy * y over the source's pixel centres,
 * resized: where the resize keeps pixel centres (destination x + 0.5 at
 * (x + 0.5) * s / d in the source, each axis on its own) every destination
 * pixel holds the ramp at its own centre, since an area average and a
 * linear interpolation of a linear function both give its value at the
 * centre. A fractional shrink averages whole pixels, whose covered centroid
 * is up to off_x / off_y px from the centre (1/12 px at 3:2, 1/24 at 8:3,
 * none at whole ratios or growing). Nearest-pixel resizing is half a source
 * pixel off at 2:1 (a level off on these ramps). */
typedef struct ramp_axis {
    uint32_t s, d;
    double slope, off_px;
} ramp_axis;

static double ramp_centre(const ramp_axis *a, uint32_t x)
{
    double c = (x + 0.5) * a->s / a->d - 0.5;
    return c < 0 ? 0 : c > a->s - 1 ? a->s - 1 : c; /* growing clamps at the border */
}

static void ramp_case(ramp_axis ax, ramp_axis ay)
{
    double tol = 0.5 + ax.slope * ax.off_px + ay.slope * ay.off_px + 1e-3; /* rounding, and the offsets */
    uint8_t *src = malloc((size_t)ax.s * ay.s * 3), *dst = malloc((size_t)ax.d * ay.d * 3);
    CHECK(src && dst);
    if (!src || !dst) goto done;
    for (uint32_t y = 0; y < ay.s; y++)
        for (uint32_t x = 0; x < ax.s; x++)
            for (int c = 0; c < 3; c++)
                src[((size_t)y * ax.s + x) * 3 + c] = (uint8_t)(20 + ax.slope * x + ay.slope * y + 0.5);
    CHECK_EQ_INT(capture__resize_rgb(src, ax.s, ay.s, dst, ax.d, ay.d), BF_OK);
    for (uint32_t y = 0; y < ay.d; y++)
        for (uint32_t x = 0; x < ax.d; x++) {
            double want = 20 + ax.slope * ramp_centre(&ax, x) + ay.slope * ramp_centre(&ay, y);
            for (int c = 0; c < 3; c++) CHECK_NEAR(dst[((size_t)y * ax.d + x) * 3 + c], want, tol);
        }
done:
    free(src);
    free(dst);
}

BF_TEST(resize_keeps_pixel_centres)
{
    const ramp_axis flat = {2, 2, 0.0, 0.0};
    ramp_case((ramp_axis){64, 32, 2.0, 0.0}, flat);        /* 2:1, an area average of pixel pairs */
    ramp_case((ramp_axis){60, 40, 3.0, 1.0 / 12.0}, flat); /* 3:2, fractional coverage */
    ramp_case((ramp_axis){64, 24, 3.0, 1.0 / 24.0}, flat); /* 8:3, three or four pixels each */
    ramp_case((ramp_axis){20, 40, 10.0, 0.0}, flat);       /* 1:2, bilinear */
    ramp_case((ramp_axis){20, 30, 10.0, 0.0}, flat);       /* 2:3, bilinear between centres */
    ramp_case((ramp_axis){200, 4, 1.0, 0.0}, flat);        /* 50:1 */
    /* Each axis by its own ratio: x shrinks 2:1 while y grows 1:2, and the
     * other way round. */
    ramp_case((ramp_axis){32, 16, 4.0, 0.0}, (ramp_axis){12, 24, 8.0, 0.0});
    ramp_case((ramp_axis){12, 24, 8.0, 0.0}, (ramp_axis){48, 32, 3.0, 1.0 / 12.0});
}

BF_TEST(resize_refuses_an_empty_image)
{
    uint8_t px[3] = {1, 2, 3}, out[3];
    CHECK_EQ_INT(capture__resize_rgb(px, 0, 1, out, 1, 1), BF_INVALID_ARG);
    CHECK_EQ_INT(capture__resize_rgb(px, 1, 1, out, 1, 0), BF_INVALID_ARG);
}

BF_TEST(resize_by_two_averages_blocks_and_keeps_corners)
{
    /* 4x2 -> 2x1: each output is the rounded mean of its 2x2 block. */
    const uint8_t src[4 * 2 * 3] = {0, 0, 0, 10, 20, 30, 100, 100, 100, 200, 200, 200,
                                    2, 4, 6, 12, 24, 36, 101, 101, 101, 255, 255, 255};
    uint8_t dst[2 * 3];
    CHECK_EQ_INT(capture__resize_rgb(src, 4, 2, dst, 2, 1), BF_OK);
    const uint8_t want[6] = {6, 12, 18, 164, 164, 164};
    CHECK(!memcmp(dst, want, 6));
    /* Growing 2x2 -> 4x4: the corners are the source corners. */
    const uint8_t small[2 * 2 * 3] = {10, 10, 10, 20, 20, 20, 30, 30, 30, 40, 40, 40};
    uint8_t big[4 * 4 * 3];
    CHECK_EQ_INT(capture__resize_rgb(small, 2, 2, big, 4, 4), BF_OK);
    CHECK_EQ_INT(big[0], 10);
    CHECK_EQ_INT(big[(0 * 4 + 3) * 3], 20);
    CHECK_EQ_INT(big[(3 * 4 + 0) * 3], 30);
    CHECK_EQ_INT(big[(3 * 4 + 3) * 3], 40);
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
