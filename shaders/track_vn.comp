#version 450
/* Vertex and normal maps of one pyramid level (KinectFusion, Newcombe et
 * al. 2011, sec. 3.2): the vertex back-projects the pixel's depth, the
 * normal is the cross product of the central differences of the vertices
 * left-right and up-down of the bilaterally smoothed depth
 * (track_smooth.comp), facing the camera. It is invalid (all zero) where
 * a neighbour is missing, outside the image, or across a depth
 * discontinuity (TRACK_NORMAL_JUMP_REL); ICP uses only pixels with both. */
#extension GL_GOOGLE_include_directive : require
#include "track.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

layout(std430, binding = 1) readonly buffer Depth { float d[]; } depth;
layout(std430, binding = 6) readonly buffer Smooth { float d[]; } smoothed;
layout(std430, binding = 2) writeonly buffer Vertex { vec4 v[]; } vertex;
layout(std430, binding = 3) writeonly buffer Normal { vec4 v[]; } normal;

layout(push_constant) uniform Push { track_image_push pc; };

vec3 unproject(uint x, uint y, float z)
{
    return vec3((float(x) - pc.cx) * z / pc.fx, (float(y) - pc.cy) * z / pc.fy, z);
}

void main()
{
    uint x = gl_GlobalInvocationID.x, y = gl_GlobalInvocationID.y;
    if (x >= pc.width || y >= pc.height) return;
    uint i = y * pc.width + x;
    uint o = pc.dst_off;
    float z = depth.d[o + i];
    vec4 v = vec4(0.0), n = vec4(0.0);
    if (z > 0.0) {
        v = vec4(unproject(x, y, z), 1.0);
        /* Differences over +-TRACK_NORMAL_STEP pixels: a wider baseline
         * averages what is left of the quantisation staircase. */
        uint r = TRACK_NORMAL_STEP;
        if (x >= r && y >= r && x + r < pc.width && y + r < pc.height) {
            float zl = smoothed.d[o + i - r], zr = smoothed.d[o + i + r];
            float zu = smoothed.d[o + i - r * pc.width], zd = smoothed.d[o + i + r * pc.width];
            float jump = 2.0 * float(r) * TRACK_NORMAL_JUMP_REL * z;
            bool ok = zl > 0.0 && zr > 0.0 && zu > 0.0 && zd > 0.0 && abs(zr - zl) <= jump && abs(zd - zu) <= jump;
            if (ok) {
                vec3 dx = unproject(x + r, y, zr) - unproject(x - r, y, zl);
                vec3 dy = unproject(x, y + r, zd) - unproject(x, y - r, zu);
                vec3 c = cross(dx, dy);
                float len = length(c);
                if (len > 0.0) {
                    c /= len;
                    if (dot(c, v.xyz) > 0.0) c = -c;
                    n = vec4(c, 0.0);
                }
            }
        }
    }
    vertex.v[o + i] = v;
    normal.v[o + i] = n;
}
