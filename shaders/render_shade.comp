#version 450
/* Second pass of the ray-cast: normals from the depth image by central
 * differences, and the shaded colour (DESIGN.md section 5: deferred
 * shading, normals from depth). Why from depth and not from the sign
 * field's gradient: the gradient of one bit per voxel over a 3x3x3
 * neighbourhood takes 27 lookups (across brick and level borders) per
 * pixel and still only knows a few dozen directions; the refined depth is
 * continuous across a flat surface, costs four reads per pixel, and is the
 * quantity ICP works with, so its normals agree with what tracking sees.
 *
 * The refined depth is flat only per pair of voxels (render.md): on a
 * surface oblique to the voxel grid it steps by up to a voxel from one
 * pair to the next, so the differences span RENDER_NORMAL_VOXELS voxels'
 * footprint (k pixels, 1 <= k <= RENDER_NORMAL_MAX_PX) rather than one
 * pixel: on a plane tilted 35 degrees this halves the normal error.
 *
 * A neighbour counts when it was hit and its depth is within
 * RENDER_EDGE_VOXELS voxels of the pixel's level plus RENDER_EDGE_REL of
 * the depth (else it is across a depth edge); with both neighbours of an
 * axis the difference is central, with one it is one-sided. A pixel with
 * no usable neighbour on an axis gets the normal facing the camera. */
#extension GL_GOOGLE_include_directive : require
#include "fusion.glsl.h"
#include "render.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

layout(std430, binding = 0) readonly buffer Depth { float v[]; } depth_in;
layout(std430, binding = 1) readonly buffer Level { uint v[]; } level_in;
layout(std430, binding = 2) writeonly buffer Normal { vec4 v[]; } normal_out;
layout(std430, binding = 3) writeonly buffer Colour { uint v[]; } colour_out;
layout(std430, binding = 4) readonly buffer SurfaceColour { uint v[]; } rgb_in;

layout(push_constant) uniform Push { render_push pc; };

#define RENDER_EDGE_VOXELS 4.0
#define RENDER_NORMAL_VOXELS 2.0
#define RENDER_NORMAL_MAX_PX 4
#define RENDER_EDGE_REL 0.02

vec3 back_project(int u, int v, float z) { return z * vec3((float(u) - pc.view.cx) / pc.view.fx, (float(v) - pc.view.cy) / pc.view.fy, 1.0); }

/* Depth of pixel (u, v) if it is usable as a neighbour of a pixel at depth
 * z with edge threshold thr, else 0. */
float neighbour(int u, int v, float z, float thr)
{
    if (u < 0 || v < 0 || u >= int(pc.view.width) || v >= int(pc.view.height)) return 0.0;
    float d = depth_in.v[uint(v) * pc.view.width + uint(u)];
    return (d > 0.0 && abs(d - z) <= thr) ? d : 0.0;
}

/* Tangent along one image axis (du, dv) = (1, 0) or (0, 1); false if
 * neither neighbour is usable. */
bool tangent(int u, int v, int du, int dv, float z, float thr, out vec3 t)
{
    float dp = neighbour(u + du, v + dv, z, thr), dm = neighbour(u - du, v - dv, z, thr);
    vec3 c = back_project(u, v, z);
    if (dp > 0.0 && dm > 0.0) t = back_project(u + du, v + dv, dp) - back_project(u - du, v - dv, dm);
    else if (dp > 0.0) t = back_project(u + du, v + dv, dp) - c;
    else if (dm > 0.0) t = c - back_project(u - du, v - dv, dm);
    else return false;
    return true;
}

void main()
{
    uvec2 px = gl_GlobalInvocationID.xy;
    if (px.x >= pc.view.width || px.y >= pc.view.height) return;
    uint pixel = px.y * pc.view.width + px.x;
    float z = depth_in.v[pixel];
    if (!(z > 0.0)) {
        normal_out.v[pixel] = vec4(0.0);
        colour_out.v[pixel] = 0u;
        return;
    }
    uint level = level_in.v[pixel];
    float thr = RENDER_EDGE_VOXELS * fusion_voxel_m(pc.view.chunk_m, min(level, FUSION_MAX_LEVEL)) + RENDER_EDGE_REL * z;

    int u = int(px.x), v = int(px.y);
    vec3 p = back_project(u, v, z);
    vec3 view = normalize(p);
    float voxel = fusion_voxel_m(pc.view.chunk_m, min(level, FUSION_MAX_LEVEL));
    int k = clamp(BF_TRUNC_I32(RENDER_NORMAL_VOXELS * voxel * pc.view.fx / z + 0.5), 1, RENDER_NORMAL_MAX_PX);
    float thr_k = thr * float(k);
    vec3 tx, ty, n;
    if (tangent(u, v, k, 0, z, thr_k, tx) && tangent(u, v, 0, k, z, thr_k, ty)) {
        n = cross(ty, tx); /* x right, y down: cross(y, x) faces the camera */
        float len = length(n);
        n = len > 0.0 ? n / len : -view;
        if (dot(n, view) > 0.0) n = -n;
    } else {
        n = -view;
    }
    normal_out.v[pixel] = vec4(n, 0.0);
    uint c = (pc.flags & RENDER_FLAG_COLOUR) != 0u ? rgb_in.v[pixel] : 0u;
    colour_out.v[pixel] = c != 0u ? render_shade_colour(-dot(n, view), c) : render_shade(-dot(n, view), level);
}
