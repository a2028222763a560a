/* eval: bounding-volume hierarchy over a triangle mesh, for ray casting
 * (the synthetic sequence generator) and closest-point queries (surface
 * error).
 *
 * Build: top-down binned SAH (Wald 2007, "On fast construction of SAH-based
 * bounding volume hierarchies"), 16 bins on each axis, leaves of at most
 * MESH_BVH_LEAF_MAX triangles unless the triangles cannot be separated
 * (identical centroids) or the depth cap is reached. Nodes are flattened in
 * depth-first order: an interior node's left child follows it, the right
 * child's index is stored. Triangles are copied in leaf order as v0, e1, e2
 * in double, so traversal touches contiguous memory and never the mesh.
 *
 * Queries run in double precision throughout. The slab test widens the far
 * distance by 2 gamma(3) (Ize 2013, "Robust BVH ray traversal") so rounding
 * can never cull a box the ray touches: the BVH then returns exactly what a
 * brute-force loop over all triangles with the same triangle test returns. */
#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "mesh/mesh.h"

#define MESH_BVH_BINS 16
#define MESH_BVH_LEAF_MAX 4
/* Deeper nodes become leaves whatever their size; bounds the traversal stack. */
#define MESH_BVH_MAX_DEPTH 60
#define MESH_BVH_STACK (MESH_BVH_MAX_DEPTH + 4)

typedef struct bvh_node {
    double lo[3], hi[3];
    uint32_t index; /* leaf: first triangle; interior: right child */
    uint32_t count; /* leaf: number of triangles (> 0); interior: 0 */
} bvh_node;

typedef struct bvh_tri {
    double v0[3], e1[3], e2[3]; /* e1 = v1 - v0, e2 = v2 - v0 */
    uint32_t tri;               /* index in the mesh */
} bvh_tri;

struct mesh_bvh {
    const mesh_data *mesh;
    uint32_t n_nodes, n_tris;
    bvh_node *nodes;
    bvh_tri *tris;
};

/* ------------------------------------------------------------ build */

typedef struct build_ctx {
    const double *box_lo, *box_hi, *centroid; /* 3 per triangle */
    uint32_t *prim;                           /* triangle order, partitioned in place */
    bvh_node *nodes;
    uint32_t n_nodes;
} build_ctx;

typedef struct build_item {
    uint32_t begin, end, depth;
    uint32_t parent; /* UINT32_MAX for the root */
    bool is_right;
} build_item;

static double half_area(const double lo[3], const double hi[3])
{
    double dx = hi[0] - lo[0], dy = hi[1] - lo[1], dz = hi[2] - lo[2];
    if (dx < 0) return 0; /* empty box */
    return dx * dy + dy * dz + dz * dx;
}

static void box_empty(double lo[3], double hi[3])
{
    for (int k = 0; k < 3; k++) {
        lo[k] = INFINITY;
        hi[k] = -INFINITY;
    }
}

static void box_grow(double lo[3], double hi[3], const double plo[3], const double phi[3])
{
    for (int k = 0; k < 3; k++) {
        if (plo[k] < lo[k]) lo[k] = plo[k];
        if (phi[k] > hi[k]) hi[k] = phi[k];
    }
}

/* Chooses the best binned SAH split of prim[begin, end). Returns false when
 * a leaf is cheaper (and allowed) or the centroids cannot be separated;
 * otherwise sets the axis and the split position (bin boundary). */
