/* The body of the two ICP kernels, track_icp.comp (shared-memory tree
 * reduction, works everywhere) and track_icp_sg.comp (subgroup additions
 * first, where the device has subgroup arithmetic). GLSL only.
 *
 * One pass fuses projective data association, the gates, the
 * point-to-plane residual and the workgroup's reduction (KinectFusion,
 * Newcombe et al. 2011, sec. 3.5; linearisation of Low 2004). Each
 * invocation walks the level's frame pixels with stride pc.n_threads and
 * keeps its sums in registers; the workgroup then adds its invocations'
 * sums and writes TRACK_PARTIAL_WORDS floats, which the CPU adds in double.
 *
 * For a frame pixel with depth z (vertex v, back-projected) and normal m
 * (frame camera; octahedral, track.glsl.h), p = T_rc v and m' = R_rc m live
 * in the reference camera; p projects to the nearest reference pixel with
 * vertex q (its depth back-projected) and normal n. An inlier has |p - q| <=
 * dist_m and m' . n >= cos(angle). Its residual is r = n . (p - q) and its
 * row a = (n, p x n): moving p by a small twist (t, w) in the reference
 * camera, p + w x p + t, changes r by a . (t, w). */
#ifndef BF_GLSL
#error "track_icp.glsl.h is GLSL only"
#endif
#extension GL_EXT_control_flow_attributes : require
#include "track.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

layout(std430, binding = 0) readonly buffer FrameD { float d[]; } frame_d;
layout(std430, binding = 1) readonly buffer FrameN { uint n[]; } frame_n;
layout(std430, binding = 2) readonly buffer RefD { float d[]; } ref_d;
layout(std430, binding = 3) readonly buffer RefN { uint n[]; } ref_n;
layout(std430, binding = 4) writeonly buffer Partial { float w[]; } partial;

layout(push_constant) uniform Push { track_icp_push pc; };

shared float s_sum[TRACK_SUMS * TRACK_ICP_LOCAL_MAX];

/* Pixel (x, y) of the level back-projected at depth z (as track_vn.comp). */
vec3 unproject(uint x, uint y, float z)
{
    return vec3((float(x) - pc.cx) * z / pc.fx, (float(y) - pc.cy) * z / pc.fy, z);
}

/* One frame pixel's association, gates and contribution. */
void add_pixel(uint x, uint y, inout float acc[TRACK_SUMS])
{
    uint i = pc.off + y * pc.width + x;
    float z = frame_d.d[i];
    uint mw = frame_n.n[i];
    if (!(z > 0.0) || mw == 0u) return;
    acc[TRACK_SUM_VALID] += 1.0;
    vec3 r0 = vec3(pc.R[0], pc.R[1], pc.R[2]);
    vec3 r1 = vec3(pc.R[3], pc.R[4], pc.R[5]);
    vec3 r2 = vec3(pc.R[6], pc.R[7], pc.R[8]);
    vec3 v = unproject(x, y, z);
    vec3 p = vec3(dot(r0, v), dot(r1, v), dot(r2, v)) + vec3(pc.t[0], pc.t[1], pc.t[2]);
    if (!(p.z > 0.0)) return;
    float u = pc.fx * p.x / p.z + pc.cx;
    float w = pc.fy * p.y / p.z + pc.cy;
    /* Nearest pixel; the float comparison also rejects NaN. */
    if (!(u > -0.5 && w > -0.5 && u < float(pc.width) - 0.5 && w < float(pc.height) - 0.5)) return;
    uint ux = uint(u + 0.5), wy = uint(w + 0.5);
    uint j = pc.off + wy * pc.width + ux;
    float zq = ref_d.d[j];
    uint nw = ref_n.n[j];
    if (!(zq > 0.0) || nw == 0u) return;
    vec3 q = unproject(ux, wy, zq);
    vec3 n = track_oct_decode(nw);
    vec3 d = p - q;
    if (dot(d, d) > pc.dist_m * pc.dist_m) return;
    vec3 m = track_oct_decode(mw);
    vec3 mr = vec3(dot(r0, m), dot(r1, m), dot(r2, m));
    if (dot(mr, n) < pc.cos_angle) return;
    float r = dot(n, d);
    vec3 c = cross(p, n);
    float a[6] = float[6](n.x, n.y, n.z, c.x, c.y, c.z);
    uint e = 0u;
    /* Fully unrolled: every index into acc and a is a constant, so they
     * stay in registers (llvmpipe runs a dynamically indexed private array
     * through memory, lane by lane). */
    [[unroll]] for (uint k = 0u; k < 6u; k++)
        [[unroll]] for (uint h = k; h < 6u; h++) acc[TRACK_SUM_ATA + e++] += a[k] * a[h];
    [[unroll]] for (uint k = 0u; k < 6u; k++) acc[TRACK_SUM_ATR + k] += a[k] * r;
    acc[TRACK_SUM_RR] += r * r;
    acc[TRACK_SUM_INLIERS] += 1.0;
    acc[TRACK_SUM_Z] += p.z;
}

