/* bench_opencv_tsdf: the speed issue's yardstick, run beside bitfuse in the
 * same bench (bench/speed.sh): OpenCV 4.6's dense TSDF volume (rgbd module,
 * cv::kinfu::makeVolume, 256^3 over 3 m: 11.7 mm voxels) with its fast ICP
 * odometry (cv::rgbd::FastICPOdometry, KinectFusion's projective
 * point-to-plane ICP, three pyramid levels) tracking each frame against the
 * volume's ray-cast at the last pose: track, integrate, ray-cast, the loop
 * ../shared/BENCHMARKS.md calls "OpenCV 4.6 TSDF 256^3 + ICP odometry".
 * KinFu itself is not used: Debian builds OpenCV without its non-free part,
 * and KinFu::create refuses to run there; its volume and odometry are free.
 *
 *   bench_opencv_tsdf SEQUENCE --out DIR [--frames N] [--res 256] [--size-m 3]
 *
 * Reads any sequence bitfuse reads (replay/), starts at the first frame's
 * ground truth (or the identity), writes DIR/trajectory.txt and
 * DIR/groundtruth.txt (TUM; the latter where frames have poses) and
 * DIR/stats.json (time per frame and per stage, wall clock: median, p95)
 * and DIR/frames.csv (the same per frame).
 * A bench tool, not part of bitfuse: built only where libopencv-contrib-dev
 * is installed. */
#include <opencv2/core.hpp>
#include <opencv2/rgbd.hpp>
#include <opencv2/rgbd/volume.hpp>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include <sys/stat.h>

/* core.h is C11: its _Noreturn is C++11's attribute here. */
#define _Noreturn [[noreturn]]
extern "C" {
#include "core/core.h"
#include "replay/replay.h"
}

namespace {

struct options {
    const char *seq = nullptr;
    std::string out;
    uint32_t frames = 0;
    int res = 256;
    float size_m = 3.0f;
    bool fuse_at_gt = false;
};

void usage(FILE *f)
{
    std::fprintf(f,
                 "usage: bench_opencv_tsdf SEQUENCE --out DIR [--frames N] [--res R] [--size-m S]\n"
                 "                         [--fuse-at-groundtruth]\n\n"
                 "OpenCV 4.6's TSDF volume (R^3 voxels over S metres, default 256 over 3 m) with\n"
                 "FastICPOdometry against its ray-cast: the yardstick of bench/speed.sh. Writes\n"
                 "DIR/trajectory.txt (TUM, camera to world), DIR/groundtruth.txt, DIR/stats.json\n"
                 "and DIR/frames.csv.\n"
                 "--fuse-at-groundtruth: every frame is tracked as usual, from the last frame's\n"
                 "true pose, then integrated and ray-cast at its own true pose (the frames must\n"
                 "have poses): the same work per frame as a run that keeps the camera, whether\n"
                 "or not this one would have; trajectory.txt holds the one-step estimates.\n");
}

bool parse(int argc, char **argv, options *o)
{
    for (int i = 1; i < argc; i++) {
        std::string a = argv[i];
        bool has = i + 1 < argc;
        if (a == "-h" || a == "--help") {
            usage(stdout);
            std::exit(0);
        } else if (a == "--out" && has) {
            o->out = argv[++i];
        } else if (a == "--frames" && has) {
            o->frames = (uint32_t)std::strtoul(argv[++i], nullptr, 10);
        } else if (a == "--res" && has) {
            o->res = std::atoi(argv[++i]);
        } else if (a == "--fuse-at-groundtruth") {
            o->fuse_at_gt = true;
        } else if (a == "--size-m" && has) {
            o->size_m = (float)std::atof(argv[++i]);
        } else if (a[0] != '-' && !o->seq) {
            o->seq = argv[i];
        } else {
            std::fprintf(stderr, "bench_opencv_tsdf: unknown or incomplete option '%s'\n", argv[i]);
            return false;
        }
    }
    if (!o->seq || o->out.empty() || o->res < 16 || !(o->size_m > 0)) {
        std::fprintf(stderr, "bench_opencv_tsdf: need SEQUENCE and --out DIR (--res >= 16, --size-m > 0)\n");
        return false;
    }
    return true;
}

cv::Matx44f to_cv(const bf_se3 &T)
{
    cv::Matx44f m = cv::Matx44f::eye();
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 3; j++) m(i, j) = (float)T.R[i][j];
    }
    m(0, 3) = (float)T.t.x, m(1, 3) = (float)T.t.y, m(2, 3) = (float)T.t.z;
    return m;
}

