/* Mesh simplification through meshoptimizer (Arseny Kapoulkine;
 * meshopt_simplify: edge collapses ordered by the quadric error metric of
 * Garland & Heckbert, "Surface simplification using quadric error metrics",
 * SIGGRAPH 1997, collapsing onto existing vertices; meshopt_simplifySloppy:
 * vertex clustering on a grid, for a cap the collapses cannot reach). The
 * library is C++ behind a C header; it is linked as a shared library that
 * brings its own C++ runtime. */
#include <float.h>
#include <math.h>
#include <meshoptimizer.h>
#include <stdlib.h>
#include <string.h>

#include "mesh_int.h"

/* Keeps the vertices idx uses, numbered in order of first use, and their
 * attributes; rewrites idx. On success *m owns new arrays and the old ones
 * are freed. */
static bf_status compact(mesh_data *m, uint32_t *idx, size_t n_idx)
{
    uint32_t *remap = bf_malloc((size_t)m->n_verts * sizeof *remap);
    if (!remap) return bf_fail(BF_NO_MEMORY, "simplify: out of memory for %u vertices", m->n_verts);
    memset(remap, 0xff, (size_t)m->n_verts * sizeof *remap);
    uint32_t n = 0;
    for (size_t i = 0; i < n_idx; i++) {
        if (remap[idx[i]] == UINT32_MAX) remap[idx[i]] = n++;
        idx[i] = remap[idx[i]];
    }
    size_t alloc = n ? n : 1;
    float *xyz = bf_malloc(alloc * 3 * sizeof *xyz);
    float *normal = m->normal ? bf_malloc(alloc * 3 * sizeof *normal) : NULL;
    uint8_t *rgb = m->rgb ? bf_malloc(alloc * 3) : NULL;
    uint32_t *tri = bf_malloc((n_idx ? n_idx : 1) * sizeof *tri);
    if (!xyz || !tri || (m->normal && !normal) || (m->rgb && !rgb)) {
        free(remap), free(xyz), free(normal), free(rgb), free(tri);
        return bf_fail(BF_NO_MEMORY, "simplify: out of memory for %u vertices", n);
    }
    for (uint32_t v = 0; v < m->n_verts; v++) {
        uint32_t r = remap[v];
        if (r == UINT32_MAX) continue;
        memcpy(&xyz[3 * (size_t)r], &m->xyz[3 * (size_t)v], 3 * sizeof *xyz);
        if (normal) memcpy(&normal[3 * (size_t)r], &m->normal[3 * (size_t)v], 3 * sizeof *normal);
        if (rgb) memcpy(&rgb[3 * (size_t)r], &m->rgb[3 * (size_t)v], 3);
    }
    memcpy(tri, idx, n_idx * sizeof *tri);
    free(remap);
    bf_vec3 origin = m->origin;
    mesh_free(m);
    m->n_verts = n;
    m->n_tris = (uint32_t)(n_idx / 3);
    m->xyz = xyz, m->normal = normal, m->rgb = rgb, m->tri = tri;
    m->origin = origin;
    return BF_OK;
}

/* The fewest triangles meshopt_simplifySloppy keeps of m, searched by
 * doubling the target from one that kept none (tmp: room for m's indices). */
static size_t smallest_clustering(uint32_t *tmp, const mesh_data *m, size_t target)
{
    size_t n_idx = 3 * (size_t)m->n_tris, n = 0;
    float err;
    for (size_t t = target < 3 ? 6 : 2 * target; n == 0 && t < n_idx; t *= 2)
        n = meshopt_simplifySloppy(tmp, m->tri, n_idx, m->xyz, m->n_verts, 3 * sizeof(float), t, FLT_MAX, &err);
    return n ? n / 3 : m->n_tris;
}

bf_status mesh_simplify(mesh_data *m, const mesh_simplify_config *cfg, mesh_simplify_stats *st)
{
    double t0 = bf_time_s();
    if (!m || !cfg) return bf_fail(BF_INVALID_ARG, "simplify: NULL mesh or config");
    if (!(cfg->max_error_m >= 0) || !isfinite(cfg->max_error_m))
        return bf_fail(BF_INVALID_ARG, "simplify: error bound %g m is not a finite number >= 0", cfg->max_error_m);
    mesh_simplify_stats sx = {.tris_before = m->n_tris, .tris_after = m->n_tris, .verts_before = m->n_verts,
                              .verts_after = m->n_verts};
    bool has_cap = cfg->max_triangles > 0, has_bound = cfg->max_error_m > 0;
    if (m->n_tris == 0 || (!has_bound && (!has_cap || m->n_tris <= cfg->max_triangles))) {
        sx.seconds = bf_time_s() - t0;
        if (st) *st = sx;
        return BF_OK;
    }
    size_t n_idx = 3 * (size_t)m->n_tris;
    uint32_t *idx = bf_malloc(n_idx * sizeof *idx), *tmp = bf_malloc(n_idx * sizeof *tmp);
    if (!idx || !tmp) {
        free(idx), free(tmp);
        return bf_fail(BF_NO_MEMORY, "simplify: out of memory for %u triangles", m->n_tris);
    }
    /* meshoptimizer's errors are relative to the mesh's extent. */
    double scale = meshopt_simplifyScale(m->xyz, m->n_verts, 3 * sizeof(float));
    if (!(scale > 0)) scale = 1;
    size_t target = has_cap && cfg->max_triangles < m->n_tris ? 3 * (size_t)cfg->max_triangles : 0;
    float bound = has_bound ? (float)(cfg->max_error_m / scale) : FLT_MAX;
    float err = 0;
    size_t n = meshopt_simplify(idx, m->tri, n_idx, m->xyz, m->n_verts, 3 * sizeof(float), target, bound, 0, &err);
    sx.error_m = err * scale;
    /* The cap holds even where the bound stopped the collapses: go on
     * without it, then cluster if the collapses ran out. */
    if (has_cap && n > target && target > 0 && has_bound) {
        size_t n2 = meshopt_simplify(tmp, idx, n, m->xyz, m->n_verts, 3 * sizeof(float), target, FLT_MAX, 0, &err);
        memcpy(idx, tmp, n2 * sizeof *idx);
        n = n2;
        sx.error_m += err * scale;
    }
    if (has_cap && n > target && target > 0) {
        size_t n2 = meshopt_simplifySloppy(tmp, idx, n, m->xyz, m->n_verts, 3 * sizeof(float), target, FLT_MAX, &err);
        memcpy(idx, tmp, n2 * sizeof *idx);
        n = n2;
        sx.error_m += err * scale;
        sx.used_sloppy = true;
    }
    /* A cap below what clustering keeps would write an empty mesh: refused,
     * naming the smallest cap that keeps some. (The collapses alone keep a
     * closed mesh's topology: an error bound does not empty it.) */
    if (n == 0 && target > 0) {
        size_t fewest = smallest_clustering(tmp, m, target);
        free(tmp), free(idx);
        return bf_fail(BF_INVALID_ARG,
                       "simplify: a cap of %llu triangle%s leaves none of the mesh's %u (the coarsest vertex clustering "
                       "that keeps any has %zu): choose a larger cap",
                       (unsigned long long)cfg->max_triangles, cfg->max_triangles == 1 ? "" : "s", m->n_tris, fewest);
    }
    free(tmp);
    bf_status s = compact(m, idx, n);
    free(idx);
    if (s != BF_OK) return s;
    sx.tris_after = m->n_tris;
    sx.verts_after = m->n_verts;
    sx.seconds = bf_time_s() - t0;
    if (st) *st = sx;
    return BF_OK;
}
