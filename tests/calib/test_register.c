/* calib: the depth camera's points as a separate colour camera sees them
 * (register.c). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "calib/calib.h"
#include "synth/synth.h"
#include "test.h"

enum { RW = 160, RH = 120 };

static bf_intrinsics depth_K(void) { return (bf_intrinsics){RW, RH, 131.25, 131.25, 79.5, 59.5, 1e4}; }

/* A colour camera beside the depth camera as on a Kinect (a few
 * centimetres along x, turned a little), here with TUM fr1's lens scaled
 * to 160 x 120, so the distortion path is taken. */
static calib_camera colour_cam(void)
{
    return (calib_camera){.width = RW, .height = RH, .fx_px = 517.3 / 4, .fy_px = 516.5 / 4,
                          .cx_px = (318.6 + 0.5) / 4 - 0.5, .cy_px = (255.3 + 0.5) / 4 - 0.5,
                          .dist = {0.2624, -0.9531, -0.0054, 0.0026, 1.1633}};
}

static bf_se3 colour_from_depth(double tx_m)
{
    bf_quat q = bf_quat_from_axis_angle(bf_v3(0.2, 1, 0.1), 1.5 * M_PI / 180);
    return bf_se3_from_qt(q, bf_v3(tx_m, 0.004, -0.002));
}

/* The plane n . p = d in the depth camera's frame. */
static const bf_vec3 plane_n = {0.2, -0.3, 0.93};
static const double plane_d = 1.4;

static double plane_z(double u, double v, const bf_intrinsics *K)
{
    double x = (u - K->cx_px) / K->fx_px, y = (v - K->cy_px) / K->fy_px;
    return plane_d / (plane_n.x * x + plane_n.y * y + plane_n.z);
}

static int cmp_d(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* A tilted plane seen through the lens. Each colour pixel's point, moved
 * at its depth from where it landed (within 0.9 pixel along both axes) to
 * the ray through the pixel's centre, projects (calib_project) onto the
 * centre to a few hundredths of a pixel at the median: the move takes the
 * pinhole's scale, and the lens's local scale differs by up to about 15%
 * at these corners. It stays off the plane by no more than the move times
 * the plane's slope in the colour camera (plus the depth's 0.1 mm steps).
 * Every colour pixel whose own ray (calib_unproject: the lens's inverse,
 * another path) meets the plane where the depth camera sees it has a
 * point; the lens's corners and the shift leave some without. */
BF_TEST(each_colour_pixel_gets_the_depth_point_seen_there)
{
    bf_intrinsics Kd = depth_K();
    calib_camera c = colour_cam();
    bf_se3 T = colour_from_depth(0.025), Ti = bf_se3_inverse(&T);
    size_t n = (size_t)RW * RH;
    uint16_t *depth = malloc(n * sizeof *depth);
    float *xyz = malloc(3 * n * sizeof *xyz);
    double *off = malloc(n * sizeof *off);
    CHECK(depth && xyz && off);
    for (uint32_t v = 0; v < RH; v++)
        for (uint32_t u = 0; u < RW; u++)
            depth[(size_t)v * RW + u] = (uint16_t)lround(plane_z(u, v, &Kd) * Kd.depth_scale);
    CHECK_OK(calib_points_on_colour(&c, &T, &Kd, depth, RW, RH, xyz));
    /* The plane's slope in the colour camera: a move across the view at
     * one depth leaves it by the move times this. */
    bf_vec3 nc = bf_v3(bf_v3_dot(bf_v3(T.R[0][0], T.R[0][1], T.R[0][2]), plane_n),
                       bf_v3_dot(bf_v3(T.R[1][0], T.R[1][1], T.R[1][2]), plane_n),
                       bf_v3_dot(bf_v3(T.R[2][0], T.R[2][1], T.R[2][2]), plane_n));
    double slope = sqrt(nc.x * nc.x + nc.y * nc.y) / fabs(nc.z);
    uint32_t n_pt = 0, n_should = 0, n_missing = 0;
    double worst_plane = 0, worst_off = 0; /* worst_plane: as a share of its bound */
    double nn = sqrt(plane_n.x * plane_n.x + plane_n.y * plane_n.y + plane_n.z * plane_n.z);
    for (uint32_t v = 0; v < RH; v++)
        for (uint32_t u = 0; u < RW; u++) {
            size_t j = (size_t)v * RW + u;
            /* Does the colour pixel's own ray meet the plane inside the depth image? */
            bf_vec3 ray;
            bool should = false;
            if (calib_unproject(&c, u, v, &ray)) {
                /* The ray in the depth frame: origin Ti.t, direction Ti.R ray. */
                bf_vec3 o = Ti.t, dir = bf_v3_sub(bf_se3_apply(&Ti, ray), Ti.t);
                double t = (plane_d - bf_v3_dot(plane_n, o)) / bf_v3_dot(plane_n, dir);
                bf_vec3 q = bf_v3_add(o, bf_v3_scale(dir, t));
                double ud = Kd.fx_px * q.x / q.z + Kd.cx_px, vd = Kd.fy_px * q.y / q.z + Kd.cy_px;
                should = t > 0 && ud > 1 && vd > 1 && ud < RW - 2 && vd < RH - 2;
            }
            n_should += should;
            const float *p = xyz + 3 * j;
            if (isnan(p[0])) {
                n_missing += should;
                continue;
            }
            bf_vec3 P = bf_v3(p[0], p[1], p[2]), Pc = bf_se3_apply(&T, P);
            double move_m = 0.9 * sqrt(2.0) * Pc.z / fmin(c.fx_px, c.fy_px);
            worst_plane = fmax(worst_plane, (fabs(bf_v3_dot(plane_n, P) - plane_d) / nn) / (move_m * slope + 1e-4));
            double uc, vc;
            CHECK(calib_project(&c, Pc, &uc, &vc));
            double o = fmax(fabs(uc - u), fabs(vc - v));
            worst_off = fmax(worst_off, o);
            off[n_pt++] = o;
        }
    CHECK(n_pt > 0);
    qsort(off, n_pt, sizeof *off, cmp_d);
    double median = n_pt ? off[n_pt / 2] : INFINITY;
    printf("  %u colour pixels with a point (%u of %u the plane is seen at missing); off the plane at most %.2f of "
           "the move's bound; off the centre: median %.3f px, at most %.3f px\n",
           n_pt, n_missing, n_should, worst_plane, median, worst_off);
    CHECK(n_should > n / 2);
    CHECK_EQ_INT(n_missing, 0);
    CHECK(n_pt < n); /* the lens's corners and the shift */
    CHECK_LE(worst_plane, 1.0);
    CHECK_LE(median, 0.05); /* 0.010 measured; the nearest landing alone was 0.40 */
    CHECK_LE(worst_off, 0.9 * sqrt(2.0) * 0.2);
    free(depth);
    free(xyz);
    free(off);
}

