#version 450
/* Mesh voxelisation (render.glsl.h, "mesh voxelisation"): for each brick
 * of the list, the crossings of its triangles with the 64 columns of voxel
 * centres along +z: one invocation a brick takes its triangles in turn and
 * XORs their flips into the brick's 16 words.
 * Coordinates are relative to the brick's low corner, in voxels, so float
 * keeps sub-voxel precision however far the brick is from the origin. */
#extension GL_GOOGLE_include_directive : require
#include "render.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

layout(std430, binding = 0) readonly buffer Tris { float v[]; } tris;     /* 3 corners x y z per triangle, map metres */
layout(std430, binding = 1) readonly buffer Bricks { uint w[]; } bricks; /* RENDER_VOX_BRICK_WORDS per brick */
layout(std430, binding = 2) readonly buffer TriIds { uint i[]; } tri_ids;
layout(std430, binding = 3) writeonly buffer Out { uint w[]; } outw;      /* RENDER_VOX_OUT_WORDS per brick */

layout(push_constant) uniform Push { render_vox_push pc; };

/* One invocation a brick: after the host's culling a brick's list holds
 * only triangles whose xy box holds one of its column centres (tens at
 * most, a few where triangles are larger than voxels), and a workgroup a
 * brick cost lavapipe more to start than the brick's work. Each
 * invocation keeps its brick's words in its own row of shared memory. */
shared uint s_w[gl_WorkGroupSize.x * RENDER_VOX_OUT_WORDS];

/* Corner j of triangle tri in voxel units relative to the brick's low corner lo (metres). */
vec3 corner(uint tri, uint j, vec3 lo, float voxel_m)
{
    uint o = 9u * tri + 3u * j;
    return (vec3(tris.v[o], tris.v[o + 1u], tris.v[o + 2u]) - lo) / voxel_m;
}

void main()
{
    uint b = (gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * gl_WorkGroupSize.x + gl_LocalInvocationID.x;
    if (b >= pc.n_bricks) return; /* no barrier below */
    uint row = gl_LocalInvocationID.x * RENDER_VOX_OUT_WORDS;
    for (uint i = 0u; i < RENDER_VOX_OUT_WORDS; i++) s_w[row + i] = 0u;
    ivec3 B = ivec3(int(bricks.w[b * RENDER_VOX_BRICK_WORDS]), int(bricks.w[b * RENDER_VOX_BRICK_WORDS + 1u]),
                    int(bricks.w[b * RENDER_VOX_BRICK_WORDS + 2u]));
    uint first = bricks.w[b * RENDER_VOX_BRICK_WORDS + 3u], last = bricks.w[b * RENDER_VOX_BRICK_WORDS + 4u];
    /* Bricks of every level in one list (level of detail); a power-of-two division is exact. */
    float voxel_m = pc.chunk_m / float(8u << bricks.w[b * RENDER_VOX_BRICK_WORDS + 5u]);
    vec3 lo = vec3(B * 8) * voxel_m;
    for (uint k = first; k < last; k++) {
        uint tri = tri_ids.i[k];
        vec3 a = corner(tri, 0u, lo, voxel_m), c1 = corner(tri, 1u, lo, voxel_m), c2 = corner(tri, 2u, lo, voxel_m);
        /* Counter-clockwise in xy; a triangle seen edge-on crosses nothing. */
        float area = (c1.x - a.x) * (c2.y - a.y) - (c1.y - a.y) * (c2.x - a.x);
        if (area == 0.0) continue;
        if (area < 0.0) {
            vec3 tmp = c1;
            c1 = c2;
            c2 = tmp;
            area = -area;
        }
        /* Columns whose centres (i + 0.5) can lie in the projection. */
        vec2 mn = min(a.xy, min(c1.xy, c2.xy)), mx = max(a.xy, max(c1.xy, c2.xy));
        ivec2 c_lo = max(ivec2(ceil(mn - 0.5)), ivec2(0)), c_hi = min(ivec2(floor(mx - 0.5)), ivec2(7));
        for (int cy = c_lo.y; cy <= c_hi.y; cy++)
            for (int cx = c_lo.x; cx <= c_hi.x; cx++) {
                float px = float(cx) + 0.5, py = float(cy) + 0.5;
                float e0 = render_edge(c1.x, c1.y, c2.x, c2.y, px, py);
                float e1 = render_edge(c2.x, c2.y, a.x, a.y, px, py);
                float e2 = render_edge(a.x, a.y, c1.x, c1.y, px, py);
                bool in0 = e0 > 0.0 || (e0 == 0.0 && render_edge_owns(c1.x, c1.y, c2.x, c2.y));
                bool in1 = e1 > 0.0 || (e1 == 0.0 && render_edge_owns(c2.x, c2.y, a.x, a.y));
                bool in2 = e2 > 0.0 || (e2 == 0.0 && render_edge_owns(a.x, a.y, c1.x, c1.y));
                if (!(in0 && in1 && in2)) continue;
                float z = (e0 * a.z + e1 * c1.z + e2 * c2.z) / area;
                /* The crossing belongs to the brick whose z range holds it. */
                if (!(z >= 0.0 && z < 8.0)) continue;
                /* Voxel centres k + 0.5 above z flip (a centre on the surface is outside):
                 * the column's voxels of heights 2j and 2j + 1 are bits b and b + 16 of word w0 + 4j. */
                int k0 = int(ceil(z - 0.5));
                if (z - 0.5 == float(k0)) k0++;
                uint w0 = brick_word(uint(cx), uint(cy), 0u), bit = brick_bit(uint(cx), uint(cy), 0u);
                for (int j = max(k0, 0) >> 1; j < 4; j++)
                    s_w[row + w0 + 4u * uint(j)] ^= (2 * j >= k0 ? 1u << bit : 0u) | (1u << (bit + 16u));
                uint col = uint(cx) + 8u * uint(cy);
                s_w[row + BRICK_WORDS + (col >> 5)] ^= 1u << (col & 31u);
            }
    }
    for (uint i = 0u; i < RENDER_VOX_OUT_WORDS; i++) outw.w[b * RENDER_VOX_OUT_WORDS + i] = s_w[row + i];
}
