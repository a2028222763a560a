/* calib: camera calibration from views of a planar checkerboard (`bitfuse
 * calibrate`): the intrinsics and lens distortion of the colour camera and,
 * given views of the same board from the depth (IR) camera, its intrinsics
 * and the rigid transform between the two (Zhang 2000, "A flexible new
 * technique for camera calibration", through OpenCV's calib3d:
 * findChessboardCorners, cornerSubPix, calibrateCamera, stereoCalibrate).
 * The calibration file (calib.json, docs/formats.md) is read and written
 * here in C; only calib_cv.cpp is C++, behind calib_int.h, and no C++
 * exception crosses into C. Depends on core (and, privately, OpenCV and
 * cJSON). See docs/calibration.md. */
#ifndef BF_CALIB_H
#define BF_CALIB_H

#include "core/core.h"

/* k1 k2 p1 p2 k3: radial (k) and tangential (p) coefficients of the
 * Brown-Conrady model in OpenCV's order. */
#define CALIB_DIST_N 5

/* One camera: pinhole intrinsics (pixel centres at integers, as
 * bf_intrinsics and OpenCV have them) and distortion of the normalised
 * image point. */
typedef struct calib_camera {
    uint32_t width, height;   /* pixels */
    double fx_px, fy_px, cx_px, cy_px;
    double dist[CALIB_DIST_N];
    double rms_px;            /* reprojection RMS of its own calibration (0: not measured) */
    /* How far out the board's corners reached: the largest distance of a
     * found corner from the principal point over that of the farthest image
     * corner, in normalised image coordinates (1: the image's corners;
     * 0: not measured). The distortion beyond it is extrapolated. */
    double coverage;
    /* How uncertain that extrapolation is: where coverage < 1, the fit with
     * the other number of radial terms (two or three), which agrees with
     * this one within the boards, differs from it by this much at the
     * farthest image corner or edge centre (pixels; 0: not measured). */
    double extrapolation_px;
} calib_camera;

/* Above this extrapolation_px (pixels) calibrate and the readers of a
 * calib.json warn: the corner finder's 0.05 px and the fit's other errors
 * stay far below it. */
#define CALIB_EXTRAPOLATION_WARN_PX 1.0

/* What a calibration file holds. T_colour_depth takes points of the depth
 * camera's frame to the colour camera's: p_colour = T_colour_depth * p_depth. */
typedef struct calib_result {
    calib_camera colour;
    bool has_depth;           /* depth (and T_colour_depth) are set */
    calib_camera depth;
    bf_se3 T_colour_depth;
    double rms_px;            /* the stereo reprojection RMS with depth, else the colour camera's */
    uint32_t n_views;         /* views used: with depth, those whose board both cameras found */
} calib_result;

/* A checkerboard: cols x rows inner corners (where four squares meet),
 * squares square_m metres wide. Corner (i, j), i < cols, j < rows, lies at
 * (i, j) * square_m on the board's plane z = 0. Boards whose cols + rows is
 * odd (9 x 6) look different turned by 180 degrees, so the corners of two
 * cameras' views pair up without doubt (calib_find_corners). */
typedef struct calib_board {
    uint32_t cols, rows;
    double square_m;
} calib_board;

#define CALIB_MIN_VIEWS 3     /* Zhang's method needs three views of the plane for five intrinsics */
#define CALIB_MAX_CORNERS 4096

/* Parses "COLSxROWS" (each 2..64); BF_INVALID_ARG with the reason otherwise. */
bf_status calib_parse_board(const char *text, calib_board *out);

/* Finds the board's inner corners in one 8-bit grey image (w*h, borrowed):
 * findChessboardCorners, then cornerSubPix in an 11 x 11 window (OpenCV).
 * *is_found false (BF_OK) when the board is not in the image. Found corners
 * go to corners_px (cols*rows (x, y) pairs, row j after row j-1), ordered
 * so that the square outside corner (0, 0) is the darker one: then two
 * cameras' lists of one view name the same corners. BF_NUMERIC for an
 * OpenCV error, with its message. */
