/* features: ORB keypoints of a colour image, lifted to 3D by its depth, and
 * the camera pose that puts one image's lifted keypoints where another
 * image's keypoints are (PnP with RANSAC). OpenCV's features2d, video and
 * calib3d behind one C++ file (features_cv.cpp): no C++ type or exception
 * crosses this header.
 *
 * Two users: eval's motion from colour (bitfuse eval-motion, a check of
 * poses that needs no ground truth) and recon's relocalisation (a lost
 * frame matched to the keyframes' lifted keypoints, docs/tracking.md). */
#ifndef BF_FEATURES_H
#define BF_FEATURES_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "core/core.h"

/* One image's keypoints and their binary descriptors; after features_lift,
 * also each keypoint's point in the camera. Opaque. */
typedef struct features_set features_set;

/* ORB keypoints (at most n_features) of an 8-bit RGB image (w*h*3), seen
 * as BT.601 luma. keep_image keeps the grey image, which features_pnp then
 * uses to place each match again by Lucas-Kanade (costs w*h bytes). */
bf_status features_detect_rgb(const uint8_t *rgb, uint32_t w, uint32_t h, uint32_t n_features, bool keep_image,
                              features_set **out);
void features_free(features_set *f); /* NULL is a no-op */
uint32_t features_count(const features_set *f);
/* Bytes the set holds (keypoints, descriptors, points, kept image). */
size_t features_bytes(const features_set *f);

/* A new set of f's keypoints, each with its point in the camera (pinhole
 * K) where depth (K's size, raw units: K->depth_scale per metre, 0 =
 * none) at its nearest pixel lies in [min_m, max_m], and no point where
 * it does not: those stay for the mutual matching (eval's, which sees
 * what it saw before lifting) and are left out of PnP and of the
 * distinctive matching. The grey image comes along when f kept one and
 * keep_image asks for it. */
bf_status features_lift(const features_set *f, const uint16_t *depth, const bf_intrinsics *K, float min_m,
                        float max_m, bool keep_image, features_set **out);

/* The same from points already found for the image's pixels (w x h x 3
 * floats, NaN: none; calib_points_on_colour's, where the colour camera is
 * not the depth camera, so the points are in the depth camera's frame),
 * each on the ray through its pixel's centre: a keypoint takes the point
 * at its sub-pixel place, bilinearly between its four pixels' points
 * where all four lie within 3% of the nearest pixel's depth (one smooth
 * surface), else the nearest pixel's (a depth edge), where that point's z
 * lies in [min_m, max_m]. */
bf_status features_lift_points(const features_set *f, const float *xyz, uint32_t w, uint32_t h, float min_m,
                               float max_m, bool keep_image, features_set **out);

/* The keypoints of a lifted set f that have a point, as plain arrays: *n
 * ORB descriptors of 32 bytes (*desc) and points x y z in the camera
 * (*xyz, floats), both malloc'd (NULL when none): what a store keeps of
 * a keyframe. */
bf_status features_export_lifted(const features_set *f, uint32_t *n, uint8_t **desc, float **xyz);
/* A lifted set made from such arrays (keyframes read back): a first set
 * for features_pnp and features_match_count; it has no keypoint
 * positions and no image, so Lucas-Kanade never runs from it. */
bf_status features_import_lifted(uint32_t n, const uint8_t *desc, const float *xyz, features_set **out);

typedef struct features_pnp_config {
    double ransac_px;           /* RANSAC's reprojection threshold [px] */
    uint32_t ransac_iterations; /* RANSAC's iterations (OpenCV's fixed seed: the same pair gives the same pose) */
    uint32_t min_inliers;       /* a pose with fewer inliers is not one */
    uint32_t max_hamming;       /* matches further apart in bits (of 256) are dropped; 0: none dropped */
    /* false: mutual nearest neighbours (eval's motion, where every match counts); true: distinctive
       matches only (features_match_count's): fewer, more often right, so RANSAC stops sooner, in about
       a third of the time (recon's relocalisation). AP3P's four-point samples were tried for it too:
       4.9 cm off where EPnP's were 8 mm (tests/features), so RANSAC draws EPnP's either way. */
    bool fast;
} features_pnp_config;

typedef struct features_pnp_result {
    bool ok;            /* a pose was found with at least min_inliers (else the counts say how far it got) */
    uint32_t n_matches; /* matches (mutual or distinctive, cfg->fast) within max_hamming */
    uint32_t n_placed;  /* of them with a lifted point, and kept by Lucas-Kanade where both have images */
    uint32_t n_inliers; /* RANSAC's */
    double rms_px;      /* reprojection RMS of the inliers after refinement */
    bf_se3 T_ba;        /* a's camera points into b's camera: X_b = T_ba X_a */
} features_pnp_result;

/* How many of a's lifted keypoints have a distinctive match among b's: the
 * nearest within max_hamming bits (0: any) and nearer than 0.8 times the
 * second nearest (Lowe's ratio). A cheap, exact ranking of which keyframes
 * see what a frame sees, before PnP (about a millisecond per 1000 x 1000
 * keypoints). */
bf_status features_match_count(const features_set *a, const features_set *b, uint32_t max_hamming, uint32_t *n);

/* The pose of b's camera against a's lifted points (a from features_lift,
 * features_lift_points or features_import_lifted; b from
 * features_detect_rgb; b's keypoints seen by camera K with the
 * lens dist, k1 k2 p1 p2 k3 as OpenCV orders them, NULL: none): matches
 * (cfg->fast says which), then, when both kept their images, each match
 * placed again in b by Lucas-Kanade, then EPnP in RANSAC and
 * Levenberg-Marquardt on the inliers. */
bf_status features_pnp(const features_set *a, const features_set *b, const bf_intrinsics *K, const double *dist,
                       const features_pnp_config *cfg, features_pnp_result *out);

#endif
