/* Point export: centres of surface voxels (confident, not overridden by
 * finer confident data, with a 6-neighbour of the other sign) with the
 * normalised gradient of the smoothed sign field as normal. Bricks are
 * visited in parallel, each filling its own list; the lists are joined in
 * brick order (independent of the thread count). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "export_int.h"

typedef struct point_out {
    float *xyz, *normal;
    size_t n;
    bool failed;
} point_out;

typedef struct point_job {
    const export__grid *g;
    point_out *out;
    double shift[3]; /* the map's origin_w less the local origin */
} point_job;

/* Field of the level-L voxel at v + (dx, dy, dz), NAN if it has none. */
static double neighbour_field(const export__grid *g, uint32_t i, uint32_t L, const int64_t v[3], int dx, int dy,
                              int dz)
{
    int64_t n[3] = {v[0] + dx, v[1] + dy, v[2] + dz};
    if (export__shr(n[0], 3) == g->bc[i][0] && export__shr(n[1], 3) == g->bc[i][1] &&
        export__shr(n[2], 3) == g->bc[i][2]) {
        int8_t f = g->sfield[(size_t)i * BRICK_VOXELS + (size_t)((n[2] & 7) * 64 + (n[1] & 7) * 8 + (n[0] & 7))];
        return f == EXPORT__NO_FIELD ? NAN : f / 127.0;
    }
    return export__grid_voxel_field(g, L, n);
}

static void points_brick(void *ctx, size_t k)
{
    const point_job *j = ctx;
    const export__grid *g = j->g;
    uint32_t i = g->order[k];
    const hostmap_brick *br = &g->s->bricks[i];
    uint32_t L = br->level;
    int64_t step = (int64_t)2 << (g->level_max - L); /* one voxel of level L in half units */
    point_out *o = &j->out[k];
    float xyz[BRICK_VOXELS * 3], nrm[BRICK_VOXELS * 3];
    size_t n = 0;
    for (uint32_t z = 0; z < 8; z++)
        for (uint32_t y = 0; y < 8; y++)
            for (uint32_t x = 0; x < 8; x++) {
                if (!export__bit(br->conf, x, y, z)) continue;
                int64_t v[3] = {g->bc[i][0] * 8 + x, g->bc[i][1] * 8 + y, g->bc[i][2] * 8 + z};
                int64_t q[3] = {export__centre_q(g, L, v[0]), export__centre_q(g, L, v[1]),
                                export__centre_q(g, L, v[2])};
                export__voxel sv;
                if (g->has_finer[i] && (!export__grid_sample(g, q, &sv) || sv.brick != i)) continue;
                bool is_free = export__bit(br->sign, x, y, z);
                /* Opposite-sign 6-neighbours, sampled from the finest data. */
                bf_vec3 toward_free = bf_v3(0, 0, 0);
                bool is_surface = false;
                for (int a = 0; a < 3; a++)
                    for (int dir = -1; dir <= 1; dir += 2) {
                        uint32_t l[3] = {x, y, z};
                        int nl = (int)l[a] + dir;
                        bool nb_known, nb_free;
                        if (nl >= 0 && nl < 8) l[a] = (uint32_t)nl;
                        if (nl >= 0 && nl < 8 && !g->has_finer[i] && export__bit(br->conf, l[0], l[1], l[2])) {
                            nb_known = true;
                            nb_free = export__bit(br->sign, l[0], l[1], l[2]);
                        } else {
                            int64_t qn[3] = {q[0], q[1], q[2]};
                            qn[a] += dir * step;
                            nb_known = export__grid_sample(g, qn, &sv);
                            nb_free = nb_known && sv.is_free;
                        }
                        if (!nb_known || nb_free == is_free) continue;
                        is_surface = true;
                        double d = (nb_free ? 1 : -1) * dir;
                        if (a == 0) toward_free.x += d;
                        if (a == 1) toward_free.y += d;
                        if (a == 2) toward_free.z += d;
                    }
                if (!is_surface) continue;
                /* The field grows toward free space: its gradient points
                 * out of the surface. Least-squares gradient over the 3x3x3
                 * box (the sum of offset * field, Sobel-like): with the box
                 * mean inside the field that is a 5-voxel-wide estimate,
                 * which follows a curved surface far better than central
                 * differences across the staircase. */
                bf_vec3 grad;
                double gc[3] = {0, 0, 0};
                double f0 = g->sfield[(size_t)i * BRICK_VOXELS + z * 64 + y * 8 + x] / 127.0;
                for (int dz = -1; dz <= 1; dz++)
                    for (int dy = -1; dy <= 1; dy++)
                        for (int dx = -1; dx <= 1; dx++) {
                            if (!dx && !dy && !dz) continue;
                            double f = neighbour_field(g, i, L, v, dx, dy, dz);
                            if (isnan(f)) continue;
                            /* Differences to the centre, so a missing
                             * neighbour (the brick or level ends) does not
                             * bias the sum. */
                            f -= f0;
                            gc[0] += dx * f, gc[1] += dy * f, gc[2] += dz * f;
                        }
                grad = bf_v3_normalize(bf_v3(gc[0], gc[1], gc[2]));
                if (bf_v3_norm(grad) == 0) grad = bf_v3_normalize(toward_free);
                for (int a = 0; a < 3; a++)
                    xyz[3 * n + (size_t)a] = (float)(j->shift[a] + (double)q[a] * g->half_m);
                nrm[3 * n] = (float)grad.x, nrm[3 * n + 1] = (float)grad.y, nrm[3 * n + 2] = (float)grad.z;
                n++;
            }
    if (n == 0) return;
    o->xyz = bf_malloc(n * 3 * sizeof *o->xyz);
    o->normal = bf_malloc(n * 3 * sizeof *o->normal);
    if (!o->xyz || !o->normal) {
        o->failed = true;
        return;
    }
    memcpy(o->xyz, xyz, n * 3 * sizeof *xyz);
    memcpy(o->normal, nrm, n * 3 * sizeof *nrm);
    o->n = n;
}

