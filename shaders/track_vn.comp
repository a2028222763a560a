#version 450
/* Normal map of one pyramid level (KinectFusion, Newcombe et al. 2011,
 * sec. 3.2): the cross product of the central differences of the
 * back-projected neighbours left-right and up-down of the bilaterally
 * smoothed depth (track_smooth.comp), facing the camera, packed in
 * octahedral coordinates (track.glsl.h). It is invalid (0) where a
 * neighbour is missing, outside the image, or across a depth
 * discontinuity (TRACK_NORMAL_JUMP_REL); ICP uses only pixels with a depth
 * and a normal. Vertices are not stored: ICP back-projects the depth.
 * mode 1 (the finest level): each pixel takes its parent's normal on the
 * level above (pc.src_off, pc.src_width) where the two depths agree. */
#extension GL_GOOGLE_include_directive : require
#include "track.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC


layout(push_constant) uniform Push { track_image_push pc; };

vec3 unproject(uint x, uint y, float z)
{
    return vec3((float(x) - pc.cx) * z / pc.fx, (float(y) - pc.cy) * z / pc.fy, z);
}

void vn_pixel(uint x, uint y)
{
    if (x >= pc.width || y >= pc.height) return;
    uint i = y * pc.width + x;
    uint o = pc.dst_off;
    TrackF32 depth = TrackF32(uvec2(pc.depth_lo, pc.depth_hi));
    TrackF32 smoothed = TrackF32(uvec2(pc.p_out_lo, pc.p_out_hi)); /* track_smooth.comp's output */
    TrackU32 normal = TrackU32(uvec2(pc.normal_lo, pc.normal_hi));
    float z = depth.v[o + i];
    uint n = 0u;
    if (pc.mode == 1u) {
        /* The finest level's normal from its parent pixel on the level
         * above (pc.src_off, pc.src_width) where the depths agree: no
         * full-resolution smoothing, and the parent's normal spans twice
         * the baseline, which averages more of the disparity staircase.
         * An odd width or height leaves the last column or row without a
         * parent (level 1 is (w >> 1) x (h >> 1)): no normal there. */
        uint px = x >> 1, py = y >> 1;
        if (px < pc.src_width && py < (pc.height >> 1)) {
            uint j = pc.src_off + py * pc.src_width + px;
            float zp = depth.v[j];
            if (z > 0.0 && zp > 0.0 && abs(z - zp) <= 2.0 * TRACK_NORMAL_JUMP_REL * z) n = normal.v[j];
        }
        normal.v[o + i] = n;
        return;
    }
    /* Differences over +-TRACK_NORMAL_STEP pixels: a wider baseline
     * averages what is left of the quantisation staircase. */
    uint r = TRACK_NORMAL_STEP;
    if (z > 0.0 && x >= r && y >= r && x + r < pc.width && y + r < pc.height) {
        float zl = smoothed.v[o + i - r], zr = smoothed.v[o + i + r];
        float zu = smoothed.v[o + i - r * pc.width], zd = smoothed.v[o + i + r * pc.width];
        float jump = 2.0 * float(r) * TRACK_NORMAL_JUMP_REL * z;
        bool ok = zl > 0.0 && zr > 0.0 && zu > 0.0 && zd > 0.0 && abs(zr - zl) <= jump && abs(zd - zu) <= jump;
        if (ok) {
            vec3 dx = unproject(x + r, y, zr) - unproject(x - r, y, zl);
            vec3 dy = unproject(x, y + r, zd) - unproject(x, y - r, zu);
            vec3 c = cross(dx, dy);
            float len = length(c);
            if (len > 0.0) {
                c /= len;
                if (dot(c, unproject(x, y, z)) > 0.0) c = -c;
                n = track_oct_encode(c);
            }
        }
    }
    normal.v[o + i] = n;
}

void main()
{
    /* TRACK_IMAGE_PX pixels per invocation (track.glsl.h says why). */
    uint x0 = gl_WorkGroupID.x * (TRACK_IMAGE_TILE * TRACK_IMAGE_PX) + gl_LocalInvocationID.x;
    for (uint j = 0u; j < TRACK_IMAGE_PX; j++) vn_pixel(x0 + j * TRACK_IMAGE_TILE, gl_GlobalInvocationID.y);
}