static bool choose_split(const build_ctx *c, uint32_t begin, uint32_t end, const bvh_node *node,
                         int *axis_out, double *split_out)
{
    uint32_t n = end - begin;
    double clo[3], chi[3];
    box_empty(clo, chi);
    for (uint32_t i = begin; i < end; i++) {
        const double *p = c->centroid + 3 * (size_t)c->prim[i];
        box_grow(clo, chi, p, p);
    }
    double best_cost = INFINITY;
    int best_axis = -1;
    double best_split = 0;
    for (int a = 0; a < 3; a++) {
        double ext = chi[a] - clo[a];
        if (!(ext > 0)) continue;
        uint32_t cnt[MESH_BVH_BINS] = {0};
        double blo[MESH_BVH_BINS][3], bhi[MESH_BVH_BINS][3];
        for (int b = 0; b < MESH_BVH_BINS; b++) box_empty(blo[b], bhi[b]);
        double scale = MESH_BVH_BINS / ext;
        for (uint32_t i = begin; i < end; i++) {
            uint32_t t = c->prim[i];
            int b = (int)((c->centroid[3 * (size_t)t + a] - clo[a]) * scale);
            if (b >= MESH_BVH_BINS) b = MESH_BVH_BINS - 1;
            if (b < 0) b = 0;
            cnt[b]++;
            box_grow(blo[b], bhi[b], c->box_lo + 3 * (size_t)t, c->box_hi + 3 * (size_t)t);
        }
        /* Sweep from the right to get the right-hand areas, then from the left. */
        double right_area[MESH_BVH_BINS];
        uint32_t right_cnt[MESH_BVH_BINS];
        double lo[3], hi[3];
        box_empty(lo, hi);
        uint32_t acc = 0;
        for (int b = MESH_BVH_BINS - 1; b > 0; b--) {
            box_grow(lo, hi, blo[b], bhi[b]);
            acc += cnt[b];
            right_area[b] = half_area(lo, hi);
            right_cnt[b] = acc;
        }
        box_empty(lo, hi);
        acc = 0;
        for (int b = 0; b < MESH_BVH_BINS - 1; b++) {
            box_grow(lo, hi, blo[b], bhi[b]);
            acc += cnt[b];
            if (acc == 0 || right_cnt[b + 1] == 0) continue;
            double cost = acc * half_area(lo, hi) + right_cnt[b + 1] * right_area[b + 1];
            if (cost < best_cost) {
                best_cost = cost;
                best_axis = a;
                best_split = clo[a] + (double)(b + 1) / scale;
            }
        }
    }
    if (best_axis < 0) return false;
    /* Costs relative to the node area: traversal 1, triangle test 1. */
    double node_area = half_area(node->lo, node->hi);
    double split_cost = node_area > 0 ? 1.0 + best_cost / node_area : 1.0 + n;
    if (n <= MESH_BVH_LEAF_MAX && split_cost >= (double)n) return false;
    *axis_out = best_axis;
    *split_out = best_split;
    return true;
}

static void build_nodes(build_ctx *c, uint32_t n_tris)
{
    build_item stack[2 * MESH_BVH_STACK];
    int sp = 0;
    stack[sp++] = (build_item){0, n_tris, 0, UINT32_MAX, false};
    while (sp > 0) {
        build_item it = stack[--sp];
        uint32_t idx = c->n_nodes++;
        if (it.is_right) c->nodes[it.parent].index = idx;
        bvh_node *node = &c->nodes[idx];
        box_empty(node->lo, node->hi);
        for (uint32_t i = it.begin; i < it.end; i++) {
            uint32_t t = c->prim[i];
            box_grow(node->lo, node->hi, c->box_lo + 3 * (size_t)t, c->box_hi + 3 * (size_t)t);
        }
        int axis;
        double split;
        bool do_split = it.end - it.begin > 1 && it.depth < MESH_BVH_MAX_DEPTH &&
                        choose_split(c, it.begin, it.end, node, &axis, &split);
        uint32_t mid = it.begin;
        if (do_split) {
            uint32_t i = it.begin, j = it.end;
            while (i < j) {
                if (c->centroid[3 * (size_t)c->prim[i] + axis] < split) {
                    i++;
                } else {
                    uint32_t tmp = c->prim[i];
                    c->prim[i] = c->prim[--j];
                    c->prim[j] = tmp;
                }
            }
            mid = i;
            /* The split lies strictly inside the centroid range, so both sides
             * are non-empty; guard against rounding anyway. */
            if (mid == it.begin || mid == it.end) mid = it.begin + (it.end - it.begin) / 2;
        }
        if (!do_split) {
            node->index = it.begin;
            node->count = it.end - it.begin;
            continue;
        }
        node->count = 0;
        node->index = 0; /* patched when the right child is created */
        /* Right first so that the left child is popped next and lands at idx + 1. */
        stack[sp++] = (build_item){mid, it.end, it.depth + 1, idx, true};
        stack[sp++] = (build_item){it.begin, mid, it.depth + 1, idx, false};
    }
}

