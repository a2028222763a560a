/* export: meshes and point clouds of the map (DESIGN.md section 2). Both
 * functions read the host copy of the map (hostmap/hostmap.h; export never
 * touches the GPU) and write a mesh_data in world coordinates, which
 * mesh_write_ply saves.
 *
 * Rules shared by both exports (docs/export.md has the details):
 *  - Only confident voxels produce geometry. Where bricks of several levels
 *    overlap, the finest confident voxel containing a point wins.
 *  - Voxel (x, y, z) of a brick at level L has its centre at
 *    origin_w + key * chunk_m + (cell * 8 + (x, y, z) + 0.5) * v(L),
 *    v(L) = chunk_m / 8 / 2^L.
 *  - Results depend only on the set of bricks: not on their order in the
 *    snapshot, nor on the thread count.
 *  - An empty snapshot gives an empty mesh (BF_OK). On failure *out is
 *    untouched.
 *  - Far from the world origin a float cannot hold a voxel's position (its
 *    step is 1 mm at 10 km), so positions are computed in double and stored
 *    relative to out->origin = export_local_origin(s): (0, 0, 0) (world
 *    coordinates) for a map within EXPORT_WORLD_FLOAT_M of the world
 *    origin, else the centre of the map's bounding box in whole metres.
 */
#ifndef BF_EXPORT_H
#define BF_EXPORT_H

#include "core/core.h"
#include "mesh/mesh.h"
#include "hostmap/hostmap.h"

/* Beyond this distance from the world origin [m] an export stores its
 * vertices relative to a local origin: within it a float's rounding stays
 * below 31 micrometres (half its step of 2^-14 m below 1024 m). */
#define EXPORT_WORLD_FLOAT_M 1000.0

/* The local origin of s's exports (the rule above). */
bf_vec3 export_local_origin(const hostmap *s);

/* Counters of one export. Levels beyond 15 are counted in index 15. */
typedef struct export_stats {
    uint32_t level_out;            /* level of the mesh's cell lattice (mesh export) */
    uint32_t n_bricks;             /* bricks used */
    uint32_t n_duplicates;         /* bricks with the same level and place as another, ignored */
    uint64_t n_cells;              /* cells that produced triangles */
    uint64_t n_triangles, n_vertices;
    uint64_t n_points;             /* surface voxels (point export) */
    uint32_t bricks_per_level[16];
    uint64_t cells_per_level[16];  /* by the level of the data at the cell's first corner */
    uint64_t points_per_level[16];
    double seconds;                /* wall time */
} export_stats;

typedef struct export_mesh_config {
    /* Level of the marching-cubes lattice. UINT32_MAX (the default) = the
     * finest level in the snapshot; coarser data is sampled on it (so the
     * mesh is closed across levels), finer data is averaged. A lower value
     * bounds the triangle count of maps with a few very fine bricks. */
    uint32_t max_level;
    /* Taubin smoothing (Taubin 1995): iterations of a lambda step followed
     * by a mu step on the uniform umbrella Laplacian. Defaults 0.5, -0.53, 5. */
    float taubin_lambda, taubin_mu;
    uint32_t taubin_iterations;
} export_mesh_config;

/* The defaults above. */
export_mesh_config export_mesh_config_default(void);

/* Triangle mesh of the confident surface: marching cubes (Lorensen & Cline
 * 1987) on one lattice of voxel centres, corners classified by the sign bit
 * of the finest confident voxel containing them, vertices placed at the
 * zero crossing of a smoothed sign field, then Taubin smoothing.
 * Indexed (welded) mesh, triangles wound so their normals point to the free
 * side (sign 1), per-vertex normals, world coordinates (less out->origin). Closed wherever the
 * surface runs through known (confident) space, also across bricks, chunks
 * and level transitions. cfg NULL = defaults; st may be NULL.
 * BF_INVALID_ARG for a malformed snapshot (level > 20, cell outside its
 * chunk, chunk_m <= 0) or config, BF_UNSUPPORTED for chunk keys so large the
 * lattice coordinates would overflow, BF_NO_MEMORY. *out is owned by the
 * caller (mesh_free). */
bf_status export_mesh(const hostmap *s, const export_mesh_config *cfg, mesh_data *out,
                             export_stats *st);

/* Point cloud (n_tris = 0) of surface voxel centres: confident voxels, not
 * overridden by finer confident data, with a 6-neighbour of the other sign
 * (the neighbour's centre sampled from the finest confident data, so across
 * bricks, chunks and levels). Normals: gradient of the smoothed sign field,
 * pointing to the free side. World coordinates (less out->origin). Failures
 * as for the mesh. */
bf_status export_points(const hostmap *s, mesh_data *out, export_stats *st);

#endif
