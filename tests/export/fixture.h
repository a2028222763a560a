/* Snapshots built on the CPU for the export tests: analytic shapes
 * voxelized into bricks at chosen levels (sign = signed distance >= 0 at the
 * voxel centre, i.e. free), and measures of the exported meshes. */
#ifndef BF_TEST_STREAM_FIXTURE_H
#define BF_TEST_STREAM_FIXTURE_H

#include "eval/eval.h"
#include "export/export.h"

/* Signed distance [m] at world point p: > 0 outside (free space). */
typedef double (*fx_sdf)(const void *shape, bf_vec3 p_w);
/* Whether the brick whose centre is c_w (world) belongs in this pass. */
typedef bool (*fx_pick)(const void *ctx, bf_vec3 c_w);

typedef struct fx_sphere {
    bf_vec3 c;
    double r;
} fx_sphere;
double fx_sphere_sdf(const void *shape, bf_vec3 p);

typedef struct fx_box {
    bf_vec3 c, half; /* axis-aligned */
} fx_box;
double fx_box_sdf(const void *shape, bf_vec3 p);

typedef struct fx_plane {
    bf_vec3 n; /* unit, points to the free side */
    double d;  /* sdf = n . p - d */
} fx_plane;
double fx_plane_sdf(const void *shape, bf_vec3 p);

/* Appends to s every brick of `level` inside the world box [lo, hi] whose
 * centre passes pick (NULL = all) and which lies within band_vox voxels of
 * the surface, with signs from sdf and confidence bits all set (confident)
 * or all clear. s starts zeroed with chunk_m and origin_w set. Aborts on
 * allocation failure (a test fixture). */
void fx_voxelize(hostmap *s, fx_sdf sdf, const void *shape, uint32_t level, bf_vec3 lo, bf_vec3 hi,
                 double band_vox, fx_pick pick, const void *pick_ctx, bool confident);
void fx_free(hostmap *s);
double fx_voxel_m(const hostmap *s, uint32_t level);

/* Edges used by one triangle only, edges used by more than two, and
 * directed edges used twice (inconsistent winding). */
typedef struct fx_topology {
    uint64_t n_boundary, n_nonmanifold, n_flipped;
} fx_topology;
void fx_mesh_topology(const mesh_data *m, fx_topology *out);

/* |sdf| statistics over the vertices and over area samples (1 per
 * (voxel/4)^2) of m: median and max, in metres. Total area in *area. */
typedef struct fx_accuracy {
    double vert_median, vert_max, area_median, area_p99, area_max, area;
} fx_accuracy;
void fx_mesh_accuracy(const mesh_data *m, fx_sdf sdf, const void *shape, double voxel_m, fx_accuracy *out);

#endif
