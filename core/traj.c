/* core: trajectories (timestamped camera poses) and the TUM rule for
 * associating two lists of timestamps. Their files are replay's. */
#include "core.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

bf_status bf_traj_push(bf_traj *traj, double t_s, const bf_se3 *T_wc)
{
    if (traj->n >= traj->cap) {
        size_t cap = traj->cap > traj->n ? traj->cap : traj->n;
        cap = cap < 64 ? 64 : 2 * cap;
        double *t = bf_realloc(traj->t_s, cap * sizeof *t);
        if (!t) return bf_fail(BF_NO_MEMORY, "trajectory of %zu poses", cap);
        traj->t_s = t;
        bf_se3 *T = bf_realloc(traj->T_wc, cap * sizeof *T);
        if (!T) return bf_fail(BF_NO_MEMORY, "trajectory of %zu poses", cap);
        traj->T_wc = T;
        traj->cap = cap;
    }
    traj->t_s[traj->n] = t_s;
    traj->T_wc[traj->n] = *T_wc;
    traj->n++;
    return BF_OK;
}


void bf_traj_free(bf_traj *traj)
{
    if (!traj) return;
    free(traj->t_s);
    free(traj->T_wc);
    memset(traj, 0, sizeof *traj);
}


bool bf_traj_interpolate(const bf_traj *traj, double t_s, bf_se3 *T_wc)
{
    size_t n = traj->n;
    if (n == 0 || !(t_s >= traj->t_s[0]) || !(t_s <= traj->t_s[n - 1])) return false;
    /* Binary search for the last sample at or before t_s. */
    size_t lo = 0, hi = n - 1;
    while (hi - lo > 1) {
        size_t mid = lo + (hi - lo) / 2;
        if (traj->t_s[mid] <= t_s)
            lo = mid;
        else
            hi = mid;
    }
    if (traj->t_s[lo] == t_s || lo == hi) {
        *T_wc = traj->T_wc[lo];
        return true;
    }
    if (traj->t_s[hi] == t_s) {
        *T_wc = traj->T_wc[hi];
        return true;
    }
    double s = (t_s - traj->t_s[lo]) / (traj->t_s[hi] - traj->t_s[lo]);
    *T_wc = bf_se3_interpolate(&traj->T_wc[lo], &traj->T_wc[hi], s);
    return true;
}


/* A candidate pair of bf_associate_stamps. */
typedef struct assoc_cand {
    double dt_s;
    size_t a, b;
} assoc_cand;

static int assoc_cand_cmp(const void *pa, const void *pb)
{
    const assoc_cand *x = pa, *y = pb;
    /* associate.py sorts the tuples (|dt|, stamp_a, stamp_b); stamps
     * increase, so comparing indices orders the ties the same way. */
    if (x->dt_s != y->dt_s) return x->dt_s < y->dt_s ? -1 : 1;
    if (x->a != y->a) return x->a < y->a ? -1 : 1;
    return (x->b > y->b) - (x->b < y->b);
}

bf_status bf_associate_stamps(const double *t_a, size_t n_a, const double *t_b, size_t n_b, double max_dt_s,
                              size_t *b_of_a)
{
    /* A sliding window over the sorted stamps finds the same candidates as
     * the script's n x m loop. The window compares |t_a - t_b| itself, never
     * t_a - max_dt_s: at 1.3e9 s a double's spacing is 2.4e-7 s, so the
     * shifted bound could round a pair just inside the tolerance out. */
    size_t n = 0, cap = 0, lo = 0;
    assoc_cand *c = NULL;
    for (size_t a = 0; a < n_a; a++) {
        double ta = t_a[a];
        while (lo < n_b && t_b[lo] < ta && !(fabs(ta - t_b[lo]) < max_dt_s)) lo++;
        for (size_t b = lo; b < n_b; b++) {
            double dt = fabs(ta - t_b[b]);
            if (!(dt < max_dt_s)) {
                if (t_b[b] > ta) break;
                continue;
            }
            if (n == cap) {
                size_t nc = cap ? 2 * cap : 1024;
                assoc_cand *nb = bf_realloc(c, nc * sizeof *nb);
                if (!nb) {
                    free(c);
                    return bf_fail(BF_NO_MEMORY, "associating %zu with %zu timestamps", n_a, n_b);
                }
                c = nb;
                cap = nc;
            }
            c[n++] = (assoc_cand){dt, a, b};
        }
    }
    if (n) qsort(c, n, sizeof *c, assoc_cand_cmp);
    bool *is_b_used = bf_calloc(n_b ? n_b : 1, 1);
    if (!is_b_used) {
        free(c);
        return bf_fail(BF_NO_MEMORY, "associating %zu with %zu timestamps", n_a, n_b);
    }
    for (size_t a = 0; a < n_a; a++) b_of_a[a] = SIZE_MAX;
    for (size_t k = 0; k < n; k++)
        if (b_of_a[c[k].a] == SIZE_MAX && !is_b_used[c[k].b]) {
            b_of_a[c[k].a] = c[k].b;
            is_b_used[c[k].b] = true;
        }
    free(is_b_used);
    free(c);
    return BF_OK;
}
