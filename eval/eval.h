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

/* ------------------------------------------------------------ synthetic sequences
 * `bitfuse synth`: a CPU ray tracer renders depth and colour of a scene
 * along a trajectory, with a Kinect v1 noise model, into a TUM folder.
 * Files: eval/room.c (scenes), eval/noise.c (sensor model), eval/render.c
 * (renderer), eval/synth.c (sequence). See docs/synth.md. */

typedef enum eval_noise {
    EVAL_NOISE_NONE,    /* ideal sensor: exact depth, rounded to 1/depth_scale */
    EVAL_NOISE_KINECT1, /* Kinect v1 (Nguyen, Izadi, Lovell 2012): eval_kinect1_* */
} eval_noise;

/* Procedural materials: the albedo is a function of the world point, so no
 * texture coordinates are needed. */
typedef enum eval_material {
    EVAL_MAT_PLAIN,   /* flat grey (meshes given with --scene MESH.ply) */
    EVAL_MAT_FLOOR,   /* wooden planks */
    EVAL_MAT_WALL,    /* painted plaster with blotches and posters */
    EVAL_MAT_CEILING, /* off-white tiles */
    EVAL_MAT_TABLE,   /* dark wood */
    EVAL_MAT_BOX,     /* two-tone checker, colour by variant */
    EVAL_MAT_OBJECT,  /* mottled solid colour, colour by variant */
    EVAL_MAT_COUNT
} eval_material;

/* A scene to render: one mesh in world coordinates (metres) plus a material
 * and a variant (which colour) per triangle. Owns all arrays. */
typedef struct eval_scene {
    eval_mesh mesh;          /* world frame, metres; mesh.normal holds vertex normals */
    uint8_t *tri_material;   /* eval_material, one per triangle */
    uint8_t *tri_variant;    /* one per triangle */
    bf_vec3 light_w;         /* point light for Lambert shading */
    bf_se3 T_wc_view;        /* where the first camera of a trajectory is placed */
    char desc[512];          /* what went in, for the log and stats.json */
} eval_scene;

/* The procedural room (room.c): 4 x 3.5 x 2.5 m, z up, floor at z = 0, with a
 * table, boxes and, when data_dir/meshes holds them, the bunny, armadillo and
 * dragon scaled to 15-25 cm standing on the table. data_dir may be NULL or
 * lack the meshes: the room is built without them (logged). */
bf_status eval_scene_room(const char *data_dir, eval_scene *out);
/* A scene of one PLY mesh, vertices multiplied by scale (metres after
 * scaling). The view looks at the mesh's box centre along -z from where its
 * bounding sphere fills the image (fx = 525, 480 rows), y up. */
bf_status eval_scene_from_ply(const char *path, double scale, eval_scene *out);
/* Takes ownership of mesh (left zeroed) as a scene with material PLAIN and
 * the given view; for tests and custom scenes. Computes vertex normals. */
bf_status eval_scene_from_mesh(eval_mesh *mesh, const bf_se3 *T_wc_view, eval_scene *out);
void eval_scene_free(eval_scene *s); /* NULL is a no-op */
/* Camera-to-world pose of a camera at eye looking at target (camera x
 * right, y down, z forward; up_w is the world's up). */
bf_se3 eval_look_at(bf_vec3 eye_w, bf_vec3 target_w, bf_vec3 up_w);

/* Kinect v1 sensor model (noise.c). z in metres along the optical axis,
 * theta the angle between the viewing ray and the surface normal. */
#define EVAL_KINECT1_BASELINE_M 0.075  /* projector - IR camera */
#define EVAL_KINECT1_DISP_STEP_PX 0.125 /* disparity in 1/8 pixel steps */
#define EVAL_KINECT1_Z_MIN_M 0.5
#define EVAL_KINECT1_Z_MAX_M 4.5
#define EVAL_KINECT1_MAX_THETA_DEG 80.0 /* no depth at more grazing angles */
/* Axial (depth) standard deviation of Nguyen et al. 2012, eq. (2) and (3):
 * 0.0012 + 0.0019 (z - 0.4)^2 [+ 0.0001 / sqrt(z) theta^2 / (pi/2 - theta)^2
 * beyond 60 degrees]. This is the total, quantisation included. */
