/* mesh: triangle meshes and point clouds on the host (flat arrays), their
 * PLY reader and writer, and a bounding-volume hierarchy for ray casts and
 * closest-point queries. What export writes, eval measures and synth
 * renders. Depends on core only. */
#ifndef BF_MESH_H
#define BF_MESH_H

#include "core/core.h"


/* ------------------------------------------------------------ meshes */

/* The largest vertex coordinate the readers take: a float's steps there are
 * 64 units, so no scene lies beyond, and a value past it (1e30 in a cut or
 * corrupt file) would stall every distance query that meets it. */
#define MESH_MAX_COORD 1e9

/* A triangle mesh or point cloud (n_tris == 0), flat arrays. Vertex i lies
 * at world point origin + xyz[i]: floats keep about 7 digits, so a mesh far
 * from the world origin (10 km: 1 mm steps) keeps its vertices relative to
 * a local origin held in double. (0, 0, 0) for a mesh in world coordinates;
 * the writers record a non-zero origin (docs/export.md, "Far from the
 * origin") and mesh_read_ply reads it back. */
typedef struct mesh_data {
    uint32_t n_verts, n_tris;
    float *xyz;      /* 3 * n_verts, relative to origin */
    float *normal;   /* 3 * n_verts or NULL */
    uint8_t *rgb;    /* 3 * n_verts or NULL (sRGB, as the camera gives it) */
    uint32_t *tri;   /* 3 * n_tris vertex indices */
    bf_vec3 origin;  /* world position of the local origin [m] */
} mesh_data;

/* Reads a PLY (ascii, binary little- or big-endian) with vertex x y z
 * (float or double), optional nx ny nz, red green blue (uchar), and faces
 * as lists of int/uint indices (polygons are fanned into triangles). Other
 * properties are skipped; a header comment "origin_w X Y Z" (as
 * mesh_write_ply writes it) sets out->origin; double positions beyond 1024
 * (the file's units) are kept relative to the first vertex's position,
 * rounded, which is added to out->origin (a reader adds origin to xyz).
 * Index out of range, truncation, NaN: BF_FORMAT. */
bf_status mesh_read_ply(const char *path, mesh_data *out);
/* Reads an OFF mesh (Geomview's format: "OFF", counts, x y z lines, faces as
 * "n i0 .. i(n-1)", polygons fanned into triangles, '#' comments, a face's
 * colour skipped). A bad count, index or number: BF_FORMAT naming the line. */
bf_status mesh_read_off(const char *path, mesh_data *out);
/* mesh_read_off for a name ending .off (any case), else mesh_read_ply. */
bf_status mesh_read(const char *path, mesh_data *out);
void mesh_free(mesh_data *m);
/* Appends a copy of src transformed by T (vertices and normals), in dst's
 * local frame: src's world points T * (src.origin + xyz) minus dst.origin
 * (an empty dst takes src's origin). */
bf_status mesh_append(mesh_data *dst, const mesh_data *src, const bf_se3 *T);
/* The edges of m (vertices at equal positions, bit for bit, taken as one)
 * that an odd number of triangles share: 0 for a closed surface; otherwise
 * the rims of its holes, edges where three faces meet, and T-junctions (a
 * vertex on another triangle's edge) (mesh/topology.c). BF_INVALID_ARG for
 * an index out of range. */
bf_status mesh_open_edges(const mesh_data *m, uint64_t *out);

/* ------------------------------------------------------------ writing (mesh/ply.c, obj.c, gltf.c) */

/* Every writer writes a temporary file beside path and renames it into
 * place once complete (fsync first), so path holds either its old content
 * or the whole new file, never a part; on failure the temporary file is
 * removed. A non-zero m->origin is recorded (PLY: header comment "origin_w
 * X Y Z"; OBJ: comment; glTF: the node's translation). An empty mesh gives
 * a valid empty file. BF_IO names the file, BF_INVALID_ARG a malformed mesh
 * (an index out of range). */
