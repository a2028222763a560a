/* Definitions shared by C and GLSL (STYLE.md section 4). glslc compiles
 * shaders with -DBF_GLSL=1; C never defines BF_GLSL. Shared functions are
 * pure (values in, value out) and use only the macros below, so one body
 * serves both sides and a GPU test can compare them bit for bit. */
#ifndef BF_COMMON_GLSL_H
#define BF_COMMON_GLSL_H

#ifdef BF_GLSL
#  define BF_FN
#  define bf_u32 uint
#  define bf_i32 int
#  define bf_f32 float
#  define bf_popcount(x) uint(bitCount(x))
/* No fused multiply-add or reassociation: C (ISO mode, -ffp-contract=off)
 * and GLSL then round every float operation the same way. */
#  define BF_PRECISE precise
#  define BF_U32(x) uint(x)
#  define BF_I32(x) int(x)
#  define BF_F32(x) float(x)
/* Float to integer, truncating, for a value known to lie within +-2^22
 * (pixel, voxel, cell and chunk coordinates; a value beyond is clamped).
 * llvmpipe (Mesa 25, LLVM 15) compiles every float-to-int conversion,
 * int() or uint(), as a scalar loop over the lanes with two compares and
 * two selects per lane; this uses vector operations only (the fusion
 * window pass 22% faster, docs/gpu.md). Adding 1.5 * 2^23 puts an
 * integer-valued float of that range into the mantissa exactly, and the
 * bits give it back: for |x| < 2^22 the same integer as int(x), so the C
 * side stays a plain cast. */
int bf_trunc_i32(float x) { return floatBitsToInt(clamp(trunc(x), -4194304.0, 4194303.0) + 12582912.0) - 0x4B400000; }
ivec2 bf_trunc_i32(vec2 x) { return floatBitsToInt(clamp(trunc(x), -4194304.0, 4194303.0) + 12582912.0) - 0x4B400000; }
ivec3 bf_trunc_i32(vec3 x) { return floatBitsToInt(clamp(trunc(x), -4194304.0, 4194303.0) + 12582912.0) - 0x4B400000; }
#  define BF_TRUNC_I32(x) bf_trunc_i32(x)
#  define BF_TRUNC_U32(x) uint(bf_trunc_i32(x))
#else
#  include <stdbool.h>
#  include <stdint.h>
#  define BF_FN static inline
typedef uint32_t bf_u32;
typedef int32_t bf_i32;
typedef float bf_f32;
#  define bf_popcount(x) ((bf_u32)__builtin_popcount(x))
#  define BF_PRECISE
#  define BF_U32(x) ((bf_u32)(x))
#  define BF_I32(x) ((bf_i32)(x))
#  define BF_F32(x) ((bf_f32)(x))
#  define BF_TRUNC_I32(x) ((bf_i32)(x))
#  define BF_TRUNC_U32(x) ((bf_u32)(x))
#endif

/* Specialization constant ids: 0..2 carry the workgroup size chosen on the
 * host from the device limits (gpu_pipeline_desc.local_size); a shader's own
 * constants start at BF_SPEC_USER. */
#define BF_SPEC_LOCAL_SIZE_X 0
#define BF_SPEC_LOCAL_SIZE_Y 1
#define BF_SPEC_LOCAL_SIZE_Z 2
#define BF_SPEC_USER 3
#ifdef BF_GLSL
#  define BF_LOCAL_SIZE_FROM_SPEC \
    layout(local_size_x_id = 0, local_size_y_id = 1, local_size_z_id = 2) in;
/* An invocation's place along a one-dimensional dispatch of
 * gpu_cmd_dispatch_linear, which spreads its groups over x and y: a device
 * allows only so many along x (65535 on Mesa's drivers). */