bf_status calib_find_corners(const calib_board *b, const uint8_t *grey, uint32_t w, uint32_t h, bool *is_found,
                             double *corners_px);

/* The corners of one camera's views: n_views lists of calib_find_corners,
 * one after another (borrowed), is_found[k] false where view k's board was
 * not found (its list is not read). */
typedef struct calib_views {
    uint32_t n_views;
    uint32_t width, height;   /* the camera's image size */
    const double *corners_px; /* n_views * cols * rows * 2 */
    const bool *is_found;
} calib_views;

/* What calib_estimate fits. */
typedef struct calib_config {
    /* Radial distortion terms, 3 (k1 k2 k3, OpenCV's default) or 2 (k3 held
     * at 0, MATLAB's and ROS's default). Neither extrapolates well past the
     * boards: on boards that reached half-way to the corners, a mild lens
     * (k1 0.1, k2 -0.2) fitted with three terms was 27 px off at the image's
     * corners and 0.2 px with two, and TUM's fr1 lens (k3 1.16) 4-34 px
     * with three and 59 px with two (docs/calibration.md). Hence
     * calib_camera.extrapolation_px. */
    uint32_t radial_terms;
} calib_config;

calib_config calib_config_default(void);

/* Calibrates the colour camera from its views (calibrateCamera: k1 k2, k3
 * with cfg->radial_terms 3, p1 p2) and, when depth is not NULL, the depth
 * camera from its views and the pair from the views both found (stereoCalibrate
 * with the two cameras' intrinsics fixed: each camera is best measured
 * alone, and the pair's views then only carry the six unknowns of the
 * transform). depth's views pair with colour's by index. Fewer than
 * CALIB_MIN_VIEWS usable views is BF_FORMAT; OpenCV's failure BF_NUMERIC.
 * *out is written only on success. */
bf_status calib_estimate(const calib_board *b, const calib_config *cfg, const calib_views *colour,
                         const calib_views *depth, calib_result *out);

/* ------------------------------------------------------------ calib.json */

/* Writes r to path atomically (temporary file, rename); numbers with 17
 * significant digits, so a file read back gives the same doubles. */
bf_status calib_write(const char *path, const calib_result *r);
/* The same JSON as a malloc'd NUL-terminated text (for --json and
 * stats.json); free() it. */
bf_status calib_to_text(const calib_result *r, char **text);
/* Reads and checks a calibration file: BF_IO when unreadable, BF_FORMAT
 * naming the file and the field for anything missing or wrong (not JSON,
 * a missing number, a non-finite one, a focal length <= 0, a principal
 * point outside the image, a rotation that is not one). Fields it does not
 * know are ignored. *out is written only on success. */
bf_status calib_read(const char *path, calib_result *out);
/* The same checks on a text already read; path names it in messages. */
bf_status calib_parse(const char *path, const char *text, size_t len, calib_result *out);

/* ------------------------------------------------------------ the model (model.c) */

/* Brown-Conrady distortion of a normalised image point (x, y) = (X/Z, Y/Z),
 * as OpenCV's projectPoints applies it (Brown 1966; OpenCV's calib3d docs):
 * r2 = x^2 + y^2, radial 1 + k1 r2 + k2 r2^2 + k3 r2^3, tangential
 * 2 p1 x y + p2 (r2 + 2 x^2) and p1 (r2 + 2 y^2) + 2 p2 x y. */
void calib_distort(const double dist[CALIB_DIST_N], double x, double y, double *xd, double *yd);
/* Its inverse by Newton's method on the 2 x 2 system, to 1e-12 in the
 * normalised plane for the mild lenses of RGB-D cameras; false when it does
 * not converge (a point far outside the image of a strong lens). */
bool calib_undistort(const double dist[CALIB_DIST_N], double xd, double yd, double *x, double *y);
/* Projects camera point p_c to pixels through c's distortion; false when
 * p_c.z <= 0. */
