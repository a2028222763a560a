/* eval internals shared by surface.c and kdtree.c: a static kd-tree over a
 * point cloud for nearest-neighbour queries. Not part of the public API. */
#ifndef BF_EVAL_INT_H
#define BF_EVAL_INT_H

#include "eval/eval.h"

/* A balanced kd-tree (median splits on the widest axis, leaves of at most
 * EVAL__KD_LEAF points) over a copy of the points: the caller's array may be
 * freed after the build. */
typedef struct eval_kdtree eval_kdtree;

#define EVAL__KD_LEAF 8

/* Builds the tree over n points xyz[3 * n]. n == 0 gives an empty tree
 * whose queries return INFINITY. BF_NO_MEMORY on allocation failure. */
bf_status eval__kdtree_build(const float *xyz, size_t n, eval_kdtree **out);
void eval__kdtree_destroy(eval_kdtree *t); /* NULL is a no-op */
/* Distance from p to the nearest point, if it is <= max_dist (INFINITY
 * otherwise, or for an empty tree); *idx (if non-NULL) gets that point's
 * index in the array the tree was built from. Thread-safe (read-only). */
double eval__kdtree_nearest(const eval_kdtree *t, bf_vec3 p, double max_dist, size_t *idx);

#endif