/* Whether the depth camera sees the surface colour pixel j shows at depth
 * depth_c[j]: that point, in the depth camera, lands on a pixel whose
 * depth agrees within 1 cm (the nearest pixel and its four neighbours,
 * for the landing's rounding). */
static bool depth_camera_sees(const bf_intrinsics *Kd, const bf_intrinsics *Kc, const bf_se3 *T_dc,
                              const uint16_t *depth, const uint16_t *depth_c, size_t j)
{
    if (!depth_c[j]) return false;
    double z = depth_c[j] / Kc->depth_scale, u = (double)(j % Kc->width), v = (double)(j / Kc->width);
    bf_vec3 q = bf_se3_apply(T_dc, bf_v3(z * (u - Kc->cx_px) / Kc->fx_px, z * (v - Kc->cy_px) / Kc->fy_px, z));
    double ud = floor(Kd->fx_px * q.x / q.z + Kd->cx_px + 0.5), vd = floor(Kd->fy_px * q.y / q.z + Kd->cy_px + 0.5);
    if (!(ud >= 1 && vd >= 1 && ud < Kd->width - 1 && vd < Kd->height - 1)) return false;
    const int du[5] = {0, 1, -1, 0, 0}, dv[5] = {0, 0, 0, 1, -1};
    for (int k = 0; k < 5; k++) {
        uint16_t d = depth[(size_t)(vd + dv[k]) * Kd->width + (size_t)(ud + du[k])];
        if (d && fabs(d / Kd->depth_scale - q.z) < 0.01) return true;
    }
    return false;
}

/* How far depth zc lies from the nearest of the depths the colour camera
 * shows at pixel j and its eight neighbours: a point that lands within
 * 0.9 pixel of j's centre lies on the surface shown at j or next to it (on
 * a surface seen at a grazing angle the depth changes fast across a pixel). */
static double shown_nearest(const bf_intrinsics *Kc, const uint16_t *depth_c, size_t j, double zc)
{
    int u = (int)(j % Kc->width), v = (int)(j / Kc->width);
    double best = INFINITY;
    for (int dv = -1; dv <= 1; dv++)
        for (int du = -1; du <= 1; du++) {
            int x = u + du, y = v + dv;
            if (x < 0 || y < 0 || x >= (int)Kc->width || y >= (int)Kc->height) continue;
            uint16_t d = depth_c[(size_t)y * Kc->width + (size_t)x];
            if (d) best = fmin(best, fabs(d / Kc->depth_scale - zc));
        }
    return best;
}

/* The room, its depth from one camera, seen by another 5 cm to the side
 * (no lens: the renderer is a pinhole). Each colour pixel's point, moved
 * into the colour camera, is at the depth the colour camera's own
 * rendering shows there: the surface it sees, never one hidden behind
 * the room's nearer things (within the slope across the landing's
 * offset). A colour pixel whose surface the depth camera sees has a
 * point. Then the depth camera as its own colour camera: each pixel with
 * depth gets its own point, bit for bit, and one without none. */
