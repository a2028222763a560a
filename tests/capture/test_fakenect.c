/* The libfreenect backend against Debian's fakenect (libfreenect-bin): the
 * test writes a dump of a synthetic scene the way fakenect's record tool
 * does (INDEX.txt listing d-TIME-STAMP.pgm / r-TIME-STAMP.ppm files, each a
 * one-line PGM/PPM header followed by the raw 640x480 frame: 11-bit
 * disparity as little-endian uint16, RGB8), and reads it back through
 * capture_open("freenect:0") with fakenect standing in for libfreenect.
 * ctest points LD_LIBRARY_PATH at fakenect's directory; run by hand, the
 * test skips unless that is done (see docs/devices.md).
 *
 * Scene: a wall tilted about both image axes (inverse depth linear in the
 * pixel coordinates) with a sphere in front of it, the camera backing away
 * 4 cm per frame, and an invalid band (raw 2047) at the top. */
#include <dlfcn.h>
#include <stdlib.h>
#include <sys/stat.h>

#include "capture/live_int.h"
#include "test.h"

#define W 640
#define H 480
#define N_FRAMES 8
/* The Kinect's 60 MHz clock, started so that it wraps after frame 2. */
#define TICKS_PER_FRAME 2000000u
#define FIRST_TICK (0xFFFFFFFFu - 2u * TICKS_PER_FRAME - 12345u)

/* Depth in mm the test's camera sees at pixel (u, v) of frame k; 0 = none. */
static double truth_mm(int k, int u, int v)
{
    if (v < 8) return 0.0; /* the sensor's blind band */
    const double f = 575.8, cx = 319.5, cy = 239.5, back_mm = 40.0 * k;
    double x = (u - cx) / f, y = (v - cy) / f; /* ray (x, y, 1) */
    /* Sphere of radius 300 mm at (0, 0, 1500 + back) in camera coordinates. */
    double zc = 1500.0 + back_mm, r = 300.0;
    double a = x * x + y * y + 1.0, b = -2.0 * zc, c = zc * zc - r * r;
    double disc = b * b - 4 * a * c;
    if (disc >= 0) return (-b - sqrt(disc)) / (2 * a);
    /* Wall: 1/z = (1 + 0.25 x + 0.15 y) / (2600 + back). */
    return (2600.0 + back_mm) / (1.0 + 0.25 * x + 0.15 * y);
}

/* The inverse of libfreenect's raw-to-mm model (registration.c), solved
 * for raw and rounded as the sensor quantises. */
static uint16_t disparity_of(double z_mm, const capture__kinect_params *p)
{
    if (!(z_mm > 0)) return 2047;
    double metric = p->dcmos_emitter_dist_cm * (1.0 - 10.0 * p->reference_distance_mm / z_mm);
    double raw = 4.0 * (metric / p->reference_pixel_size_mm + 0.375 + p->const_shift);
    long r = lround(raw);
    return (uint16_t)(r < 0 ? 0 : r > 2046 ? 2047 : r);
}

/* dz/draw of the model at depth z: z^2 * pixel / (40 * distance * baseline)
 * (differentiate z = 10 d b / (b - m), m = pixel * (raw/4 - shift - 0.375)). */
static double mm_per_raw(double z_mm, const capture__kinect_params *p)
{
    return z_mm * z_mm * p->reference_pixel_size_mm / (40.0 * p->reference_distance_mm * p->dcmos_emitter_dist_cm);
}

static bool write_dump(const char *dir, uint16_t *raw, uint8_t *rgb, const capture__kinect_params *p)
{
    char path[4096];
    if (bf_path_join(path, sizeof path, dir, "INDEX.txt")) return false;
    FILE *index = fopen(path, "w");
    if (!index) return false;
    for (int k = 0; k < N_FRAMES; k++) {
        for (int v = 0; v < H; v++)
            for (int u = 0; u < W; u++) {
                raw[v * W + u] = disparity_of(truth_mm(k, u, v), p);
                uint8_t *c = rgb + (v * W + u) * 3;
                c[0] = (uint8_t)(10 * k), c[1] = (uint8_t)u, c[2] = (uint8_t)v;
            }
        uint32_t tick = FIRST_TICK + (uint32_t)k * TICKS_PER_FRAME; /* wraps */
        /* record.c's names: type, wall time (fakenect sleeps by its
         * differences), device timestamp. 30 Hz, colour 1 ms after depth. */
        double t_wall = 1700000000.0 + k / 30.0;
        char name[128];
        for (int is_rgb = 0; is_rgb < 2; is_rgb++) {
            snprintf(name, sizeof name, "%c-%f-%u.%s", is_rgb ? 'r' : 'd', t_wall + is_rgb * 0.001,
                     tick + (uint32_t)is_rgb * 60000u, is_rgb ? "ppm" : "pgm");
            fprintf(index, "%s\n", name);
            if (bf_path_join(path, sizeof path, dir, name)) return false;
            FILE *f = fopen(path, "wb");
            if (!f) return false;
            fprintf(f, is_rgb ? "P6 %d %d 255\n" : "P5 %d %d 65535\n", W, H);
            size_t ok = is_rgb ? fwrite(rgb, 3, (size_t)W * H, f) : fwrite(raw, 2, (size_t)W * H, f);
            if (fclose(f) || ok != (size_t)W * H) return false;
        }
    }
    return fclose(index) == 0;
}