bool calib_project(const calib_camera *c, bf_vec3 p_c, double *u_px, double *v_px);
/* The ray (z = 1) through pixel (u, v); false as calib_undistort. */
bool calib_unproject(const calib_camera *c, double u_px, double v_px, bf_vec3 *ray_c);

/* A camera's pinhole part as core's intrinsics (distortion dropped;
 * depth_scale left 0 for the caller). */
bf_intrinsics calib_camera_intrinsics(const calib_camera *c);

/* ------------------------------------------------------------ undistorted images (undistort.c) */

/* A lens's distortion taken out of its images: each pixel of the pinhole
 * camera with the same fx, fy, cx, cy takes the image's pixel nearest to
 * where the lens put that ray (calib_distort), as OpenCV's remap with
 * initUndistortRectifyMap and INTER_NEAREST does. Nearest, not
 * interpolated: a depth sample is never blended across a depth edge (it
 * moves by at most half a pixel), and its value, the depth along the
 * optical axis, does not change with the pixel's place. Pixels whose ray
 * the lens puts outside the image get 0 (no depth; black). */
typedef struct calib_undistort_map {
    uint32_t width, height;
    int32_t *src;  /* width*height: the source pixel of each pixel, -1 for none; owned */
    uint32_t n_outside; /* pixels with no source */
    double max_shift_px; /* the largest distance between a pixel and its source */
} calib_undistort_map;

/* Builds the map of camera c (its size, intrinsics and dist). BF_INVALID_ARG
 * naming the coefficients when the lens folds the image over itself within
 * its corners (the radial term's r (1 + k1 r^2 + k2 r^4 + k3 r^6) stops
 * growing before the corners' radius: the model does not describe a real
 * lens there). *out is written on success; free with
 * calib_undistort_map_free. */
bf_status calib_undistort_map_make(const calib_camera *c, calib_undistort_map *out);
void calib_undistort_map_free(calib_undistort_map *m); /* zeroes *m; NULL is a no-op */
/* dst[i] = src[map->src[i]] (0 where none); dst must not be src. rgb8:
 * three bytes a pixel. */
void calib_undistort_u16(const calib_undistort_map *m, const uint16_t *src, uint16_t *dst);
void calib_undistort_rgb8(const calib_undistort_map *m, const uint8_t *src, uint8_t *dst);
/* Whether any coefficient is non-zero. */
bool calib_has_distortion(const double dist[CALIB_DIST_N]);

/* ------------------------------------------------------------ depth seen from the colour camera (register.c) */

/* The depth camera's points as a separate colour camera sees them: for
 * each pixel of the colour camera's w x h image, the point of depth (Kd;
 * Kd->depth_scale raw units a metre) that the colour camera sees there,
 * in the depth camera's frame (x y z floats, NaN where none). Each depth
 * pixel's point is moved into the colour camera (p_colour =
 * T_colour_depth p_depth) and projected through its lens
 * (calib_project); a colour pixel takes, of the points landing within 0.9
 * pixel of its centre along both axes and not hidden behind the nearest of
 * them (by 3% of the depth or 1 cm), the one landing nearest its centre,
 * moved at its depth (along the colour camera's axis) onto the ray through
 * the pixel's centre (to first order: the pinhole's scale, which the lens
 * changes by a few per cent). What is found in the colour camera's own
 * image (ORB keypoints) is then lifted as if the device had registered the
 * two, between pixels where they lie on one surface (features_lift_points).
 * xyz: w x h x 3 floats. */
bf_status calib_points_on_colour(const calib_camera *colour, const bf_se3 *T_colour_depth, const bf_intrinsics *Kd,
                                 const uint16_t *depth, uint32_t w, uint32_t h, float *xyz);

/* ------------------------------------------------------------ depth correction (depth.c, depth_json.c) */

