/* calib: a lens's distortion taken out of depth images (undistort.c). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "calib/calib.h"
#include "test.h"

/* TUM fr1's published calibration, scaled to 160 x 120: the lens of the
 * real sequences this is for. */
static calib_camera fr1_small(void)
{
    return (calib_camera){.width = 160, .height = 120, .fx_px = 517.3 / 4, .fy_px = 516.5 / 4,
                          .cx_px = (318.6 + 0.5) / 4 - 0.5, .cy_px = (255.3 + 0.5) / 4 - 0.5,
                          .dist = {0.2624, -0.9531, -0.0054, 0.0026, 1.1633}};
}

/* The plane n . p = d seen through the lens: each raw pixel's ray is the
 * lens's inverse (calib_unproject, Newton's method, an independent path
 * from the map's forward model), and the image holds the plane's depth
 * along the optical axis in 0.1 mm units. */
static const bf_vec3 plane_n = {0.25, -0.35, 0.90};
static const double plane_d = 1.6;

static void render_plane(const calib_camera *c, uint16_t *raw)
{
    for (uint32_t v = 0; v < c->height; v++)
        for (uint32_t u = 0; u < c->width; u++) {
            bf_vec3 ray;
            CHECK(calib_unproject(c, u, v, &ray));
            double z = plane_d / (plane_n.x * ray.x + plane_n.y * ray.y + plane_n.z * ray.z);
            raw[v * c->width + u] = (uint16_t)lround(z * 1e4);
        }
}

/* How far a pinhole back-projection of pixel (u, v) at depth z lies from
 * the plane, along its normal. */
static double plane_distance(const calib_camera *c, double u, double v, double z)
{
    double x = (u - c->cx_px) / c->fx_px * z, y = (v - c->cy_px) / c->fy_px * z;
    double norm = sqrt(plane_n.x * plane_n.x + plane_n.y * plane_n.y + plane_n.z * plane_n.z);
    return fabs(plane_n.x * x + plane_n.y * y + plane_n.z * z - plane_d) / norm;
}

/* The worst distance from the plane of the image's points, each pixel
 * back-projected as a pinhole at its depth; how many pixels had depth. */
static double worst_plane_distance(const calib_camera *c, const uint16_t *img, uint32_t *n_depth)
{
    double worst = 0;
    *n_depth = 0;
    for (uint32_t v = 0; v < c->height; v++)
        for (uint32_t u = 0; u < c->width; u++) {
            uint16_t z = img[v * c->width + u];
            if (!z) continue;
            (*n_depth)++;
            worst = fmax(worst, plane_distance(c, u, v, z * 1e-4));
        }
    return worst;
}

BF_TEST(undistorted_depth_lies_on_the_plane_the_lens_saw)
{
    calib_camera c = fr1_small();
    size_t n = (size_t)c.width * c.height;
    uint16_t *raw = malloc(n * sizeof *raw), *out = malloc(n * sizeof *out);
    CHECK(raw && out);
    render_plane(&c, raw);
    calib_undistort_map m;
    CHECK_OK(calib_undistort_map_make(&c, &m));
    calib_undistort_u16(&m, raw, out);
    uint32_t n_raw, n_out;
    double as_read = worst_plane_distance(&c, raw, &n_raw);
    double undistorted = worst_plane_distance(&c, out, &n_out);
    /* A nearest pixel is at most half a pixel (diagonally 0.71) from where
     * the ray landed, so its depth is off by at most the plane's depth change
     * over 0.71 px (its steepest step between neighbours, plus the 0.05 mm
     * rounding); the distance along the plane's normal is that depth error
     * times |n . (x, y, 1)| / |n| at the pixel, largest at a corner. */
    double step_bound = 0;
    for (uint32_t v = 0; v + 1 < c.height; v++)
        for (uint32_t u = 0; u + 1 < c.width; u++) {
            size_t i = (size_t)v * c.width + u;
            step_bound = fmax(step_bound, 1e-4 * hypot((double)raw[i + 1] - raw[i], (double)raw[i + c.width] - raw[i]));
        }
    double along_normal = 0, norm = sqrt(plane_n.x * plane_n.x + plane_n.y * plane_n.y + plane_n.z * plane_n.z);
    for (int corner = 0; corner < 4; corner++) {
        double x = ((corner & 1) ? c.width - 1 : 0) - c.cx_px, y = ((corner & 2) ? c.height - 1 : 0) - c.cy_px;
        along_normal = fmax(along_normal, fabs(plane_n.x * x / c.fx_px + plane_n.y * y / c.fy_px + plane_n.z) / norm);
    }
    step_bound = (0.71 * step_bound + 5e-5) * along_normal;
    printf("  plane: as read up to %.2f mm off, undistorted %.2f mm (bound %.2f), %u of %u pixels kept, "
           "shift up to %.1f px\n",
             1e3 * as_read, 1e3 * undistorted, 1e3 * step_bound, n_out, n_raw, m.max_shift_px);
    CHECK_LE(undistorted, step_bound);
    /* The lens matters at this size: read as a pinhole the image bends the
     * plane by more than twice the bound (25.5 mm against 5.2 undistorted). */
    CHECK(as_read > 2 * step_bound);
    /* fr1's lens pushes the image's edges out: the pinhole's border rays
     * land beyond the image and get no depth; all others keep theirs. */
    CHECK(m.n_outside > 0);
    CHECK_EQ_INT(n_out + m.n_outside, n_raw);
    /* The shift counts the pixels whose source is inside the image: 24.2 px
     * at 640 x 480 (36.8 at the corners, whose sources lie outside), 5.8 at
     * this quarter size. */
    CHECK(m.max_shift_px > 5.5 && m.max_shift_px < 6.1);
    calib_undistort_map_free(&m);
    free(raw);
    free(out);
}

