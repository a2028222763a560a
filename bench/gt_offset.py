#!/usr/bin/env python3
"""How much of a trajectory's error against a motion-capture ground truth is
the ground truth's own frame (docs/real_frames.md, "The frame before where
the map is thin"): for each run, the ATE as eval-traj computes it (Horn's
rigid alignment), the ATE once one point fixed in the camera, o, is fitted
with the alignment (p_gt = R_a (p_est + R_est o) + t_a: the point the
motion capture follows is not the depth camera's centre), and the median
per-frame rotation error (RPE, one frame) with the run's timestamps shifted
by each of SHIFTS seconds (a clock offset between the depth and the motion
capture shows as a lower median at a shift).

    bench/gt_offset.py GROUNDTRUTH RUN [RUN ...]    # RUN: a replay's folder (trajectory.txt)
"""
import sys

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

SHIFTS = (-0.04, -0.03, -0.02, -0.01, 0.0, 0.01, 0.02)


def horn(a, b):
    """R, t minimising |R a + t - b| over the rows (Horn / Umeyama without scale)."""
    ma, mb = a.mean(0), b.mean(0)
    u, _, vt = np.linalg.svd((a - ma).T @ (b - mb))
    d = np.diag([1, 1, np.sign(np.linalg.det(vt.T @ u.T))])
    r = vt.T @ d @ u.T
    return r, mb - r @ ma


def rmse(a, b):
    return float(np.sqrt(((a - b) ** 2).sum(1).mean()))


def matched(gt, est, shift=0.0):
    """The estimate's poses within the ground truth's time span and the
    ground truth interpolated at their (shifted) times."""
    t = est[:, 0] + shift
    m = (t >= gt[0, 0]) & (t <= gt[-1, 0])
    t, e = t[m], est[m]
    p_gt = np.stack([np.interp(t, gt[:, 0], gt[:, k]) for k in (1, 2, 3)], 1)
    r_gt = Slerp(gt[:, 0], Rotation.from_quat(gt[:, 4:8]))(t)
    return e[:, 1:4], Rotation.from_quat(e[:, 4:8]), p_gt, r_gt


def offset_fit(p, r_est, p_gt, iterations=50):
    """o and the ATE with it: alternating the alignment and a linear solve for o."""
    re = r_est.as_matrix()
    o = np.zeros(3)
    for _ in range(iterations):
        q = p + re @ o
        r, t = horn(q, p_gt)
        a = np.einsum("ij,njk->nik", r, re).reshape(-1, 3)
        o = np.linalg.lstsq(a, (p_gt - t - p @ r.T).reshape(-1), rcond=None)[0]
    q = p + re @ o
    r, t = horn(q, p_gt)
    return o, rmse(q @ r.T + t, p_gt)


def rpe_rot_median(r_est, r_gt):
    a = r_est[:-1].inv() * r_est[1:]
    b = r_gt[:-1].inv() * r_gt[1:]
    return float(np.median(np.degrees((a * b.inv()).magnitude())))


def main():
    if len(sys.argv) < 3:
        sys.exit("usage: bench/gt_offset.py GROUNDTRUTH RUN [RUN ...]")
    gt = np.loadtxt(sys.argv[1])
    print("| run | ATE mm | ATE with o mm | o mm (camera x, y, z) | RPE rotation median deg by shift (s): "
          + ", ".join("%+.2f" % s for s in SHIFTS) + " |")
    print("|---|---|---|---|---|")
    for run in sys.argv[2:]:
        est = np.loadtxt(run + "/trajectory.txt")
        p, r_est, p_gt, r_gt = matched(gt, est)
        r, t = horn(p, p_gt)
        ate = rmse(p @ r.T + t, p_gt)
        o, ate_o = offset_fit(p, r_est, p_gt)
        rpe = []
        for s in SHIFTS:
            _, r_s, _, g_s = matched(gt, est, s)
            rpe.append(rpe_rot_median(r_s, g_s))
        print("| %s | %.2f | %.2f | %s | %s |" % (run, 1e3 * ate, 1e3 * ate_o, ", ".join("%.1f" % v for v in 1e3 * o),
                                                  ", ".join("%.3f" % v for v in rpe)))


if __name__ == "__main__":
    main()
