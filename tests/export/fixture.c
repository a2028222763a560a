#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fixture.h"
#include "shaders/bf_common.glsl.h"

double fx_sphere_sdf(const void *shape, bf_vec3 p)
{
    const fx_sphere *s = shape;
    return bf_v3_norm(bf_v3_sub(p, s->c)) - s->r;
}

double fx_box_sdf(const void *shape, bf_vec3 p)
{
    const fx_box *b = shape;
    double q[3] = {fabs(p.x - b->c.x) - b->half.x, fabs(p.y - b->c.y) - b->half.y, fabs(p.z - b->c.z) - b->half.z};
    double out = 0, in = fmax(q[0], fmax(q[1], q[2]));
    for (int a = 0; a < 3; a++) out += q[a] > 0 ? q[a] * q[a] : 0;
    return sqrt(out) + (in < 0 ? in : 0);
}

double fx_plane_sdf(const void *shape, bf_vec3 p)
{
    const fx_plane *pl = shape;
    return bf_v3_dot(pl->n, p) - pl->d;
}

double fx_voxel_m(const hostmap *s, uint32_t level) { return (double)s->chunk_m / 8.0 / (double)(1u << level); }

static int64_t floor_div(double x, double step) { return (int64_t)floor(x / step); }

void fx_voxelize(hostmap *s, fx_sdf sdf, const void *shape, uint32_t level, bf_vec3 lo, bf_vec3 hi,
                 double band_vox, fx_pick pick, const void *pick_ctx, bool confident)
{
    double v = fx_voxel_m(s, level), B = 8 * v;
    bf_vec3 o = s->origin_w;
    int64_t b0[3] = {floor_div(lo.x - o.x, B), floor_div(lo.y - o.y, B), floor_div(lo.z - o.z, B)};
    int64_t b1[3] = {floor_div(hi.x - o.x, B), floor_div(hi.y - o.y, B), floor_div(hi.z - o.z, B)};
    int64_t per_chunk = (int64_t)1 << level;
    for (int64_t bz = b0[2]; bz <= b1[2]; bz++)
        for (int64_t by = b0[1]; by <= b1[1]; by++)
            for (int64_t bx = b0[0]; bx <= b1[0]; bx++) {
                bf_vec3 c = bf_v3(o.x + (bx + 0.5) * B, o.y + (by + 0.5) * B, o.z + (bz + 0.5) * B);
                if (fabs(sdf(shape, c)) > B * sqrt(3) / 2 + band_vox * v) continue;
                if (pick && !pick(pick_ctx, c)) continue;
                hostmap_brick br;
                memset(&br, 0, sizeof br);
                int64_t b[3] = {bx, by, bz};
                for (int a = 0; a < 3; a++) {
                    int64_t key = b[a] >= 0 ? b[a] / per_chunk : -((-b[a] + per_chunk - 1) / per_chunk);
                    br.key[a] = (int32_t)key;
                    br.cell[a] = (uint32_t)(b[a] - key * per_chunk);
                }
                br.level = level;
                br.error = 0.001f;
                for (uint32_t z = 0; z < 8; z++)
                    for (uint32_t y = 0; y < 8; y++)
                        for (uint32_t x = 0; x < 8; x++) {
                            bf_vec3 p = bf_v3(o.x + ((bx * 8 + x) + 0.5) * v, o.y + ((by * 8 + y) + 0.5) * v,
                                              o.z + ((bz * 8 + z) + 0.5) * v);
                            uint32_t w = brick_word(x, y, z), bit = 1u << brick_bit(x, y, z);
                            if (sdf(shape, p) >= 0) br.sign[w] |= bit;
                            if (confident) br.conf[w] |= bit;
                        }
                if (s->n_bricks % 1024 == 0) {
                    hostmap_brick *nb = realloc(s->bricks, ((size_t)s->n_bricks + 1024) * sizeof *nb);
                    BF_ASSERT(nb);
                    s->bricks = nb;
                }
                s->bricks[s->n_bricks++] = br;
            }
}

