#!/usr/bin/python3
"""Does the depth's scale drift over a sequence, or carry one disparity offset? (docs/real_frames.md,
"What is left": the depth's scale over time.)

    depth_scale_pairs.py DATA TRAJ pairs A,B [A,B ...]
    depth_scale_pairs.py DATA TRAJ scan D0 [D0 ...]

DATA: a pose-per-frame folder (7-Scenes layout, depth in millimetres, fx = fy = 585, 640x480).
TRAJ: a TUM trajectory with one line per frame in order (bitfuse replay's trajectory.txt of DATA).
Frame A's depth is aligned to frame B's by point-to-plane ICP (B's normals, projective association,
Huber at 3 sigma_z, weights (sigma_z(1 m) / sigma_z(z))^2) from TRAJ's relative pose.
`pairs`: per pair, the fit with 6 degrees of freedom, with a seventh for a scale of A's depth, and
with a seventh for a disparity offset of A's depth (1/z' = 1/z + d); residuals are given in
disparity units (residual / z^2), which a scale or offset of the depth does not shrink. A depth
whose scale drifts over the sequence gives scales that grow with the pair's span.
`scan`: every pair of a fixed list aligned with 6 degrees of freedom after a global disparity
offset D0 (per metre) is taken out of both frames; the mean residual in disparity units per D0.
A camera with such an offset has its minimum away from 0.
"""
import sys

import cv2
import numpy as np

FX = FY = 585.0
CX, CY = 320.0, 240.0
SCAN_PAIRS = [(0, 20), (0, 450), (20, 60), (50, 100), (100, 140), (150, 190), (200, 240), (250, 290),
              (300, 340), (350, 390), (400, 440), (450, 490), (120, 160), (330, 360)]


def quat_to_R(q):
    x, y, z, w = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def read_traj(path):
    T = []
    for line in open(path):
        if line.startswith('#') or not line.strip():
            continue
        v = list(map(float, line.split()))
        M = np.eye(4)
        M[:3, :3] = quat_to_R(np.array(v[4:8]))
        M[:3, 3] = v[1:4]
        T.append(M)
    return T


def read_depth(data, k, d0):
    """Frame k's depth in metres within 0.3-4.5 m, with the disparity offset d0 taken out."""
    d = cv2.imread('%s/frame-%06d.depth.png' % (data, k), cv2.IMREAD_UNCHANGED).astype(np.float64) / 1000
    d[(d > 4.5) | (d < 0.3)] = 0
    return np.where(d > 0, d / np.maximum(1 - d0 * d, 1e-3), 0)


def vertex_map(d):
    h, w = d.shape
    u, v = np.meshgrid(np.arange(w), np.arange(h))
    return np.dstack([(u - CX) * d / FX, (v - CY) * d / FY, d])


def normal_map(d):
    """Normals from a bilaterally smoothed copy; none across depth steps of 5 cm."""
    V = vertex_map(cv2.bilateralFilter(d.astype(np.float32), 7, 0.03, 4).astype(np.float64))
    dx, dy = np.zeros_like(V), np.zeros_like(V)
    dx[:, 1:-1] = V[:, 2:] - V[:, :-2]
    dy[1:-1] = V[2:] - V[:-2]
    n = np.cross(dx, dy)
    nn = np.linalg.norm(n, axis=2, keepdims=True)
    ok = (nn[..., 0] > 0) & (d > 0)
    ok &= np.abs(np.roll(d, 1, 1) - np.roll(d, -1, 1)) < 0.05
    ok &= np.abs(np.roll(d, 1, 0) - np.roll(d, -1, 0)) < 0.05
    return n / np.maximum(nn, 1e-12), ok


