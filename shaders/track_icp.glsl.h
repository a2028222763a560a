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
 * in the reference camera; p projects to the nearest pixel of the
 * reference's level (the frame's, or one above it: track_config.ref_level) with
 * vertex q (its depth back-projected) and normal n. An inlier has |p - q| <=
 * dist_m and m' . n >= cos(angle). Its residual is r = n . (p - q) and its
 * row a = (n, p x n): moving p by a small twist (t, w) in the reference
 * camera, p + w x p + t, changes r by a . (t, w). */
#ifndef BF_GLSL
#error "track_icp.glsl.h is GLSL only"
#endif
#include "track.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

layout(std430, binding = 0) readonly buffer Addr { uvec2 a[TRACK_ADDRS]; } addr;
layout(std430, binding = 1) writeonly buffer Partial { float w[]; } partial;

/* The pyramids, through their addresses (main sets them from addr). */
TrackF32 frame_d, ref_d, frame_i, ref_i;
TrackU32 frame_n, ref_n;

layout(push_constant) uniform Push { track_icp_push pc; };

shared vec4 s_sum[9u * TRACK_ICP_LOCAL_MAX];

/* Pixel (x, y) of the level back-projected at depth z (as track_vn.comp). */
vec3 unproject(uint x, uint y, float z)
{
    return vec3((float(x) - pc.cx) * z / pc.fx, (float(y) - pc.cy) * z / pc.fy, z);
}

/* The reference level's intrinsics: pc.ref_shift levels above the frame's
 * (track__level_intrinsics: fx / 2^s, (cx + 1/2) / 2^s - 1/2). */
struct ref_geom {
    float fx, fy, cx, cy;
};
ref_geom ref_geometry()
{
    float s = 1.0 / float(1u << pc.ref_shift);
    ref_geom g;
    g.fx = pc.fx * s;
    g.fy = pc.fy * s;
    g.cx = (pc.cx + 0.5) * s - 0.5;
    g.cy = (pc.cy + 0.5) * s - 0.5;
    return g;
}

/* The sums in eight vec4 registers, words 4q .. 4q + 3 of the TRACK_SUM_*
 * layout in s[q]. Plain variables, no arrays:
 * llvmpipe keeps a private array it cannot fully resolve in memory and
 * reads and writes it lane by lane, which made this kernel 5x slower. */
#define TRACK_ICP_ZERO4 vec4(0.0)
struct icp_acc {
    vec4 s0, s1, s2, s3, s4, s5, s6, s7, s8;
};

/* Row a = (n, c) with residual r and weight w into the normal equations
 * (TRACK_SUM_ATA, TRACK_SUM_ATR). */
void add_row(vec3 n, vec3 c, float r, float wgt, inout icp_acc A)
{
    vec3 nq = wgt * n, cw = wgt * c;
    float rw = wgt * r;
    /* The upper triangle of a a^T row by row, then a r. */
    A.s0 += nq.x * vec4(n, c.x);
    A.s1 += vec4(nq.x * c.y, nq.x * c.z, nq.y * n.y, nq.y * n.z);
    A.s2 += vec4(nq.y * c, nq.z * n.z);
    A.s3 += vec4(nq.z * c, cw.x * c.x);
    A.s4 += vec4(cw.x * c.y, cw.x * c.z, cw.y * c.y, cw.y * c.z);
    A.s5 += vec4(cw.z * c.z, rw * n);
    A.s6.xyz += rw * c;
}

/* The photometric term of an inlier (Steinbruecker, Sturm and Cremers
 * 2011; joint with ICP as in ElasticFusion, Whelan et al. 2015, and
 * Open3D's hybrid odometry): p, the frame pixel's point in the reference
 * camera, projects with the frame level's intrinsics to (u, v) of the
 * reference's intensity at this level (the frame the reference was made
 * with, at the reference's pose). The residual is r = I_ref(u, v) -
 * I_frame(pixel i, column fx, row fy); moving p by the twist (t, w) changes it by g . (t + w x
 * p), g = J_pi(p)^T grad I_ref, so its row is (g, p x g) like a normal's.
 * The gradient is the bilinear interpolant's own derivative. */