bf_status mesh_bvh_build(const mesh_data *m, mesh_bvh **out)
{
    if (!m || !out || (m->n_tris > 0 && (!m->tri || !m->xyz)))
        return bf_fail(BF_INVALID_ARG, "mesh_bvh_build: no mesh");
    uint32_t n = m->n_tris;
    for (size_t i = 0; i < 3 * (size_t)n; i++)
        if (m->tri[i] >= m->n_verts)
            return bf_fail(BF_INVALID_ARG, "mesh_bvh_build: triangle %zu: vertex index %u out of range (%u vertices)",
                           i / 3, m->tri[i], m->n_verts);
    mesh_bvh *b = bf_calloc(1, sizeof *b);
    double *box_lo = NULL, *box_hi = NULL, *centroid = NULL;
    uint32_t *prim = NULL;
    if (!b) goto fail;
    b->mesh = m;
    b->n_tris = n;
    if (n > 0) {
        box_lo = bf_malloc(3 * sizeof(double) * n);
        box_hi = bf_malloc(3 * sizeof(double) * n);
        centroid = bf_malloc(3 * sizeof(double) * n);
        prim = bf_malloc(sizeof(uint32_t) * n);
        b->nodes = bf_malloc(sizeof(bvh_node) * (2 * (size_t)n - 1));
        b->tris = bf_malloc(sizeof(bvh_tri) * n);
        if (!box_lo || !box_hi || !centroid || !prim || !b->nodes || !b->tris) goto fail;
        for (uint32_t t = 0; t < n; t++) {
            double *lo = box_lo + 3 * (size_t)t, *hi = box_hi + 3 * (size_t)t;
            box_empty(lo, hi);
            for (int k = 0; k < 3; k++) {
                const float *v = m->xyz + 3 * (size_t)m->tri[3 * (size_t)t + k];
                double p[3] = {v[0], v[1], v[2]};
                box_grow(lo, hi, p, p);
            }
            for (int a = 0; a < 3; a++) centroid[3 * (size_t)t + a] = 0.5 * (lo[a] + hi[a]);
            prim[t] = t;
        }
        build_ctx c = {box_lo, box_hi, centroid, prim, b->nodes, 0};
        build_nodes(&c, n);
        b->n_nodes = c.n_nodes;
        for (uint32_t i = 0; i < n; i++) {
            uint32_t t = prim[i];
            const float *v0 = m->xyz + 3 * (size_t)m->tri[3 * (size_t)t];
            const float *v1 = m->xyz + 3 * (size_t)m->tri[3 * (size_t)t + 1];
            const float *v2 = m->xyz + 3 * (size_t)m->tri[3 * (size_t)t + 2];
            bvh_tri *bt = &b->tris[i];
            for (int a = 0; a < 3; a++) {
                bt->v0[a] = v0[a];
                bt->e1[a] = (double)v1[a] - (double)v0[a];
                bt->e2[a] = (double)v2[a] - (double)v0[a];
            }
            bt->tri = t;
        }
    }
    free(box_lo);
    free(box_hi);
    free(centroid);
    free(prim);
    bf_debug("mesh_bvh_build: %u triangles, %u nodes", n, b->n_nodes);
    *out = b;
    return BF_OK;
fail:
    free(box_lo);
    free(box_hi);
    free(centroid);
    free(prim);
    mesh_bvh_destroy(b);
    return bf_fail(BF_NO_MEMORY, "mesh_bvh_build: out of memory for %u triangles", n);
}

void mesh_bvh_destroy(mesh_bvh *b)
{
    if (!b) return;
    free(b->nodes);
    free(b->tris);
    free(b);
}

