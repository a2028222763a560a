/* A textured box room rendered at a known pose, colour and depth, for the
 * tests of ORB and PnP (tests/eval/test_motion.c, tests/features). Static
 * functions: each test file gets its own copy. */
#ifndef BF_TESTS_BOX_ROOM_H
#define BF_TESTS_BOX_ROOM_H

#include <math.h>
#include <stdint.h>

#include "core/core.h"

#define BOX_W 640
#define BOX_H 480

static const bf_intrinsics box_K = {BOX_W, BOX_H, 525.0, 525.0, 319.5, 239.5, 5000.0};

/* A 4 x 3 x 4.5 m box (x in [-2, 2], y in [-1.5, 1.5], z in [-1, 3.5]) whose
 * walls are tiled with 5 cm squares of random grey (a hash of the square),
 * the kind of corners ORB finds. */
static inline double box_texture(bf_vec3 p)
{
    int64_t i = (int64_t)floor(p.x / 0.05), j = (int64_t)floor(p.y / 0.05), k = (int64_t)floor(p.z / 0.05);
    uint64_t h = (uint64_t)(i * 73856093) ^ (uint64_t)(j * 19349663) ^ (uint64_t)(k * 83492791);
    h ^= h >> 33;
    h *= 0xff51afd7ed558ccdull;
    h ^= h >> 29;
    return 30.0 + (double)(h % 200);
}

/* The ray o + s d (d in world) to the box's inside: the nearest wall hit. */
static inline double box_hit(bf_vec3 o, bf_vec3 d)
{
    const double lo[3] = {-2, -1.5, -1}, hi[3] = {2, 1.5, 3.5};
    const double oo[3] = {o.x, o.y, o.z}, dd[3] = {d.x, d.y, d.z};
    double best = INFINITY;
    for (int a = 0; a < 3; a++) {
        if (dd[a] == 0) continue;
        double s = ((dd[a] > 0 ? hi[a] : lo[a]) - oo[a]) / dd[a];
        if (s > 0 && s < best) best = s;
    }
    return best;
}

/* Renders the room seen from T_wc: 2 x 2 samples a pixel for the colour
 * (grey in all three channels), the centre ray's z for the depth. */
static inline void box_render(const bf_se3 *T_wc, uint8_t *rgb, uint16_t *depth)
{
    for (int v = 0; v < BOX_H; v++)
        for (int u = 0; u < BOX_W; u++) {
            double sum = 0;
            for (int s = 0; s < 4; s++) {
                double uu = u - 0.25 + 0.5 * (s & 1), vv = v - 0.25 + 0.5 * (s >> 1);
                bf_vec3 dc = bf_v3((uu - box_K.cx_px) / box_K.fx_px, (vv - box_K.cy_px) / box_K.fy_px, 1.0);
                bf_vec3 d = bf_se3_rotate(T_wc, dc);
                double t = box_hit(T_wc->t, d);
                sum += box_texture(bf_v3_add(T_wc->t, bf_v3_scale(d, t)));
            }
            uint8_t g = (uint8_t)lround(sum / 4);
            size_t i = (size_t)v * BOX_W + u;
            rgb[3 * i] = rgb[3 * i + 1] = rgb[3 * i + 2] = g;
            bf_vec3 dc = bf_v3((u - box_K.cx_px) / box_K.fx_px, (v - box_K.cy_px) / box_K.fy_px, 1.0);
            bf_vec3 d = bf_se3_rotate(T_wc, dc);
            double z = box_hit(T_wc->t, d); /* dc has z = 1: the ray parameter is the depth */
            depth[i] = (uint16_t)lround(z * box_K.depth_scale);
        }
}

static inline bf_se3 box_pose(double rx, double ry, double rz, double tx, double ty, double tz)
{
    double xi[6] = {0, 0, 0, rx, ry, rz};
    bf_se3 T = bf_se3_exp(xi);
    T.t = bf_v3(tx, ty, tz);
    return T;
}

#endif
