/* mesh: triangle meshes and point clouds on the host (flat arrays), their
 * PLY reader and writer, and a bounding-volume hierarchy for ray casts and
 * closest-point queries. What export writes, eval measures and synth
 * renders. Depends on core only. */
#ifndef BF_MESH_H
#define BF_MESH_H

#include "core/core.h"


/* ------------------------------------------------------------ meshes */

/* A triangle mesh or point cloud (n_tris == 0), flat arrays. */
typedef struct mesh_data {
    uint32_t n_verts, n_tris;
    float *xyz;      /* 3 * n_verts */
    float *normal;   /* 3 * n_verts or NULL */
    uint8_t *rgb;    /* 3 * n_verts or NULL */
    uint32_t *tri;   /* 3 * n_tris vertex indices */
} mesh_data;

/* Reads a PLY (ascii, binary little- or big-endian) with vertex x y z
 * (float or double), optional nx ny nz, red green blue (uchar), and faces
 * as lists of int/uint indices (polygons are fanned into triangles). Other
 * properties are skipped. Index out of range, truncation, NaN: BF_FORMAT. */
bf_status mesh_read_ply(const char *path, mesh_data *out);
/* Writes binary little-endian PLY (with normals / colour when present). */
bf_status mesh_write_ply(const char *path, const mesh_data *m);
void mesh_free(mesh_data *m);
/* Appends a copy of src transformed by T (vertices and normals). */
bf_status mesh_append(mesh_data *dst, const mesh_data *src, const bf_se3 *T);

/* ------------------------------------------------------------ BVH */

/* Bounding-volume hierarchy over a mesh's triangles (binned SAH), for ray
 * casting (synth) and closest-point queries (surface error). Borrows the
 * mesh, which must outlive it. */
typedef struct mesh_bvh mesh_bvh;

typedef struct mesh_hit {
    double t;         /* ray parameter of the hit */
    uint32_t tri;     /* triangle index */
    double u, v;      /* barycentrics of vertices 1 and 2 */
} mesh_hit;

bf_status mesh_bvh_build(const mesh_data *m, mesh_bvh **out);
void mesh_bvh_destroy(mesh_bvh *b);
/* Nearest hit with t in (t_min, t_max) of the ray o + t d; false if none.
 * Thread-safe (read-only). */
bool mesh_bvh_raycast(const mesh_bvh *b, bf_vec3 o, bf_vec3 d, double t_min, double t_max,
                      mesh_hit *hit);
/* Closest point of the mesh surface to p within max_dist; returns its
 * distance (INFINITY if none within max_dist) and, if non-NULL, the point
 * and triangle. Thread-safe. */
double mesh_bvh_closest(const mesh_bvh *b, bf_vec3 p, double max_dist, bf_vec3 *closest,
                        uint32_t *tri);

#endif
