/* Colour of exported vertices and points: the map's colour (hostmap.rgb565)
 * of the finest confident voxel holding the point, or, where that voxel has
 * none (colour is kept only near the surface, where frames saw it), the
 * mean of the coloured voxels of the same level around it: its 3x3x3
 * neighbourhood, else its 5x5x5 one (a surface voxel no frame coloured
 * whose nearest colour lies two voxels along the surface: the colour trim,
 * docs/colour.md, keeps none off the surface to borrow from). */
#include <math.h>
#include <stdlib.h>

#include "export_int.h"
#include "shaders/fusion.glsl.h"

/* RGB565 of level-L global voxel v, 0 when it has none or no brick holds it. */
static uint32_t voxel_colour(const export__grid *g, uint32_t level, const int64_t v[3])
{
    int64_t b[3] = {export__shr(v[0], 3), export__shr(v[1], 3), export__shr(v[2], 3)};
    uint32_t idx = export__grid_find(g, level, b);
    if (idx == EXPORT__NONE) return 0;
    uint32_t x = (uint32_t)(v[0] & 7), y = (uint32_t)(v[1] & 7), z = (uint32_t)(v[2] & 7);
    return g->s->rgb565[(size_t)idx * BRICK_VOXELS + x + 8 * y + 64 * z];
}

typedef struct colour_job {
    const export__grid *g;
    mesh_data *m;
} colour_job;

static void colour_one(void *ctx, size_t i)
{
    const colour_job *j = ctx;
    const export__grid *g = j->g;
    const float *p = j->m->xyz + 3 * i;
    /* Vertices are relative to the mesh's local origin (mesh_data.origin). */
    bf_vec3 shift = bf_v3_sub(j->m->origin, g->s->origin_w);
    int64_t q[3] = {(int64_t)floor(((double)p[0] + shift.x) / g->half_m),
                    (int64_t)floor(((double)p[1] + shift.y) / g->half_m),
                    (int64_t)floor(((double)p[2] + shift.z) / g->half_m)};
    uint8_t *o = j->m->rgb + 3 * i;
    export__voxel vx;
    uint32_t c = 0;
    if (export__grid_sample(g, q, &vx)) {
        c = g->s->rgb565[(size_t)vx.brick * BRICK_VOXELS + vx.x + 8 * vx.y + 64 * vx.z];
        for (int r = 1; c == 0 && r <= 2; r++) {
            uint32_t sum[3] = {0, 0, 0}, n = 0;
            for (int dz = -r; dz <= r; dz++)
                for (int dy = -r; dy <= r; dy++)
                    for (int dx = -r; dx <= r; dx++) {
                        if (r == 2 && abs(dx) < 2 && abs(dy) < 2 && abs(dz) < 2) continue; /* none there */
                        int64_t v[3] = {vx.g[0] + dx, vx.g[1] + dy, vx.g[2] + dz};
                        uint32_t cn = voxel_colour(g, vx.level, v);
                        if (!cn) continue;
                        sum[0] += bf_565_r(cn), sum[1] += bf_565_g(cn), sum[2] += bf_565_b(cn);
                        n++;
                    }
            if (n) {
                for (int k = 0; k < 3; k++) o[k] = (uint8_t)((sum[k] + n / 2) / n);
                return;
            }
        }
    }
    if (c == 0) { /* nothing seen: a neutral grey, as an uncoloured export */
        o[0] = o[1] = o[2] = 160;
        return;
    }
    o[0] = (uint8_t)bf_565_r(c), o[1] = (uint8_t)bf_565_g(c), o[2] = (uint8_t)bf_565_b(c);
}

bf_status export__colourise(const export__grid *g, mesh_data *m)
{
    if (!g->s->rgb565 || m->n_verts == 0) return BF_OK;
    m->rgb = bf_malloc((size_t)m->n_verts * 3);
    if (!m->rgb) return bf_fail(BF_NO_MEMORY, "export: colour of %u vertices", m->n_verts);
    colour_job job = {g, m};
    bf_parallel_for(m->n_verts, colour_one, &job);
    return BF_OK;
}