BF_TEST(undistortion_without_a_lens_is_a_copy)
{
    calib_camera c = fr1_small();
    memset(c.dist, 0, sizeof c.dist);
    CHECK(!calib_has_distortion(c.dist));
    size_t n = (size_t)c.width * c.height;
    uint16_t *raw = malloc(n * sizeof *raw), *out = malloc(n * sizeof *out);
    uint8_t *rgb = malloc(3 * n), *rgb_out = malloc(3 * n);
    CHECK(raw && out && rgb && rgb_out);
    for (size_t i = 0; i < n; i++) raw[i] = (uint16_t)(i * 7919u);
    for (size_t i = 0; i < 3 * n; i++) rgb[i] = (uint8_t)(i * 31u);
    calib_undistort_map m;
    CHECK_OK(calib_undistort_map_make(&c, &m));
    calib_undistort_u16(&m, raw, out);
    calib_undistort_rgb8(&m, rgb, rgb_out);
    CHECK(memcmp(raw, out, n * sizeof *raw) == 0);
    CHECK(memcmp(rgb, rgb_out, 3 * n) == 0);
    CHECK(m.max_shift_px == 0 && m.n_outside == 0);
    calib_undistort_map_free(&m);
    calib_undistort_map_free(NULL);
    free(raw);
    free(out);
    free(rgb);
    free(rgb_out);
}

/* Holes stay holes and colour moves with its depth: both images take one
 * map; a pixel whose ray the lens sends outside the image gets nothing. */
BF_TEST(undistortion_moves_colour_with_depth_and_keeps_holes)
{
    calib_camera c = fr1_small(); /* its border rays land outside the image */
    size_t n = (size_t)c.width * c.height;
    uint16_t *raw = malloc(n * sizeof *raw), *out = malloc(n * sizeof *out);
    uint8_t *rgb = malloc(3 * n), *rgb_out = malloc(3 * n);
    CHECK(raw && out && rgb && rgb_out);
    for (size_t i = 0; i < n; i++) {
        raw[i] = (i % 5 == 0) ? 0 : (uint16_t)(1 + i % 60000); /* every fifth pixel a hole */
        rgb[3 * i] = (uint8_t)i, rgb[3 * i + 1] = (uint8_t)(i >> 8), rgb[3 * i + 2] = raw[i] ? 200 : 0;
    }
    calib_undistort_map m;
    CHECK_OK(calib_undistort_map_make(&c, &m));
    calib_undistort_u16(&m, raw, out);
    calib_undistort_rgb8(&m, rgb, rgb_out);
    CHECK(m.n_outside > 0);
    uint32_t n_holes = 0, n_none = 0;
    for (size_t i = 0; i < n; i++) {
        int32_t s = m.src[i];
        if (s < 0) {
            n_none++;
            CHECK(out[i] == 0 && rgb_out[3 * i] == 0 && rgb_out[3 * i + 1] == 0 && rgb_out[3 * i + 2] == 0);
            continue;
        }
        CHECK_EQ_INT(out[i], raw[s]);
        CHECK(memcmp(rgb_out + 3 * i, rgb + 3 * (size_t)s, 3) == 0);
        n_holes += out[i] == 0;
    }
    CHECK_EQ_INT(n_none, m.n_outside);
    CHECK(n_holes > 0);
    printf("  fr1 lens: %u pixels without a source, %u holes carried\n", n_none, n_holes);
    calib_undistort_map_free(&m);
    free(raw);
    free(out);
    free(rgb);
    free(rgb_out);
}

BF_TEST(undistortion_refuses_what_no_lens_does)
{
    calib_camera c = fr1_small();
    /* r (1 - 0.9 r^2) stops growing at r = 0.61, inside fr1's corners (0.79). */
    c.dist[0] = -0.9, c.dist[1] = 0, c.dist[4] = 0;
    calib_undistort_map m = {.width = 99};
    bf_clear_error();
    CHECK_STATUS(calib_undistort_map_make(&c, &m), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("folds");
    CHECK_ERROR_MENTIONS("k1 -0.9");
    CHECK_EQ_INT(m.width, 99u); /* untouched */
    /* Monotonic, but every pixel sent outside the image (a typo's k1 1e300,
     * p1 1e10): no frame would keep any depth. */
    c = fr1_small();
    c.dist[0] = 1e300;
    CHECK_STATUS(calib_undistort_map_make(&c, &m), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("outside it (not a lens)");
    c = fr1_small();
    c.dist[2] = 1e10;
    CHECK_STATUS(calib_undistort_map_make(&c, &m), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("outside it (not a lens)");
    CHECK_EQ_INT(m.width, 99u); /* untouched */
    c = fr1_small();
    c.dist[2] = NAN;
    CHECK_STATUS(calib_undistort_map_make(&c, &m), BF_INVALID_ARG);
    CHECK_ERROR_MENTIONS("p1 is not finite");
    c = fr1_small();
    c.fx_px = 0;
    CHECK_STATUS(calib_undistort_map_make(&c, &m), BF_INVALID_ARG);
}