void add_photometric(uint i, uint fx, uint fy, vec3 p, inout icp_acc A)
{
    uint W = pc.size & 0xFFFFu, H = pc.size >> 16;
    float ic = frame_i.v[i];
    float u = pc.fx * p.x / p.z + pc.cx, v = pc.fy * p.y / p.z + pc.cy;
    if (!(ic >= 0.0) || !(u >= 0.0 && v >= 0.0 && u < float(W - 1u) && v < float(H - 1u))) return;
    uint x0 = BF_TRUNC_U32(u), y0 = BF_TRUNC_U32(v);
    float a = u - float(x0), b = v - float(y0);
    uint j = pc.off + y0 * W + x0;
    float i00 = ref_i.v[j], i10 = ref_i.v[j + 1u], i01 = ref_i.v[j + W], i11 = ref_i.v[j + W + 1u];
    if (!(min(min(i00, i10), min(i01, i11)) >= 0.0)) return;
    float r = mix(mix(i00, i10, a), mix(i01, i11, a), b) - ic;
    float gu = mix(i10 - i00, i11 - i01, b), gv = mix(i01 - i00, i11 - i10, a);
    float iz = 1.0 / p.z;
    vec3 g = vec3(pc.fx * gu * iz, pc.fy * gv * iz, -(pc.fx * gu * p.x + pc.fy * gv * p.y) * iz * iz);
    float e = abs(r), wgt = pc.photo_w;
    if (e > pc.photo_huber) wgt *= pc.photo_huber / e;
    add_row(g, cross(p, g), r, wgt, A);
    /* The frame's own gradient at the pixel (forward differences, as the
     * reference's above): a frame blurred by its motion has less of it than
     * the sharp reference (track_config.photo_sharpness_min). */
    float ir = fx + 1u < W ? frame_i.v[i + 1u] : -1.0, id = fy + 1u < H ? frame_i.v[i + W] : -1.0;
    float gf = ir >= 0.0 && id >= 0.0 ? (ir - ic) * (ir - ic) + (id - ic) * (id - ic) : 0.0;
    float gr = ir >= 0.0 && id >= 0.0 ? gu * gu + gv * gv : 0.0;
    A.s8 += vec4(1.0, r * r, gr, gf); /* TRACK_SUM_PHOTO_N, _RR, _GREF, _GFRAME */
}

