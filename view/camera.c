/* The viewer's free camera: orbit, pan and zoom about a pivot point. */
#include <math.h>

#include "view_int.h"

#define VIEW_PIVOT_MIN_M 0.01

static bf_vec3 column(const bf_se3 *T, int j) { return bf_v3(T->R[0][j], T->R[1][j], T->R[2][j]); }

static bf_vec3 pivot_of(const view__camera *c)
{
    return bf_v3_add(c->T_wc.t, bf_v3_scale(column(&c->T_wc, 2), c->pivot_m));
}

view__camera view__camera_make(const bf_se3 *T_wc, double pivot_m)
{
    view__camera c = {.T_wc = *T_wc, .pivot_m = pivot_m > VIEW_PIVOT_MIN_M ? pivot_m : VIEW_PIVOT_MIN_M};
    c.up_w = bf_v3_scale(column(T_wc, 1), -1.0); /* the camera's y points down */
    return c;
}

/* T_wc turned by R_turn about the point p: t' = p + R (t - p), R' = R R_wc. */
static void turn_about(bf_se3 *T, bf_quat q, bf_vec3 p)
{
    bf_se3 Rt = bf_se3_from_qt(q, bf_v3(0, 0, 0));
    bf_vec3 t = bf_v3_add(p, bf_se3_rotate(&Rt, bf_v3_sub(T->t, p)));
    bf_se3 only_R = *T;
    only_R.t = bf_v3(0, 0, 0);
    *T = bf_se3_mul(&Rt, &only_R);
    T->t = t;
}

void view__camera_orbit(view__camera *c, double yaw_rad, double pitch_rad)
{
    bf_vec3 p = pivot_of(c);
    turn_about(&c->T_wc, bf_quat_from_axis_angle(c->up_w, yaw_rad), p);
    /* The camera's x stays perpendicular to up: turning about up keeps it
     * so, and turning about x itself does not move it. No roll builds up. */
    turn_about(&c->T_wc, bf_quat_from_axis_angle(column(&c->T_wc, 0), pitch_rad), p);
}

void view__camera_pan(view__camera *c, double dx_px, double dy_px, double f_px)
{
    double s = c->pivot_m / f_px;
    bf_vec3 move = bf_v3_add(bf_v3_scale(column(&c->T_wc, 0), dx_px * s), bf_v3_scale(column(&c->T_wc, 1), dy_px * s));
    c->T_wc.t = bf_v3_sub(c->T_wc.t, move);
}

void view__camera_zoom(view__camera *c, double notches, double fraction)
{
    double d = c->pivot_m * pow(1.0 - fraction, notches);
    if (d < VIEW_PIVOT_MIN_M) d = VIEW_PIVOT_MIN_M;
    c->T_wc.t = bf_v3_add(c->T_wc.t, bf_v3_scale(column(&c->T_wc, 2), c->pivot_m - d));
    c->pivot_m = d;
}
