#version 450
/* Mesh voxelisation (render.glsl.h, "mesh voxelisation"): for each brick
 * of the list, the crossings of its triangles with the 64 columns of voxel
 * centres along +z: each invocation takes one triangle at a time and XORs
 * its flips into the brick's 16 words in shared memory.
 * Coordinates are relative to the brick's low corner, in voxels, so float
 * keeps sub-voxel precision however far the brick is from the origin. */
#extension GL_GOOGLE_include_directive : require
#include "render.glsl.h"

BF_LOCAL_SIZE_FROM_SPEC

layout(std430, binding = 0) readonly buffer Verts { float v[]; } verts;  /* x y z per vertex, map metres */
layout(std430, binding = 1) readonly buffer Tris { uint i[]; } tris;     /* 3 vertex indices per triangle */
layout(std430, binding = 2) readonly buffer Bricks { uint w[]; } bricks; /* RENDER_VOX_BRICK_WORDS per brick */
layout(std430, binding = 3) readonly buffer TriIds { uint i[]; } tri_ids;
layout(std430, binding = 4) writeonly buffer Out { uint w[]; } outw;      /* RENDER_VOX_OUT_WORDS per brick */

layout(push_constant) uniform Push { render_vox_push pc; };

shared uint s_flip[BRICK_WORDS];
shared uint s_par[2];

/* Vertex k in voxel units relative to the brick's low corner lo (metres). */
vec3 vertex(uint k, vec3 lo, float voxel_m)
{
    return (vec3(verts.v[3u * k], verts.v[3u * k + 1u], verts.v[3u * k + 2u]) - lo) / voxel_m;
}

void main()
{
    uint b = gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x;
    if (b >= pc.n_bricks) return; /* uniform */
    uint t = gl_LocalInvocationID.x;
    if (t < BRICK_WORDS) s_flip[t] = 0u;
    if (t < 2u) s_par[t] = 0u;
    barrier();
    ivec3 B = ivec3(int(bricks.w[b * RENDER_VOX_BRICK_WORDS]), int(bricks.w[b * RENDER_VOX_BRICK_WORDS + 1u]),
                    int(bricks.w[b * RENDER_VOX_BRICK_WORDS + 2u]));
    uint first = bricks.w[b * RENDER_VOX_BRICK_WORDS + 3u], last = bricks.w[b * RENDER_VOX_BRICK_WORDS + 4u];
    /* Bricks of every level in one list (level of detail); a power-of-two division is exact. */
    float voxel_m = pc.chunk_m / float(8u << bricks.w[b * RENDER_VOX_BRICK_WORDS + 5u]);
    vec3 lo = vec3(B * 8) * voxel_m;
    /* One triangle per invocation at a time, over the columns its xy
     * bounding box covers in the brick (usually one to four): the work
     * follows the triangles' area, not 64 columns per triangle. */
    for (uint k = first + t; k < last; k += gl_WorkGroupSize.x) {
        uint tri = tri_ids.i[k];
        vec3 a = vertex(tris.i[3u * tri], lo, voxel_m), c1 = vertex(tris.i[3u * tri + 1u], lo, voxel_m);
        vec3 c2 = vertex(tris.i[3u * tri + 2u], lo, voxel_m);
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
                /* Voxel centres k + 0.5 above z flip (a centre on the surface is outside). */
                int k0 = int(ceil(z - 0.5));
                if (z - 0.5 == float(k0)) k0++;
                for (int zz = max(k0, 0); zz < 8; zz++)
                    atomicXor(s_flip[brick_word(uint(cx), uint(cy), uint(zz))], 1u << brick_bit(uint(cx), uint(cy), uint(zz)));
                uint col = uint(cx) + 8u * uint(cy);
                atomicXor(s_par[col >> 5], 1u << (col & 31u));
            }
    }
    barrier();
    if (t < BRICK_WORDS) outw.w[b * RENDER_VOX_OUT_WORDS + t] = s_flip[t];
    if (t < 2u) outw.w[b * RENDER_VOX_OUT_WORDS + BRICK_WORDS + t] = s_par[t];
}