double eval_kinect1_axial_sigma(double z_m, double theta_rad);
/* Lateral standard deviation in pixels: 0.8 + 0.035 theta / (pi/2 - theta). */
double eval_kinect1_lateral_sigma_px(double theta_rad);
/* Depth step of the disparity quantisation at z: z^2 step / (baseline fx). */
double eval_kinect1_depth_step(double z_m, double fx_px);
/* The Gaussian part: sqrt(axial^2 - step^2 / 12), so that the Gaussian plus
 * the (uniform) quantisation error have the model's variance. */
double eval_kinect1_gauss_sigma(double z_m, double theta_rad, double fx_px);
/* Depth after quantising its disparity on the grid (k + offset) * step,
 * offset in [0, 1); z <= 0 gives 0. */
double eval_kinect1_quantize(double z_m, double fx_px, double offset);

/* The renderer: one per image size and scene, reused for every frame. */
typedef struct eval_render_config {
    bf_intrinsics K;   /* size, pinhole (ray through the pixel centre), depth_scale */
    eval_noise noise;
    uint64_t seed;
} eval_render_config;

typedef struct eval_render_stats {
    uint32_t n_hit;    /* pixels whose ray hit the scene */
    uint32_t n_valid;  /* pixels with depth after the sensor model */
    double seconds;
} eval_render_stats;

typedef struct eval_renderer eval_renderer;
/* Builds the scene's BVH and the image buffers. The scene is borrowed and
 * must outlive the renderer. */
bf_status eval_renderer_create(const eval_scene *scene, const eval_render_config *cfg, eval_renderer **out);
void eval_renderer_destroy(eval_renderer *r); /* NULL is a no-op */
/* Renders the frame numbered frame (it keys the noise) at camera pose T_wc
 * into depth (width*height raw units, 0 = none) and rgb (width*height*3,
 * may be NULL). Multi-threaded; the result depends only on the scene, the
 * config, frame and T_wc. st may be NULL. */
bf_status eval_render(eval_renderer *r, uint32_t frame, const bf_se3 *T_wc, uint16_t *depth, uint8_t *rgb,
                      eval_render_stats *st);
/* The noise-free world point seen at pixel (u, v) in the last eval_render,
 * true only if that pixel got valid depth. */
bool eval_render_clean_point(const eval_renderer *r, uint32_t u, uint32_t v, bf_vec3 *p_w);

/* A whole sequence (synth.c): what `bitfuse synth` runs. */
typedef struct eval_synth_config {
    const char *scene;      /* "room" or a PLY path */
    const char *data_dir;   /* shared data for the room's meshes; NULL = none */
    double mesh_scale;      /* for a PLY scene; 0 = 1 */
    const char *traj_path;  /* TUM trajectory the camera follows */
    uint32_t n_frames;      /* frames to render (fewer if the trajectory ends) */
    double rate_hz;         /* 0 = 30 */
    eval_noise noise;
    uint64_t seed;
    bf_intrinsics K;        /* size 0 = 640x480; fx 0 = 525, 525, (w-1)/2, (h-1)/2;
                               depth_scale 0 = 5000 */
    const char *out_dir;
    double seen_cell_m;     /* seen.ply grid; 0 = 0.005 */
} eval_synth_config;

typedef struct eval_synth_result {
    uint32_t n_frames;      /* written */
    double mean_frame_s, median_frame_s; /* render time per frame */
    double total_s;         /* wall time of the whole run (scene, BVH, PNGs, ...) */
    double valid_share;     /* valid depth pixels / all pixels */
    bf_se3 T_world_traj;    /* placement: rendered pose = T_world_traj * trajectory pose */
    uint32_t n_seen;        /* points in seen.ply */
    uint32_t n_scene_tris;
} eval_synth_result;

/* Renders cfg->n_frames frames at cfg->rate_hz from the trajectory's first
 * timestamp, poses interpolated (replay_traj_interpolate) and placed by
 * T_world_traj = scene.T_wc_view * inv(first pose), and writes out_dir:
 * rgb/, depth/, rgb.txt, depth.txt, groundtruth.txt (rendered poses),
 * camera.txt, scene.ply, seen.ply, stats.json. A trajectory shorter than
 * requested stops early with a warning; no frame at all is BF_INVALID_ARG. */
bf_status eval_synth_run(const eval_synth_config *cfg, eval_synth_result *out);

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

