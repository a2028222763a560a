#!/usr/bin/env python3
"""Independent oracle for the trajectory tests (tests/eval/test_traj.c).

Re-implements, with numpy, the rules of the TUM RGB-D benchmark scripts
(associate.py, evaluate_ate.py, evaluate_rpe.py by Juergen Sturm, TUM, BSD
licence): association by greedy nearest timestamps (|dt| < 0.02 s), Horn
alignment via the SVD of the cross-covariance (rot = U diag(1,1,det) V^T),
and the fixed-delta RPE. It shares no code with eval/traj_error.c (which uses
Horn's quaternion method instead of the SVD). The numbers it prints are
hard-coded in test_traj.c.

usage: python3 tests/eval/tum_oracle.py GROUNDTRUTH ESTIMATE
"""
import sys

import numpy as np


def read(path):
    rows = []
    for line in open(path):
        line = line.replace(",", " ").replace("\t", " ").strip()
        if not line or line.startswith("#"):
            continue
        v = [float(x) for x in line.split()]
        if len(v) == 8:
            rows.append(v)
    rows.sort()
    return np.array(rows)


def associate(ta, tb, max_difference=0.02):
    cand = sorted((abs(a - b), a, b) for a in ta for b in tb if abs(a - b) < max_difference)
    used_a, used_b, matches = set(), set(), []
    for _, a, b in cand:
        if a not in used_a and b not in used_b:
            used_a.add(a)
            used_b.add(b)
            matches.append((a, b))
    return sorted(matches)


def align(model, data):
    """model, data: 3 x n. Returns rot, trans with data ~ rot @ model + trans."""
    mz = model - model.mean(1, keepdims=True)
    dz = data - data.mean(1, keepdims=True)
    W = mz @ dz.T
    U, _, Vh = np.linalg.svd(W.T)
    S = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vh) < 0:
        S[2, 2] = -1
    rot = U @ S @ Vh
    trans = data.mean(1, keepdims=True) - rot @ model.mean(1, keepdims=True)
    err = np.sqrt(((rot @ model + trans - data) ** 2).sum(0))
    return rot, trans, err


def pose(row):
    t = row[1:4]
    q = np.array(row[4:8], dtype=float)  # qx qy qz qw
    q *= np.sqrt(2.0 / q.dot(q))
    q = np.outer(q, q)
    return np.array([
        [1 - q[1, 1] - q[2, 2], q[0, 1] - q[2, 3], q[0, 2] + q[1, 3], t[0]],
        [q[0, 1] + q[2, 3], 1 - q[0, 0] - q[2, 2], q[1, 2] - q[0, 3], t[1]],
        [q[0, 2] - q[1, 3], q[1, 2] + q[0, 3], 1 - q[0, 0] - q[1, 1], t[2]],
        [0, 0, 0, 1]])


def closest(L, t):
    return int(np.argmin(np.abs(np.asarray(L) - t)))


def rpe(gt, est, delta, per_frame):
    sg, se = gt[:, 0], est[:, 0]
    P = [pose(r) for r in est]
    G = [pose(r) for r in gt]
    index = np.arange(len(se), dtype=float) if per_frame else se
    max_dt = 2 * np.median(np.diff(sg))
    et, er = [], []
    for i in range(len(se)):
        j = closest(index, index[i] + delta)
        if j == len(se) - 1:
            continue
        g0, g1 = closest(sg, se[i]), closest(sg, se[j])
        if abs(sg[g0] - se[i]) > max_dt or abs(sg[g1] - se[j]) > max_dt:
            continue
        A = np.linalg.inv(P[j]) @ P[i]
        B = np.linalg.inv(G[g1]) @ G[g0]
        E = np.linalg.inv(A) @ B
        et.append(np.linalg.norm(E[0:3, 3]))
        er.append(np.degrees(np.arccos(min(1, max(-1, (np.trace(E[0:3, 0:3]) - 1) / 2)))))
    return np.array(et), np.array(er)


def stats(name, e):
    print("%s n=%d rmse=%.12g mean=%.12g median=%.12g std=%.12g min=%.12g max=%.12g" %
          (name, len(e), np.sqrt(e.dot(e) / len(e)), e.mean(), np.median(e), e.std(), e.min(), e.max()))


def main():
    gt, est = read(sys.argv[1]), read(sys.argv[2])
    m = associate(list(gt[:, 0]), list(est[:, 0]))
    gi = {t: k for k, t in enumerate(gt[:, 0])}
    ei = {t: k for k, t in enumerate(est[:, 0])}
    G = np.array([gt[gi[a], 1:4] for a, _ in m]).T
    E = np.array([est[ei[b], 1:4] for _, b in m]).T
    rot, trans, err = align(E, G)
    stats("ate", err)
    print("rot", rot.tolist(), "trans", trans.ravel().tolist())
    for per_frame, delta in ((False, 1.0), (True, 1.0)):
        et, er = rpe(gt, est, delta, per_frame)
        stats("rpe_%s_trans" % ("frame" if per_frame else "1s"), et)
        stats("rpe_%s_rot_deg" % ("frame" if per_frame else "1s"), er)


if __name__ == "__main__":
    main()
