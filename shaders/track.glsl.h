/* Camera tracking, as both C and GLSL see it (DESIGN.md section 6;
 * Newcombe et al. 2011 KinectFusion for the pyramids and projective
 * point-to-plane ICP, Low 2004 for the linearisation, Chambolle 2004 and
 * Reichl's dissertation ch. 8 for the depth-adapted ROF filter).
 *
 * Images are row-major float depth in metres (0 = none). A pyramid buffer
 * holds its TRACK_MAX_LEVELS levels one after the other; level l is
 * (width >> l) x (height >> l) pixels and starts at the pixel offset given
 * in the push constants. Normal maps are one uint per pixel, the unit
 * normal facing the camera in octahedral coordinates as two snorm16
 * (track_oct_encode), 0 where there is none (0 decodes to +z, which never
 * faces the camera). There are no vertex maps: a vertex is the pixel's
 * depth back-projected, and on lavapipe every loaded component costs a
 * bounds-checked load per lane, so ICP reads 4 words per pixel instead of
 * 16. The ROF dual field is vec2 per pixel.
 *
 * The image kernels (track_depth, track_pyrdown, track_smooth, track_vn,
 * track_rof, track_rof_primal) read and write the pyramids through their
 * device addresses in the push constants (track_image_push; on lavapipe a
 * storage-buffer access at a per-lane index is a scalar loop over the lanes,
 * one through an address a gather: gpu_buffer_address), and bind
 *   0 raw      input: u16 depth two per word (low half first), or float bits,
 *              from word raw_off (a frame in fusion's incoming slot)
 *   1 counters TRACK_CNT_* (uint)
 * The ICP kernel (push constants full) reads the same addresses from
 * binding 0, TRACK_ADDR_* (uvec2 each); binding 1 is the partial sums
 * (TRACK_PARTIAL_WORDS floats per workgroup).
 *
 * Intensity pyramids (the photometric term) are float luma in [0, 1] per
 * pixel of the depth pyramid's geometry, TRACK_NO_INTENSITY where the pixel
 * has no depth or its colour is outside the colour image. The intensity
 * kernel (track_intensity.comp): 0 the frame's RGB565 colour (two per word,
 * the depth image's size, from word raw_off), 1 the frame's depth pyramid,
 * 2 the intensity pyramid written.
 */
#ifndef BF_TRACK_GLSL_H
#define BF_TRACK_GLSL_H

#ifdef BF_GLSL
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_buffer_reference_uvec2 : require
#endif
#include "bf_common.glsl.h"

#define TRACK_LEVELS 3u
#define TRACK_IMAGE_BUFFERS 2u
/* The image kernels' workgroups: TRACK_IMAGE_TILE^2 invocations, each taking
 * TRACK_IMAGE_PX pixels TRACK_IMAGE_TILE apart in x (neighbouring lanes stay
 * neighbouring pixels). On lavapipe every 8 invocations cost about 16
 * integer divisions (their local indices from the workgroup's size), more
 * than these kernels' own work on a pixel: 8 pixels share them (the
 * finest level's depth pass 1.7 -> 0.7 ms on the 2-core machine). */
#define TRACK_IMAGE_TILE 8u
#define TRACK_IMAGE_PX 8u
#define TRACK_ICP_BUFFERS 2u
#define TRACK_INTENSITY_BUFFERS 3u
#define TRACK_NO_INTENSITY (-1.0f)

/* The ICP's address table (binding 0): the device address of each buffer it
 * reads per pixel. */
#define TRACK_ADDR_FRAME_DEPTH 0u
#define TRACK_ADDR_FRAME_NORMAL 1u
#define TRACK_ADDR_REF_DEPTH 2u
#define TRACK_ADDR_REF_NORMAL 3u
#define TRACK_ADDR_FRAME_INT 4u
#define TRACK_ADDR_REF_INT 5u
#define TRACK_ADDRS 6u

/* Counters (uint words of the counters buffer). */
#define TRACK_CNT_FRAME_VALID 0u /* valid depth pixels of the frame, finest level */
#define TRACK_CNT_REF_VALID 1u   /* valid depth pixels of the reference, finest level */
#define TRACK_CNT_WORDS 4u


