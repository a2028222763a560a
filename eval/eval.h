/* eval: measures that check the reconstruction, independent of the GPU code
 * they check (DESIGN.md section 8): trajectory error (ATE, RPE as the TUM
 * benchmark tools define them), surface error against a reference mesh, the
 * motion the colour images show and the colour of a coloured mesh (PSNR).
 * Depends on core, mesh, features and calib. See docs/eval.md. */
#ifndef BF_EVAL_H
#define BF_EVAL_H

#include "calib/calib.h"
#include "core/core.h"
#include "mesh/mesh.h"


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
bf_status eval_ate(const bf_traj *gt, const bf_traj *est, double max_dt_s,
                   eval_ate_result *out);

typedef struct eval_rpe_result {
    size_t n_pairs;
    double max_dt_s;       /* the association tolerance used (|dt| <= it): the caller's, else TUM's default */
    eval_err_stats trans;  /* metres per delta */
    eval_err_stats rot;    /* degrees per delta */
} eval_rpe_result;

/* Relative pose error as TUM's evaluate_rpe.py with a fixed delta: per
 * second (delta_s = 1, in seconds) or per frame (delta = 1 frame when
 * per_frame is true, delta_s ignored). */
bf_status eval_rpe(const bf_traj *gt, const bf_traj *est, double max_dt_s, bool per_frame,
                   double delta_s, eval_rpe_result *out);

/* ------------------------------------------------------------ trajectory helpers (docs/eval.md has the formulas)
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
bf_status eval_associate(const bf_traj *gt, const bf_traj *est, double max_dt_s,
                         eval_match **out, size_t *n);

/* Horn's closed-form absolute orientation (unit quaternions, JOSA A 1987):
 * the rigid T (no scale) minimising sum |T * model_i - data_i|^2. Always a
 * proper rotation; degenerate sets (collinear, coincident) give one of the
 * optimal rotations (the identity when all points coincide). */
bf_status eval_horn_align(const bf_vec3 *model, const bf_vec3 *data, size_t n, bf_se3 *T_data_model);

/* rmse, mean, median (numpy's: mean of the middle two), population std,
 * min and max of v[0..n). n == 0: BF_INVALID_ARG. */
bf_status eval_err_stats_compute(const double *v, size_t n, eval_err_stats *out);

/* ------------------------------------------------------------ surface error (docs/eval.md) */

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
    bool used_ref_vertices;  /* ... over the reference's vertices (a point cloud, or triangles without area) */
    double seconds;          /* wall time of the evaluation */
} eval_surface_result;

/* Surface error of rec against the reference ref (a triangle mesh; a point
 * cloud reference is used as points). visible (NULL = none) holds the
 * reference points the camera observed; completeness is then computed over
 * them. Multi-threaded (bf_parallel_for), deterministic for a given config.
 * Empty inputs: BF_INVALID_ARG. */
bf_status eval_surface(const mesh_data *ref, const mesh_data *rec, const mesh_data *visible,
                       const eval_surface_config *cfg, eval_surface_result *out);

/* Area-uniform samples of m's triangles: n = min(max_samples,
 * round(area * samples_per_m2)) (at least 1 for a mesh with area), points
 * drawn with a counter-based generator so the result depends only on seed
 * (not on the thread count). *xyz is malloc'd (3 * n floats); tri (may be
 * NULL) receives a malloc'd array of each sample's triangle. A mesh without
 * area gives n = 0 and NULL arrays. */
bf_status eval_mesh_sample_area(const mesh_data *m, double samples_per_m2, uint64_t max_samples,
                                uint64_t seed, float **xyz, uint32_t **tri, size_t *n);

/* ------------------------------------------------------------ colour */

/* Renders the coloured mesh m (bvh built over it; vertices relative to
 * m->origin) seen by camera K through its lens dist (CALIB_DIST_N
 * Brown-Conrady coefficients; NULL: a pinhole) from T_wc (world): per pixel
 * the colour interpolated at the nearest hit (rgb_out, w*h*3) and whether
 * there is one (hit_out, w*h). BF_INVALID_ARG without vertex colour. */
bf_status eval_colour_render(const mesh_data *m, const mesh_bvh *bvh, const bf_intrinsics *K, const double *dist,
                             const bf_se3 *T_wc, uint8_t *rgb_out, uint8_t *hit_out);
