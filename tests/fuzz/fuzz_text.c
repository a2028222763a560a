/* Fuzz target: the one-file text readers: a TUM trajectory
 * (groundtruth.txt, an estimate), camera.txt ("fx fy cx cy [scale [k1 k2 p1 p2 k3]]") and a
 * 4x4 pose matrix (frame-NNNNNN.pose.txt). The input is the file; every
 * reader reads it, and it reads if one of them takes it. */
#include "fuzz.h"
#include "replay/replay_int.h"

bf_status fuzz_text(const uint8_t *data, size_t size)
{
    const char *path = fuzz_write(fuzz_scratch(), "file.txt", data, size);
    if (!path) return BF_IO;
    bf_traj traj = {0};
    bf_status s_traj = replay_traj_read_tum(path, &traj);
    bf_traj_free(&traj);
    bf_intrinsics K = {0};
    double dist[CALIB_DIST_N];
    bf_status s_camera = replay__camera_txt_read(path, &K, dist);
    bf_se3 T;
    bf_status s = replay__pose_matrix_read(path, &T);
    return s_traj == BF_OK || s_camera == BF_OK ? BF_OK : s;
}

FUZZ_TARGET(fuzz_text)