typedef enum mesh_format {
    MESH_FORMAT_PLY, /* binary little-endian PLY: positions, normals, colour (uchar) */
    MESH_FORMAT_OBJ, /* Wavefront OBJ + MTL: "v x y z r g b", "vn", "f a//a b//b c//c" */
    MESH_FORMAT_GLB, /* glTF 2.0 binary: POSITION, NORMAL, COLOR_0, uint32 indices */
} mesh_format;

/* "ply", "obj", "glb". */
const char *mesh_format_name(mesh_format f);
/* The format of a name ("ply", "obj", "glb", any case): false for another. */
bool mesh_format_parse(const char *name, mesh_format *out);
/* The format of path's extension (.ply, .obj, .glb, any case); BF_INVALID_ARG
 * naming the path for another or none. */
bf_status mesh_format_of_path(const char *path, mesh_format *out);
/* Writes m to path in format f (one of the writers below). */
bf_status mesh_write(const char *path, mesh_format f, const mesh_data *m);
/* Binary little-endian PLY (with normals / colour when present). */
bf_status mesh_write_ply(const char *path, const mesh_data *m);
/* Wavefront OBJ with a material file beside it (path with .mtl for its
 * extension, named by "mtllib"): vertex colours as the common
 * "v x y z r g b" extension (r, g, b in [0, 1]; MeshLab, Blender, Open3D
 * read it), normals as "vn", faces "f a//a b//b c//c"; a point cloud has
 * only "v" lines. Both files are written atomically, the material first. */
bf_status mesh_write_obj(const char *path, const mesh_data *m);
/* glTF 2.0 binary (.glb; Khronos glTF 2.0 specification): one node (its
 * translation = m->origin when non-zero) with one mesh of one primitive:
 * POSITION (float VEC3, with min/max), NORMAL (unit float VEC3) and COLOR_0
 * (float VEC3, linear: the sRGB colours converted) when present, uint32
 * indices for triangles (mode 4) or none for a point cloud (mode 0, POINTS);
 * a matte, double-sided material (open scans are seen from both sides).
 * BF_UNSUPPORTED when the file would pass the format's 4 GiB. */
bf_status mesh_write_glb(const char *path, const mesh_data *m);

/* ------------------------------------------------------------ simplification (mesh/simplify.c) */

/* Edge-collapse simplification by meshoptimizer's meshopt_simplify (Garland
 * & Heckbert 1997 quadric error metrics, vertices kept in place: the result
 * uses a subset of the input's vertices, so normals and colours stay those
 * of the full mesh). */
typedef struct mesh_simplify_config {
    /* Hard cap on triangles (0: none). When the topology-preserving
     * collapses cannot get there (the error bound stops them, or they run
     * out of legal collapses), the rest is cut by meshopt_simplifySloppy
     * (vertex clustering), counted in used_sloppy. */
    uint64_t max_triangles;
    /* Stop collapsing where the next collapse would move the surface more
     * than this [m] (meshoptimizer's quadric estimate; 0: no bound). With a
     * cap, the cap wins when both cannot hold. */
    double max_error_m;
} mesh_simplify_config;

typedef struct mesh_simplify_stats {
    uint64_t tris_before, tris_after, verts_before, verts_after;
    /* meshoptimizer's estimate of the distance the collapses moved the
     * surface [m] (a sum over the passes run: a bound, not a measurement). */
    double error_m;
    bool used_sloppy;
    double seconds;
} mesh_simplify_stats;

/* Simplifies m in place: *m is replaced by the simplified mesh (vertices
 * compacted in order of first use, attributes carried along) only on
 * success. A point cloud or a mesh already within the cap and without an
 * error bound is left as is. st may be NULL. BF_NO_MEMORY. */
bf_status mesh_simplify(mesh_data *m, const mesh_simplify_config *cfg, mesh_simplify_stats *st);

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