bf_se3 from_cv(const cv::Matx44d &m)
{
    bf_se3 T;
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 3; j++) T.R[i][j] = m(i, j);
    }
    T.t = bf_v3(m(0, 3), m(1, 3), m(2, 3));
    return T;
}

double percentile(std::vector<double> v, double p)
{
    if (v.empty()) return NAN;
    std::sort(v.begin(), v.end());
    double k = p / 100.0 * (double)(v.size() - 1);
    size_t lo = (size_t)k, hi = std::min(lo + 1, v.size() - 1);
    return v[lo] + (k - (double)lo) * (v[hi] - v[lo]);
}

double ms_since(uint64_t t0) { return (double)(bf_time_ns() - t0) * 1e-6; }

struct series {
    std::vector<double> frame, track, integrate, raycast;
};

/* DIR/frames.csv: a frame a line, to tell the frames it tracked from the
 * ones after it lost the camera (its ray-cast then sees other parts of the
 * volume, and its time with them). */
bool write_frames(const std::string &dir, const series &s, const std::vector<char> &ok)
{
    std::string path = dir + "/frames.csv";
    FILE *f = std::fopen(path.c_str(), "w");
    if (!f) return false;
    std::fprintf(f, "index,tracked,frame_ms,track_ms,integrate_ms,raycast_ms\n");
    for (size_t i = 0; i < s.frame.size(); i++) {
        std::fprintf(f, "%zu,%d,%.3f,%.3f,%.3f,%.3f\n", i, ok[i], s.frame[i], i > 0 ? s.track[i - 1] : 0.0,
                     s.integrate[i], s.raycast[i]);
    }
    return std::fclose(f) == 0;
}

void write_pose(FILE *f, double t_s, const bf_se3 &T)
{
    bf_quat q;
    bf_vec3 t;
    bf_se3_to_qt(&T, &q, &t);
    std::fprintf(f, "%.6f %.6f %.6f %.6f %.6f %.6f %.6f %.6f\n", t_s, t.x, t.y, t.z, q.x, q.y, q.z, q.w);
}

void write_stage(FILE *f, const char *name, const std::vector<double> &v, bool last)
{
    std::fprintf(f, "    \"%s\": {\"median\": %.3f, \"p95\": %.3f}%s\n", name, percentile(v, 50), percentile(v, 95),
                 last ? "" : ",");
}

bool write_stats(const options &o, const series &s, uint32_t tracked, uint32_t failed, uint32_t no_depth)
{
    std::string path = o.out + "/stats.json";
    FILE *f = std::fopen(path.c_str(), "w");
    if (!f) {
        std::fprintf(stderr, "bench_opencv_tsdf: %s: cannot write\n", path.c_str());
        return false;
    }
    std::fprintf(f, "{\n  \"system\": \"OpenCV %s TSDF %d^3 over %.2f m + FastICPOdometry\",\n", CV_VERSION, o.res,
                 (double)o.size_m);
    std::fprintf(f, "  \"voxel_m\": %.6f,\n  \"threads\": %d,\n  \"fuse_at_groundtruth\": %s,\n",
                 (double)(o.size_m / (float)o.res), cv::getNumThreads(), o.fuse_at_gt ? "true" : "false");
    std::fprintf(f, "  \"frames\": {\"total\": %zu, \"tracked\": %u, \"failed\": %u, \"no_depth\": %u},\n",
                 s.frame.size(), tracked, failed, no_depth);
    std::fprintf(f, "  \"frame_ms\": {\"median\": %.3f, \"p95\": %.3f, \"first\": %.3f},\n",
                 percentile(s.frame, 50), percentile(s.frame, 95), s.frame.empty() ? NAN : s.frame[0]);
    std::fprintf(f, "  \"stage_ms\": {\n");
    write_stage(f, "track", s.track, false);
    write_stage(f, "integrate", s.integrate, false);
    write_stage(f, "raycast", s.raycast, true);
    std::fprintf(f, "  }\n}\n");
    return std::fclose(f) == 0;
}