/* ------------------------------------------------------------ ray casting */

/* 2 gamma(3) with gamma(n) = n eps / (1 - n eps), eps = 2^-53 (Pharr, Jakob,
 * Humphreys, PBRT 3rd ed., section 3.9): widening the far slab distance by
 * this factor keeps the slab test conservative under rounding. */
#define MESH_BVH_SLAB_WIDEN (1.0 + 2.0 * (3.0 * (DBL_EPSILON * 0.5)) / (1.0 - 3.0 * (DBL_EPSILON * 0.5)))

/* Entry distance of the ray into the box, or INFINITY if it misses the
 * interval (t_min, t_max). */
static inline double slab(const bvh_node *nd, const double o[3], const double inv[3], double t_min,
                          double t_max)
{
    double t0 = t_min, t1 = t_max;
    for (int a = 0; a < 3; a++) {
        double tn = (nd->lo[a] - o[a]) * inv[a];
        double tf = (nd->hi[a] - o[a]) * inv[a];
        if (tn > tf) {
            double s = tn;
            tn = tf;
            tf = s;
        }
        tf *= MESH_BVH_SLAB_WIDEN;
        t0 = tn > t0 ? tn : t0;
        t1 = tf < t1 ? tf : t1;
    }
    return t0 <= t1 ? t0 : INFINITY;
}

/* Möller and Trumbore (1997), "Fast, minimum storage ray-triangle
 * intersection", in double. Returns true with t, u, v when t_min < t < t_max. */
static inline bool tri_hit(const bvh_tri *tr, const double o[3], const double d[3], double t_min,
                           double t_max, double *t_out, double *u_out, double *v_out)
{
    const double *e1 = tr->e1, *e2 = tr->e2;
    double p[3] = {d[1] * e2[2] - d[2] * e2[1], d[2] * e2[0] - d[0] * e2[2], d[0] * e2[1] - d[1] * e2[0]};
    double det = e1[0] * p[0] + e1[1] * p[1] + e1[2] * p[2];
    if (det == 0) return false;
    double inv_det = 1.0 / det;
    double s[3] = {o[0] - tr->v0[0], o[1] - tr->v0[1], o[2] - tr->v0[2]};
    double u = (s[0] * p[0] + s[1] * p[1] + s[2] * p[2]) * inv_det;
    if (u < 0 || u > 1) return false;
    double q[3] = {s[1] * e1[2] - s[2] * e1[1], s[2] * e1[0] - s[0] * e1[2], s[0] * e1[1] - s[1] * e1[0]};
    double v = (d[0] * q[0] + d[1] * q[1] + d[2] * q[2]) * inv_det;
    if (v < 0 || u + v > 1) return false;
    double t = (e2[0] * q[0] + e2[1] * q[1] + e2[2] * q[2]) * inv_det;
    if (!(t > t_min && t < t_max)) return false;
    *t_out = t;
    *u_out = u;
    *v_out = v;
    return true;
}

