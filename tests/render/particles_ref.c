/* The particle oracle (particles_ref.h): for each sphere in front of the
 * camera, the pixels of its projected box, an exact ray-sphere test each. */
#include <math.h>
#include <string.h>

#include "particles_ref.h"

void particles_ref_cast(const float *xyz, uint64_t n, double radius_m, const bf_intrinsics *K, const bf_se3 *T_wc,
                        double near_m, double far_m, float *depth)
{
    uint32_t W = K->width, H = K->height;
    memset(depth, 0, (size_t)W * H * sizeof *depth);
    bf_se3 T_cw = bf_se3_inverse(T_wc);
    double r2 = radius_m * radius_m;
    for (uint64_t i = 0; i < n; i++) {
        bf_vec3 c = bf_se3_apply(&T_cw, bf_v3(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]));
        if (c.z - radius_m < near_m || c.z - radius_m >= far_m) continue; /* the near plane cuts it: not in a view we test */
        /* The sphere's image lies within the projections of its box's
         * front face (z - r) grown by r: a conservative pixel box. */
        double zf = c.z - radius_m;
        double u0 = K->fx_px * (c.x - radius_m) / (c.x - radius_m < 0 ? zf : c.z + radius_m) + K->cx_px;
        double u1 = K->fx_px * (c.x + radius_m) / (c.x + radius_m > 0 ? zf : c.z + radius_m) + K->cx_px;
        double v0 = K->fy_px * (c.y - radius_m) / (c.y - radius_m < 0 ? zf : c.z + radius_m) + K->cy_px;
        double v1 = K->fy_px * (c.y + radius_m) / (c.y + radius_m > 0 ? zf : c.z + radius_m) + K->cy_px;
        int64_t ua = (int64_t)floor(u0) - 1, ub = (int64_t)ceil(u1) + 1;
        int64_t va = (int64_t)floor(v0) - 1, vb = (int64_t)ceil(v1) + 1;
        if (ua < 0) ua = 0;
        if (va < 0) va = 0;
        if (ub > (int64_t)W - 1) ub = (int64_t)W - 1;
        if (vb > (int64_t)H - 1) vb = (int64_t)H - 1;
        for (int64_t v = va; v <= vb; v++)
            for (int64_t u = ua; u <= ub; u++) {
                /* Ray d = ((u - cx)/fx, (v - cy)/fy, 1): |t d - c|^2 = r^2. */
                double d[3] = {(u - K->cx_px) / K->fx_px, (v - K->cy_px) / K->fy_px, 1.0};
                double a = d[0] * d[0] + d[1] * d[1] + 1.0;
                double b = d[0] * c.x + d[1] * c.y + c.z;
                double cc = c.x * c.x + c.y * c.y + c.z * c.z - r2;
                double disc = b * b - a * cc;
                if (disc < 0) continue;
                double t = (b - sqrt(disc)) / a;
                if (t < near_m || t >= far_m) continue;
                float *px = &depth[(size_t)v * W + (size_t)u];
                if (*px == 0 || t < *px) *px = (float)t;
            }
    }
}