/* Input modes of track_depth. */
#define TRACK_RAW_U16 0u      /* raw binding: u16 sensor units, two per word */
#define TRACK_RAW_F32 1u      /* raw binding: float metres */
#define TRACK_RAW_IN_PLACE 2u /* the depth level itself (float metres written there by the ray-cast) */

/* ------------------------------------------------------------ ICP sums
 * One workgroup's partial sums of the point-to-plane system (Low 2004):
 * per inlier the row a = (n, p x n) and residual r = n . (p - q), with p
 * the frame's point moved into the reference camera, q, n the reference's
 * vertex and normal. The CPU adds the partials in double. */
#define TRACK_SUM_ATA 0u       /* 21 words: upper triangle of sum a a^T, row by row */
#define TRACK_SUM_ATR 21u      /* 6 words: sum a r */
#define TRACK_SUM_RR 27u       /* sum r^2 */
#define TRACK_SUM_INLIERS 28u  /* inliers (a count, exact in float below 2^24 per group) */
#define TRACK_SUM_VALID 29u    /* frame samples with vertex and normal */
#define TRACK_SUM_Z 30u        /* sum of the inliers' depth in the reference camera */
#define TRACK_SUM_RN 31u       /* sum (r / sigma_z)^2 of the inliers: their residuals in the sensor model's units */
#define TRACK_SUM_PHOTO_N 32u  /* photometric rows (the term's inliers) */
#define TRACK_SUM_PHOTO_RR 33u /* sum of their intensity residuals squared */
#define TRACK_SUM_PHOTO_GREF 34u   /* sum |grad I_ref|^2 over the rows where the frame's gradient is known too */
#define TRACK_SUM_PHOTO_GFRAME 35u /* sum |grad I_frame|^2 over the same rows */
#define TRACK_SUMS 36u         /* words summed */
#define TRACK_PARTIAL_WORDS 36u
#define TRACK_ICP_LOCAL_MAX 64u /* invocations per workgroup at most (shared arrays) */

/* Push constants of the image kernels. */
struct track_image_push {
    bf_u32 width, height;   /* of the level written */
    bf_u32 src_off;         /* pixel offset of the level read (pyrdown) */
    bf_u32 dst_off;         /* pixel offset of the level written / read (vn, rof) */
    bf_u32 mode;            /* TRACK_RAW_* (depth) */
    bf_u32 counter;         /* TRACK_CNT_* (depth) */
    bf_f32 unit_m;          /* metres per raw unit (depth, u16 mode) */
    bf_f32 max_depth_m;     /* beyond: invalid (depth) */
    bf_f32 fx, fy, cx, cy;  /* of the level (vn) */
    bf_f32 lambda0;         /* ROF data weight at 1 m */
    bf_f32 tau;             /* ROF step (Chambolle 2004: 1/4) */
    bf_u32 src_width;       /* of the level read (pyrdown) */
    bf_u32 raw_off;         /* word offset of the raw image in binding 0 (depth, TRACK_RAW_U16 / F32) */
    bf_f32 sigma_a, sigma_b, sigma_c; /* the sensor's noise (bf_sensor_sigma; pyrdown, smooth) */
    bf_u32 pad;
    /* Device addresses (low, high word) of the pyramids read and written: */
    bf_u32 depth_lo, depth_hi;   /* depth (float) */
    bf_u32 normal_lo, normal_hi; /* normals (uint, octahedral) */
    bf_u32 p_in_lo, p_in_hi;     /* ROF dual field read (vec2); after the ROF: smoothing scratch (float) */
    bf_u32 p_out_lo, p_out_hi;   /* ROF dual field written (vec2); after the ROF: the depth pyramid
                                    that normals are computed from (float, track_smooth.comp) */
};
#ifndef BF_GLSL
typedef struct track_image_push track_image_push;
_Static_assert(sizeof(track_image_push) == 112, "track_image_push must match std430");
#endif

/* Push constants of the ICP kernel: the frame's pose relative to the
 * reference camera, T_rc (the CPU composes world poses in double and hands
 * over only this, so tracking far from the world origin loses nothing). */
