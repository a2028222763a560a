/* eval: measures that check the reconstruction, independent of the GPU code
 * they check (DESIGN.md section 8): trajectory error (ATE, RPE as the TUM
 * benchmark tools define them), surface error against a reference mesh, and
 * the synthetic sequence generator (a CPU ray tracer with a Kinect v1 noise
 * model). Depends on core and replay (trajectory files, image writers).
 * See docs/eval.md. */
#ifndef BF_EVAL_H
#define BF_EVAL_H

#include "core/core.h"
#include "replay/replay.h"

/* ------------------------------------------------------------ meshes */

/* A triangle mesh or point cloud (n_tris == 0), flat arrays. */
typedef struct eval_mesh {
    uint32_t n_verts, n_tris;
    float *xyz;      /* 3 * n_verts */
    float *normal;   /* 3 * n_verts or NULL */
    uint8_t *rgb;    /* 3 * n_verts or NULL */
    uint32_t *tri;   /* 3 * n_tris vertex indices */
} eval_mesh;

/* Reads a PLY (ascii, binary little- or big-endian) with vertex x y z
 * (float or double), optional nx ny nz, red green blue (uchar), and faces
 * as lists of int/uint indices (polygons are fanned into triangles). Other
 * properties are skipped. Index out of range, truncation, NaN: BF_FORMAT. */
bf_status eval_mesh_read_ply(const char *path, eval_mesh *out);
/* Writes binary little-endian PLY (with normals / colour when present). */
bf_status eval_mesh_write_ply(const char *path, const eval_mesh *m);
void eval_mesh_free(eval_mesh *m);
/* Appends a copy of src transformed by T (vertices and normals). */
bf_status eval_mesh_append(eval_mesh *dst, const eval_mesh *src, const bf_se3 *T);

/* ------------------------------------------------------------ BVH */

/* Bounding-volume hierarchy over a mesh's triangles (binned SAH), for ray
 * casting (synth) and closest-point queries (surface error). Borrows the
 * mesh, which must outlive it. */
typedef struct eval_bvh eval_bvh;

typedef struct eval_hit {
    double t;         /* ray parameter of the hit */
    uint32_t tri;     /* triangle index */
    double u, v;      /* barycentrics of vertices 1 and 2 */
} eval_hit;

bf_status eval_bvh_build(const eval_mesh *m, eval_bvh **out);
void eval_bvh_destroy(eval_bvh *b);
/* Nearest hit with t in (t_min, t_max) of the ray o + t d; false if none.
 * Thread-safe (read-only). */
bool eval_bvh_raycast(const eval_bvh *b, bf_vec3 o, bf_vec3 d, double t_min, double t_max,
                      eval_hit *hit);
/* Closest point of the mesh surface to p within max_dist; returns its
 * distance (INFINITY if none within max_dist) and, if non-NULL, the point
 * and triangle. Thread-safe. */
double eval_bvh_closest(const eval_bvh *b, bf_vec3 p, double max_dist, bf_vec3 *closest,
                        uint32_t *tri);

/* ------------------------------------------------------------ trajectory */

typedef struct eval_err_stats {
    double rmse, mean, median, std, min, max;
} eval_err_stats;

typedef struct eval_ate_result {
    size_t n_matched;      /* pose pairs associated */
    eval_err_stats trans;  /* translational error after alignment, metres */
    bf_se3 T_gt_est;       /* Horn alignment taking est into gt's frame */
} eval_ate_result;

/* Absolute trajectory error as TUM's evaluate_ate.py: associate by nearest
 * timestamp (|dt| <= max_dt_s, 0.02 s in TUM), align est to gt with Horn's
 * closed form (rotation + translation, no scale), error statistics. */
bf_status eval_ate(const replay_traj *gt, const replay_traj *est, double max_dt_s,
                   eval_ate_result *out);

typedef struct eval_rpe_result {
    size_t n_pairs;
    eval_err_stats trans;  /* metres per delta */
    eval_err_stats rot;    /* degrees per delta */
} eval_rpe_result;

/* Relative pose error as TUM's evaluate_rpe.py with a fixed delta: per
 * second (delta_s = 1, in seconds) or per frame (delta = 1 frame when
 * per_frame is true, delta_s ignored). */
bf_status eval_rpe(const replay_traj *gt, const replay_traj *est, double max_dt_s, bool per_frame,
                   double delta_s, eval_rpe_result *out);

#endif