/* Squared 8-bit errors summed over channels and pixels. */
typedef struct eval_colour_sums {
    double sse;
    uint64_t n;     /* channel samples */
} eval_colour_sums;
/* Adds the differences of images a and b (w*h*3) at the pixels mask marks. */
void eval_colour_compare(const uint8_t *a, const uint8_t *b, const uint8_t *mask, size_t n_px, eval_colour_sums *acc);
/* 10 log10(255^2 / MSE) [dB]; NAN without samples. */
double eval_colour_psnr(const eval_colour_sums *s);

/* ------------------------------------------------------------ motion from colour (docs/eval.md)
 * A check of camera poses that needs no ground truth: the motion between
 * two frames as their colour images show it. ORB features of both images
 * (OpenCV's features2d) are matched, the first frame's depth lifts its
 * features to 3-D, and PnP with RANSAC and a Levenberg-Marquardt refinement
 * (calib3d) gives the second camera's pose in the first's frame. The
 * colour carries neither the depth camera's fixed error pattern nor
 * anything of a tracker, so a trajectory, or a ground truth, can be
 * checked against it (bitfuse eval-motion). The colour is registered to
 * the depth (TUM, bitfuse logs), taken as registered (7-Scenes), or a
 * camera of its own on a calibrated rig (eval_motion_rig). */

typedef struct eval_motion_config {
    uint32_t n_features;        /* ORB features per image, default 4000 */
    double ransac_px;           /* RANSAC's reprojection threshold in pixels, default 2 */
    uint32_t ransac_iterations; /* default 2000 */
    uint32_t min_inliers;       /* a pair with fewer gives no motion, default 50 */
    float min_depth_m;          /* features lifted only from depths in */
    float max_depth_m;          /* [min, max], default 0.3 .. 4 m */
} eval_motion_config;

eval_motion_config eval_motion_config_default(void);

/* One frame's ORB features (from the luma of its RGB image). */
typedef struct eval_motion_image eval_motion_image;

/* BF_INVALID_ARG without an image or with a size of 0; BF_NO_MEMORY. */
bf_status eval_motion_image_make(const uint8_t *rgb, uint32_t w, uint32_t h, const eval_motion_config *cfg,
                                 eval_motion_image **out);
void eval_motion_image_free(eval_motion_image *im); /* NULL is a no-op */
uint32_t eval_motion_image_features(const eval_motion_image *im);

typedef struct eval_motion_pair {
    bool ok;                 /* a pose with at least min_inliers inliers */
    bf_se3 T_ab;             /* camera b's pose in camera a's frame (T_wa^-1 T_wb) */
    uint32_t n_matches;      /* mutual nearest neighbours of the descriptors */
    uint32_t n_lifted;       /* of them with a's depth in range */
    uint32_t n_inliers;      /* RANSAC's inliers (0 when none was found) */
    double rms_px;           /* their reprojection RMS after the refinement */
} eval_motion_pair;

/* A colour camera of its own (calib.json): its intrinsics and lens, and
 * where it sits against the depth camera (p_colour = T_colour_depth
 * p_depth). */
typedef struct eval_motion_rig {
    const calib_camera *colour;
    bf_se3 T_colour_depth;
} eval_motion_rig;

/* The motion from a to b: a's features lifted by depth_a (raw units,
 * K->depth_scale per metre, 0 = none; K is the depth camera), matched to
 * b's. rig NULL: the colour is registered to the depth (K is a's and b's
 * colour camera too). With a rig the features are the colour camera's own,
 * lifted by the depth it sees (calib_points_on_colour), PnP runs through
 * its lens, and the motion is the depth camera's, as the trajectories
 * are. Too few inliers is not an error: out->ok is false and the counts
 * say how far it got. BF_INVALID_ARG for images of another size than K's. */
bf_status eval_motion_pnp(const eval_motion_image *a, const uint16_t *depth_a, const bf_intrinsics *K,
                          const eval_motion_rig *rig, const eval_motion_image *b, const eval_motion_config *cfg,
                          eval_motion_pair *out);

/* A trajectory's relative pose over a pair (T_wa, T_wb: its poses of the
 * pair's two frames) against the colour's T_ab. */
typedef struct eval_motion_error {
    double trans_m;   /* |t_traj - t_colour|, in a's camera frame */
    double rot_deg;   /* angle of R_colour^T R_traj */
    double along_m;   /* t_traj . t_colour / |t_colour|: the trajectory's step along the colour's */
    double colour_m;  /* |t_colour| */
} eval_motion_error;

void eval_motion_compare(const bf_se3 *T_ab_colour, const bf_se3 *T_wa, const bf_se3 *T_wb, eval_motion_error *out);

#endif