struct track_icp_push {
    bf_f32 R[9];            /* row-major, frame camera -> reference camera */
    bf_f32 t[3];
    bf_f32 fx, fy, cx, cy;  /* of the level */
    bf_u32 size;            /* of the level: width | height << 16 (track_icp_size) */
    bf_u32 off;             /* pixel offset of the level in the pyramids */
    bf_u32 n_threads;       /* workgroups * local size: the pixel loop's stride */
    bf_f32 dist_m;          /* association gates */
    bf_f32 cos_angle;
    bf_u32 sub;             /* 1: every pixel; 2: every second (a checkerboard) */
    bf_f32 huber_k;         /* Huber threshold on r / sigma_z(z); 0: no Huber weights */
    bf_f32 noise_exp;       /* each residual weighted by (sigma_z(1 m) / sigma_z(z))^noise_exp; 0: no noise weights */
    /* The reference's level read: ref_shift levels above the frame's (0:
     * the same level), w x h pixels at pixel offset ref_off; its
     * intrinsics follow from the frame level's (track__level_intrinsics). */
    bf_u32 ref_off, ref_size, ref_shift; /* ref_size: width | height << 16 */
    bf_f32 sigma_a, sigma_b, sigma_c; /* the sensor's noise (bf_sensor_sigma; the weights) */
    /* The photometric term (0: off): each inlier's intensity residual counts
     * with weight photo_w, Huber's weight beyond photo_huber (intensity). */
    bf_f32 photo_w, photo_huber;
};
BF_FN bf_u32 track_icp_size(bf_u32 width, bf_u32 height) { return width | (height << 16); }
#ifndef BF_GLSL
typedef struct track_icp_push track_icp_push;
_Static_assert(sizeof(track_icp_push) == 128, "track_icp_push must match std430");
#endif

/* Push constants of track_intensity.comp: the frame's luma at the finest
 * level from its colour (TRACK_INT_REGISTERED: colour pixel i shows what
 * depth pixel i measured; TRACK_INT_CAMERA: the pixel's point through
 * T_colour_depth (R, t), the colour camera's Brown-Conrady distortion and
 * intrinsics, sampled bilinearly), or a coarser level from the one below
 * (TRACK_INT_DOWN: the mean of the 2x2 block's valid samples). */
#define TRACK_INT_REGISTERED 0u
#define TRACK_INT_CAMERA 1u
#define TRACK_INT_DOWN 2u
struct track_intensity_push {
    bf_f32 R[9];            /* row-major, depth camera -> colour camera */
    bf_f32 t[3];
    bf_f32 fx, fy, cx, cy;  /* the depth camera, finest level */
    bf_f32 cfx, cfy, ccx, ccy; /* the colour camera */
    bf_f32 dist[5];         /* k1 k2 p1 p2 k3, OpenCV's order */
    bf_u32 width, height;   /* of the level written (the colour image is the finest level's size) */
    bf_u32 mode;            /* TRACK_INT_* */
    bf_u32 raw_off;         /* word offset of the colour in binding 0 */
    bf_u32 src_off, dst_off; /* pixel offsets of the level read (down) and written */
    bf_u32 src_width;
};
#ifndef BF_GLSL
typedef struct track_intensity_push track_intensity_push;
_Static_assert(sizeof(track_intensity_push) == 128, "track_intensity_push must match std430");
#endif

/* ------------------------------------------------------------ shared math */

#ifdef BF_GLSL
/* Pyramids read and written through a device address (the push constants'
 * *_lo, *_hi; the ICP's address table). No bounds check: every index stays
 * inside its level. */
layout(buffer_reference, std430, buffer_reference_align = 4) buffer TrackF32 { float v[]; };
layout(buffer_reference, std430, buffer_reference_align = 4) buffer TrackU32 { uint v[]; };
layout(buffer_reference, std430, buffer_reference_align = 8) buffer TrackVec2 { vec2 v[]; };

/* Unit vectors in octahedral coordinates, two snorm16 in a uint (Cigolle
 * et al. 2014, "A survey of efficient representations for independent unit
 * vectors", JCGT 3(2)): about 0.003 degrees of error. */
