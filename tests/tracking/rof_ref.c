/* CPU oracle of the ROF filter; shaders/track_rof.comp has the method and
 * the reasons. Floats and the shared functions of shaders/track.glsl.h, in
 * the kernel's order, so GPU and CPU differ only by the division and square
 * root rounding Vulkan allows. */
#include "rof_ref.h"

#include <math.h>

#include "shaders/track.glsl.h"

static float div_p(const float *p, uint32_t w, uint32_t x, uint32_t y)
{
    uint32_t i = y * w + x;
    float pl = x > 0 ? p[2 * (i - 1)] : 0.0f;
    float pu = y > 0 ? p[2 * (i - w) + 1] : 0.0f;
    float d = (p[2 * i] - pl) + (p[2 * i + 1] - pu);
    return d;
}

static float w_at(const float *p, uint32_t w, uint32_t x, uint32_t y, float f, float lambda)
{
    float v = div_p(p, w, x, y) / lambda - f;
    return v;
}

void rof_ref_iterate(const float *f, uint32_t w, uint32_t h, float lambda0, float tau, const float *p_in, float *p_out)
{
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            uint32_t i = y * w + x;
            float fi = f[i];
            if (!(fi > 0.0f)) {
                p_out[2 * i] = p_out[2 * i + 1] = 0.0f;
                continue;
            }
            float fr = x + 1 < w ? f[i + 1] : 0.0f;
            float fd = y + 1 < h ? f[i + w] : 0.0f;
            int mx = fr > 0.0f, my = fd > 0.0f;
            float lambda = track_rof_lambda(fi, lambda0);
            float wi = w_at(p_in, w, x, y, fi, lambda);
            float lmin = lambda;
            float gx = 0.0f, gy = 0.0f;
            if (mx) {
                float lr = track_rof_lambda(fr, lambda0);
                gx = w_at(p_in, w, x + 1, y, fr, lr) - wi;
                lmin = fminf(lmin, lr);
            }
            if (my) {
                float ld = track_rof_lambda(fd, lambda0);
                gy = w_at(p_in, w, x, y + 1, fd, ld) - wi;
                lmin = fminf(lmin, ld);
            }
            float s = tau * lmin;
            float gn = sqrtf(gx * gx + gy * gy);
            p_out[2 * i] = mx ? track_rof_step(p_in[2 * i], gx, s, gn) : 0.0f;
            p_out[2 * i + 1] = my ? track_rof_step(p_in[2 * i + 1], gy, s, gn) : 0.0f;
        }
}

void rof_ref_primal(const float *f, uint32_t w, uint32_t h, float lambda0, const float *p, float *u)
{
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            uint32_t i = y * w + x;
            if (!(f[i] > 0.0f)) {
                u[i] = 0.0f;
                continue;
            }
            float d = div_p(p, w, x, y);
            float v = f[i] - d / track_rof_lambda(f[i], lambda0);
            u[i] = v > 0.0f ? v : f[i];
        }
}

double rof_ref_energy(const float *f, const float *u, uint32_t w, uint32_t h, float lambda0)
{
    double e = 0;
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            uint32_t i = y * w + x;
            if (!(f[i] > 0.0f)) continue;
            double gx = x + 1 < w && f[i + 1] > 0.0f ? (double)u[i + 1] - u[i] : 0.0;
            double gy = y + 1 < h && f[i + w] > 0.0f ? (double)u[i + w] - u[i] : 0.0;
            double lambda = (double)lambda0 * f[i] * f[i];
            double r = (double)u[i] - f[i];
            e += sqrt(gx * gx + gy * gy) + 0.5 * lambda * r * r;
        }
    return e;
}

double rof_ref_dual(const float *f, const float *p, uint32_t w, uint32_t h, float lambda0)
{
    double e = 0;
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            uint32_t i = y * w + x;
            if (!(f[i] > 0.0f)) continue;
            uint32_t il = i - 1, iu = i - w;
            double d = (double)p[2 * i] - (x > 0 ? p[2 * il] : 0.0) + (double)p[2 * i + 1] - (y > 0 ? p[2 * iu + 1] : 0.0);
            double lambda = (double)lambda0 * f[i] * f[i];
            e += f[i] * d - d * d / (2.0 * lambda);
        }
    return e;
}
