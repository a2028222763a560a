#version 450
/* Raw depth -> metres, finest level of a depth pyramid (DESIGN.md section
 * 1, preprocess): u16 sensor units times unit_m, float metres, or the
 * level's own floats (a ray-cast reference written in place). 0, NaN, infinite, negative or beyond max_depth_m
 * become 0 (no depth). Counts the valid pixels into counters[pc.counter]:
 * one atomic per subgroup
 * (subgroup arithmetic is required: lavapipe has it, and a shared counter
 * costs a barrier and an atomic per lane there). */
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#include "track.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

layout(std430, binding = 0) readonly buffer Raw { uint w[]; } raw;
layout(std430, binding = 1) buffer Counters { uint c[]; } counters;

layout(push_constant) uniform Push { track_image_push pc; };

/* Converts pixel (x, y); true where it has a depth. */
bool depth_pixel(uint x, uint y, TrackF32 depth)
{
    if (x >= pc.width || y >= pc.height) return false;
    uint i = y * pc.width + x;
    float z;
    if (pc.mode == TRACK_RAW_U16) {
        uint v = (raw.w[pc.raw_off + (i >> 1)] >> ((i & 1u) * 16u)) & 0xFFFFu;
        z = float(v) * pc.unit_m;
    } else if (pc.mode == TRACK_RAW_F32) {
        z = uintBitsToFloat(raw.w[pc.raw_off + i]);
    } else {
        z = depth.v[pc.dst_off + i]; /* each invocation reads and writes only its own pixel */
    }
    /* The comparison is false for NaN; isinf / isnan guard drivers that
     * assume finite math. */
    bool ok = z > 0.0 && z <= pc.max_depth_m && !isnan(z) && !isinf(z);
    depth.v[pc.dst_off + i] = ok ? z : 0.0;
    return ok;
}

void main()
{
    /* TRACK_IMAGE_PX pixels per invocation (track.glsl.h says why). */
    TrackF32 depth = TrackF32(uvec2(pc.depth_lo, pc.depth_hi));
    uint x0 = gl_WorkGroupID.x * (TRACK_IMAGE_TILE * TRACK_IMAGE_PX) + gl_LocalInvocationID.x;
    uint n_ok = 0u;
    for (uint j = 0u; j < TRACK_IMAGE_PX; j++)
        if (depth_pixel(x0 + j * TRACK_IMAGE_TILE, gl_GlobalInvocationID.y, depth)) n_ok++;
    uint n = subgroupAdd(n_ok);
    if (subgroupElect() && n != 0u) atomicAdd(counters.c[pc.counter], n);
}