def align(data, T, a, b, model=None, d0=0.0, iters=25):
    """A's depth onto B's; model None (6 DoF), 'scale' or 'disp'. Returns the seventh parameter
    (scale, or offset per metre), the inliers and the RMS residual in disparity units (1/m)."""
    dA, dB = read_depth(data, a, d0), read_depth(data, b, d0)
    v, u = np.nonzero(dA)
    z = dA[v, u]
    P0 = np.stack([(u - CX) * z / FX, (v - CY) * z / FY, z], 1)[::3]
    VB = vertex_map(dB)
    NB, okB = normal_map(dB)
    M = np.linalg.inv(T[b]) @ T[a]
    R, t, s, off = M[:3, :3].copy(), M[:3, 3].copy(), 1.0, 0.0
    for _ in range(iters):
        P = P0 / (1 + off * P0[:, 2:3]) if model == 'disp' else P0
        Q = (s * P) @ R.T + t
        good = Q[:, 2] > 0.2
        zq = np.where(good, Q[:, 2], 1)
        u = np.round(Q[:, 0] / zq * FX + CX).astype(int)
        v = np.round(Q[:, 1] / zq * FY + CY).astype(int)
        good &= (u >= 0) & (u < 640) & (v >= 0) & (v < 480)
        u, v = np.where(good, u, 0), np.where(good, v, 0)
        good &= okB[v, u]
        q, n = VB[v, u], NB[v, u]
        r = np.einsum('ij,ij->i', Q - q, n)
        good &= np.abs(r) < 0.05
        sig = 0.0012 + 0.0019 * (q[good][:, 2] - 0.4) ** 2
        rg, ng, Qg = r[good], n[good], Q[good]
        Pg = (s * P[good]) @ R.T
        w = (0.0012 / sig) ** 2 * np.where(np.abs(rg) < 3 * sig, 1, 3 * sig / np.maximum(np.abs(rg), 1e-12))
        J = np.zeros((len(rg), 7))
        J[:, :3] = np.cross(Pg, ng)
        J[:, 3:6] = ng
        J[:, 6] = np.einsum('ij,ij->i', Pg, ng)  # d r / d log s
        if model == 'disp':
            J[:, 6] *= -P[good][:, 2]  # d r / d offset
        if model is None:
            J = J[:, :6]
        x = -np.linalg.solve(J.T @ (J * w[:, None]), J.T @ (w * rg))
        dR = cv2.Rodrigues(x[:3].reshape(3, 1))[0]
        R, t = dR @ R, dR @ t + x[3:6]
        if model == 'scale':
            s *= np.exp(x[6])
        elif model == 'disp':
            off += x[6]
    rd = rg / Qg[:, 2] ** 2
    rd = rd[np.abs(rd) < 0.01]
    return (s if model == 'scale' else off), len(rg), float(np.sqrt(np.mean(rd ** 2)))


def main():
    if len(sys.argv) < 5 or sys.argv[3] not in ('pairs', 'scan'):
        sys.exit(__doc__)
    data, T, mode = sys.argv[1], read_traj(sys.argv[2]), sys.argv[3]
    if mode == 'pairs':
        for arg in sys.argv[4:]:
            a, b = map(int, arg.split(','))
            _, n, r6 = align(data, T, a, b)
            s, _, rs = align(data, T, a, b, 'scale')
            off, _, rd = align(data, T, a, b, 'disp')
            print('%4d -> %4d: %6d inliers | 6 DoF %.3f /km | scale %+7.2f per mille %.3f /km | '
                  'disparity offset %+6.2f /km %.3f /km' % (a, b, n, r6 * 1000, (s - 1) * 1000, rs * 1000,
                                                           off * 1000, rd * 1000), flush=True)
    else:
        for d0 in map(float, sys.argv[4:]):
            r = [align(data, T, a, b, d0=d0)[2] for a, b in SCAN_PAIRS]
            print('d0 %+.4f /m: mean residual %.4f /km  [%s]' % (d0, np.mean(r) * 1000,
                                                               ' '.join('%.2f' % (x * 1000) for x in r)), flush=True)


if __name__ == '__main__':
    main()
