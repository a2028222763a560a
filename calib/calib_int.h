/* calib: the boundary between the C side (calib.c, calib_json.c) and the
 * C++ file that calls OpenCV (calib_cv.cpp). Plain C types only: C++ never
 * sees core.h, and C never sees an exception. Each function returns 0 on
 * success or CALIB__ERR_* with a message in msg (cap bytes). */
#ifndef BF_CALIB_INT_H
#define BF_CALIB_INT_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

enum {
    CALIB__OK = 0,
    CALIB__ERR_OPENCV = 1, /* a cv::Exception or another failure inside OpenCV */
    CALIB__ERR_MEMORY = 2, /* std::bad_alloc */
};

/* calib_find_corners's work: *found 0 or 1, corners as it documents. */
int calib__cv_find_corners(const uint8_t *grey, int w, int h, int cols, int rows, int *found, double *corners,
                           char *msg, size_t cap);

/* calibrateCamera on n views of n_corners object points each (obj: x, y
 * per corner, z = 0; img: corners of view k at img + 2 * n_corners * k);
 * fix_k3: k3 held at 0 (CALIB_FIX_K3).
 * K: fx fy cx cy; dist: k1 k2 p1 p2 k3; *rms: OpenCV's RMS reprojection
 * error in pixels. */
int calib__cv_calibrate(int n, int n_corners, const double *obj, const double *img, int w, int h, int fix_k3,
                        double K[4], double dist[5], double *rms, char *msg, size_t cap);

/* stereoCalibrate with both intrinsics fixed: camera 1 is the depth
 * camera, 2 the colour camera, so (R, t) takes depth points to colour
 * ones. R row-major. */
int calib__cv_stereo(int n, int n_corners, const double *obj, const double *img1, const double *img2, int w1, int h1,
                     const double K1[4], const double d1[5], const double K2[4], const double d2[5], double R[9],
                     double t[3], double *rms, char *msg, size_t cap);

#ifdef __cplusplus
}
#endif

#endif
