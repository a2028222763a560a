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
 * For a frame pixel with vertex v and normal m (frame camera), p = T_rc v
 * and m' = R_rc m live in the reference camera; p projects to the nearest
 * reference pixel with vertex q and normal n. An inlier has |p - q| <=
 * dist_m and m' . n >= cos(angle). Its residual is r = n . (p - q) and its
 * row a = (n, p x n): moving p by a small twist (t, w) in the reference
 * camera, p + w x p + t, changes r by a . (t, w). */
#ifndef BF_GLSL
#error "track_icp.glsl.h is GLSL only"
#endif
#include "track.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

layout(std430, binding = 0) readonly buffer FrameV { vec4 v[]; } frame_v;
layout(std430, binding = 1) readonly buffer FrameN { vec4 v[]; } frame_n;
layout(std430, binding = 2) readonly buffer RefV { vec4 v[]; } ref_v;
layout(std430, binding = 3) readonly buffer RefN { vec4 v[]; } ref_n;
layout(std430, binding = 4) writeonly buffer Partial { float w[]; } partial;

layout(push_constant) uniform Push { track_icp_push pc; };

shared float s_sum[TRACK_SUMS * TRACK_ICP_LOCAL_MAX];

void main()
{
    float acc[TRACK_SUMS];
    for (uint k = 0u; k < TRACK_SUMS; k++) acc[k] = 0.0;
    vec3 r0 = vec3(pc.R[0], pc.R[1], pc.R[2]);
    vec3 r1 = vec3(pc.R[3], pc.R[4], pc.R[5]);
    vec3 r2 = vec3(pc.R[6], pc.R[7], pc.R[8]);
    vec3 t = vec3(pc.t[0], pc.t[1], pc.t[2]);
    uint n_pix = pc.width * pc.height;
    float dist2 = pc.dist_m * pc.dist_m;
    for (uint k = gl_GlobalInvocationID.x; k < n_pix; k += pc.n_threads) {
        vec4 v = frame_v.v[pc.off + k];
        vec4 m = frame_n.v[pc.off + k];
        if (v.w == 0.0 || m == vec4(0.0)) continue;
        acc[TRACK_SUM_VALID] += 1.0;
        vec3 p = vec3(dot(r0, v.xyz), dot(r1, v.xyz), dot(r2, v.xyz)) + t;
        if (!(p.z > 0.0)) continue;
        vec3 mr = vec3(dot(r0, m.xyz), dot(r1, m.xyz), dot(r2, m.xyz));
        float u = pc.fx * p.x / p.z + pc.cx;
        float w = pc.fy * p.y / p.z + pc.cy;
        /* Nearest pixel; the float comparison also rejects NaN. */
        if (!(u > -0.5 && w > -0.5 && u < float(pc.width) - 0.5 && w < float(pc.height) - 0.5)) continue;
        uint j = pc.off + uint(w + 0.5) * pc.width + uint(u + 0.5);
        vec4 q = ref_v.v[j];
        vec4 n4 = ref_n.v[j];
        if (q.w == 0.0 || n4 == vec4(0.0)) continue;
        vec3 n = n4.xyz;
        vec3 d = p - q.xyz;
        if (dot(d, d) > dist2 || dot(mr, n) < pc.cos_angle) continue;
        float r = dot(n, d);
        vec3 c = cross(p, n);
        float a[6] = float[6](n.x, n.y, n.z, c.x, c.y, c.z);
        uint e = 0u;
        for (uint i = 0u; i < 6u; i++)
            for (uint h = i; h < 6u; h++) acc[TRACK_SUM_ATA + e++] += a[i] * a[h];
        for (uint i = 0u; i < 6u; i++) acc[TRACK_SUM_ATR + i] += a[i] * r;
        acc[TRACK_SUM_RR] += r * r;
        acc[TRACK_SUM_INLIERS] += 1.0;
        acc[TRACK_SUM_Z] += p.z;
    }

    uint li = gl_LocalInvocationIndex;
    uint L = gl_WorkGroupSize.x;
#ifdef TRACK_ICP_SUBGROUP
    /* Subgroup sums first; one shared word per subgroup and sum. */
    for (uint k = 0u; k < TRACK_SUMS; k++) {
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
    for (uint k = 0u; k < TRACK_SUMS; k++) s_sum[k * TRACK_ICP_LOCAL_MAX + li] = acc[k];
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
