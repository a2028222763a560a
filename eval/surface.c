/* Surface error of a reconstruction against a reference mesh: accuracy
 * (reconstruction -> reference) and completeness (reference -> reconstruction),
 * the two directions of the measure used by the Middlebury multi-view stereo
 * benchmark (Seitz et al., CVPR 2006) and the DTU set (Aanaes et al., IJCV
 * 2016); definitions and formulas in docs/eval.md.
 *
 * Closest points on a mesh come from the BVH (mesh_bvh_closest), nearest
 * points of a cloud from the kd-tree (kdtree.c). Queries run in chunks on
 * bf_parallel_for; every random choice is a counter-based hash of (seed,
 * sample index), so results do not depend on the thread count. */
#include "eval_int.h"

#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#define SURF_CHUNK 2048 /* points per parallel work item */

eval_surface_config eval_surface_config_default(void)
{
    return (eval_surface_config){
        .threshold_m = 0.01,
        .max_dist_m = INFINITY,
        .samples_per_m2 = 2e5, /* one sample per 5 mm^2 */
        .max_samples = 1000000,
        .seed = 1,
    };
}

/* ------------------------------------------------------------ sampling */

/* splitmix64's finaliser (Steele, Lea and Flood, OOPSLA 2014): a bijective
 * 64-bit mix, used as a counter-based generator. */