/* The depth camera's fixed error pattern (vertical bands and a slow bowl of
 * a few parts per thousand on Kinect v1; Smisek et al. 2011), as one
 * multiplier per cell of cell_px x cell_px pixels, the same at every depth:
 * corrected depth = raw depth x the multiplier, bilinear between the cells'
 * centres (calib_depth_map). Estimated from a sequence and its trajectory
 * by pairs of frames (calib_depth_estimate: the self-calibration of
 * Teichman, Miller and Thrun 2013, "CLAMS", in its simplest form); the
 * image's mean multiplier is 1 (a scale error of the whole image is not
 * seen by pairs of frames). Written as depth_correction.json
 * (docs/formats.md); replay, live and fuse take it with --depth-correction. */
#define CALIB_DEPTH_GRID_MAX 4800u /* cells: 40 x 30 of 16 px at 640 x 480, 80 x 60 of 8 px at 640 x 480 */
#define CALIB_DEPTH_GAPS 2u
typedef struct calib_depth_correction {
    uint32_t width, height;   /* the depth image it applies to */
    uint32_t cell_px;
    uint32_t grid_w, grid_h;  /* ceil(width / cell_px), ceil(height / cell_px) */
    float mult[CALIB_DEPTH_GRID_MAX]; /* grid_h rows of grid_w: raw depth times this */
    /* How it was made (reported; 0 when unknown): frames and pairs used, the
     * cells with enough samples, and the RMS over those cells of the
     * pattern measured before the first pass and after the last. */
    uint32_t n_frames, n_pairs, n_cells_measured;
    double rms_before, rms_after;
    /* The lens taken out of the frames it was made from (all 0: read as a
     * pinhole), when is_lens_known: the pattern lies in those frames'
     * pixels, so frames read through another lens must not take it
     * (calib_depth_same_lens). Files written before the field: unknown. */
    bool is_lens_known;
    double lens[CALIB_DIST_N];
} calib_depth_correction;
/* Whether frames read through lens dist (NULL or all 0: a pinhole) are in
 * the pixels c was made in; true when c does not say. */
bool calib_depth_same_lens(const calib_depth_correction *c, const double *dist);

typedef struct calib_depth_config {
    uint32_t cell_px;       /* 16 */
    uint32_t gaps[CALIB_DEPTH_GAPS]; /* the pairs: frames this many apart (by index), 15 and 30; 0: unused */
    uint32_t stride;        /* a pair's first frame every stride frames, 3 */
    uint32_t iterations;    /* passes that update the multipliers, 10 (a last one measures what is left) */
    float max_depth_m;      /* samples beyond are not used, 4 m */
    float agree;            /* a landed point counts where |z_a - z_b->a| < agree z_a (else another surface), 0.04 */
    uint32_t min_samples;   /* a cell's multiplier moves only with this many samples in a pass, 100 */
} calib_depth_config;
calib_depth_config calib_depth_config_default(void);

/* n depth images (raw units, depth_scale per metre), each with its index in
 * the sequence (increasing) and its camera-to-world pose. Only frames the
 * pairs need are read (stride, gaps): a caller may keep only those. */
typedef struct calib_depth_frames {
    uint32_t n;
    const uint16_t *const *depth;
    const uint32_t *index;
    const bf_se3 *T_wc;
    bf_intrinsics K;
} calib_depth_frames;

/* BF_FORMAT when no pair of frames is at a gap; *out written on success. */
bf_status calib_depth_estimate(const calib_depth_config *cfg, const calib_depth_frames *in,
                               calib_depth_correction *out);
/* The smallest and largest multiplier of the grid. */
void calib_depth_range(const calib_depth_correction *c, float *lo, float *hi);
/* The multiplier of every pixel (width x height floats). */
void calib_depth_map(const calib_depth_correction *c, float *map);
/* dst = round(src x map), 0 stays 0 (no depth), clamped to [1, 65535]; dst may be src. */
void calib_depth_apply(const float *map, const uint16_t *src, uint16_t *dst, size_t n);
/* depth_correction.json: atomic write; read checks every field (BF_IO
 * unreadable, BF_FORMAT naming the file and field). */
bf_status calib_depth_write(const char *path, const calib_depth_correction *c);
bf_status calib_depth_read(const char *path, calib_depth_correction *c);
bf_status calib_depth_parse(const char *path, const char *text, size_t len, calib_depth_correction *c);

#endif
