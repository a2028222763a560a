// features: ORB keypoints, their lifting by depth and PnP with RANSAC,
// through OpenCV's features2d, video (Lucas-Kanade) and calib3d. A thin
// layer behind features_int.h; every entry point catches everything, so no
// C++ exception unwinds through C frames.
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/video/tracking.hpp>

#include <cmath>
#include <cstdio>
#include <limits>
#include <new>
#include <vector>

#include "features_int.h"

struct features_set {
    cv::Mat grey; // kept on request, for the Lucas-Kanade refinement of a match
    std::vector<cv::KeyPoint> keys;
    cv::Mat desc;
    // After lifting: each keypoint's point in the camera, NaN where the
    // depth had none (the keypoints stay, so matching sees what it saw
    // before lifting).
    std::vector<cv::Point3d> pts;
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
        return fail(FEATURES__ERR_OPENCV, msg, cap, e.what());
    } catch (const std::bad_alloc &) {
        return fail(FEATURES__ERR_MEMORY, msg, cap, "out of memory");
    } catch (const std::exception &e) {
        return fail(FEATURES__ERR_OPENCV, msg, cap, e.what());
    } catch (...) {
        return fail(FEATURES__ERR_OPENCV, msg, cap, "unknown exception");
    }
}

} // namespace

extern "C" int features__detect(const uint8_t *grey, int w, int h, int n_features, int keep_image,
                                features_set **out, char *msg, size_t cap)
{
    *out = nullptr;
    return guarded(msg, cap, [&] {
        const cv::Mat im(h, w, CV_8UC1, const_cast<uint8_t *>(grey));
        features_set *f = new features_set;
        try {
            cv::Ptr<cv::ORB> orb = cv::ORB::create(n_features);
            orb->detectAndCompute(im, cv::noArray(), f->keys, f->desc);
            if (keep_image) f->grey = im.clone();
        } catch (...) {
            delete f;
            throw;
        }
        *out = f;
        return FEATURES__OK;
    });
}

extern "C" void features__free(features_set *f) { delete f; }

extern "C" int features__count(const features_set *f) { return f ? (int)f->keys.size() : 0; }

extern "C" size_t features__bytes(const features_set *f)
{
    if (!f) return 0;
    return sizeof *f + f->keys.capacity() * sizeof(cv::KeyPoint) + f->desc.total() * f->desc.elemSize() +
           f->pts.capacity() * sizeof(cv::Point3d) + f->grey.total() * f->grey.elemSize();
}

extern "C" int features__lift(const features_set *f, const uint16_t *depth, int w, int h, double scale,
                              const double K[4], double min_m, double max_m, int keep_image, features_set **out,
                              char *msg, size_t cap)
{
    *out = nullptr;
    return guarded(msg, cap, [&] {
        features_set *l = new features_set;
        try {
            l->keys = f->keys;
            l->desc = f->desc.clone();
            if (keep_image) l->grey = f->grey;
            const double nan = std::numeric_limits<double>::quiet_NaN();
            l->pts.reserve(f->keys.size());
            for (const cv::KeyPoint &k : f->keys) {
                int u = (int)std::lround(k.pt.x), v = (int)std::lround(k.pt.y);
                float z = 0.0f;
                if (u >= 0 && v >= 0 && u < w && v < h) {
                    float m = (float)(depth[(size_t)v * (size_t)w + (size_t)u] / scale);
                    if (m >= min_m && m <= max_m) z = m;
                }
                if (!(z > 0)) {
                    l->pts.emplace_back(nan, nan, nan);
                    continue;
                }
                l->pts.emplace_back((k.pt.x - K[2]) * z / K[0], (k.pt.y - K[3]) * z / K[1], z);
            }
        } catch (...) {
            delete l;
            throw;
        }
        *out = l;
        return FEATURES__OK;
    });
}

extern "C" int features__pnp(const features_set *a, const features_set *b, const double K[4], double ransac_px,
                             int ransac_iterations, features__pnp_out *r, char *msg, size_t cap)
{
    *r = features__pnp_out{};
    return guarded(msg, cap, [&] {
        if (a->desc.empty() || b->desc.empty()) return FEATURES__OK;
        // Mutual nearest neighbours in Hamming distance: no ratio test,
        // RANSAC takes out what is left of the wrong ones.
        std::vector<cv::DMatch> m;
        cv::BFMatcher(cv::NORM_HAMMING, true).match(a->desc, b->desc, m);
        r->n_matches = (uint32_t)m.size();
        std::vector<cv::Point3d> obj;
        std::vector<cv::Point2f> pa, pb;
        obj.reserve(m.size());
        for (const cv::DMatch &d : m) {
            const cv::Point3d &X = a->pts[(size_t)d.queryIdx];
            if (std::isnan(X.z)) continue; // no depth there (or a range the caller left out)
            obj.push_back(X);
            pa.push_back(a->keys[(size_t)d.queryIdx].pt);
            pb.push_back(b->keys[(size_t)d.trainIdx].pt);
        }
        std::vector<cv::Point2d> img;
        if (!a->grey.empty() && !b->grey.empty()) {
            // ORB places a keypoint to about a pixel, and on one pair of
            // views those errors are not independent: on tests/eval's
            // rendered room they moved the pose by 7-14 mm. So a's keypoint
            // is kept and its place in b is found again by pyramidal
            // Lucas-Kanade from the match; a match the two do not agree on
            // within 2 px is dropped.
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
        } else {
            for (const cv::Point2f &p : pb) img.emplace_back(p);
        }
        r->n_placed = (uint32_t)obj.size();
        if (obj.size() < 6) return FEATURES__OK;
        const cv::Mat Km = (cv::Mat_<double>(3, 3) << K[0], 0, K[2], 0, K[1], K[3], 0, 0, 1);
        cv::Mat rv, tv;
        std::vector<int> inl;
        // solvePnPRansac draws from a generator of its own with a fixed seed:
        // the same pairs give the same poses.
        if (!cv::solvePnPRansac(obj, img, Km, cv::noArray(), rv, tv, false, ransac_iterations, (float)ransac_px, 0.999,
                                inl, cv::SOLVEPNP_EPNP) ||
            inl.size() < 6)
            return FEATURES__OK;
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
        cv::Mat R;
        cv::Rodrigues(rv, R);
        for (int i = 0; i < 3; i++) {
            for (int j = 0; j < 3; j++) r->R_ba[3 * i + j] = R.at<double>(i, j);
            r->t_ba[i] = tv.at<double>(i);
        }
        r->ok = 1;
        return FEATURES__OK;
    });
}