/* ------------------------------------------------------------ trajectory helpers
 * (added with eval/traj.c; docs/eval.md has the formulas)
 *
 * eval_ate: max_dt_s <= 0 means TUM's 0.02 s; as in associate.py a pair
 * must satisfy |dt| < max_dt_s (strictly). Fewer than two pairs: BF_FORMAT.
 * eval_rpe: max_dt_s bounds the gap between an estimated stamp and its
 * nearest ground-truth stamp; <= 0 means TUM's rule, twice the median
 * ground-truth sampling interval. Every pair is evaluated (evaluate_rpe.py
 * --fixed_delta --max_pairs 0). Fewer than two pairs: BF_FORMAT. */

/* One associated pose pair: indices into gt and est. */
typedef struct eval_match {
    size_t i_gt, i_est;
} eval_match;

/* TUM associate.py: all pairs with |t_gt - t_est| < max_dt_s (<= 0: 0.02 s),
 * taken greedily in order of |dt|, each pose used at most once; sorted by
 * gt time. *out is malloc'd (free it), *n may be 0. */
bf_status eval_associate(const replay_traj *gt, const replay_traj *est, double max_dt_s,
                         eval_match **out, size_t *n);

/* Horn's closed-form absolute orientation (unit quaternions, JOSA A 1987):
 * the rigid T (no scale) minimising sum |T * model_i - data_i|^2. Always a
 * proper rotation; degenerate sets (collinear, coincident) give one of the
 * optimal rotations (the identity when all points coincide). */
bf_status eval_horn_align(const bf_vec3 *model, const bf_vec3 *data, size_t n, bf_se3 *T_data_model);

/* rmse, mean, median (numpy's: mean of the middle two), population std,
 * min and max of v[0..n). n == 0: BF_INVALID_ARG. */
bf_status eval_err_stats_compute(const double *v, size_t n, eval_err_stats *out);

/* ------------------------------------------------------------ surface error
 * (added with eval/surface.c; docs/eval.md) */

typedef struct eval_surface_config {
    double threshold_m;       /* completeness threshold [m], default 0.01 */
    double max_dist_m;        /* distances beyond are left out of the statistics
                                 and counted in n_beyond; default INFINITY */
    double samples_per_m2;    /* area-uniform sampling density, default 2e5
                                 (one sample per 5 mm^2) */
    uint64_t max_samples;     /* cap per sampled mesh, default 1,000,000 */
    uint64_t seed;            /* sampling seed, default 1 */
} eval_surface_config;

/* The defaults above. */
eval_surface_config eval_surface_config_default(void);

typedef struct eval_dist_stats {
    size_t n;            /* distances in the statistics (<= max_dist) */
    size_t n_beyond;     /* points with nothing within max_dist (left out) */
    size_t n_within;     /* distances <= threshold */
    double mean, median, p90, rmse, max; /* metres, NaN when n == 0 */
} eval_dist_stats;

typedef struct eval_surface_result {
    /* Accuracy: from each reconstruction point (its vertices plus, for a
     * mesh, area samples of its triangles) to the reference surface. */
    eval_dist_stats accuracy;
    size_t n_rec_vertices, n_rec_samples;
    /* Completeness: from each reference point (area samples of the
     * reference, or the visible points when given) to the reconstruction
     * (its points, and its surface when it is a mesh). */
    eval_dist_stats completeness_dist;
    double completeness;     /* n_within / all reference points, in [0, 1] */
    double precision;        /* accuracy.n_within / all reconstruction points */
    size_t n_ref_points;
    bool used_visible;       /* completeness over the visibility mask */
    double seconds;          /* wall time of the evaluation */
} eval_surface_result;

/* Surface error of rec against the reference ref (a triangle mesh; a point
 * cloud reference is used as points). visible (NULL = none) holds the
 * reference points the camera observed; completeness is then computed over
 * them. Multi-threaded (bf_parallel_for), deterministic for a given config.
 * Empty inputs: BF_INVALID_ARG. */
bf_status eval_surface(const eval_mesh *ref, const eval_mesh *rec, const eval_mesh *visible,
                       const eval_surface_config *cfg, eval_surface_result *out);

/* Area-uniform samples of m's triangles: n = min(max_samples,
 * round(area * samples_per_m2)) (at least 1 for a mesh with area), points
 * drawn with a counter-based generator so the result depends only on seed
 * (not on the thread count). *xyz is malloc'd (3 * n floats); tri (may be
 * NULL) receives a malloc'd array of each sample's triangle. A mesh without
 * area gives n = 0 and NULL arrays. */
bf_status eval_mesh_sample_area(const eval_mesh *m, double samples_per_m2, uint64_t max_samples,
                                uint64_t seed, float **xyz, uint32_t **tri, size_t *n);

#endif
