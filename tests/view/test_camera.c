/* The viewer's free camera (view/camera.c): orbit keeps the pivot where it
 * is and never rolls the horizon, pan moves the pivot's plane with the
 * cursor, zoom approaches the pivot. CPU only. */
#include "test.h"
#include "view/view_int.h"

static bf_vec3 col(const bf_se3 *T, int j) { return bf_v3(T->R[0][j], T->R[1][j], T->R[2][j]); }
static double dot(bf_vec3 a, bf_vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static bf_vec3 pivot(const view__camera *c) { return bf_v3_add(c->T_wc.t, bf_v3_scale(col(&c->T_wc, 2), c->pivot_m)); }
static double dist(bf_vec3 a, bf_vec3 b) { bf_vec3 d = bf_v3_sub(a, b); return sqrt(dot(d, d)); }

/* A TUM-like start: turned about y and x, away from the origin. */
static bf_se3 start_pose(void)
{
    bf_quat q = bf_quat_mul(bf_quat_from_axis_angle(bf_v3(0, 1, 0), 0.7), bf_quat_from_axis_angle(bf_v3(1, 0, 0), -0.3));
    return bf_se3_from_qt(q, bf_v3(1.5, -0.4, 2.0));
}

BF_TEST(orbit_keeps_the_pivot_and_the_horizon_over_many_drags)
{
    bf_se3 T = start_pose();
    view__camera c = view__camera_make(&T, 2.5);
    bf_vec3 p0 = pivot(&c), up = c.up_w;
    /* A long wandering drag: rounding may move the pivot by ~1e-15 m a step. */
    for (int i = 0; i < 1000; i++) {
        view__camera_orbit(&c, 0.01 * sin(0.05 * i), 0.013 * cos(0.031 * i));
        CHECK_LE(dist(pivot(&c), p0), 1e-9);
        CHECK_LE(fabs(dot(col(&c.T_wc, 0), up)), 1e-9); /* the camera's x stays horizontal: no roll */
    }
    CHECK_NEAR(c.pivot_m, 2.5, 0);
    /* A pure yaw of a full turn comes back to the start. */
    view__camera d = view__camera_make(&T, 2.5);
    for (int i = 0; i < 360; i++) view__camera_orbit(&d, M_PI / 180.0, 0);
    CHECK_LE(dist(d.T_wc.t, T.t), 1e-9);
}

BF_TEST(pan_moves_the_pivot_plane_with_the_cursor_and_zoom_approaches_the_pivot)
{
    bf_se3 T = start_pose();
    view__camera c = view__camera_make(&T, 2.0);
    bf_vec3 p0 = pivot(&c);
    /* Dragging 100 px right at f = 500 px moves the camera 100 * 2 / 500 = 0.4 m
     * left, so a point on the pivot plane stays under the cursor. */
    view__camera_pan(&c, 100, -50, 500);
    bf_vec3 d = bf_v3_sub(c.T_wc.t, T.t);
    CHECK_NEAR(dot(d, col(&T, 0)), -0.4, 1e-12);
    CHECK_NEAR(dot(d, col(&T, 1)), 0.2, 1e-12);
    CHECK_NEAR(dot(d, col(&T, 2)), 0.0, 1e-12);
    /* Zoom: one notch in at 10% keeps the pivot and shortens the distance. */
    view__camera z = view__camera_make(&T, 2.0);
    view__camera_zoom(&z, 1, 0.1);
    CHECK_NEAR(z.pivot_m, 1.8, 1e-12);
    CHECK_LE(dist(pivot(&z), p0), 1e-12);
    view__camera_zoom(&z, -1, 0.1);
    CHECK_NEAR(z.pivot_m, 1.8 * (1 / 0.9), 1e-12);
    /* Never through the pivot. */
    view__camera_zoom(&z, 1000, 0.1);
    CHECK_LE(0.01 - 1e-12, z.pivot_m);
}