#  define BF_LINEAR_INDEX \
    ((gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * gl_WorkGroupSize.x + gl_LocalInvocationID.x)
#endif

/* ------------------------------------------------------------ the sensor */

/* Axial depth noise sigma(z) = a + b (z - c)^2 [m] (Nguyen, Izadi, Lovell
 * 2012), with a, b, c from the one bf_sensor (core/core.h) that fusion and
 * tracking both receive. */
BF_FN bf_f32 bf_sensor_sigma(bf_f32 z, bf_f32 a, bf_f32 b, bf_f32 c)
{
    BF_PRECISE bf_f32 d = z - c;
    BF_PRECISE bf_f32 s = a + b * d * d;
    return s;
}

/* ------------------------------------------------------------ colour cameras */

/* Channels of an RGB565 colour in [0, 255] (bit replication). */
BF_FN bf_u32 bf_565_r(bf_u32 c) { return (((c >> 11) & 31u) << 3) | (((c >> 11) & 31u) >> 2); }
BF_FN bf_u32 bf_565_g(bf_u32 c) { return (((c >> 5) & 63u) << 2) | (((c >> 5) & 63u) >> 4); }
BF_FN bf_u32 bf_565_b(bf_u32 c) { return ((c & 31u) << 3) | ((c & 31u) >> 2); }
/* Luma of an RGB565 colour in [0, 1] (ITU-R BT.601 weights, as OpenCV's
 * RGB2GRAY): the photometric term of tracking compares these. */
BF_FN bf_f32 bf_565_luma(bf_u32 c)
{
    return (0.299f * BF_F32(bf_565_r(c)) + 0.587f * BF_F32(bf_565_g(c)) + 0.114f * BF_F32(bf_565_b(c))) / 255.0f;
}

/* Brown-Conrady distortion of the normalised image point (x, y) = (X/Z,
 * Y/Z), as OpenCV's projectPoints and calib/'s calib_distort apply it:
 * radial 1 + k1 r2 + k2 r2^2 + k3 r2^3, tangential 2 p1 x y + p2 (r2 +
 * 2 x^2) and p1 (r2 + 2 y^2) + 2 p2 x y. */
BF_FN bf_f32 bf_distort_x(bf_f32 x, bf_f32 y, bf_f32 k1, bf_f32 k2, bf_f32 p1, bf_f32 p2, bf_f32 k3)
{
    bf_f32 r2 = x * x + y * y;
    return x * (1.0f + r2 * (k1 + r2 * (k2 + r2 * k3))) + 2.0f * p1 * x * y + p2 * (r2 + 2.0f * x * x);
}
BF_FN bf_f32 bf_distort_y(bf_f32 x, bf_f32 y, bf_f32 k1, bf_f32 k2, bf_f32 p1, bf_f32 p2, bf_f32 k3)
{
    bf_f32 r2 = x * x + y * y;
    return y * (1.0f + r2 * (k1 + r2 * (k2 + r2 * k3))) + p1 * (r2 + 2.0f * y * y) + 2.0f * p2 * x * y;
}

/* ------------------------------------------------------------ bricks */

/* A brick is 8x8x8 voxels, one bit per voxel in each bit plane (sign,
 * confidence): 16 words of 32 bits, each word a 4x4x2 sub-brick
 * (Reichl 2016, ch. 8; DESIGN.md section 3). */
#define BRICK_EDGE 8u
#define BRICK_VOXELS 512u
#define BRICK_WORDS 16u

/* Word of voxel (x, y, z), each in [0, 8). */
BF_FN bf_u32 brick_word(bf_u32 x, bf_u32 y, bf_u32 z) { return (z >> 1) * 4u + (y >> 2) * 2u + (x >> 2); }
/* Bit of voxel (x, y, z) inside its word. */
BF_FN bf_u32 brick_bit(bf_u32 x, bf_u32 y, bf_u32 z) { return (z & 1u) * 16u + (y & 3u) * 4u + (x & 3u); }
/* Set bits below bit i (in [0, 32)) of w: the voxel's colour slot. */
BF_FN bf_u32 brick_rank(bf_u32 w, bf_u32 i) { return bf_popcount(w & ((1u << i) - 1u)); }

#endif