/* One frame pixel's association, gates and contribution. */
void add_pixel(uint x, uint y, ref_geom G, inout icp_acc A)
{
    uint W = pc.size & 0xFFFFu;
    uint i = pc.off + y * W + x;
    float z = frame_d.v[i];
    uint mw = frame_n.v[i];
    if (!(z > 0.0) || mw == 0u) return;
    A.s7.y += 1.0; /* TRACK_SUM_VALID */
    vec3 r0 = vec3(pc.R[0], pc.R[1], pc.R[2]);
    vec3 r1 = vec3(pc.R[3], pc.R[4], pc.R[5]);
    vec3 r2 = vec3(pc.R[6], pc.R[7], pc.R[8]);
    vec3 v = unproject(x, y, z);
    vec3 p = vec3(dot(r0, v), dot(r1, v), dot(r2, v)) + vec3(pc.t[0], pc.t[1], pc.t[2]);
    if (!(p.z > 0.0)) return;
    float u = G.fx * p.x / p.z + G.cx;
    float w = G.fy * p.y / p.z + G.cy;
    /* Nearest reference pixel; the float comparison also rejects NaN. */
    uint RW = pc.ref_size & 0xFFFFu, RH = pc.ref_size >> 16;
    if (!(u > -0.5 && w > -0.5 && u < float(RW) - 0.5 && w < float(RH) - 0.5)) return;
    uint ux = BF_TRUNC_U32(u + 0.5), wy = BF_TRUNC_U32(w + 0.5);
    uint j = pc.ref_off + wy * RW + ux;
    float zq = ref_d.v[j];
    uint nw = ref_n.v[j];
    if (!(zq > 0.0) || nw == 0u) return;
    vec3 q = vec3((float(ux) - G.cx) * zq / G.fx, (float(wy) - G.cy) * zq / G.fy, zq);
    vec3 n = track_oct_decode(nw);
    vec3 d = p - q;
    if (dot(d, d) > pc.dist_m * pc.dist_m) return;
    vec3 m = track_oct_decode(mw);
    vec3 mr = vec3(dot(r0, m), dot(r1, m), dot(r2, m));
    if (dot(mr, n) < pc.cos_angle) return;
    float r = dot(n, d);
    /* Weighted least squares (IRLS): with noise weights each residual counts
     * by the sensor's depth noise relative to 1 m to the power noise_exp, 3
     * by default (2 is the inverse variance; bf_sensor_sigma: Kinect v1's
     * grows with z^2: with 3 a sample at 3 m weighs ~400 times less than one
     * at 1 m (~50 with 2), where the map is finer and the frame less noisy;
     * docs/real_frames.md has other powers on real frames), and
     * Huber's weight on the residual in units of that noise bounds the pull
     * of the few associations that land on a wrong surface (silhouettes,
     * surfaces the map has not seen yet) without a hard gate that could
     * reject everything while the motion is still large. */
    float wgt = 1.0;
    float sig = bf_sensor_sigma(max(p.z, zq), pc.sigma_a, pc.sigma_b, pc.sigma_c);
    float e = abs(r) / sig;
    if (pc.noise_exp > 0.0 || pc.huber_k > 0.0) { /* uniform: plain iterations skip it */
        if (pc.noise_exp > 0.0) {
            float sw = bf_sensor_sigma(1.0, pc.sigma_a, pc.sigma_b, pc.sigma_c) / sig;
            wgt = pc.noise_exp == 2.0 ? sw * sw : pow(sw, pc.noise_exp);
        }
        if (pc.huber_k > 0.0 && e > pc.huber_k) wgt *= pc.huber_k / e;
    }
    /* a = (n, p x n); then r^2, the inlier and its depth. */
    add_row(n, cross(p, n), r, wgt, A);
    A.s6.w += r * r;
    A.s7 += vec4(1.0, 0.0, p.z, e * e);
    if (pc.photo_w > 0.0) add_photometric(i, x, y, p, A);
}

