#version 450
/* Dual iterations of the depth-adapted ROF filter on the reference's
 * foreground f > 0 (Chambolle 2004, with the per-pixel data weight of
 * Reichl's dissertation ch. 8; docs/tracking.md), up to TRACK_ROF_K per
 * dispatch on a shared-memory region with a halo (track.glsl.h): the
 * interior equals the global iteration, operation for operation.
 *
 * With w = div p / lambda - f (= -u, the current primal estimate) the step
 * is p <- (p + s grad w) / (1 + s |grad w|), s = tau lambda_min: grad(v /
 * lambda) with v = div p - lambda f, the exact gradient of the dual energy
 * sum (div p - lambda f)^2 / (2 lambda), and lambda_min the smallest
 * lambda whose divergence reads this pixel's p (here, right, down), which
 * keeps Chambolle's step bound tau <= 1/4 per pixel (Gershgorin). Gradient
 * by forward differences, divergence by backward differences (its negative
 * adjoint); a neighbour outside the image or the mask contributes nothing
 * (Neumann at the mask's edge): the background never leaks in.
 *
 * pc.mode iterations; TRACK_FLAG_ROF_LOAD starts from p_in (binding 4),
 * else from p = 0; TRACK_FLAG_ROF_FINAL writes the primal u = f - div p /
 * lambda into the depth (binding 1; kept at f where u <= 0), else the dual
 * field into p_out (binding 5). f is binding 6. tests/tracking/rof_ref.c
 * is the CPU oracle. */
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require
#include "track.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

layout(std430, binding = 1) writeonly buffer Depth { float d[]; } depth;
layout(std430, binding = 4) readonly buffer PIn { vec2 p[]; } p_in;
layout(std430, binding = 5) writeonly buffer POut { vec2 p[]; } p_out;
layout(std430, binding = 6) readonly buffer F { float d[]; } rof_f;

layout(push_constant) uniform Push { track_image_push pc; };

#define R TRACK_ROF_REGION
#define N (TRACK_ROF_REGION * TRACK_ROF_REGION)
#define L (TRACK_ROF_LOCAL_XY * TRACK_ROF_LOCAL_XY)
#define PER ((N + L - 1u) / L)

shared float s_px[N];
shared float s_py[N];
shared float s_w[N];

void main()
{
    uint li = gl_LocalInvocationIndex;
    int x0 = int(gl_WorkGroupID.x * TRACK_ROF_TILE) - int(TRACK_ROF_HALO);
    int y0 = int(gl_WorkGroupID.y * TRACK_ROF_TILE) - int(TRACK_ROF_HALO);
    int W = int(pc.width), H = int(pc.height);
    /* Each invocation owns region pixels li, li + L, ...: their f, lambda,
     * step and mask bits stay in registers for all iterations. */
    float f[PER], lam[PER], s[PER];
    bool mx[PER], my[PER];
    [[unroll]] for (uint n = 0u; n < PER; n++) {
        uint k = li + n * L;
        f[n] = 0.0, lam[n] = 1.0, s[n] = 0.0, mx[n] = false, my[n] = false;
        if (k >= N) continue;
        int lx = int(k % R), ly = int(k / R);
        int gx = x0 + lx, gy = y0 + ly;
        vec2 p = vec2(0.0);
        if (gx >= 0 && gy >= 0 && gx < W && gy < H) {
            int gi = gy * W + gx;
            float fi = rof_f.d[gi];
            if (fi > 0.0) {
                /* Neighbours beyond the region count as outside the mask:
                 * wrong, but only in the halo. */
                float fr = gx + 1 < W && lx + 1 < int(R) ? rof_f.d[gi + 1] : 0.0;
                float fd = gy + 1 < H && ly + 1 < int(R) ? rof_f.d[gi + W] : 0.0;
                float l = track_rof_lambda(fi, pc.lambda0);
                float lmin = l;
                mx[n] = fr > 0.0;
                my[n] = fd > 0.0;
                if (mx[n]) lmin = min(lmin, track_rof_lambda(fr, pc.lambda0));
                if (my[n]) lmin = min(lmin, track_rof_lambda(fd, pc.lambda0));
                BF_PRECISE float st = pc.tau * lmin;
                f[n] = fi, lam[n] = l, s[n] = st;
                if ((pc.flags & TRACK_FLAG_ROF_LOAD) != 0u) p = p_in.p[gi];
            }
        }
        s_px[k] = p.x;
        s_py[k] = p.y;
    }
    for (uint it = 0u; it < pc.mode; it++) {
        /* p of the last iteration (or the start) -> the divergences. */
        barrier();
        [[unroll]] for (uint n = 0u; n < PER; n++) {
            uint k = li + n * L;
            if (k >= N || !(f[n] > 0.0)) continue;
            uint lx = k % R;
            float pl = lx > 0u ? s_px[k - 1u] : 0.0;
            float pu = k >= R ? s_py[k - R] : 0.0;
            BF_PRECISE float d = (s_px[k] - pl) + (s_py[k] - pu);
            BF_PRECISE float w = d / lam[n] - f[n];
            s_w[k] = w;
        }
        /* w -> the dual steps (each reads its own p only). */
        barrier();
        [[unroll]] for (uint n = 0u; n < PER; n++) {
            uint k = li + n * L;
            if (k >= N || !(f[n] > 0.0)) continue;
            float w = s_w[k];
            BF_PRECISE float gx = mx[n] ? s_w[k + 1u] - w : 0.0;
            BF_PRECISE float gy = my[n] ? s_w[k + R] - w : 0.0;
            BF_PRECISE float gn = sqrt(gx * gx + gy * gy);
            s_px[k] = mx[n] ? track_rof_step(s_px[k], gx, s[n], gn) : 0.0;
            s_py[k] = my[n] ? track_rof_step(s_py[k], gy, s[n], gn) : 0.0;
        }
    }
    barrier();
    bool final_ = (pc.flags & TRACK_FLAG_ROF_FINAL) != 0u;
    [[unroll]] for (uint n = 0u; n < PER; n++) {
        uint k = li + n * L;
        if (k >= N) continue;
        int lx = int(k % R), ly = int(k / R);
        int gx = x0 + lx, gy = y0 + ly;
        if (lx < int(TRACK_ROF_HALO) || ly < int(TRACK_ROF_HALO) || lx >= int(TRACK_ROF_HALO + TRACK_ROF_TILE) ||
            ly >= int(TRACK_ROF_HALO + TRACK_ROF_TILE) || gx >= W || gy >= H)
            continue;
        int gi = gy * W + gx;
        if (final_) {
            if (!(f[n] > 0.0)) continue; /* the depth there is 0 already */
            /* p one pixel left and up is in the region (halo >= 1) and is 0
             * outside the image, as the global kernel's border rule. */
            BF_PRECISE float d = (s_px[k] - s_px[k - 1u]) + (s_py[k] - s_py[k - R]);
            BF_PRECISE float u = f[n] - d / lam[n];
            /* A smoothing strong enough to push a pixel to the camera would
             * make it invalid; keep the measurement there instead. */
            depth.d[gi] = u > 0.0 ? u : f[n];
        } else {
            p_out.p[gi] = vec2(s_px[k], s_py[k]);
        }
    }
}
