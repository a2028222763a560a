/* A static kd-tree for nearest-point queries (completeness of the surface
 * error): median split on the widest axis of each node's points (Friedman,
 * Bentley and Finkel 1977), leaves of at most EVAL__KD_LEAF points stored
 * contiguously so a leaf scan walks one cache-friendly run. */
#include "eval_int.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define KD_LEAF_AXIS 3u
#define KD_STACK 128

typedef struct kd_node {
    float split;   /* inner: coordinate on axis dividing left (<=) and right (>=) */
    uint32_t axis; /* 0..2, or KD_LEAF_AXIS */
    uint32_t a, b; /* inner: left, right child; leaf: [a, b) in pts */
} kd_node;

struct eval_kdtree {
    size_t n, n_nodes;
    float *pts;    /* 3 * n, in leaf order */
    uint32_t *idx; /* original index of each point */
    kd_node *nodes;
};

typedef struct kd_build {
    const float *xyz;
    uint32_t *perm;
    kd_node *nodes;
    size_t n_nodes, cap;
} kd_build;

static float kd_key(const kd_build *kb, size_t i, int axis) { return kb->xyz[3 * (size_t)kb->perm[i] + axis]; }

static void kd_swap(uint32_t *p, size_t i, size_t j)
{
    uint32_t t = p[i];
    p[i] = p[j];
    p[j] = t;
}

/* Reorders perm[lo, hi) so that element k has the key it would have if
 * sorted, smaller-or-equal keys before it and greater-or-equal after
 * (quickselect with a three-way partition: runs of equal coordinates, common
 * on planes and grids, cannot make it quadratic). */
static void kd_select(kd_build *kb, int axis, size_t lo, size_t hi, size_t k)
{
    while (hi - lo > 1) {
        float a = kd_key(kb, lo, axis), b = kd_key(kb, lo + (hi - lo) / 2, axis), c = kd_key(kb, hi - 1, axis);
        float pivot = a < b ? (b < c ? b : (a < c ? c : a)) : (a < c ? a : (b < c ? c : b));
        size_t lt = lo, i = lo, gt = hi;
        while (i < gt) {
            float v = kd_key(kb, i, axis);
            if (v < pivot)
                kd_swap(kb->perm, lt++, i++);
            else if (v > pivot)
                kd_swap(kb->perm, i, --gt);
            else
                i++;
        }
        if (k < lt)
            hi = lt;
        else if (k >= gt)
            lo = gt;
        else
            return;
    }
}