vec2 track_oct_sign(vec2 v) { return vec2(v.x >= 0.0 ? 1.0 : -1.0, v.y >= 0.0 ? 1.0 : -1.0); }
uint track_oct_encode(vec3 n)
{
    vec2 p = n.xy / (abs(n.x) + abs(n.y) + abs(n.z));
    if (n.z < 0.0) p = (1.0 - abs(p.yx)) * track_oct_sign(p);
    return packSnorm2x16(p);
}
vec3 track_oct_decode(uint w)
{
    vec2 p = unpackSnorm2x16(w);
    vec3 n = vec3(p, 1.0 - abs(p.x) - abs(p.y));
    if (n.z < 0.0) n.xy = (1.0 - abs(n.yx)) * track_oct_sign(n.xy);
    return normalize(n);
}
#endif

/* Pyramid: depths of a 2x2 block within this of the block's nearest depth
 * are averaged (KinectFusion averages within 3 sigma of the centre; a 2x2
 * block has no centre, the nearest sample stands in so that a background
 * sample never drags a foreground edge back). sigma_z: the sensor's noise
 * at that depth (bf_sensor_sigma). */
BF_FN bf_f32 track_block_thresh(bf_f32 sigma_z) { return 3.0f * sigma_z; }

/* Bilateral smoothing of the depth that normals are computed from
 * (track_smooth.comp): radius in pixels, spatial weight exp(-k^2 W) with
 * W = 1 / (2 sigma_s^2), sigma_s = 2 px, and the range sigma 4 sigma_z(z)
 * (the sensor's noise at z, bf_sensor_sigma):
 * wide enough to pass a disparity quantisation step (Kinect v1 at 640x480:
 * 0.0032 z^2, e.g. 2.9 cm at 3 m against 5.6 cm), narrow enough to stop at
 * a real edge of 10 cm or more up to 3 m. */
#define TRACK_SMOOTH_RADIUS 3u
#define TRACK_SMOOTH_SPACE_W 0.125f
BF_FN bf_f32 track_smooth_range(bf_f32 sigma_z) { return 4.0f * sigma_z; }

/* Normals: a neighbour farther than this in depth (per pixel of distance)
 * is across a discontinuity and the normal is invalid: 5% of z allows
 * surfaces up to about 87 degrees from the view direction at 525 px focal
 * length (slope z / f per pixel times tan(theta)) while cutting silhouettes. */
#define TRACK_NORMAL_JUMP_REL 0.05f
/* Half the baseline of the normals' central differences, pixels. */
#define TRACK_NORMAL_STEP 1u

/* ROF data weight lambda(z) = lambda0 z^2 (z in metres, lambda0 at 1 m;
 * docs/tracking.md derives it). The ROF energy is
 *   E(u) = sum |grad u| + sum lambda(f)/2 (u - f)^2
 * on the mask f > 0. A structure of r pixels and depth contrast h is
 * flattened when h < 2 / (lambda r); a surface detail of metric size rho at
 * depth z spans r = rho f / z pixels, so it is flattened below
 * h* = 2 z / (lambda rho f) = 2 / (lambda0 rho f z) with this lambda: near
 * surfaces (many pixels, where the map's ray-cast shows voxel staircases)
 * are smoothed more, far ones (few pixels per structure) keep their shape,
 * as Reichl asks. The weight grows with z^2 like the sensor's noise. */
BF_FN bf_f32 track_rof_lambda(bf_f32 z, bf_f32 lambda0)
{
    BF_PRECISE bf_f32 l = lambda0 * z * z;
    return l;
}

/* Chambolle's semi-implicit dual step (2004, eq. 9) on one pixel:
 * p <- (p + s g) / (1 + s |g|), for one component c of p. */
BF_FN bf_f32 track_rof_step(bf_f32 p, bf_f32 g, bf_f32 s, bf_f32 gnorm)
{
    BF_PRECISE bf_f32 num = p + s * g;
    BF_PRECISE bf_f32 den = 1.0f + s * gnorm;
    return num / den;
}

#endif