bf_status export_points(const hostmap *s, mesh_data *out, export_stats *st)
{
    double t0 = bf_time_s();
    if (!out) return bf_fail(BF_INVALID_ARG, "export: point output is NULL");
    export__grid g;
    bf_status rc = export__grid_build(s, true, &g);
    if (rc != BF_OK) return rc;
    export_stats sx;
    memset(&sx, 0, sizeof sx);
    sx.n_bricks = g.n;
    sx.n_duplicates = g.n_duplicates;
    sx.level_out = g.level_max;
    mesh_data m = {0};
    point_out *po = NULL;
    for (uint32_t k = 0; k < g.n; k++) sx.bricks_per_level[export__level_slot(s->bricks[g.order[k]].level)]++;
    if (g.n) {
        po = bf_calloc(g.n, sizeof *po);
        if (!po) goto fail_mem;
        m.origin = export_local_origin(s);
        point_job job = {&g, po, {s->origin_w.x - m.origin.x, s->origin_w.y - m.origin.y, s->origin_w.z - m.origin.z}};
        bf_parallel_for(g.n, points_brick, &job);
        size_t n = 0;
        for (uint32_t k = 0; k < g.n; k++) {
            if (po[k].failed) goto fail_mem;
            n += po[k].n;
            sx.points_per_level[export__level_slot(s->bricks[g.order[k]].level)] += po[k].n;
        }
        if (n > UINT32_MAX) {
            rc = bf_fail(BF_UNSUPPORTED, "export: %zu points do not fit 32-bit counts", n);
            goto fail;
        }
        if (n) {
            m.xyz = bf_malloc(n * 3 * sizeof *m.xyz);
            m.normal = bf_malloc(n * 3 * sizeof *m.normal);
            if (!m.xyz || !m.normal) goto fail_mem;
            for (uint32_t k = 0; k < g.n; k++) {
                if (po[k].n == 0) continue;
                memcpy(m.xyz + 3 * (size_t)m.n_verts, po[k].xyz, po[k].n * 3 * sizeof *m.xyz);
                memcpy(m.normal + 3 * (size_t)m.n_verts, po[k].normal, po[k].n * 3 * sizeof *m.normal);
                m.n_verts += (uint32_t)po[k].n;
            }
        }
    }
    if ((rc = export__colourise(&g, &m)) != BF_OK) goto fail;
    sx.n_points = m.n_verts;
    sx.n_vertices = m.n_verts;
    if (po)
        for (uint32_t k = 0; k < g.n; k++) free(po[k].xyz), free(po[k].normal);
    free(po);
    export__grid_free(&g);
    sx.seconds = bf_time_s() - t0;
    *out = m;
    if (st) *st = sx;
    return BF_OK;
fail_mem:
    rc = bf_fail(BF_NO_MEMORY, "export: no memory for the points of %u bricks", g.n);
fail:
    if (po)
        for (uint32_t k = 0; k < g.n; k++) free(po[k].xyz), free(po[k].normal);
    free(po);
    mesh_free(&m);
    export__grid_free(&g);
    return rc;
}