void main()
{
    icp_acc A = icp_acc(vec4(0.0), vec4(0.0), vec4(0.0), vec4(0.0), vec4(0.0), vec4(0.0), vec4(0.0), vec4(0.0),
                        vec4(0.0));
    /* Samples k = id, id + n_threads, ... of the level; sample k is pixel
     * k * sub (sub 2: even columns, shifted by one on odd rows, a
     * checkerboard; sub 4: every fourth column, shifted by two on odd rows,
     * the checkerboard of the 2x2 blocks' corners). x and y are stepped, not divided: one division per
     * invocation (lavapipe divides lane by lane). */
    uint W = pc.size & 0xFFFFu, H = pc.size >> 16;
    uint k0 = gl_GlobalInvocationID.x * pc.sub, stride = pc.n_threads * pc.sub;
    uint x = k0 % W, y = k0 / W;
    uint sx = stride % W, sy = stride / W;
    ref_geom G = ref_geometry();
    frame_d = TrackF32(addr.a[TRACK_ADDR_FRAME_DEPTH]), frame_n = TrackU32(addr.a[TRACK_ADDR_FRAME_NORMAL]);
    ref_d = TrackF32(addr.a[TRACK_ADDR_REF_DEPTH]), ref_n = TrackU32(addr.a[TRACK_ADDR_REF_NORMAL]);
    frame_i = TrackF32(addr.a[TRACK_ADDR_FRAME_INT]), ref_i = TrackF32(addr.a[TRACK_ADDR_REF_INT]);
    while (y < H) {
        uint xx = x + (y & 1u) * (pc.sub >> 1);
        if (xx < W) add_pixel(xx, y, G, A);
        x += sx;
        y += sy;
        if (x >= W) {
            x -= W;
            y++;
        }
    }

    uint li = gl_LocalInvocationIndex;
    uint L = gl_WorkGroupSize.x;
    uint base = gl_WorkGroupID.x * TRACK_PARTIAL_WORDS;
#ifdef TRACK_ICP_SUBGROUP
    /* Subgroup sums first; one shared vec4 per subgroup and quarter. */
    vec4 t0 = subgroupAdd(A.s0), t1 = subgroupAdd(A.s1), t2 = subgroupAdd(A.s2), t3 = subgroupAdd(A.s3);
    vec4 t4 = subgroupAdd(A.s4), t5 = subgroupAdd(A.s5), t6 = subgroupAdd(A.s6), t7 = subgroupAdd(A.s7);
    vec4 t8 = subgroupAdd(A.s8);
    if (subgroupElect()) {
        uint g = gl_SubgroupID;
        s_sum[0u * TRACK_ICP_LOCAL_MAX + g] = t0, s_sum[1u * TRACK_ICP_LOCAL_MAX + g] = t1;
        s_sum[2u * TRACK_ICP_LOCAL_MAX + g] = t2, s_sum[3u * TRACK_ICP_LOCAL_MAX + g] = t3;
        s_sum[4u * TRACK_ICP_LOCAL_MAX + g] = t4, s_sum[5u * TRACK_ICP_LOCAL_MAX + g] = t5;
        s_sum[6u * TRACK_ICP_LOCAL_MAX + g] = t6, s_sum[7u * TRACK_ICP_LOCAL_MAX + g] = t7;
        s_sum[8u * TRACK_ICP_LOCAL_MAX + g] = t8;
    }
    barrier();
    if (li < 9u) {
        vec4 t = vec4(0.0);
        for (uint g = 0u; g < gl_NumSubgroups; g++) t += s_sum[li * TRACK_ICP_LOCAL_MAX + g];
        partial.w[base + 4u * li] = t.x, partial.w[base + 4u * li + 1u] = t.y;
        partial.w[base + 4u * li + 2u] = t.z, partial.w[base + 4u * li + 3u] = t.w;
    }
#else
    /* Shared-memory tree reduction (L is a power of two). */
    s_sum[0u * TRACK_ICP_LOCAL_MAX + li] = A.s0, s_sum[1u * TRACK_ICP_LOCAL_MAX + li] = A.s1;
    s_sum[2u * TRACK_ICP_LOCAL_MAX + li] = A.s2, s_sum[3u * TRACK_ICP_LOCAL_MAX + li] = A.s3;
    s_sum[4u * TRACK_ICP_LOCAL_MAX + li] = A.s4, s_sum[5u * TRACK_ICP_LOCAL_MAX + li] = A.s5;
    s_sum[6u * TRACK_ICP_LOCAL_MAX + li] = A.s6, s_sum[7u * TRACK_ICP_LOCAL_MAX + li] = A.s7;
    s_sum[8u * TRACK_ICP_LOCAL_MAX + li] = A.s8;
    for (uint s = L / 2u; s > 0u; s >>= 1) {
        barrier();
        if (li < s)
            for (uint q = 0u; q < 9u; q++)
                s_sum[q * TRACK_ICP_LOCAL_MAX + li] += s_sum[q * TRACK_ICP_LOCAL_MAX + li + s];
    }
    barrier();
    if (li < 9u) {
        vec4 t = s_sum[li * TRACK_ICP_LOCAL_MAX];
        partial.w[base + 4u * li] = t.x, partial.w[base + 4u * li + 1u] = t.y;
        partial.w[base + 4u * li + 2u] = t.z, partial.w[base + 4u * li + 3u] = t.w;
    }
#endif
}