bool mesh_bvh_raycast(const mesh_bvh *b, bf_vec3 o, bf_vec3 d, double t_min, double t_max, mesh_hit *hit)
{
    if (!b || b->n_nodes == 0 || !(t_max > t_min)) return false;
    double org[3] = {o.x, o.y, o.z}, dir[3] = {d.x, d.y, d.z}, inv[3];
    /* A zero component gets a huge finite inverse instead of infinity, so
     * (lo - o) * inv never forms 0 * inf = NaN. */
    for (int a = 0; a < 3; a++) inv[a] = dir[a] != 0 ? 1.0 / dir[a] : copysign(1e300, dir[a]);
    double best_t = t_max, bu = 0, bv = 0;
    uint32_t best_tri = UINT32_MAX;
    /* Deferred far children with their entry distance: popped only while
     * they can still hold a nearer hit. */
    struct {
        uint32_t idx;
        double t_near;
    } stack[MESH_BVH_STACK];
    int sp = 0;
    uint32_t idx = 0;
    if (slab(&b->nodes[0], org, inv, t_min, best_t) == INFINITY) return false;
    for (;;) {
        const bvh_node *nd = &b->nodes[idx];
        if (nd->count > 0) {
            for (uint32_t i = nd->index; i < nd->index + nd->count; i++) {
                double t, u, v;
                if (tri_hit(&b->tris[i], org, dir, t_min, best_t, &t, &u, &v)) {
                    best_t = t;
                    bu = u;
                    bv = v;
                    best_tri = b->tris[i].tri;
                }
            }
        } else {
            uint32_t l = idx + 1, r = nd->index;
            double tl = slab(&b->nodes[l], org, inv, t_min, best_t);
            double tr = slab(&b->nodes[r], org, inv, t_min, best_t);
            if (tl != INFINITY && tr != INFINITY) {
                /* Visit the nearer child first; the other waits on the stack. */
                if (tr < tl) {
                    idx = r;
                    stack[sp].idx = l;
                    stack[sp++].t_near = tl;
                } else {
                    idx = l;
                    stack[sp].idx = r;
                    stack[sp++].t_near = tr;
                }
                continue;
            }
            if (tl != INFINITY) {
                idx = l;
                continue;
            }
            if (tr != INFINITY) {
                idx = r;
                continue;
            }
        }
        /* Pop the next node that can still hold a nearer hit. */
        for (;;) {
            if (sp == 0) goto done;
            sp--;
            if (stack[sp].t_near <= best_t) break;
        }
        idx = stack[sp].idx;
    }
done:
    if (best_tri == UINT32_MAX) return false;
    if (hit) {
        hit->t = best_t;
        hit->tri = best_tri;
        hit->u = bu;
        hit->v = bv;
    }
    return true;
}

/* ------------------------------------------------------------ closest point */

static inline double box_dist2(const bvh_node *nd, const double p[3])
{
    double s = 0;
    for (int a = 0; a < 3; a++) {
        double e = p[a] < nd->lo[a] ? nd->lo[a] - p[a] : p[a] > nd->hi[a] ? p[a] - nd->hi[a] : 0;
        s += e * e;
    }
    return s;
}

static inline double dot3(const double a[3], const double b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

/* Closest point of segment a + s (b - a), s in [0, 1], to p. */
static void closest_on_segment(const double p[3], const double a[3], const double b[3], double out[3])
{
    double ab[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, ap[3] = {p[0] - a[0], p[1] - a[1], p[2] - a[2]};
    double l2 = dot3(ab, ab), s = l2 > 0 ? dot3(ap, ab) / l2 : 0;
    s = s < 0 ? 0 : s > 1 ? 1 : s;
    for (int k = 0; k < 3; k++) out[k] = a[k] + s * ab[k];
}

static double dist2(const double a[3], const double b[3])
{
    double d[3] = {a[0] - b[0], a[1] - b[1], a[2] - b[2]};
    return dot3(d, d);
}

/* Closest point of a triangle to p by Voronoi regions (Ericson, "Real-Time
 * Collision Detection", 2005, section 5.1.5). A degenerate (zero-area)
 * triangle falls back to its three edges. */
static void closest_on_tri(const bvh_tri *tr, const double p[3], double out[3])
{
    const double *a = tr->v0, *ab = tr->e1, *ac = tr->e2;
    double ap[3] = {p[0] - a[0], p[1] - a[1], p[2] - a[2]};
    double d1 = dot3(ab, ap), d2 = dot3(ac, ap);
    if (d1 <= 0 && d2 <= 0) {
        memcpy(out, a, sizeof(double) * 3);
        return;
    }
    double bp[3] = {ap[0] - ab[0], ap[1] - ab[1], ap[2] - ab[2]};
    double d3 = dot3(ab, bp), d4 = dot3(ac, bp);
    if (d3 >= 0 && d4 <= d3) {
        for (int k = 0; k < 3; k++) out[k] = a[k] + ab[k];
        return;
    }
    double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0 && d1 - d3 > 0) {
        double v = d1 / (d1 - d3);
        for (int k = 0; k < 3; k++) out[k] = a[k] + v * ab[k];
        return;
    }
    double cp[3] = {ap[0] - ac[0], ap[1] - ac[1], ap[2] - ac[2]};
    double d5 = dot3(ab, cp), d6 = dot3(ac, cp);
    if (d6 >= 0 && d5 <= d6) {
        for (int k = 0; k < 3; k++) out[k] = a[k] + ac[k];
        return;
    }
    double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0 && d2 - d6 > 0) {
        double w = d2 / (d2 - d6);
        for (int k = 0; k < 3; k++) out[k] = a[k] + w * ac[k];
        return;
    }
    double va = d3 * d6 - d5 * d4;
    if (va <= 0 && d4 - d3 >= 0 && d5 - d6 >= 0 && (d4 - d3) + (d5 - d6) > 0) {
        double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        for (int k = 0; k < 3; k++) out[k] = a[k] + ab[k] + w * (ac[k] - ab[k]);
        return;
    }
    double den = va + vb + vc;
    if (den > 0 && isfinite(1.0 / den)) {
        double v = vb / den, w = vc / den;
        for (int k = 0; k < 3; k++) out[k] = a[k] + ab[k] * v + ac[k] * w;
        return;
    }
    /* Degenerate triangle: the nearest of its three edges. */
    double b[3] = {a[0] + ab[0], a[1] + ab[1], a[2] + ab[2]}, c[3] = {a[0] + ac[0], a[1] + ac[1], a[2] + ac[2]};
    double q[3], best = INFINITY;
    const double *ends[3][2] = {{a, b}, {b, c}, {c, a}};
    for (int e = 0; e < 3; e++) {
        closest_on_segment(p, ends[e][0], ends[e][1], q);
        double d = dist2(p, q);
        if (d < best) {
            best = d;
            memcpy(out, q, sizeof q);
        }
    }
}