void fx_free(hostmap *s)
{
    free(s->bricks);
    s->bricks = NULL;
    s->n_bricks = 0;
}

typedef struct edge_rec {
    uint32_t a, b; /* directed */
} edge_rec;

static int cmp_edge(const void *x, const void *y)
{
    const edge_rec *p = x, *q = y;
    uint32_t pa = p->a < p->b ? p->a : p->b, pb = p->a < p->b ? p->b : p->a;
    uint32_t qa = q->a < q->b ? q->a : q->b, qb = q->a < q->b ? q->b : q->a;
    if (pa != qa) return pa < qa ? -1 : 1;
    if (pb != qb) return pb < qb ? -1 : 1;
    if (p->a != q->a) return p->a < q->a ? -1 : 1;
    return 0;
}

void fx_mesh_topology(const mesh_data *m, fx_topology *out)
{
    memset(out, 0, sizeof *out);
    size_t n = (size_t)m->n_tris * 3;
    edge_rec *e = malloc((n ? n : 1) * sizeof *e);
    BF_ASSERT(e);
    for (uint32_t t = 0; t < m->n_tris; t++)
        for (int k = 0; k < 3; k++) e[3 * t + k] = (edge_rec){m->tri[3 * t + k], m->tri[3 * t + (k + 1) % 3]};
    qsort(e, n, sizeof *e, cmp_edge);
    for (size_t i = 0; i < n;) {
        size_t j = i + 1;
        while (j < n && (e[j].a == e[i].a || e[j].a == e[i].b) && (e[j].b == e[i].a || e[j].b == e[i].b)) j++;
        size_t cnt = j - i;
        if (cnt == 1) out->n_boundary++;
        if (cnt > 2) out->n_nonmanifold++;
        if (cnt == 2 && e[i].a == e[i + 1].a) out->n_flipped++;
        i = j;
    }
    free(e);
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

void fx_mesh_accuracy(const mesh_data *m, fx_sdf sdf, const void *shape, double voxel_m, fx_accuracy *out)
{
    memset(out, 0, sizeof *out);
    double *d = malloc((m->n_verts ? m->n_verts : 1) * sizeof *d);
    BF_ASSERT(d);
    for (uint32_t v = 0; v < m->n_verts; v++)
        d[v] = fabs(sdf(shape, bf_v3(m->xyz[3 * v], m->xyz[3 * v + 1], m->xyz[3 * v + 2])));
    qsort(d, m->n_verts, sizeof *d, cmp_double);
    if (m->n_verts) {
        out->vert_median = d[m->n_verts / 2];
        out->vert_max = d[m->n_verts - 1];
    }
    free(d);
    for (uint32_t t = 0; t < m->n_tris; t++) {
        const float *a = &m->xyz[3 * m->tri[3 * t]], *b = &m->xyz[3 * m->tri[3 * t + 1]],
                    *c = &m->xyz[3 * m->tri[3 * t + 2]];
        bf_vec3 n = bf_v3_cross(bf_v3(b[0] - a[0], b[1] - a[1], b[2] - a[2]), bf_v3(c[0] - a[0], c[1] - a[1], c[2] - a[2]));
        out->area += bf_v3_norm(n) / 2;
    }
    float *xyz = NULL;
    size_t ns = 0;
    BF_ASSERT(eval_mesh_sample_area(m, 16.0 / (voxel_m * voxel_m), 2000000, 7, &xyz, NULL, &ns) == BF_OK);
    d = malloc((ns ? ns : 1) * sizeof *d);
    BF_ASSERT(d);
    for (size_t i = 0; i < ns; i++) d[i] = fabs(sdf(shape, bf_v3(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2])));
    qsort(d, ns, sizeof *d, cmp_double);
    if (ns) {
        out->area_median = d[ns / 2];
        out->area_p99 = d[(size_t)(0.99 * (double)(ns - 1))];
        out->area_max = d[ns - 1];
    }
    free(d);
    free(xyz);
}
