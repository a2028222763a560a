/* features: the boundary between features.c and the C++ file that calls
 * OpenCV (features_cv.cpp). Plain C types only: C++ never sees core.h, and
 * C never sees an exception. Each int function returns FEATURES__OK or
 * FEATURES__ERR_* with a message in msg (cap bytes). Not public API. */
#ifndef BF_FEATURES_INT_H
#define BF_FEATURES_INT_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

enum {
    FEATURES__OK = 0,
    FEATURES__ERR_OPENCV = 1, /* a cv::Exception or another failure inside OpenCV */
    FEATURES__ERR_MEMORY = 2, /* std::bad_alloc */
    FEATURES__ERR_ARG = 3,    /* the caller's mistake (a set not lifted where one must be) */
};

typedef struct features_set features_set;

int features__detect(const uint8_t *grey, int w, int h, int n_features, int keep_image, features_set **out,
                     char *msg, size_t cap);
void features__free(features_set *f);
int features__count(const features_set *f);
size_t features__bytes(const features_set *f);

/* K: fx fy cx cy; depth: w*h raw units, scale per metre. */
int features__lift(const features_set *f, const uint16_t *depth, int w, int h, double scale, const double K[4],
                   double min_m, double max_m, int keep_image, features_set **out, char *msg, size_t cap);

/* xyz: w*h*3 floats, NaN where none. */
int features__lift_points(const features_set *f, const float *xyz, int w, int h, double min_m, double max_m,
                          int keep_image, features_set **out, char *msg, size_t cap);

/* Lifted keypoints with a point: count, then copies into desc (n x 32) and xyz (n x 3). */
int features__lifted_count(const features_set *f);
void features__lifted_copy(const features_set *f, uint8_t *desc, float *xyz);
int features__import(uint32_t n, const uint8_t *desc, const float *xyz, features_set **out, char *msg, size_t cap);

typedef struct features__pnp_out {
    int ok;
    uint32_t n_matches, n_placed, n_inliers;
    double rms_px;
    double R_ba[9], t_ba[3]; /* X_b = R X_a + t, row-major, metres */
} features__pnp_out;

/* Distinctive matches of a's lifted keypoints in b (features_match_count). */
int features__match_count(const features_set *a, const features_set *b, int max_hamming, uint32_t *n, char *msg,
                          size_t cap);

/* dist: 5 coefficients or NULL. */
int features__pnp(const features_set *a, const features_set *b, const double K[4], const double *dist, double ransac_px,
                  int ransac_iterations, int max_hamming, int fast, features__pnp_out *r, char *msg, size_t cap);

#ifdef __cplusplus
}
#endif

#endif
