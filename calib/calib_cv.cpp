// calib: the only C++ of bitfuse, a thin layer over OpenCV's calib3d
// (calib_int.h). Every entry point catches everything: a C++ exception
// must never unwind through C frames.
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cstdio>
#include <new>
#include <vector>

#include "calib_int.h"

namespace {

int fail(int code, char *msg, size_t cap, const char *what)
{
    std::snprintf(msg, cap, "%s", what);
    return code;
}

// Runs fn, turning exceptions into the boundary's codes.
template <class F> int guarded(char *msg, size_t cap, F fn)
{
    try {
        fn();
        return CALIB__OK;
    } catch (const cv::Exception &e) {
        return fail(CALIB__ERR_OPENCV, msg, cap, e.what());
    } catch (const std::bad_alloc &) {
        return fail(CALIB__ERR_MEMORY, msg, cap, "out of memory");
    } catch (const std::exception &e) {
        return fail(CALIB__ERR_OPENCV, msg, cap, e.what());
    } catch (...) {
        return fail(CALIB__ERR_OPENCV, msg, cap, "unknown exception");
    }
}

// Mean grey in a 3 x 3 window at (x, y), clamped to the image.
double grey_at(const cv::Mat &im, cv::Point2f p)
{
    int x0 = cvRound(p.x), y0 = cvRound(p.y), n = 0;
    double sum = 0;
    for (int y = y0 - 1; y <= y0 + 1; y++)
        for (int x = x0 - 1; x <= x0 + 1; x++)
            if (x >= 0 && y >= 0 && x < im.cols && y < im.rows) {
                sum += im.at<uint8_t>(y, x);
                n++;
            }
    return n ? sum / n : 0;
}

std::vector<cv::Point3f> object_points(int n_corners, const double *obj)
{
    std::vector<cv::Point3f> o((size_t)n_corners);
    for (int i = 0; i < n_corners; i++) o[(size_t)i] = cv::Point3f((float)obj[2 * i], (float)obj[2 * i + 1], 0.f);
    return o;
}

std::vector<std::vector<cv::Point2f>> image_points(int n, int n_corners, const double *img)
{
    std::vector<std::vector<cv::Point2f>> v((size_t)n);
    for (int k = 0; k < n; k++) {
        const double *p = img + (size_t)2 * n_corners * k;
        v[(size_t)k].resize((size_t)n_corners);
        for (int i = 0; i < n_corners; i++) v[(size_t)k][(size_t)i] = cv::Point2f((float)p[2 * i], (float)p[2 * i + 1]);
    }
    return v;
}

cv::Mat camera_matrix(const double K[4])
{
    return (cv::Mat_<double>(3, 3) << K[0], 0, K[2], 0, K[1], K[3], 0, 0, 1);
}

} // namespace

extern "C" int calib__cv_find_corners(const uint8_t *grey, int w, int h, int cols, int rows, int *found,
                                      double *corners, char *msg, size_t cap)
{
    return guarded(msg, cap, [&] {
        // The image is only read: OpenCV gets a header over the caller's pixels.
        const cv::Mat im(h, w, CV_8UC1, const_cast<uint8_t *>(grey));
        std::vector<cv::Point2f> c;
        cv::Size pattern(cols, rows);
        bool ok = cv::findChessboardCorners(im, pattern, c, cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE);
        *found = ok && (int)c.size() == cols * rows;
        if (!*found) return;
        // An 11 x 11 window (5 px each side) as OpenCV's calibration sample
        // uses: large enough to average the edge's noise, small enough to
        // stay inside a square of a board seen from a metre.
        cv::cornerSubPix(im, c, cv::Size(5, 5), cv::Size(-1, -1),
                         cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 100, 1e-4));
        // The square diagonally outside corner (0, 0) against its
        // neighbour along the row: the order whose first outer square is
        // the dark one is kept, the other reversed (a turn by 180 degrees,
        // which swaps the colours of the corner squares when cols + rows
        // is odd). Two cameras then number one view's corners alike.
        cv::Point2f c0 = c[0], dx = c[1] - c[0], dy = c[(size_t)cols] - c[0];
        double outer = grey_at(im, c0 - 0.5f * dx - 0.5f * dy);
        double beside = grey_at(im, c0 + 0.5f * dx - 0.5f * dy);
        if (outer > beside) std::reverse(c.begin(), c.end());
        for (size_t i = 0; i < c.size(); i++) {
            corners[2 * i] = c[i].x;
            corners[2 * i + 1] = c[i].y;
        }
    });
}

extern "C" int calib__cv_calibrate(int n, int n_corners, const double *obj, const double *img, int w, int h,
                                   int fix_k3, double K[4], double dist[5], double *rms, char *msg, size_t cap)
{
    return guarded(msg, cap, [&] {
        std::vector<std::vector<cv::Point3f>> o((size_t)n, object_points(n_corners, obj));
        std::vector<std::vector<cv::Point2f>> p = image_points(n, n_corners, img);
        cv::Mat Km, d, rv, tv;
        double e = cv::calibrateCamera(o, p, cv::Size(w, h), Km, d, rv, tv, fix_k3 ? cv::CALIB_FIX_K3 : 0,
                                       cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-12));
        K[0] = Km.at<double>(0, 0), K[1] = Km.at<double>(1, 1), K[2] = Km.at<double>(0, 2), K[3] = Km.at<double>(1, 2);
        for (int i = 0; i < 5; i++) dist[i] = i < (int)d.total() ? d.at<double>(i) : 0.0;
        *rms = e;
    });
}

extern "C" int calib__cv_stereo(int n, int n_corners, const double *obj, const double *img1, const double *img2,
                                int w1, int h1, const double K1[4], const double d1[5], const double K2[4],
                                const double d2[5], double R[9], double t[3], double *rms, char *msg, size_t cap)
{
    return guarded(msg, cap, [&] {
        std::vector<std::vector<cv::Point3f>> o((size_t)n, object_points(n_corners, obj));
        std::vector<std::vector<cv::Point2f>> p1 = image_points(n, n_corners, img1);
        std::vector<std::vector<cv::Point2f>> p2 = image_points(n, n_corners, img2);
        cv::Mat Km1 = camera_matrix(K1), Km2 = camera_matrix(K2);
        cv::Mat dm1(1, 5, CV_64F, const_cast<double *>(d1)), dm2(1, 5, CV_64F, const_cast<double *>(d2));
        dm1 = dm1.clone(), dm2 = dm2.clone(); // stereoCalibrate may write them back
        cv::Mat Rm, Tm, E, F;
        double e = cv::stereoCalibrate(o, p1, p2, Km1, dm1, Km2, dm2, cv::Size(w1, h1), Rm, Tm, E, F,
                                       cv::CALIB_FIX_INTRINSIC,
                                       cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-12));
        for (int i = 0; i < 9; i++) R[i] = Rm.at<double>(i / 3, i % 3);
        for (int i = 0; i < 3; i++) t[i] = Tm.at<double>(i);
        *rms = e;
    });
}