BF_TEST(points_on_colour_are_what_the_colour_camera_sees)
{
    synth_scene sc;
    CHECK_OK(synth_scene_room(NULL, &sc));
    bf_intrinsics Kd = depth_K();
    calib_camera c = {.width = RW, .height = RH, .fx_px = 140.0, .fy_px = 139.0, .cx_px = 82.0, .cy_px = 58.0};
    bf_intrinsics Kc = {RW, RH, c.fx_px, c.fy_px, c.cx_px, c.cy_px, 1e4};
    bf_se3 T_cd = colour_from_depth(0.05), T_dc = bf_se3_inverse(&T_cd);
    bf_se3 Twd = sc.T_wc_view, Twc = bf_se3_mul(&Twd, &T_dc);
    size_t n = (size_t)RW * RH;
    uint16_t *depth = malloc(n * sizeof *depth), *depth_c = malloc(n * sizeof *depth_c);
    float *xyz = malloc(3 * n * sizeof *xyz);
    CHECK(depth && depth_c && xyz);
    synth_renderer *rd, *rc;
    synth_render_config cd = {.K = Kd, .noise = SYNTH_NOISE_NONE}, cc = {.K = Kc, .noise = SYNTH_NOISE_NONE};
    CHECK_OK(synth_renderer_create(&sc, &cd, &rd));
    CHECK_OK(synth_renderer_create(&sc, &cc, &rc));
    CHECK_OK(synth_render(rd, 0, &Twd, depth, NULL, NULL));
    CHECK_OK(synth_render(rc, 0, &Twc, depth_c, NULL, NULL));
    CHECK_OK(calib_points_on_colour(&c, &T_cd, &Kd, depth, RW, RH, xyz));
    uint32_t n_pt = 0, n_near = 0, n_hidden = 0, n_both = 0, n_both_pt = 0;
    double worst = 0;
    for (size_t j = 0; j < n; j++) {
        bool both = depth_camera_sees(&Kd, &Kc, &T_dc, depth, depth_c, j);
        n_both += both;
        if (isnan(xyz[3 * j]) || !depth_c[j]) continue;
        n_both_pt += both;
        double zc = bf_se3_apply(&T_cd, bf_v3(xyz[3 * j], xyz[3 * j + 1], xyz[3 * j + 2])).z;
        double shown = depth_c[j] / Kc.depth_scale, d = shown_nearest(&Kc, depth_c, j, zc);
        n_pt++;
        n_near += d <= 0.005 + 0.01 * shown;
        n_hidden += d > 0.05 && zc > shown;
        worst = fmax(worst, d);
    }
    printf("  %u colour pixels with a point: %.2f%% within 5 mm + 1%% of the depth the colour camera shows, %u "
           "5 cm or more behind it (worst %.1f mm); %u of %u pixels the depth camera also sees have a point\n",
           n_pt, 100.0 * n_near / n_pt, n_hidden, 1e3 * worst, n_both_pt, n_both);
    CHECK(n_pt > n / 2);
    CHECK(n_near >= 0.99 * n_pt);
    CHECK_LE(n_hidden, n_pt / 1000);
    CHECK(n_both_pt >= 0.99 * n_both);
    /* The depth camera as its own colour camera. */
    calib_camera same = {.width = RW, .height = RH, .fx_px = Kd.fx_px, .fy_px = Kd.fy_px, .cx_px = Kd.cx_px,
                         .cy_px = Kd.cy_px};
    bf_se3 I = bf_se3_identity();
    CHECK_OK(calib_points_on_colour(&same, &I, &Kd, depth, RW, RH, xyz));
    for (uint32_t v = 0; v < RH; v++)
        for (uint32_t u = 0; u < RW; u++) {
            size_t i = (size_t)v * RW + u;
            if (!depth[i]) {
                CHECK(isnan(xyz[3 * i]) && isnan(xyz[3 * i + 1]) && isnan(xyz[3 * i + 2]));
                continue;
            }
            double z = depth[i] / Kd.depth_scale;
            CHECK(xyz[3 * i] == (float)(z * (u - Kd.cx_px) / Kd.fx_px));
            CHECK(xyz[3 * i + 1] == (float)(z * (v - Kd.cy_px) / Kd.fy_px));
            CHECK(xyz[3 * i + 2] == (float)z);
        }
    synth_renderer_destroy(rd);
    synth_renderer_destroy(rc);
    synth_scene_free(&sc);
    free(depth);
    free(depth_c);
    free(xyz);
}

BF_TEST(points_on_colour_refuse_missing_images)
{
    bf_intrinsics Kd = depth_K();
    calib_camera c = colour_cam();
    bf_se3 T = bf_se3_identity();
    uint16_t depth[4] = {0};
    float xyz[12];
    CHECK_EQ_INT(calib_points_on_colour(&c, &T, &Kd, NULL, RW, RH, xyz), BF_INVALID_ARG);
    CHECK_EQ_INT(calib_points_on_colour(&c, &T, &Kd, depth, RW, RH, NULL), BF_INVALID_ARG);
    CHECK_EQ_INT(calib_points_on_colour(&c, &T, &Kd, depth, 0, RH, xyz), BF_INVALID_ARG);
    Kd.depth_scale = 0;
    CHECK_EQ_INT(calib_points_on_colour(&c, &T, &Kd, depth, RW, RH, xyz), BF_INVALID_ARG);
}