static uint32_t kd_build_node(kd_build *kb, size_t lo, size_t hi)
{
    BF_ASSERT(kb->n_nodes < kb->cap);
    uint32_t id = (uint32_t)kb->n_nodes++;
    kd_node *nd = &kb->nodes[id];
    if (hi - lo <= EVAL__KD_LEAF) {
        *nd = (kd_node){0, KD_LEAF_AXIS, (uint32_t)lo, (uint32_t)hi};
        return id;
    }
    float mn[3] = {INFINITY, INFINITY, INFINITY}, mx[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (size_t i = lo; i < hi; i++)
        for (int k = 0; k < 3; k++) {
            float v = kd_key(kb, i, k);
            mn[k] = fminf(mn[k], v);
            mx[k] = fmaxf(mx[k], v);
        }
    int axis = 0;
    for (int k = 1; k < 3; k++)
        if (mx[k] - mn[k] > mx[axis] - mn[axis]) axis = k;
    size_t mid = lo + (hi - lo) / 2;
    kd_select(kb, axis, lo, hi, mid);
    float split = kd_key(kb, mid, axis);
    uint32_t l = kd_build_node(kb, lo, mid);
    uint32_t r = kd_build_node(kb, mid, hi);
    kb->nodes[id] = (kd_node){split, (uint32_t)axis, l, r};
    return id;
}

bf_status eval__kdtree_build(const float *xyz, size_t n, eval_kdtree **out)
{
    if (n >= UINT32_MAX) return bf_fail(BF_INVALID_ARG, "kd-tree: %zu points (at most 2^32-2)", n);
    eval_kdtree *t = calloc(1, sizeof *t);
    kd_build kb = {.xyz = xyz};
    if (!t) goto oom;
    t->n = n;
    /* Every leaf holds more than EVAL__KD_LEAF / 2 points (median splits of
     * a node with more than EVAL__KD_LEAF), so there are fewer than
     * 2n / EVAL__KD_LEAF + 1 leaves and twice that many nodes. */
    kb.cap = 2 * (2 * n / EVAL__KD_LEAF + 1) + 1;
    kb.nodes = malloc(kb.cap * sizeof *kb.nodes);
    kb.perm = malloc((n ? n : 1) * sizeof *kb.perm);
    t->pts = malloc((n ? n : 1) * 3 * sizeof *t->pts);
    if (!kb.nodes || !kb.perm || !t->pts) goto oom;
    for (size_t i = 0; i < n; i++) kb.perm[i] = (uint32_t)i;
    if (n > 0) kd_build_node(&kb, 0, n);
    for (size_t i = 0; i < n; i++) memcpy(&t->pts[3 * i], &xyz[3 * (size_t)kb.perm[i]], 3 * sizeof(float));
    t->idx = kb.perm;
    t->nodes = kb.nodes;
    t->n_nodes = kb.n_nodes;
    *out = t;
    return BF_OK;
oom:
    free(kb.nodes);
    free(kb.perm);
    if (t) free(t->pts);
    free(t);
    return bf_fail(BF_NO_MEMORY, "kd-tree: out of memory for %zu points", n);
}

void eval__kdtree_destroy(eval_kdtree *t)
{
    if (!t) return;
    free(t->pts);
    free(t->idx);
    free(t->nodes);
    free(t);
}

double eval__kdtree_nearest(const eval_kdtree *t, bf_vec3 p, double max_dist, size_t *idx)
{
    if (!t || t->n == 0 || !(max_dist >= 0)) return INFINITY;
    const double q[3] = {p.x, p.y, p.z};
    double best2 = max_dist == INFINITY ? INFINITY : max_dist * max_dist;
    size_t best = SIZE_MAX;
    /* Each entry carries a lower bound of the squared distance to its node. */
    struct {
        uint32_t node;
        double d2;
    } stack[KD_STACK];
    int sp = 0;
    stack[sp].node = 0;
    stack[sp++].d2 = 0;
    while (sp > 0) {
        uint32_t ni = stack[--sp].node;
        double d2n = stack[sp].d2;
        if (d2n > best2) continue;
        const kd_node *nd = &t->nodes[ni];
        if (nd->axis == KD_LEAF_AXIS) {
            for (uint32_t i = nd->a; i < nd->b; i++) {
                const float *v = &t->pts[3 * (size_t)i];
                double dx = v[0] - q[0], dy = v[1] - q[1], dz = v[2] - q[2];
                double d2 = dx * dx + dy * dy + dz * dz;
                if (d2 < best2 || (d2 == best2 && best == SIZE_MAX)) {
                    best2 = d2;
                    best = i;
                }
            }
            continue;
        }
        double diff = q[nd->axis] - nd->split;
        uint32_t near = diff < 0 ? nd->a : nd->b, far = diff < 0 ? nd->b : nd->a;
        /* The far side lies beyond the splitting plane; keep the larger of
         * the two lower bounds. Push far first so near is searched first. */
        double far2 = fmax(d2n, diff * diff);
        BF_ASSERT(sp + 2 <= KD_STACK);
        if (far2 <= best2) {
            stack[sp].node = far;
            stack[sp++].d2 = far2;
        }
        stack[sp].node = near;
        stack[sp++].d2 = d2n;
    }
    if (best == SIZE_MAX) return INFINITY;
    if (idx) *idx = t->idx[best];
    return sqrt(best2);
}
