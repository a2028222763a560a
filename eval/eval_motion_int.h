/* eval: the boundary between motion.c and the C++ file that calls OpenCV
 * (motion_cv.cpp). Plain C types only: C++ never sees core.h, and C never
 * sees an exception. Each int function returns EVAL__CV_OK or
 * EVAL__CV_ERR_* with a message in msg (cap bytes). Not public API. */
#ifndef BF_EVAL_MOTION_INT_H
#define BF_EVAL_MOTION_INT_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

enum {
    EVAL__CV_OK = 0,
    EVAL__CV_ERR_OPENCV = 1, /* a cv::Exception or another failure inside OpenCV */
    EVAL__CV_ERR_MEMORY = 2, /* std::bad_alloc */
};

/* ORB keypoints and descriptors of one grey image. */
typedef struct eval__cv_features eval__cv_features;

int eval__cv_features_make(const uint8_t *grey, int w, int h, int n_features, eval__cv_features **out, char *msg,
                           size_t cap);
void eval__cv_features_free(eval__cv_features *f); /* NULL is a no-op */
int eval__cv_features_count(const eval__cv_features *f);

typedef struct eval__cv_pnp_result {
    int ok;                  /* a pose was found (else the counts say how far it got) */
    uint32_t n_matches;      /* mutual nearest neighbours */
    uint32_t n_lifted;       /* of them with depth in a */
    uint32_t n_inliers;      /* RANSAC's */
    double rms_px;           /* reprojection RMS of the inliers after refinement */
    double R_ba[9], t_ba[3]; /* X_b = R X_a + t, row-major, metres */
} eval__cv_pnp_result;

/* a's features lifted by depth_a_m (w*h metres, 0 = none; a pixel's depth
 * at the feature's nearest pixel), their places in b refined by
 * Lucas-Kanade, PnP with RANSAC (EPnP, ransac_px, ransac_iterations;
 * OpenCV's fixed seed), then Levenberg-Marquardt on the inliers. K: fx fy
 * cx cy. */
int eval__cv_pnp(const eval__cv_features *a, const float *depth_a_m, const eval__cv_features *b, int w, int h,
                 const double K[4], double ransac_px, int ransac_iterations, eval__cv_pnp_result *r, char *msg,
                 size_t cap);

#ifdef __cplusplus
}
#endif

#endif