static bool fakenect_loaded(void) { return dlsym(RTLD_DEFAULT, "freenect_copy_registration") == NULL; }

BF_TEST(fakenect_dump_replays_depth_within_disparity_quantisation)
{
    if (!fakenect_loaded())
        BF_SKIP("libfreenect is the real one; run through ctest (LD_LIBRARY_PATH=<libdir>/fakenect)");
    capture__kinect_params p = capture__kinect_default_params();
    char dir[4096];
    CHECK_OK(bf_path_join(dir, sizeof dir, bf_test_tmpdir(), "fakenect-dump"));
    CHECK(mkdir(dir, 0755) == 0);
    uint16_t *raw = malloc((size_t)W * H * 2);
    uint8_t *rgb = malloc((size_t)W * H * 3);
    CHECK(raw && rgb);
    bool ok = write_dump(dir, raw, rgb, &p);
    free(raw);
    free(rgb);
    CHECK(ok);
    setenv("FAKENECT_PATH", dir, 1);

    rgbd_source *src = NULL;
    /* fakenect has no registration: asking for it is a clear refusal. */
    CHECK_STATUS(capture_open("freenect:0?depth=registered", &src), BF_UNSUPPORTED);
    CHECK_ERROR_MENTIONS("depth=disparity");
    CHECK_OK(capture_open("freenect:0", &src));
    CHECK(!strcmp(src->kind, "freenect (fakenect)"));
    const bf_intrinsics *K = rgbd_source_intrinsics(src);
    CHECK_EQ_INT(K->width, W);
    CHECK_EQ_INT(K->height, H);
    CHECK_NEAR(K->fx_px, 575.816, 0.001);

    double max_err_mm = 0, sum_sq = 0, max_ratio = 0, max_bound_mm = 0;
    size_t n_valid = 0, n_invalid_ok = 0;
    for (int k = 0; k < N_FRAMES; k++) {
        bf_frame f;
        CHECK_OK(rgbd_source_next(src, &f));
        CHECK_EQ_INT(f.index, k);
        CHECK(f.rgb != NULL);
        /* Colour of the same frame: red channel = 10 k. */
        CHECK_EQ_INT(f.rgb[(100 * W + 200) * 3 + 0], 10 * k);
        CHECK_EQ_INT(f.rgb[(100 * W + 200) * 3 + 1], 200);
        /* Device clock: 60 MHz ticks, unwrapped across the 32-bit wrap. */
        CHECK_NEAR(f.t_depth_s, (FIRST_TICK + (double)k * TICKS_PER_FRAME) / 60e6, 1e-9);
        CHECK_NEAR(f.t_rgb_s - f.t_depth_s, 0.001, 1e-9);
        for (int v = 0; v < H; v++)
            for (int u = 0; u < W; u++) {
                double z = truth_mm(k, u, v);
                uint16_t d = f.depth[v * W + u];
                if (z == 0) {
                    n_invalid_ok += d == 0;
                    continue;
                }
                double z_out = d * 1000.0 / K->depth_scale;
                /* Half a disparity step at the larger of the two depths
                 * (the step grows with z), plus half the 0.2 mm output
                 * unit and float slack. */
                double bound = 0.5 * mm_per_raw(fmax(z, z_out), &p) + 0.1 + 1e-6;
                double err = fabs(z_out - z);
                if (!(err <= bound))
                    bf__test_fail(__FILE__, __LINE__, "frame %d (%d, %d): %.3f mm vs truth %.3f mm, bound %.3f", k,
                                  u, v, z_out, z, bound);
                if (err > bound) return;
                max_err_mm = fmax(max_err_mm, err);
                max_ratio = fmax(max_ratio, err / bound);
                max_bound_mm = fmax(max_bound_mm, bound);
                sum_sq += err * err;
                n_valid++;
            }
    }
    CHECK_EQ_INT(n_invalid_ok, (size_t)N_FRAMES * 8 * W);
    printf("    fakenect depth vs truth: %zu px, max %.2f mm, rms %.2f mm, max error/bound %.3f "
           "(bound up to %.2f mm at the far wall)\n",
           n_valid, max_err_mm, sqrt(sum_sq / (double)n_valid), max_ratio, max_bound_mm);
    rgbd_source_close(src);
}

BF_TEST(fakenect_missing_dump_is_no_device_not_exit)
{
    if (!fakenect_loaded()) BF_SKIP("libfreenect is the real one");
    /* fakenect itself would exit(1) here; the backend checks first. */
    setenv("FAKENECT_PATH", "/nonexistent/bitfuse-dump", 1);
    rgbd_source *src = NULL;
    CHECK_STATUS(capture_open("freenect:0", &src), BF_NO_DEVICE);
    CHECK_ERROR_MENTIONS("INDEX.txt");
    unsetenv("FAKENECT_PATH");
    CHECK_STATUS(capture_open("freenect:0", &src), BF_NO_DEVICE);
    CHECK_ERROR_MENTIONS("FAKENECT_PATH");
}