double mesh_bvh_closest(const mesh_bvh *b, bf_vec3 p, double max_dist, bf_vec3 *closest, uint32_t *tri)
{
    if (!b || b->n_nodes == 0 || !(max_dist >= 0)) return INFINITY;
    double q[3] = {p.x, p.y, p.z};
    double best2 = max_dist == INFINITY ? INFINITY : max_dist * max_dist, best_pt[3] = {0, 0, 0};
    uint32_t best_tri = UINT32_MAX;
    typedef struct { uint32_t idx; double d2; } entry;
    entry stack[MESH_BVH_STACK];
    int sp = 0;
    double d0 = box_dist2(&b->nodes[0], q);
    if (d0 > best2) return INFINITY;
    stack[sp++] = (entry){0, d0};
    while (sp > 0) {
        entry e = stack[--sp];
        if (e.d2 > best2) continue;
        const bvh_node *nd = &b->nodes[e.idx];
        if (nd->count > 0) {
            for (uint32_t i = nd->index; i < nd->index + nd->count; i++) {
                double c[3];
                closest_on_tri(&b->tris[i], q, c);
                double d2 = dist2(q, c);
                if (d2 <= best2 && (d2 < best2 || best_tri == UINT32_MAX)) {
                    best2 = d2;
                    memcpy(best_pt, c, sizeof c);
                    best_tri = b->tris[i].tri;
                }
            }
            continue;
        }
        uint32_t l = e.idx + 1, r = nd->index;
        double dl = box_dist2(&b->nodes[l], q), dr = box_dist2(&b->nodes[r], q);
        /* Push the farther child first so the nearer one is searched first. */
        if (dl <= dr) {
            if (dr <= best2) stack[sp++] = (entry){r, dr};
            if (dl <= best2) stack[sp++] = (entry){l, dl};
        } else {
            if (dl <= best2) stack[sp++] = (entry){l, dl};
            if (dr <= best2) stack[sp++] = (entry){r, dr};
        }
    }
    if (best_tri == UINT32_MAX) return INFINITY;
    if (closest) *closest = bf_v3(best_pt[0], best_pt[1], best_pt[2]);
    if (tri) *tri = best_tri;
    return sqrt(best2);
}