void main()
{
    float acc[TRACK_SUMS];
    [[unroll]] for (uint k = 0u; k < TRACK_SUMS; k++) acc[k] = 0.0;
    /* Samples k = id, id + n_threads, ... of the level; sample k is pixel
     * k * sub (sub 2: even columns, shifted by one on odd rows, a
     * checkerboard). x and y are stepped, not divided: one division per
     * invocation (lavapipe divides lane by lane). */
    uint W = pc.width;
    uint k0 = gl_GlobalInvocationID.x * pc.sub, stride = pc.n_threads * pc.sub;
    uint x = k0 % W, y = k0 / W;
    uint sx = stride % W, sy = stride / W;
    while (y < pc.height) {
        uint xx = x + (pc.sub == 2u ? (y & 1u) : 0u);
        if (xx < W) add_pixel(xx, y, acc);
        x += sx;
        y += sy;
        if (x >= W) {
            x -= W;
            y++;
        }
    }

    uint li = gl_LocalInvocationIndex;
    uint L = gl_WorkGroupSize.x;
#ifdef TRACK_ICP_SUBGROUP
    /* Subgroup sums first; one shared word per subgroup and sum. */
    [[unroll]] for (uint k = 0u; k < TRACK_SUMS; k++) {
        float s = subgroupAdd(acc[k]);
        if (subgroupElect()) s_sum[k * TRACK_ICP_LOCAL_MAX + gl_SubgroupID] = s;
    }
    barrier();
    for (uint k = li; k < TRACK_PARTIAL_WORDS; k += L) {
        float s = 0.0;
        if (k < TRACK_SUMS)
            for (uint g = 0u; g < gl_NumSubgroups; g++) s += s_sum[k * TRACK_ICP_LOCAL_MAX + g];
        partial.w[gl_WorkGroupID.x * TRACK_PARTIAL_WORDS + k] = s;
    }
#else
    /* Shared-memory tree reduction (L is a power of two). */
    [[unroll]] for (uint k = 0u; k < TRACK_SUMS; k++) s_sum[k * TRACK_ICP_LOCAL_MAX + li] = acc[k];
    for (uint s = L / 2u; s > 0u; s >>= 1) {
        barrier();
        if (li < s)
            for (uint k = 0u; k < TRACK_SUMS; k++)
                s_sum[k * TRACK_ICP_LOCAL_MAX + li] += s_sum[k * TRACK_ICP_LOCAL_MAX + li + s];
    }
    barrier();
    for (uint k = li; k < TRACK_PARTIAL_WORDS; k += L)
        partial.w[gl_WorkGroupID.x * TRACK_PARTIAL_WORDS + k] = k < TRACK_SUMS ? s_sum[k * TRACK_ICP_LOCAL_MAX] : 0.0;
#endif
}
