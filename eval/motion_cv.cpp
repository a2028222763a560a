// eval: the camera's motion between two colour images, through OpenCV's
// features2d (ORB) and calib3d (PnP with RANSAC). A thin layer behind
// eval_motion_int.h; every entry point catches everything, so no C++
// exception unwinds through C frames.
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/video/tracking.hpp>

#include <cmath>
#include <cstdio>
#include <new>
#include <vector>

#include "eval_motion_int.h"

struct eval__cv_features {
    cv::Mat grey; // kept for the Lucas-Kanade refinement of a match
    std::vector<cv::KeyPoint> keys;
    cv::Mat desc;
};

namespace {

int fail(int code, char *msg, size_t cap, const char *what)
{
    std::snprintf(msg, cap, "%s", what);
    return code;
}

template <class F> int guarded(char *msg, size_t cap, F fn)
{
    try {
        return fn();
    } catch (const cv::Exception &e) {
        return fail(EVAL__CV_ERR_OPENCV, msg, cap, e.what());
    } catch (const std::bad_alloc &) {
        return fail(EVAL__CV_ERR_MEMORY, msg, cap, "out of memory");
    } catch (const std::exception &e) {
        return fail(EVAL__CV_ERR_OPENCV, msg, cap, e.what());
    } catch (...) {
        return fail(EVAL__CV_ERR_OPENCV, msg, cap, "unknown exception");
    }
}

} // namespace

extern "C" int eval__cv_features_make(const uint8_t *grey, int w, int h, int n_features, eval__cv_features **out,
                                      char *msg, size_t cap)
{
    *out = nullptr;
    return guarded(msg, cap, [&] {
        const cv::Mat im(h, w, CV_8UC1, const_cast<uint8_t *>(grey));
        eval__cv_features *f = new eval__cv_features;
        try {
            f->grey = im.clone();
            cv::Ptr<cv::ORB> orb = cv::ORB::create(n_features);
            orb->detectAndCompute(f->grey, cv::noArray(), f->keys, f->desc);
        } catch (...) {
            delete f;
            throw;
        }
        *out = f;
        return EVAL__CV_OK;
    });
}

extern "C" void eval__cv_features_free(eval__cv_features *f) { delete f; }

extern "C" int eval__cv_features_count(const eval__cv_features *f) { return f ? (int)f->keys.size() : 0; }

extern "C" int eval__cv_pnp(const eval__cv_features *a, const float *depth_a_m, const eval__cv_features *b, int w,
                            int h, const double K[4], double ransac_px, int ransac_iterations,
                            eval__cv_pnp_result *r, char *msg, size_t cap)
{
    *r = eval__cv_pnp_result{};
    return guarded(msg, cap, [&] {
        if (a->desc.empty() || b->desc.empty()) return EVAL__CV_OK;
        // Mutual nearest neighbours in Hamming distance: no ratio test,
        // RANSAC takes out what is left of the wrong ones.
        std::vector<cv::DMatch> m;
        cv::BFMatcher(cv::NORM_HAMMING, true).match(a->desc, b->desc, m);
        r->n_matches = (uint32_t)m.size();
        // ORB places a keypoint to about a pixel, and on one pair of views
        // those errors are not independent: on tests/eval's rendered room
        // they moved the pose by 7-14 mm. So a's keypoint is kept and its
        // place in b is found again by pyramidal Lucas-Kanade from the
        // match; a match the two do not agree on within 2 px is dropped.
        std::vector<cv::Point3d> obj;
        std::vector<cv::Point2f> pa, pb;
        obj.reserve(m.size());
        for (const cv::DMatch &d : m) {
            const cv::Point2f &p = a->keys[(size_t)d.queryIdx].pt;
            int u = (int)std::lround(p.x), v = (int)std::lround(p.y);
            if (u < 0 || v < 0 || u >= w || v >= h) continue;
            float z = depth_a_m[(size_t)v * (size_t)w + (size_t)u];
            if (!(z > 0)) continue; // no depth there (or a range the caller left out)
            obj.emplace_back((p.x - K[2]) * z / K[0], (p.y - K[3]) * z / K[1], z);
            pa.push_back(p);
            pb.push_back(b->keys[(size_t)d.trainIdx].pt);
        }
        std::vector<cv::Point2d> img;
        if (!pa.empty()) {
            std::vector<cv::Point2f> lk = pb;
            std::vector<uchar> st;
            std::vector<float> err;
            cv::calcOpticalFlowPyrLK(a->grey, b->grey, pa, lk, st, err, cv::Size(11, 11), 1,
                                     cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 30, 0.01),
                                     cv::OPTFLOW_USE_INITIAL_FLOW);
            size_t n = 0;
            for (size_t k = 0; k < pa.size(); k++) {
                cv::Point2f dd = lk[k] - pb[k];
                if (!st[k] || dd.x * dd.x + dd.y * dd.y > 4.0f) continue;
                obj[n++] = obj[k];
                img.emplace_back(lk[k]);
            }
            obj.resize(n);
        }
        r->n_lifted = (uint32_t)obj.size();
        if (obj.size() < 6) return EVAL__CV_OK;
        const cv::Mat Km = (cv::Mat_<double>(3, 3) << K[0], 0, K[2], 0, K[1], K[3], 0, 0, 1);
        cv::Mat rv, tv;
        std::vector<int> inl;
        // solvePnPRansac draws from a generator of its own with a fixed seed:
        // the same pairs give the same poses.
        if (!cv::solvePnPRansac(obj, img, Km, cv::noArray(), rv, tv, false, ransac_iterations, (float)ransac_px, 0.999,
                                inl, cv::SOLVEPNP_EPNP) ||
            inl.size() < 6)
            return EVAL__CV_OK;
        std::vector<cv::Point3d> oi;
        std::vector<cv::Point2d> ii;
        for (int k : inl) {
            oi.push_back(obj[(size_t)k]);
            ii.push_back(img[(size_t)k]);
        }
        cv::solvePnPRefineLM(oi, ii, Km, cv::noArray(), rv, tv);
        std::vector<cv::Point2d> proj;
        cv::projectPoints(oi, rv, tv, Km, cv::noArray(), proj);
        double ss = 0;
        for (size_t k = 0; k < oi.size(); k++) {
            double dx = proj[k].x - ii[k].x, dy = proj[k].y - ii[k].y;
            ss += dx * dx + dy * dy;
        }
        r->rms_px = std::sqrt(ss / (double)oi.size());
        r->n_inliers = (uint32_t)inl.size();
        // rv, tv take a's camera points into b's camera: X_b = R X_a + t.
        cv::Mat R;
        cv::Rodrigues(rv, R);
        for (int i = 0; i < 3; i++) {
            for (int j = 0; j < 3; j++) r->R_ba[3 * i + j] = R.at<double>(i, j);
            r->t_ba[i] = tv.at<double>(i);
        }
        r->ok = 1;
        return EVAL__CV_OK;
    });
}
