#!/usr/bin/python3
"""Do a trajectory's poses make two frames' depths agree, near and far? (docs/real_frames.md,
"The map's far surfaces sit in front of the newest frame's depth".)

    frame_consistency.py DATA TRAJ KB KA[,KA...] [--depth-correction FILE]

DATA: a pose-per-frame folder (7-Scenes layout: frame-NNNNNN.depth.png in millimetres,
frame-NNNNNN.pose.txt camera to world, camera-intrinsics.txt). TRAJ: a TUM trajectory with one
line per frame in order (bitfuse replay's trajectory.txt of DATA). Each frame KA's depth is
moved into frame KB's camera twice: with TRAJ's poses and with DATA's own (the ground truth). A
pixel of KB takes the mean of the points landing on it within 5% of the nearest one; the
table gives, per band of KB's depth, the median of (moved KA - KB) in mm over KB's smooth
pixels (5x5 spread under 2% of the depth), with the pixel count. A rigid pose that fits the
depth gives medians near 0 in every band. With --depth-correction, both frames' depths are
first multiplied by that depth_correction.json (bitfuse calibrate-depth), as replay
--depth-correction does.
"""
import argparse
import json
import os

import cv2
import numpy as np

BANDS = ((1.0, 1.5), (1.5, 2.0), (2.0, 2.5), (2.5, 3.0), (3.0, 3.5))


def smooth_mask(d):
    """Pixels of depth image d (metres, 0: none) whose 5x5 neighbourhood all has depth within
    2% of the pixel's depth plus 3 mm: no edge there, so a small shift does not change the depth
    much (bench/map_bias.sh takes it too)."""
    k5 = np.ones((5, 5), np.uint8)
    hi = cv2.dilate(d.astype(np.float32), k5)
    lo = cv2.erode(np.where(d > 0, d, 99).astype(np.float32), k5)
    return (lo < 99) & ((hi - lo) < 0.02 * d + 0.003) & (d > 0)


def quat_to_R(q):
    x, y, z, w = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("data")
    p.add_argument("traj")
    p.add_argument("kb", type=int)
    p.add_argument("ka")
    p.add_argument("--depth-correction")
    a = p.parse_args()
    K = np.loadtxt(os.path.join(a.data, "camera-intrinsics.txt"))
    f, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    mul = None
    if a.depth_correction:
        j = json.load(open(a.depth_correction))
        mul = np.kron(np.array(j["multipliers"]), np.ones((j["cell_px"], j["cell_px"])))
    rows = [l.split() for l in open(a.traj) if l.strip() and not l.startswith("#")]

    def depth(k):
        path = os.path.join(a.data, "frame-%06d.depth.png" % k)
        d = cv2.imread(path, -1)
        if d is None:
            raise SystemExit("frame_consistency.py: %s: cannot read" % path)
        d = d.astype(np.float64) / 1000
        d[d >= 65] = 0  # 65535: no depth
        return d * mul if mul is not None else d

    def traj_pose(k):
        r = np.array(rows[k][1:8], float)
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = quat_to_R(r[3:7]), r[0:3]
        return T

    def gt_pose(k):
        T = np.loadtxt(os.path.join(a.data, "frame-%06d.pose.txt" % k))
        u, _, vt = np.linalg.svd(T[:3, :3])  # 7-Scenes' rotations are not quite orthonormal
        T[:3, :3] = u @ vt
        return T

    db = depth(a.kb)
    H, W = db.shape
    u, v = np.meshgrid(np.arange(W), np.arange(H))
    smooth = smooth_mask(db)

    def moved(ka, pose):
        da = depth(ka)
        m = da > 0
        P = np.stack([(u[m] - cx) / f * da[m], (v[m] - cy) / fy * da[m], da[m], np.ones(m.sum())])
        Q = np.linalg.inv(pose(a.kb)) @ pose(ka) @ P
        z = Q[2]
        ok = z > 0.3
        uu = np.round(Q[0, ok] / z[ok] * f + cx).astype(int)
        vv = np.round(Q[1, ok] / z[ok] * fy + cy).astype(int)
        z = z[ok]
        ins = (uu >= 0) & (uu < W) & (vv >= 0) & (vv < H)
        uu, vv, z = uu[ins], vv[ins], z[ins]
        near = np.full((H, W), np.inf)
        np.minimum.at(near, (vv, uu), z)
        keep = z < near[vv, uu] * 1.05
        s, n = np.zeros((H, W)), np.zeros((H, W))
        np.add.at(s, (vv[keep], uu[keep]), z[keep])
        np.add.at(n, (vv[keep], uu[keep]), 1)
        return np.where(n > 0, s / np.maximum(n, 1), 0)

    print("median (frame KA moved into %d - frame %d) mm (pixels), by the depth of frame %d" % (a.kb, a.kb, a.kb))
    print("| KA | poses | " + " | ".join("%.1f-%.1f m" % b for b in BANDS) + " |")
    print("|---|---|" + "---|" * len(BANDS))
    for ka in (int(x) for x in a.ka.split(",")):
        for name, pose in (("trajectory", traj_pose), ("ground truth", gt_pose)):
            w = moved(ka, pose)
            cells = []
            for lo_, hi_ in BANDS:
                s = smooth & (w > 0) & (db >= lo_) & (db < hi_)
                cells.append("%+.1f (%d)" % (np.median((w - db)[s]) * 1e3, s.sum()) if s.sum() > 300 else "-")
            print("| %d | %s | %s |" % (ka, name, " | ".join(cells)))


if __name__ == "__main__":
    main()
