#version 450
/* One dual iteration of the depth-adapted ROF filter on the reference's
 * foreground f > 0 (Chambolle 2004, with the per-pixel data weight of
 * Reichl's dissertation ch. 8; docs/tracking.md). With
 *   w = div p / lambda - f   (= -u, the current primal estimate)
 * the step is p <- (p + s grad w) / (1 + s |grad w|), s = tau lambda_min:
 * grad(v / lambda) with v = div p - lambda f, the exact gradient of the dual
 * energy sum (div p - lambda f)^2 / (2 lambda), and lambda_min the smallest
 * lambda whose divergence reads this pixel's p (here, right, down), which
 * keeps Chambolle's step bound tau <= 1/4 per pixel (Gershgorin).
 * Gradient by forward differences, divergence by backward differences (its
 * negative adjoint); a neighbour outside the image or the mask contributes
 * nothing (Neumann at the mask's edge): the background never leaks in.
 * tests/tracking/rof_ref.c is the CPU oracle of this kernel.
 * Several iterations per dispatch on shared-memory tiles with a halo (exact,
 * 1.7x the pixel updates) measured 3x slower per iteration on lavapipe
 * than this kernel: shared memory there is read and written lane by lane
 * like a storage buffer, and every barrier switches coroutines
 * (docs/tracking.md). */
#extension GL_GOOGLE_include_directive : require
#include "track.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

/* The depth, the dual field read and the one written (main sets them). */
TrackF32 depth;
TrackVec2 p_in, p_out;

layout(push_constant) uniform Push { track_image_push pc; };

/* Divergence of p at pixel i = (x, y): backward differences; p is zero
 * outside the mask and in components whose forward neighbour is outside. */
float div_p(uint i, uint x, uint y)
{
    vec2 p = p_in.v[i];
    float pl = x > 0u ? p_in.v[i - 1u].x : 0.0;
    float pu = y > 0u ? p_in.v[i - pc.width].y : 0.0;
    BF_PRECISE float d = (p.x - pl) + (p.y - pu);
    return d;
}

/* w = div p / lambda - f at a pixel of the mask. */
float w_at(uint i, uint x, uint y, float f, float lambda)
{
    BF_PRECISE float w = div_p(i, x, y) / lambda - f;
    return w;
}

void rof_pixel(uint x, uint y)
{
    if (x >= pc.width || y >= pc.height) return;
    uint i = y * pc.width + x;
    /* The level's depth at pixel offset pc.dst_off; p is level-local. */
    uint o = pc.dst_off;
    float f = depth.v[o + i];
    if (!(f > 0.0)) {
        p_out.v[i] = vec2(0.0);
        return;
    }
    float fr = x + 1u < pc.width ? depth.v[o + i + 1u] : 0.0;
    float fd = y + 1u < pc.height ? depth.v[o + i + pc.width] : 0.0;
    bool mx = fr > 0.0, my = fd > 0.0;
    float lambda = track_rof_lambda(f, pc.lambda0);
    float w = w_at(i, x, y, f, lambda);
    float lmin = lambda;
    BF_PRECISE float gx = 0.0, gy = 0.0;
    if (mx) {
        float lr = track_rof_lambda(fr, pc.lambda0);
        gx = w_at(i + 1u, x + 1u, y, fr, lr) - w;
        lmin = min(lmin, lr);
    }
    if (my) {
        float ld = track_rof_lambda(fd, pc.lambda0);
        gy = w_at(i + pc.width, x, y + 1u, fd, ld) - w;
        lmin = min(lmin, ld);
    }
    BF_PRECISE float s = pc.tau * lmin;
    BF_PRECISE float gn = sqrt(gx * gx + gy * gy);
    vec2 p = p_in.v[i];
    p_out.v[i] = vec2(mx ? track_rof_step(p.x, gx, s, gn) : 0.0, my ? track_rof_step(p.y, gy, s, gn) : 0.0);
}

void main()
{
    /* TRACK_IMAGE_PX pixels per invocation (track.glsl.h says why). */
    depth = TrackF32(uvec2(pc.depth_lo, pc.depth_hi));
    p_in = TrackVec2(uvec2(pc.p_in_lo, pc.p_in_hi));
    p_out = TrackVec2(uvec2(pc.p_out_lo, pc.p_out_hi));
    uint x0 = gl_WorkGroupID.x * (TRACK_IMAGE_TILE * TRACK_IMAGE_PX) + gl_LocalInvocationID.x;
    for (uint j = 0u; j < TRACK_IMAGE_PX; j++) rof_pixel(x0 + j * TRACK_IMAGE_TILE, gl_GlobalInvocationID.y);
}
