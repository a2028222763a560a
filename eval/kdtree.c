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

/* The build permutes the tree's own copy of the points (and their original
 * indices) in place, so every pass over a node reads one contiguous run
 * instead of chasing an index array through the caller's points. */
typedef struct kd_build {
    float *pts;
    uint32_t *idx;
    kd_node *nodes;
    size_t n_nodes, cap;
} kd_build;

static void kd_swap(kd_build *kb, size_t i, size_t j)
{
    float t[3];
    memcpy(t, &kb->pts[3 * i], sizeof t);
    memcpy(&kb->pts[3 * i], &kb->pts[3 * j], sizeof t);
    memcpy(&kb->pts[3 * j], t, sizeof t);
    uint32_t u = kb->idx[i];
    kb->idx[i] = kb->idx[j];
    kb->idx[j] = u;
}

/* Reorders [lo, hi) so that element k has the key it would have if sorted,
 * smaller-or-equal keys before it and greater-or-equal after (quickselect
 * with a three-way partition: runs of equal coordinates, common on planes
 * and grids, cannot make it quadratic). */
static void kd_select(kd_build *kb, int axis, size_t lo, size_t hi, size_t k)
{
    const float *p = kb->pts + axis;
    while (hi - lo > 1) {
        float a = p[3 * lo], b = p[3 * (lo + (hi - lo) / 2)], c = p[3 * (hi - 1)];
        float pivot = a < b ? (b < c ? b : (a < c ? c : a)) : (a < c ? a : (b < c ? c : b));
        size_t lt = lo, i = lo, gt = hi;
        while (i < gt) {
            float v = p[3 * i];
            if (v < pivot)
                kd_swap(kb, lt++, i++);
            else if (v > pivot)
                kd_swap(kb, i, --gt);
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

/* box: bounds of the node's points, tight at the root and narrowed by the
 * split planes below it (a looser box only changes which axis is split). */
static uint32_t kd_build_node(kd_build *kb, size_t lo, size_t hi, const float box[6])
{
    BF_ASSERT(kb->n_nodes < kb->cap);
    uint32_t id = (uint32_t)kb->n_nodes++;
    kd_node *nd = &kb->nodes[id];
    if (hi - lo <= EVAL__KD_LEAF) {
        *nd = (kd_node){0, KD_LEAF_AXIS, (uint32_t)lo, (uint32_t)hi};
        return id;
    }
    int axis = 0;
    for (int k = 1; k < 3; k++)
        if (box[3 + k] - box[k] > box[3 + axis] - box[axis]) axis = k;
    size_t mid = lo + (hi - lo) / 2;
    kd_select(kb, axis, lo, hi, mid);
    float split = kb->pts[3 * mid + axis];
    float lbox[6], rbox[6];
    memcpy(lbox, box, sizeof lbox);
    memcpy(rbox, box, sizeof rbox);
    lbox[3 + axis] = split;
    rbox[axis] = split;
    uint32_t l = kd_build_node(kb, lo, mid, lbox);
    uint32_t r = kd_build_node(kb, mid, hi, rbox);
    kb->nodes[id] = (kd_node){split, (uint32_t)axis, l, r};
    return id;
}

bf_status eval__kdtree_build(const float *xyz, size_t n, eval_kdtree **out)
{
    if (n >= UINT32_MAX) return bf_fail(BF_INVALID_ARG, "kd-tree: %zu points (at most 2^32-2)", n);
    eval_kdtree *t = bf_calloc(1, sizeof *t);
    kd_build kb = {0};
    if (!t) goto oom;
    t->n = n;
    /* Every leaf holds more than EVAL__KD_LEAF / 2 points (median splits of
     * a node with more than EVAL__KD_LEAF), so there are fewer than
     * 2n / EVAL__KD_LEAF + 1 leaves and twice that many nodes. */
    kb.cap = 2 * (2 * n / EVAL__KD_LEAF + 1) + 1;
    kb.nodes = bf_malloc(kb.cap * sizeof *kb.nodes);
    kb.idx = bf_malloc((n ? n : 1) * sizeof *kb.idx);
    kb.pts = bf_malloc((n ? n : 1) * 3 * sizeof *kb.pts);
    if (!kb.nodes || !kb.idx || !kb.pts) goto oom;
    if (n) memcpy(kb.pts, xyz, n * 3 * sizeof *kb.pts);
    for (size_t i = 0; i < n; i++) kb.idx[i] = (uint32_t)i;
    if (n > 0) {
        float box[6] = {INFINITY, INFINITY, INFINITY, -INFINITY, -INFINITY, -INFINITY};
        for (size_t i = 0; i < n; i++)
            for (int k = 0; k < 3; k++) {
                box[k] = fminf(box[k], kb.pts[3 * i + k]);
                box[3 + k] = fmaxf(box[3 + k], kb.pts[3 * i + k]);
            }
        kd_build_node(&kb, 0, n, box);
    }
    t->pts = kb.pts;
    t->idx = kb.idx;
    t->nodes = kb.nodes;
    t->n_nodes = kb.n_nodes;
    *out = t;
    return BF_OK;
oom:
    free(kb.nodes);
    free(kb.idx);
    free(kb.pts);
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
    /* Each entry carries a lower bound of the squared distance to its node,
     * the sum over the axes of the squared distance from q to the node's
     * slab on that axis (Arya and Mount's incremental distance, 1993). A
     * bound from one axis alone lets a query far from the cloud visit
     * nearly every node. */
    struct {
        uint32_t node;
        double d2;
        double off[3]; /* distance from q to the node's region along each axis */
    } stack[KD_STACK];
    int sp = 0;
    stack[sp].node = 0;
    stack[sp].d2 = 0;
    stack[sp].off[0] = stack[sp].off[1] = stack[sp].off[2] = 0;
    sp++;
    while (sp > 0) {
        sp--;
        uint32_t ni = stack[sp].node;
        double d2n = stack[sp].d2;
        double off[3] = {stack[sp].off[0], stack[sp].off[1], stack[sp].off[2]};
        /* The bound sums three rounded squares: allow for its rounding so a
         * point exactly on a splitting plane is never pruned. */
        if (d2n > best2 * (1 + 1e-12)) continue;
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
        /* The far side begins at the splitting plane, which lies at least as
         * far from q on this axis as the node's own region does: its offset
         * on the axis becomes |diff|, the others stay. Push far first so
         * near is searched first. */
        double far2 = d2n - off[nd->axis] * off[nd->axis] + diff * diff;
        if (far2 < d2n) far2 = d2n; /* rounding */
        BF_ASSERT(sp + 2 <= KD_STACK);
        if (far2 <= best2 * (1 + 1e-12)) {
            stack[sp].node = far;
            stack[sp].d2 = far2;
            memcpy(stack[sp].off, off, sizeof off);
            stack[sp].off[nd->axis] = fabs(diff);
            sp++;
        }
        stack[sp].node = near;
        stack[sp].d2 = d2n;
        memcpy(stack[sp].off, off, sizeof off);
        sp++;
    }
    if (best == SIZE_MAX) return INFINITY;
    if (idx) *idx = t->idx[best];
    return sqrt(best2);
}
