/* calib: the camera model every user of a calibration shares (the
 * synthetic boards of synth/, registration): pinhole plus Brown-Conrady
 * distortion, OpenCV's convention. No OpenCV here: this file links alone. */
#include <math.h>

#include "calib.h"

void calib_distort(const double dist[CALIB_DIST_N], double x, double y, double *xd, double *yd)
{
    double k1 = dist[0], k2 = dist[1], p1 = dist[2], p2 = dist[3], k3 = dist[4];
    double r2 = x * x + y * y;
    double radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3));
    *xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x);
    *yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y;
}

bool calib_undistort(const double dist[CALIB_DIST_N], double xd, double yd, double *x_out, double *y_out)
{
    double k1 = dist[0], k2 = dist[1], p1 = dist[2], p2 = dist[3], k3 = dist[4];
    double x = xd, y = yd;
    for (int it = 0; it < 50; it++) {
        double fx, fy;
        calib_distort(dist, x, y, &fx, &fy);
        double ex = fx - xd, ey = fy - yd;
        if (fabs(ex) < 1e-12 && fabs(ey) < 1e-12) {
            *x_out = x, *y_out = y;
            return true;
        }
        /* The Jacobian of calib_distort at (x, y). */
        double r2 = x * x + y * y;
        double radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3));
        double dradial = k1 + r2 * (2 * k2 + 3 * k3 * r2); /* d radial / d r2 */
        double a = radial + 2 * x * x * dradial + 2 * p1 * y + 6 * p2 * x;
        double b = 2 * x * y * dradial + 2 * p1 * x + 2 * p2 * y;
        double c = 2 * x * y * dradial + 2 * p1 * x + 2 * p2 * y;
        double d = radial + 2 * y * y * dradial + 6 * p1 * y + 2 * p2 * x;
        double det = a * d - b * c;
        if (!(fabs(det) > 1e-12)) return false;
        x -= (d * ex - b * ey) / det;
        y -= (a * ey - c * ex) / det;
        if (!isfinite(x) || !isfinite(y)) return false;
    }
    return false;
}

bool calib_project(const calib_camera *c, bf_vec3 p_c, double *u_px, double *v_px)
{
    if (!(p_c.z > 0)) return false;
    double xd, yd;
    calib_distort(c->dist, p_c.x / p_c.z, p_c.y / p_c.z, &xd, &yd);
    *u_px = c->fx_px * xd + c->cx_px;
    *v_px = c->fy_px * yd + c->cy_px;
    return true;
}

bool calib_unproject(const calib_camera *c, double u_px, double v_px, bf_vec3 *ray_c)
{
    double x, y;
    if (!calib_undistort(c->dist, (u_px - c->cx_px) / c->fx_px, (v_px - c->cy_px) / c->fy_px, &x, &y)) return false;
    *ray_c = bf_v3(x, y, 1);
    return true;
}
