#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fixture.h"

void fx_uv_sphere(mesh_data *m, double r, bf_vec3 c, uint32_t rings, uint32_t segs)
{
    memset(m, 0, sizeof *m);
    m->n_verts = (rings + 1) * segs;
    m->n_tris = 2 * rings * segs;
    m->xyz = malloc(3 * sizeof(float) * m->n_verts);
    m->normal = malloc(3 * sizeof(float) * m->n_verts);
    m->rgb = malloc(3 * (size_t)m->n_verts);
    m->tri = malloc(3 * sizeof(uint32_t) * m->n_tris);
    BF_ASSERT(m->xyz && m->normal && m->rgb && m->tri);
    for (uint32_t i = 0; i <= rings; i++)
        for (uint32_t j = 0; j < segs; j++) {
            /* Rings strictly inside the poles: no degenerate triangles. */
            double th = M_PI * (i + 0.5) / (rings + 1), ph = 2 * M_PI * j / segs;
            double n[3] = {sin(th) * cos(ph), sin(th) * sin(ph), cos(th)};
            uint32_t v = i * segs + j;
            m->xyz[3 * v] = (float)(c.x + r * n[0]);
            m->xyz[3 * v + 1] = (float)(c.y + r * n[1]);
            m->xyz[3 * v + 2] = (float)(c.z + r * n[2]);
            for (int k = 0; k < 3; k++) m->normal[3 * v + k] = (float)n[k];
            m->rgb[3 * v] = (uint8_t)v, m->rgb[3 * v + 1] = (uint8_t)(v >> 8), m->rgb[3 * v + 2] = (uint8_t)(v >> 16);
        }
    uint32_t t = 0;
    for (uint32_t i = 0; i < rings; i++)
        for (uint32_t j = 0; j < segs; j++) {
            uint32_t a = i * segs + j, b = i * segs + (j + 1) % segs, d = a + segs, e = b + segs;
            uint32_t q[6] = {a, d, b, b, d, e};
            memcpy(&m->tri[3 * t], q, sizeof q);
            t += 2;
        }
}

