/* Closed meshes the tests make themselves (no shared data needed). */
#ifndef BF_TEST_MESH_SHAPES_H
#define BF_TEST_MESH_SHAPES_H

#include <math.h>
#include <stdlib.h>

#include "mesh/mesh.h"

/* A closed torus around the z axis (radii R, r; nu x nv quads split in two),
 * outward normals; free with mesh_free. */
static inline mesh_data test_torus(double R, double r, uint32_t nu, uint32_t nv)
{
    mesh_data m = {0};
    m.n_verts = nu * nv, m.n_tris = 2 * nu * nv;
    m.xyz = malloc((size_t)m.n_verts * 12);
    m.tri = malloc((size_t)m.n_tris * 12);
    for (uint32_t i = 0; i < nu; i++)
        for (uint32_t j = 0; j < nv; j++) {
            double u = 2 * M_PI * i / nu, v = 2 * M_PI * j / nv;
            float *p = m.xyz + 3 * (size_t)(i * nv + j);
            p[0] = (float)((R + r * cos(v)) * cos(u)), p[1] = (float)((R + r * cos(v)) * sin(u));
            p[2] = (float)(r * sin(v));
            uint32_t a = i * nv + j, b = ((i + 1) % nu) * nv + j, c = ((i + 1) % nu) * nv + (j + 1) % nv,
                     d = i * nv + (j + 1) % nv;
            uint32_t *t = m.tri + 6 * (size_t)(i * nv + j);
            t[0] = a, t[1] = b, t[2] = c, t[3] = a, t[4] = c, t[5] = d;
        }
    return m;
}

/* A closed axis-aligned box [lo, hi] (12 triangles, outward normals); free
 * with mesh_free. */
static inline mesh_data test_box(const double lo[3], const double hi[3])
{
    static const uint32_t quads[6][4] = {{0, 1, 3, 2}, {4, 6, 7, 5}, {0, 4, 5, 1}, {2, 3, 7, 6}, {0, 2, 6, 4}, {1, 5, 7, 3}};
    mesh_data m = {0};
    m.n_verts = 8, m.n_tris = 12;
    m.xyz = malloc(8 * 12);
    m.tri = malloc(12 * 12);
    for (uint32_t k = 0; k < 8; k++) /* corner k: x from bit 2, y from bit 1, z from bit 0 */
        for (int a = 0; a < 3; a++) m.xyz[3 * k + a] = (float)((k >> (2 - a) & 1) ? hi[a] : lo[a]);
    for (uint32_t f = 0; f < 6; f++) {
        const uint32_t *q = quads[f];
        uint32_t *t = m.tri + 6 * f;
        t[0] = q[0], t[1] = q[1], t[2] = q[2], t[3] = q[0], t[4] = q[2], t[5] = q[3];
    }
    return m;
}

#endif