int run(const options &o)
{
    replay_options ro = {};
    ro.max_frames = o.frames;
    rgbd_source *src = nullptr;
    if (replay_open(o.seq, &ro, &src) != BF_OK) {
        std::fprintf(stderr, "bench_opencv_tsdf: %s\n", bf_last_error());
        return 1;
    }
    const bf_intrinsics *K = rgbd_source_intrinsics(src);
    cv::Size size((int)K->width, (int)K->height);
    cv::Mat Km = (cv::Mat_<float>(3, 3) << (float)K->fx_px, 0, (float)K->cx_px, 0, (float)K->fy_px, (float)K->cy_px, 0, 0, 1);
    cv::kinfu::Intr intr((float)K->fx_px, (float)K->fy_px, (float)K->cx_px, (float)K->cy_px);
    float voxel = o.size_m / (float)o.res;
    /* KinFu's defaults for everything but the grid: a truncation of 7
     * voxels, weights up to 64, depth beyond 4 m dropped, the ray marched in
     * quarter-truncation steps. */
    cv::Ptr<cv::kinfu::Volume> vol;
    cv::Ptr<cv::rgbd::FastICPOdometry> odo = cv::rgbd::FastICPOdometry::create(Km);
    odo->setMaxDistDiff(0.1f);
    cv::Matx44f T_w0 = cv::Matx44f::eye(); /* world from the first camera */
    cv::Matx44f T_0c = cv::Matx44f::eye(); /* first camera from the current one */
    cv::Matx44f T_out = cv::Matx44f::eye(); /* the estimate reported (with fuse_at_gt, not T_0c) */
    cv::Mat ref_depth;                     /* the volume's ray-cast at the last pose, metres */
    series s;
    std::vector<char> frame_ok;
    uint32_t tracked = 0, failed = 0, no_depth = 0;
    std::string traj_path = o.out + "/trajectory.txt";
    FILE *traj = std::fopen(traj_path.c_str(), "w");
    if (!traj) {
        std::fprintf(stderr, "bench_opencv_tsdf: %s: cannot write\n", traj_path.c_str());
        rgbd_source_close(src);
        return 1;
    }
    /* The frames' ground truth beside it, for bitfuse eval-traj (a
     * pose-per-frame folder has no groundtruth.txt of its own). */
    std::string gt_path = o.out + "/groundtruth.txt";
    FILE *gt = std::fopen(gt_path.c_str(), "w");
    if (!gt) {
        std::fprintf(stderr, "bench_opencv_tsdf: %s: cannot write\n", gt_path.c_str());
        std::fclose(traj);
        rgbd_source_close(src);
        return 1;
    }
    bf_frame fr;
    bf_status st;
    uint32_t n = 0;
    while ((st = rgbd_source_next(src, &fr)) == BF_OK) {
        cv::Mat raw((int)fr.height, (int)fr.width, CV_16UC1, (void *)fr.depth);
        cv::Mat raw_f, depth; /* the volume takes raw units as float (KinFu's DEPTH_TYPE), the odometry metres */
        raw.convertTo(raw_f, CV_32F);
        raw.convertTo(depth, CV_32F, 1.0 / K->depth_scale);
        uint64_t t0 = bf_time_ns();
        double track_ms = 0;
        if (o.fuse_at_gt && !fr.has_pose) {
            std::fprintf(stderr, "bench_opencv_tsdf: %s: frame %u has no ground truth (--fuse-at-groundtruth)\n", o.seq,
                         fr.index);
            rgbd_source_close(src);
            std::fclose(traj);
            std::fclose(gt);
            return 1;
        }
        if (!vol) {
            frame_ok.push_back(1);
            if (fr.has_pose) T_w0 = to_cv(fr.T_wc);
            /* The volume in front of the first camera, centred across its view
             * (KinFu's placement). */
            cv::Matx44f vol_pose = cv::Matx44f::eye();
            vol_pose(0, 3) = -o.size_m / 2, vol_pose(1, 3) = -o.size_m / 2, vol_pose(2, 3) = 0.5f;
            vol = cv::kinfu::makeVolume(cv::kinfu::VolumeType::TSDF, voxel, vol_pose, 0.25f, 7 * voxel, 64, 4.0f,
                                        cv::Vec3i(o.res, o.res, o.res));
        } else {
            cv::Matx44d Rt = cv::Matx44d::eye();
            bool ok = false;
            if (!ref_depth.empty() && cv::countNonZero(depth) > 0) {
                cv::Ptr<cv::rgbd::OdometryFrame> a = cv::rgbd::OdometryFrame::create(cv::Mat(), depth);
                cv::Ptr<cv::rgbd::OdometryFrame> b = cv::rgbd::OdometryFrame::create(cv::Mat(), ref_depth);
                cv::Mat Rt_m;
                ok = odo->compute(a, b, Rt_m);
                if (ok) Rt = cv::Matx44d((const double *)Rt_m.ptr<double>());
            }
            /* dst_p = Rt src_p: the current camera in the last one's frame. */
            cv::Matx44f T_est = ok ? T_0c * cv::Matx44f(Rt) : T_0c;
            if (ok) {
                tracked++;
            } else {
                failed++;
            }
            frame_ok.push_back(ok);
            T_0c = T_est;
            T_out = T_est;
            if (o.fuse_at_gt) T_0c = T_w0.inv() * to_cv(fr.T_wc);
            track_ms = ms_since(t0);
        }
        if (cv::countNonZero(depth) == 0) no_depth++;
        uint64_t t1 = bf_time_ns();
        vol->integrate(raw_f, (float)K->depth_scale, T_0c, intr);
        double integrate_ms = ms_since(t1);
        uint64_t t2 = bf_time_ns();
        cv::Mat pts, nrm;
        vol->raycast(T_0c, intr, size, pts, nrm);
        std::vector<cv::Mat> ch;
        cv::split(pts, ch); /* camera-space points: z is the depth */
        ref_depth = ch[2];
        ref_depth.setTo(0.0f, ref_depth != ref_depth); /* misses are NaN; 0 is no depth, as in a frame */
        double raycast_ms = ms_since(t2);
        s.frame.push_back(ms_since(t0));
        if (n > 0) s.track.push_back(track_ms);
        s.integrate.push_back(integrate_ms);
        s.raycast.push_back(raycast_ms);
        write_pose(traj, fr.t_depth_s, from_cv(cv::Matx44d(T_w0 * T_out)));
        if (fr.has_pose) write_pose(gt, fr.t_depth_s, fr.T_wc);
        n++;
        if (n % 50 == 0) std::fprintf(stderr, "bench_opencv_tsdf: %u frames, %.1f ms median\n", n,
                                      percentile(s.frame, 50));
    }
    rgbd_source_close(src);
    bool ok = std::fclose(traj) == 0;
    ok = std::fclose(gt) == 0 && ok;
    if (st != BF_END) {
        std::fprintf(stderr, "bench_opencv_tsdf: %s\n", bf_last_error());
        return 1;
    }
    ok = write_stats(o, s, tracked, failed, no_depth) && write_frames(o.out, s, frame_ok) && ok;
    std::printf("bench_opencv_tsdf: %u frames (%u tracked, %u failed), %.1f ms median (p95 %.1f): track %.1f, "
                "integrate %.1f, ray-cast %.1f ms\n",
                n, tracked, failed, percentile(s.frame, 50), percentile(s.frame, 95), percentile(s.track, 50),
                percentile(s.integrate, 50), percentile(s.raycast, 50));
    return ok ? 0 : 1;
}

} // namespace

int main(int argc, char **argv)
{
    options o;
    if (!parse(argc, argv, &o)) {
        usage(stderr);
        return 2;
    }
    if (mkdir(o.out.c_str(), 0777) != 0 && errno != EEXIST) {
        std::fprintf(stderr, "bench_opencv_tsdf: %s: cannot create\n", o.out.c_str());
        return 1;
    }
    try {
        return run(o);
    } catch (const cv::Exception &e) {
        std::fprintf(stderr, "bench_opencv_tsdf: %s: OpenCV: %s\n", o.seq, e.what());
        return 1;
    }
}
