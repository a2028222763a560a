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
#include <cstring>
#include <limits>
#include <new>
#include <stdexcept>
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
    } catch (const std::invalid_argument &e) {
        return fail(FEATURES__ERR_ARG, msg, cap, e.what());
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
    return guarded(msg, cap, [&]() -> int {
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

namespace {

// A copy of f (its keypoints, descriptors and, on request, its image)
// whose keypoints each take the point point_of gives them (NaN: none).
template <class PointOf> features_set *lifted_copy(const features_set *f, int keep_image, PointOf point_of)
{
    features_set *l = new features_set;
    try {
        l->keys = f->keys;
        l->desc = f->desc.clone();
        if (keep_image) l->grey = f->grey;
        l->pts.reserve(f->keys.size());
        for (const cv::KeyPoint &k : f->keys) l->pts.push_back(point_of(k));
    } catch (...) {
        delete l;
        throw;
    }
    return l;
}

const double nan_d = std::numeric_limits<double>::quiet_NaN();

// Four pixels' points whose depths (the depth camera's z) lie within
// this share of the nearest one's are taken for one smooth surface: a few
// times Kinect v1's noise at 1-4 m (the occlusion margin of
// calib_points_on_colour is the same 3%).
const float SMOOTH_REL = 0.03f;

// The point at (x, y) between four pixels' points, bilinearly, where all
// four have one within SMOOTH_REL of z (the nearest pixel's depth) and in
// [min_m, max_m]: one smooth surface, whose points lie on the rays through
// their pixels' centres (calib_points_on_colour places them so). Across a
// depth edge it would be a point of neither surface: false, and the
// nearest pixel's is taken.
bool between(const float *xyz, int w, int h, double x, double y, float z, double min_m, double max_m,
             cv::Point3d &out)
{
    int x0 = (int)std::floor(x), y0 = (int)std::floor(y);
    if (x0 < 0 || y0 < 0 || x0 + 1 >= w || y0 + 1 >= h) return false;
    double a = x - x0, b = y - y0, wt[4] = {(1 - a) * (1 - b), a * (1 - b), (1 - a) * b, a * b};
    const float *p[4] = {xyz + 3 * ((size_t)y0 * (size_t)w + (size_t)x0), nullptr, nullptr, nullptr};
    p[1] = p[0] + 3, p[2] = p[0] + 3 * (size_t)w, p[3] = p[2] + 3;
    double s[3] = {0, 0, 0};
    for (int i = 0; i < 4; i++) {
        bool ok = std::fabs(p[i][2] - z) <= SMOOTH_REL * z && p[i][2] >= min_m && p[i][2] <= max_m;
        if (!ok || !std::isfinite(p[i][0]) || !std::isfinite(p[i][1])) return false;
        for (int c = 0; c < 3; c++) s[c] += wt[i] * p[i][c];
    }
    out = cv::Point3d(s[0], s[1], s[2]);
    return true;
}

} // namespace

extern "C" int features__lift(const features_set *f, const uint16_t *depth, int w, int h, double scale,
                              const double K[4], double min_m, double max_m, int keep_image, features_set **out,
                              char *msg, size_t cap)
{
    *out = nullptr;
    return guarded(msg, cap, [&]() -> int {
        *out = lifted_copy(f, keep_image, [&](const cv::KeyPoint &k) {
            int u = (int)std::lround(k.pt.x), v = (int)std::lround(k.pt.y);
            float z = 0.0f;
            if (u >= 0 && v >= 0 && u < w && v < h) {
                float m = (float)(depth[(size_t)v * (size_t)w + (size_t)u] / scale);
                if (m >= min_m && m <= max_m) z = m;
            }
            if (!(z > 0)) return cv::Point3d(nan_d, nan_d, nan_d);
            return cv::Point3d((k.pt.x - K[2]) * z / K[0], (k.pt.y - K[3]) * z / K[1], z);
        });
        return FEATURES__OK;
    });
}

extern "C" int features__lift_points(const features_set *f, const float *xyz, int w, int h, double min_m,
                                     double max_m, int keep_image, features_set **out, char *msg, size_t cap)
{
    *out = nullptr;
    return guarded(msg, cap, [&]() -> int {
        *out = lifted_copy(f, keep_image, [&](const cv::KeyPoint &k) {
            int u = (int)std::lround(k.pt.x), v = (int)std::lround(k.pt.y);
            if (u < 0 || v < 0 || u >= w || v >= h) return cv::Point3d(nan_d, nan_d, nan_d);
            const float *p = xyz + 3 * ((size_t)v * (size_t)w + (size_t)u);
            if (!(p[2] >= min_m && p[2] <= max_m) || !std::isfinite(p[0]) || !std::isfinite(p[1]))
                return cv::Point3d(nan_d, nan_d, nan_d);
            cv::Point3d q;
            if (between(xyz, w, h, k.pt.x, k.pt.y, p[2], min_m, max_m, q)) return q;
            return cv::Point3d(p[0], p[1], p[2]);
        });
        return FEATURES__OK;
    });
}

extern "C" int features__lifted_count(const features_set *f)
{
    int n = 0;
    for (const cv::Point3d &p : f->pts)
        if (!std::isnan(p.z)) n++;
    return n;
}

extern "C" void features__lifted_copy(const features_set *f, uint8_t *desc, float *xyz)
{
    size_t k = 0;
    for (size_t i = 0; i < f->pts.size(); i++) {
        const cv::Point3d &p = f->pts[i];
        if (std::isnan(p.z)) continue;
        std::memcpy(desc + 32 * k, f->desc.ptr<uint8_t>((int)i), 32);
        xyz[3 * k] = (float)p.x, xyz[3 * k + 1] = (float)p.y, xyz[3 * k + 2] = (float)p.z;
        k++;
    }
}

extern "C" int features__import(uint32_t n, const uint8_t *desc, const float *xyz, features_set **out, char *msg,
                                size_t cap)
{
    *out = nullptr;
    return guarded(msg, cap, [&]() -> int {
        features_set *f = new features_set;
        try {
            f->keys.resize(n);
            f->desc = cv::Mat((int)n, 32, CV_8U);
            if (n) std::memcpy(f->desc.data, desc, (size_t)n * 32);
            f->pts.reserve(n);
            for (uint32_t i = 0; i < n; i++) f->pts.emplace_back(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
        } catch (...) {
            delete f;
            throw;
        }
        *out = f;
        return FEATURES__OK;
    });
}

namespace {

// Bits that differ between two 32-byte ORB descriptors.
template <int (*Popcount)(unsigned long long)> inline int hamming32(const uint64_t *x, const uint64_t *y)
{
    return Popcount(x[0] ^ y[0]) + Popcount(x[1] ^ y[1]) + Popcount(x[2] ^ y[2]) + Popcount(x[3] ^ y[3]);
}

inline int popcount_plain(unsigned long long v) { return __builtin_popcountll(v); }

// Each lifted descriptor of a whose nearest neighbour among b's is within
// max_hamming bits (0: any) and clearly nearer than the second (Lowe's
// ratio, 0.8): a distinctive match, found exactly by brute force. A pair
// of descriptors is four 64-bit popcounts, so one keyframe against a
// frame costs about a millisecond where the CPU has a popcount
// instruction (OpenCV's matcher in Debian's build: 6 ms one way, 13 with
// the cross check).
template <int (*Popcount)(unsigned long long)>
void distinctive(const features_set *a, const features_set *b, int max_hamming, std::vector<cv::DMatch> &out)
{
    const int nb = b->desc.rows;
    for (int i = 0; i < a->desc.rows; i++) {
        if (!a->pts.empty() && std::isnan(a->pts[(size_t)i].z)) continue;
        uint64_t x[4];
        std::memcpy(x, a->desc.ptr<uint8_t>(i), sizeof x);
        int best = 257, second = 257, at = -1;
        for (int j = 0; j < nb; j++) {
            uint64_t y[4];
            std::memcpy(y, b->desc.ptr<uint8_t>(j), sizeof y);
            int d = hamming32<Popcount>(x, y);
            if (d < best) second = best, best = d, at = j;
            else if (d < second) second = d;
        }
        if (at >= 0 && (max_hamming <= 0 || best <= max_hamming) && 5 * best < 4 * second)
            out.emplace_back(i, at, (float)best);
    }
}

#if defined(__x86_64__) || defined(__i386__)
__attribute__((target("popcnt"))) int popcount_hw(unsigned long long v) { return __builtin_popcountll(v); }
// flatten: the template and its popcounts inlined here, so they are
// compiled for the popcount instruction too.
__attribute__((target("popcnt"), flatten)) void distinctive_hw(const features_set *a, const features_set *b, int max_hamming,
                                                       std::vector<cv::DMatch> &out)
{
    distinctive<popcount_hw>(a, b, max_hamming, out);
}
#endif

// The matches PnP starts from: a's descriptors against b's, either mutual
// nearest neighbours (no ratio test; RANSAC takes out what is left of the
// wrong ones) or distinctive ones (fewer, more often right, and quicker).
// Either within max_hamming bits (0: any).
std::vector<cv::DMatch> matches_of(const features_set *a, const features_set *b, int max_hamming, bool is_distinctive)
{
    std::vector<cv::DMatch> m;
    if (a->desc.empty() || b->desc.empty()) return m;
    if (is_distinctive) {
        if (a->desc.cols != 32 || b->desc.cols != 32 || a->desc.type() != CV_8U || b->desc.type() != CV_8U)
            throw std::invalid_argument("descriptors are not ORB's 32 bytes");
#if defined(__x86_64__) || defined(__i386__)
        if (__builtin_cpu_supports("popcnt")) {
            distinctive_hw(a, b, max_hamming, m);
            return m;
        }
#endif
        distinctive<popcount_plain>(a, b, max_hamming, m);
        return m;
    }
    cv::BFMatcher(cv::NORM_HAMMING, true).match(a->desc, b->desc, m);
    if (max_hamming > 0) {
        size_t n = 0;
        for (const cv::DMatch &d : m)
            if (d.distance <= (float)max_hamming) m[n++] = d;
        m.resize(n);
    }
    return m;
}

} // namespace

extern "C" int features__match_count(const features_set *a, const features_set *b, int max_hamming, uint32_t *n,
                                     char *msg, size_t cap)
{
    *n = 0;
    return guarded(msg, cap, [&]() -> int {
        *n = (uint32_t)matches_of(a, b, max_hamming, true).size();
        return FEATURES__OK;
    });
}

extern "C" int features__pnp(const features_set *a, const features_set *b, const double K[4], const double *dist,
                             double ransac_px, int ransac_iterations, int max_hamming, int fast, features__pnp_out *r,
                             char *msg, size_t cap)
{
    *r = features__pnp_out{};
    return guarded(msg, cap, [&]() -> int {
        if (a->pts.size() != a->keys.size())
            return fail(FEATURES__ERR_ARG, msg, cap, "the first set's keypoints are not lifted (features_lift)");
        if (a->desc.empty() || b->desc.empty()) return FEATURES__OK;
        std::vector<cv::DMatch> m = matches_of(a, b, max_hamming, fast != 0);
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
        cv::Mat D;
        if (dist) D = (cv::Mat_<double>(1, 5) << dist[0], dist[1], dist[2], dist[3], dist[4]);
        cv::Mat rv, tv;
        std::vector<int> inl;
        // solvePnPRansac draws from a generator of its own with a fixed seed:
        // the same pairs give the same poses.
        if (!cv::solvePnPRansac(obj, img, Km, D, rv, tv, false, ransac_iterations, (float)ransac_px, 0.999, inl,
                                cv::SOLVEPNP_EPNP) ||
            inl.size() < 6)
            return FEATURES__OK;
        std::vector<cv::Point3d> oi;
        std::vector<cv::Point2d> ii;
        for (int k : inl) {
            oi.push_back(obj[(size_t)k]);
            ii.push_back(img[(size_t)k]);
        }
        cv::solvePnPRefineLM(oi, ii, Km, D, rv, tv);
        std::vector<cv::Point2d> proj;
        cv::projectPoints(oi, rv, tv, Km, D, proj);
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