static uint64_t mix64(uint64_t z)
{
    z += 0x9e3779b97f4a7c15ull;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

static double unit_double(uint64_t x) { return (double)(x >> 11) * 0x1.0p-53; } /* [0, 1) */

typedef struct sample_job {
    const mesh_data *m;
    const double *cdf; /* cdf[i] = area of triangles 0..i */
    double total;
    uint64_t seed;
    size_t n;
    float *xyz;
    uint32_t *tri;
} sample_job;

static bf_vec3 mesh_vertex(const mesh_data *m, uint32_t v)
{
    return bf_v3(m->xyz[3 * (size_t)v], m->xyz[3 * (size_t)v + 1], m->xyz[3 * (size_t)v + 2]);
}

static void sample_chunk(void *ctx, size_t c)
{
    const sample_job *j = ctx;
    size_t end = (c + 1) * SURF_CHUNK < j->n ? (c + 1) * SURF_CHUNK : j->n;
    for (size_t k = c * SURF_CHUNK; k < end; k++) {
        uint64_t h = mix64(j->seed ^ mix64(k));
        double u0 = unit_double(h), u1 = unit_double(h = mix64(h)), u2 = unit_double(mix64(h));
        /* Triangle by area: the first with cdf > u0 * total (zero-area
         * triangles are never chosen). */
        double target = u0 * j->total;
        size_t lo = 0, hi = j->m->n_tris - 1;
        while (lo < hi) {
            size_t mid = lo + (hi - lo) / 2;
            if (j->cdf[mid] > target)
                hi = mid;
            else
                lo = mid + 1;
        }
        const uint32_t *t = &j->m->tri[3 * lo];
        /* Uniform point in the triangle (Osada et al., "Shape distributions",
         * ACM TOG 2002, eq. 1). */
        double r1 = sqrt(u1);
        bf_vec3 p = bf_v3_add(bf_v3_add(bf_v3_scale(mesh_vertex(j->m, t[0]), 1 - r1),
                                        bf_v3_scale(mesh_vertex(j->m, t[1]), r1 * (1 - u2))),
                              bf_v3_scale(mesh_vertex(j->m, t[2]), r1 * u2));
        j->xyz[3 * k] = (float)p.x;
        j->xyz[3 * k + 1] = (float)p.y;
        j->xyz[3 * k + 2] = (float)p.z;
        if (j->tri) j->tri[k] = (uint32_t)lo;
    }
}

bf_status eval_mesh_sample_area(const mesh_data *m, double samples_per_m2, uint64_t max_samples,
                                uint64_t seed, float **xyz, uint32_t **tri, size_t *n_out)
{
    if (!(samples_per_m2 > 0) || !isfinite(samples_per_m2) || max_samples == 0)
        return bf_fail(BF_INVALID_ARG, "surface sampling: density %g per m^2, cap %llu", samples_per_m2,
                       (unsigned long long)max_samples);
    for (size_t i = 0; i < 3 * (size_t)m->n_tris; i++)
        if (m->tri[i] >= m->n_verts)
            return bf_fail(BF_INVALID_ARG, "surface sampling: triangle %zu uses vertex %u of %u", i / 3,
                           m->tri[i], m->n_verts);
    double *cdf = bf_malloc((m->n_tris ? m->n_tris : 1) * sizeof *cdf);
    if (!cdf) return bf_fail(BF_NO_MEMORY, "surface sampling: out of memory");
    double total = 0;
    for (size_t i = 0; i < m->n_tris; i++) {
        const uint32_t *t = &m->tri[3 * i];
        bf_vec3 a = mesh_vertex(m, t[0]), b = mesh_vertex(m, t[1]), c = mesh_vertex(m, t[2]);
        total += 0.5 * bf_v3_norm(bf_v3_cross(bf_v3_sub(b, a), bf_v3_sub(c, a)));
        cdf[i] = total;
    }
    if (!(total > 0) || !isfinite(total)) {
        free(cdf);
        *xyz = NULL;
        if (tri) *tri = NULL;
        *n_out = 0;
        return BF_OK;
    }
    double want = round(total * samples_per_m2);
    size_t n = want < 1 ? 1 : want >= (double)max_samples ? (size_t)max_samples : (size_t)want;
    if (n > SIZE_MAX / (3 * sizeof(float))) {
        free(cdf);
        return bf_fail(BF_INVALID_ARG, "surface sampling: %zu samples are too many", n);
    }
    float *p = bf_malloc(n * 3 * sizeof *p);
    uint32_t *ti = tri ? bf_malloc(n * sizeof *ti) : NULL;
    if (!p || (tri && !ti)) {
        free(cdf);
        free(p);
        free(ti);
        return bf_fail(BF_NO_MEMORY, "surface sampling: out of memory for %zu samples", n);
    }
    sample_job job = {.m = m, .cdf = cdf, .total = total, .seed = mix64(seed), .n = n, .xyz = p, .tri = ti};
    bf_parallel_for((n + SURF_CHUNK - 1) / SURF_CHUNK, sample_chunk, &job);
    free(cdf);
    *xyz = p;
    if (tri) *tri = ti;
    *n_out = n;
    return BF_OK;
}

/* ------------------------------------------------------------ distances */

/* What distances are measured to: a mesh surface (BVH), a point set
 * (kd-tree), or both (the nearer wins). */
typedef struct surf_target {
    const mesh_bvh *bvh;
    const eval_kdtree *kd;
} surf_target;

typedef struct dist_job {
    const float *pts;
    size_t n;
    surf_target tgt;
    double max_dist;
    double *out;
    atomic_size_t done;
    pthread_mutex_t lock; /* guards the progress line */
    bf_progress *progress;
    uint64_t progress_base;
} dist_job;

static void dist_chunk(void *ctx, size_t c)
{
    dist_job *j = ctx;
    size_t begin = c * SURF_CHUNK, end = begin + SURF_CHUNK < j->n ? begin + SURF_CHUNK : j->n;
    for (size_t i = begin; i < end; i++) {
        bf_vec3 p = bf_v3(j->pts[3 * i], j->pts[3 * i + 1], j->pts[3 * i + 2]);
        double d = INFINITY;
        if (j->tgt.bvh) d = mesh_bvh_closest(j->tgt.bvh, p, j->max_dist, NULL, NULL);
        if (j->tgt.kd) d = fmin(d, eval__kdtree_nearest(j->tgt.kd, p, fmin(d, j->max_dist), NULL));
        j->out[i] = d;
    }
    size_t done = atomic_fetch_add(&j->done, end - begin) + (end - begin);
    /* Whoever holds the lock prints; the others do not wait for it. */
    if (pthread_mutex_trylock(&j->lock) == 0) {
        bf_progress_update(j->progress, j->progress_base + done);
        pthread_mutex_unlock(&j->lock);
    }
}

static void run_distances(const float *pts, size_t n, surf_target tgt, double max_dist, double *out,
                          bf_progress *progress, uint64_t progress_base)
{
    dist_job job = {.pts = pts, .n = n, .tgt = tgt, .max_dist = max_dist, .out = out, .progress = progress,
                    .progress_base = progress_base};
    atomic_init(&job.done, 0);
    pthread_mutex_init(&job.lock, NULL);
    bf_parallel_for((n + SURF_CHUNK - 1) / SURF_CHUNK, dist_chunk, &job);
    pthread_mutex_destroy(&job.lock);
}

/* Statistics of d[0..n) (INFINITY = nothing within max_dist). */
static bf_status dist_stats(const double *d, size_t n, double threshold, double max_dist, eval_dist_stats *out)
{
    double *v = bf_malloc((n ? n : 1) * sizeof *v);
    if (!v) return bf_fail(BF_NO_MEMORY, "surface error: out of memory for %zu distances", n);
    eval_dist_stats s = {0};
    double sum = 0, sum2 = 0, mx = 0;
    for (size_t i = 0; i < n; i++) {
        if (d[i] <= threshold) s.n_within++;
        if (!(d[i] <= max_dist)) continue;
        v[s.n++] = d[i];
        sum += d[i];
        sum2 += d[i] * d[i];
        mx = fmax(mx, d[i]);
    }
    s.n_beyond = n - s.n;
    if (s.n == 0) {
        s.mean = s.median = s.p90 = s.rmse = s.max = NAN;
    } else {
        s.mean = sum / (double)s.n;
        s.rmse = sqrt(sum2 / (double)s.n);
        s.max = mx;
        s.median = bf_percentile_inplace(v, s.n, 50);
        s.p90 = bf_percentile_inplace(v, s.n, 90); /* already sorted: cheap */
    }
    free(v);
    *out = s;
    return BF_OK;
}

/* ------------------------------------------------------------ evaluation */

static bf_status surface_local(const mesh_data *ref, const mesh_data *rec, const mesh_data *visible,
                               const eval_surface_config *cfg_in, eval_surface_result *out);

static bool same_origin(const mesh_data *a, const mesh_data *b)
{
    return a->origin.x == b->origin.x && a->origin.y == b->origin.y && a->origin.z == b->origin.z;
}

/* A copy of m's vertices and triangles relative to `origin` (the shift in
 * double, stored as float; no normals or colours: the measure reads
 * neither). Meshes far from the world origin keep a local one of their own
 * (mesh_data.origin, a PLY's "origin_w" comment), and distances are only
 * meaningful in one frame. */
static bf_status rebase(const mesh_data *m, bf_vec3 origin, mesh_data *out)
{
    memset(out, 0, sizeof *out);
    out->xyz = bf_malloc(((size_t)m->n_verts * 3 + 1) * sizeof *out->xyz);
    out->tri = bf_malloc(((size_t)m->n_tris * 3 + 1) * sizeof *out->tri);
    if (!out->xyz || !out->tri) {
        mesh_free(out);
        return bf_fail(BF_NO_MEMORY, "surface error: out of memory for %u vertices", m->n_verts);
    }
    const double o[3] = {m->origin.x - origin.x, m->origin.y - origin.y, m->origin.z - origin.z};
    for (size_t i = 0; i < 3 * (size_t)m->n_verts; i++) out->xyz[i] = (float)(o[i % 3] + (double)m->xyz[i]);
    if (m->n_tris) memcpy(out->tri, m->tri, (size_t)m->n_tris * 3 * sizeof *out->tri);
    out->n_verts = m->n_verts;
    out->n_tris = m->n_tris;
    out->origin = origin;
    return BF_OK;
}

bf_status eval_surface(const mesh_data *ref, const mesh_data *rec, const mesh_data *visible,
                       const eval_surface_config *cfg_in, eval_surface_result *out)
{
    if (!ref || !rec || (same_origin(ref, rec) && (!visible || same_origin(ref, visible))))
        return surface_local(ref, rec, visible, cfg_in, out);
    /* One frame for all three: the reference's local origin, or the
     * reconstruction's when the reference has none (a mesh bitfuse wrote
     * far out against a reference in world coordinates). */
    bool ref_has = ref->origin.x != 0 || ref->origin.y != 0 || ref->origin.z != 0;
    bf_vec3 o = ref_has ? ref->origin : rec->origin;
    mesh_data a = {0}, b = {0}, c = {0};
    bf_status s = rebase(ref, o, &a);
    if (s == BF_OK) s = rebase(rec, o, &b);
    if (s == BF_OK && visible) s = rebase(visible, o, &c);
    if (s == BF_OK) s = surface_local(&a, &b, visible ? &c : NULL, cfg_in, out);
    mesh_free(&a);
    mesh_free(&b);
    mesh_free(&c);
    return s;
}

static bf_status surface_local(const mesh_data *ref, const mesh_data *rec, const mesh_data *visible,
                               const eval_surface_config *cfg_in, eval_surface_result *out)
{
    eval_surface_config cfg = cfg_in ? *cfg_in : eval_surface_config_default();
    if (!ref || ref->n_verts == 0) return bf_fail(BF_INVALID_ARG, "surface error: the reference is empty");
    if (!rec || rec->n_verts == 0) return bf_fail(BF_INVALID_ARG, "surface error: the reconstruction is empty");
    if (visible && visible->n_verts == 0)
        return bf_fail(BF_INVALID_ARG, "surface error: the visibility mask has no points");
    if (!(cfg.threshold_m > 0) || !isfinite(cfg.threshold_m) || !(cfg.max_dist_m > 0))
        return bf_fail(BF_INVALID_ARG, "surface error: threshold %g m and max distance %g m must be positive",
                       cfg.threshold_m, cfg.max_dist_m);

    double t0 = bf_time_s();
    bf_status s = BF_OK;
    mesh_bvh *ref_bvh = NULL, *rec_bvh = NULL;
    eval_kdtree *ref_kd = NULL, *rec_kd = NULL;
    float *rec_samples = NULL, *rec_pts = NULL, *ref_samples = NULL, *loose = NULL;
    double *acc = NULL, *comp = NULL;
    size_t n_rec_samples = 0, n_ref_samples = 0;

    /* Accuracy: reconstruction points to the reference surface. */
    surf_target to_ref = {0};
    if (ref->n_tris) {
        if ((s = mesh_bvh_build(ref, &ref_bvh))) goto done;
        to_ref.bvh = ref_bvh;
    } else {
        if ((s = eval__kdtree_build(ref->xyz, ref->n_verts, &ref_kd))) goto done;
        to_ref.kd = ref_kd;
    }
    /* The reconstruction's own samples use a different stream than the
     * reference's, so the two never share sample positions. */
    if (rec->n_tris &&
        (s = eval_mesh_sample_area(rec, cfg.samples_per_m2, cfg.max_samples, cfg.seed ^ 0x5265634d65736821ull,
                                   &rec_samples, NULL, &n_rec_samples)))
        goto done;
    size_t n_acc = (size_t)rec->n_verts + n_rec_samples;
    rec_pts = bf_malloc(n_acc * 3 * sizeof *rec_pts);
    acc = bf_malloc(n_acc * sizeof *acc);
    if (!rec_pts || !acc) {
        s = bf_fail(BF_NO_MEMORY, "surface error: out of memory for %zu points", n_acc);
        goto done;
    }
    memcpy(rec_pts, rec->xyz, (size_t)rec->n_verts * 3 * sizeof *rec_pts);
    if (n_rec_samples) memcpy(rec_pts + 3 * (size_t)rec->n_verts, rec_samples, n_rec_samples * 3 * sizeof *rec_pts);

    /* Completeness: reference points (visible ones, or area samples) to the
     * reconstruction: its surface when it is a mesh (plus any vertex no
     * triangle uses), else its points. */
    const float *comp_pts;
    size_t n_comp;
    if (visible) {
        comp_pts = visible->xyz;
        n_comp = visible->n_verts;
    } else if (ref->n_tris) {
        if ((s = eval_mesh_sample_area(ref, cfg.samples_per_m2, cfg.max_samples, cfg.seed, &ref_samples, NULL,
                                       &n_ref_samples)))
            goto done;
        comp_pts = ref_samples;
        n_comp = n_ref_samples;
        if (n_comp == 0) { /* a mesh without area: its vertices */
            comp_pts = ref->xyz;
            n_comp = ref->n_verts;
        }
    } else {
        comp_pts = ref->xyz;
        n_comp = ref->n_verts;
    }
    surf_target to_rec = {0};
    if (rec->n_tris) {
        if ((s = mesh_bvh_build(rec, &rec_bvh))) goto done;
        to_rec.bvh = rec_bvh;
        uint8_t *used = bf_calloc(rec->n_verts, 1);
        loose = bf_malloc((size_t)rec->n_verts * 3 * sizeof *loose);
        if (!used || !loose) {
            free(used);
            s = bf_fail(BF_NO_MEMORY, "surface error: out of memory");
            goto done;
        }
        for (size_t i = 0; i < 3 * (size_t)rec->n_tris; i++) used[rec->tri[i]] = 1;
        size_t n_loose = 0;
        for (size_t v = 0; v < rec->n_verts; v++)
            if (!used[v]) memcpy(&loose[3 * n_loose++], &rec->xyz[3 * v], 3 * sizeof *loose);
        free(used);
        if (n_loose) {
            if ((s = eval__kdtree_build(loose, n_loose, &rec_kd))) goto done;
            to_rec.kd = rec_kd;
        }
    } else {
        if ((s = eval__kdtree_build(rec->xyz, rec->n_verts, &rec_kd))) goto done;
        to_rec.kd = rec_kd;
    }
    comp = bf_malloc((n_comp ? n_comp : 1) * sizeof *comp);
    if (!comp) {
        s = bf_fail(BF_NO_MEMORY, "surface error: out of memory for %zu points", n_comp);
        goto done;
    }

    double t1 = bf_time_s();
    bf_progress prog;
    bf_progress_begin(&prog, "eval-surface: points", (uint64_t)(n_acc + n_comp));
    run_distances(rec_pts, n_acc, to_ref, cfg.max_dist_m, acc, &prog, 0);
    double t2 = bf_time_s();
    run_distances(comp_pts, n_comp, to_rec, cfg.max_dist_m, comp, &prog, n_acc);
    double t3 = bf_time_s();
    bf_progress_end(&prog, (uint64_t)(n_acc + n_comp));
    bf_debug("eval-surface: setup (trees, samples) %.2f s, %zu accuracy queries %.2f s, "
             "%zu completeness queries %.2f s", t1 - t0, n_acc, t2 - t1, n_comp, t3 - t2);

    eval_surface_result r = {0};
    if ((s = dist_stats(acc, n_acc, cfg.threshold_m, cfg.max_dist_m, &r.accuracy))) goto done;
    if ((s = dist_stats(comp, n_comp, cfg.threshold_m, cfg.max_dist_m, &r.completeness_dist))) goto done;
    r.n_rec_vertices = rec->n_verts;
    r.n_rec_samples = n_rec_samples;
    r.n_ref_points = n_comp;
    r.used_visible = visible != NULL;
    r.used_ref_vertices = !visible && comp_pts == ref->xyz;
    r.completeness = (double)r.completeness_dist.n_within / (double)n_comp;
    r.precision = (double)r.accuracy.n_within / (double)n_acc;
    r.seconds = bf_time_s() - t0;
    *out = r;

done:
    mesh_bvh_destroy(ref_bvh);
    mesh_bvh_destroy(rec_bvh);
    eval__kdtree_destroy(ref_kd);
    eval__kdtree_destroy(rec_kd);
    free(rec_samples);
    free(rec_pts);
    free(ref_samples);
    free(loose);
    free(acc);
    free(comp);
    return s;
}
