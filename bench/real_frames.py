#!/usr/bin/python3
"""Where the trajectory error on real frames comes from (bench/real_frames.sh).

    real_frames.py DATA OUT MD PNG

DATA: a pose-per-frame folder (frame-NNNNNN.{depth.png,pose.txt}, camera to world).
OUT: the replays, one folder per run, listed in OUT/runs.tsv (name, label, options),
the first two being the plain loop ("plain") and --fuse-at-groundtruth ("fgt"), and
OUT/eval/NAME.{all,cut}.json (bitfuse eval-traj --json over all frames and frames
0..CUT). Writes OUT/depth_stats.csv (cached), OUT/per_frame.csv, the plot PNG and
the generated blocks of MD (between <!-- gen:NAME --> and <!-- /gen:NAME -->; the
rest of MD, the analysis, is kept).
"""
import csv
import json
import os
import re
import sys

import numpy as np

CUT = 420          # ground truth jumps 27 mm between dev frames 420 and 421
BLOCK = 50
FPS = 30.0         # replay's timestamps of numbered frames: index / 30
MAX_DEPTH_M = 4.5  # tracking's max_depth_m


# ------------------------------------------------------------------ poses

def quat_to_R(qx, qy, qz, qw):
    n = np.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    x, y, z, w = qx / n, qy / n, qz / n, qw / n
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def read_tum(path):
    """{frame index: 4x4 T_wc} from a TUM file whose stamps are index / FPS."""
    out = {}
    for line in open(path):
        v = line.split()
        if not v or v[0].startswith("#"):
            continue
        t, tx, ty, tz, qx, qy, qz, qw = map(float, v[:8])
        T = np.eye(4)
        T[:3, :3] = quat_to_R(qx, qy, qz, qw)
        T[:3, 3] = (tx, ty, tz)
        out[int(round(t * FPS))] = T
    return out


def read_intrinsics(data):
    K = np.loadtxt(os.path.join(data, "camera-intrinsics.txt"))
    return K[0, 0], K[1, 1], K[0, 2], K[1, 2]


def read_gt(data, n):
    """The true poses; their rotations (7-Scenes: |R^T R - I| ~ 3e-4) replaced by the nearest
    rotation (polar factor), else every angle measured against them is off by ~1.7 degrees."""
    G = np.array([np.loadtxt(os.path.join(data, "frame-%06d.pose.txt" % i)) for i in range(n)])
    for T in G:
        U, _, Vt = np.linalg.svd(T[:3, :3])
        T[:3, :3] = U @ np.diag([1, 1, np.linalg.det(U @ Vt)]) @ Vt
    return G


def R_to_quat(R):
    # Shepperd's method
    t = np.trace(R)
    if t > 0:
        s = 2 * np.sqrt(t + 1)
        return np.array([(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, s / 4])
    i = int(np.argmax(np.diag(R)))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = 2 * np.sqrt(1 + R[i, i] - R[j, j] - R[k, k])
    q = np.zeros(4)
    q[i] = s / 4
    q[j] = (R[j, i] + R[i, j]) / s
    q[k] = (R[k, i] + R[i, k]) / s
    q[3] = (R[k, j] - R[j, k]) / s
    return q


def write_tum(path, T, first, last):
    with open(path, "w") as f:
        for i in range(first, last + 1):
            q = R_to_quat(T[i][:3, :3])
            if q[3] < 0:
                q = -q
            f.write("%.6f %.9f %.9f %.9f %.9f %.9f %.9f %.9f\n" % ((i / FPS,) + tuple(T[i][:3, 3]) + tuple(q)))


def inv(T):
    Ti = np.eye(4)
    Ti[:3, :3] = T[:3, :3].T
    Ti[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return Ti


def rot_vec(R):
    """axis * angle (radians) of a rotation matrix."""
    c = np.clip((np.trace(R) - 1) / 2, -1, 1)
    a = np.arccos(c)
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if a < 1e-9:
        return w / 2
    return w * a / (2 * np.sin(a))


def angle_deg(R):
    return np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1)))


def horn(P_est, P_gt):
    """R, t with R p_est + t ~ p_gt (TUM evaluate_ate's align, no scale)."""
    me, mg = P_est.mean(0), P_gt.mean(0)
    H = (P_est - me).T @ (P_gt - mg)
    U, _, Vt = np.linalg.svd(H)
    S = np.eye(3)
    if np.linalg.det(Vt.T @ U.T) < 0:
        S[2, 2] = -1
    R = Vt.T @ S @ U.T
    return R, mg - R @ me


def ate_rmse(P_est, P_gt):
    R, t = horn(P_est, P_gt)
    e = np.linalg.norm(P_est @ R.T + t - P_gt, axis=1)
    return float(np.sqrt(np.mean(e * e))), e


# ------------------------------------------------------------------ inputs

def depth_stats(data, n, cache):
    if os.path.exists(cache):
        rows = list(csv.DictReader(open(cache)))
        if len(rows) == n:
            return {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}
    from PIL import Image
    cols = {"valid_share": [], "median_m": [], "p90_m": [], "beyond_3m_share": [], "near_share": []}
    for i in range(n):
        d = np.asarray(Image.open(os.path.join(data, "frame-%06d.depth.png" % i)), dtype=np.float64) / 1000.0
        v = d[(d > 0) & (d <= MAX_DEPTH_M) & (d < 65.0)]
        cols["valid_share"].append(v.size / d.size)
        cols["median_m"].append(np.median(v) if v.size else 0)
        cols["p90_m"].append(np.percentile(v, 90) if v.size else 0)
        cols["beyond_3m_share"].append((v > 3.0).sum() / max(v.size, 1))
        cols["near_share"].append((v < 0.8).sum() / max(v.size, 1))
    with open(cache, "w") as f:
        w = csv.writer(f)
        w.writerow(cols.keys())
        for i in range(n):
            w.writerow(["%.5f" % cols[k][i] for k in cols])
    return {k: np.array(v) for k, v in cols.items()}


K_CONSIST = (1, 15, 40)


class DepthAgreement:
    """How well two poses explain two depth images, without ground truth: frame b's depth
    (every 4th pixel) mapped into frame a with T_a^-1 T_b; the share of the pixels landing on
    valid depth whose depth agrees within 1% (Kinect v1's noise at ~2 m is ~0.5%)."""

    def __init__(self, data, K):
        from PIL import Image
        self.Image, self.data, self.K, self.cache = Image, data, K, {}
        fx, fy, cx, cy = K
        self.v, self.u = np.mgrid[0:480:4, 0:640:4]

    def depth(self, i):
        if i not in self.cache:
            d = np.asarray(self.Image.open(os.path.join(self.data, "frame-%06d.depth.png" % i)), dtype=np.float64) / 1e3
            d[(d <= 0) | (d > MAX_DEPTH_M)] = 0
            self.cache[i] = d
        return self.cache[i]

    def share(self, a, b, Ta, Tb):
        fx, fy, cx, cy = self.K
        db = self.depth(b)[::4, ::4]
        m = db > 0
        z = db[m]
        P = np.stack([(self.u[m] - cx) * z / fx, (self.v[m] - cy) * z / fy, z, np.ones_like(z)])
        Q = (inv(Ta) @ Tb) @ P
        ok = Q[2] > 0.1
        ua = np.round(fx * Q[0][ok] / Q[2][ok] + cx).astype(int)
        va = np.round(fy * Q[1][ok] / Q[2][ok] + cy).astype(int)
        zq = Q[2][ok]
        inside = (ua >= 0) & (ua < 640) & (va >= 0) & (va < 480)
        da = self.depth(a)[va[inside], ua[inside]]
        zq = zq[inside]
        hit = da > 0
        if hit.sum() < 100:
            return np.nan
        return float((np.abs(da[hit] - zq[hit]) < 0.01 * zq[hit]).mean())


def dominant_plane(data, i, K, seed=0, iters=300, tol=0.01):
    """RANSAC: the plane that most of frame i's depth points (every 2nd pixel) lie within tol of;
    its unit normal (camera frame) and the share of the points on it."""
    from PIL import Image
    fx, fy, cx, cy = K
    d = np.asarray(Image.open(os.path.join(data, "frame-%06d.depth.png" % i)), dtype=np.float64)[::2, ::2] / 1e3
    v, u = np.mgrid[0:480:2, 0:640:2]
    m = (d > 0) & (d <= MAX_DEPTH_M)
    z = d[m]
    X = np.stack([(u[m] - cx) * z / fx, (v[m] - cy) * z / fy, z], 1)
    rng = np.random.default_rng(seed)
    best, best_n = 0, None
    for _ in range(iters):
        s = X[rng.choice(len(X), 3, replace=False)]
        nrm = np.cross(s[1] - s[0], s[2] - s[0])
        if np.linalg.norm(nrm) < 1e-9:
            continue
        nrm /= np.linalg.norm(nrm)
        c = int((np.abs((X - s[0]) @ nrm) < tol).sum())
        if c > best:
            best, best_n = c, nrm
    return best_n, best / len(X)


def read_frames_csv(path):
    rows = list(csv.DictReader(open(path)))
    return {int(r["index"]): r for r in rows}


class Run:
    def __init__(self, out, name, label, opts, G):
        self.name, self.label, self.opts = name, label, opts
        d = os.path.join(out, name)
        self.stats = json.load(open(os.path.join(d, "stats.json")))
        self.frames = read_frames_csv(os.path.join(d, "frames.csv"))
        est = read_tum(os.path.join(d, "trajectory.txt"))
        n = len(G)
        missing = [i for i in range(n) if i not in est]
        if missing:
            sys.exit("%s: trajectory misses frames %s" % (name, missing[:5]))
        self.T = np.array([est[i] for i in range(n)])
        self.fgt = "--fuse-at-groundtruth" in opts
        self.ev = {}
        for part in ("all", "cut"):
            p = os.path.join(out, "eval", "%s.%s.json" % (name, part))
            self.ev[part] = json.load(open(p)) if os.path.exists(p) else None
        self.compute(G)

    def compute(self, G):
        T, n = self.T, len(G)
        Pe, Pg = T[:, :3, 3], G[:, :3, 3]
        self.ate_all, self.e_aligned = ate_rmse(Pe, Pg)
        self.ate_cut, _ = ate_rmse(Pe[:CUT + 1], Pg[:CUT + 1])
        # unaligned: the run starts at the first true pose
        self.e_pos = np.linalg.norm(Pe - Pg, axis=1)
        self.e_rot = np.array([angle_deg(G[i][:3, :3].T @ T[i][:3, :3]) for i in range(n)])
        # per-step error (camera frame of the step's end): plain = RPE per frame;
        # fuse-at-groundtruth: the estimate against its true pose (one step from the previous true pose)
        st, sr = np.full(n, np.nan), np.full(n, np.nan)
        sv_t, sv_r = np.full((n, 3), np.nan), np.full((n, 3), np.nan)
        for i in range(1, n):
            if self.fgt:
                E = inv(G[i]) @ T[i]
            else:
                E = inv(inv(G[i - 1]) @ G[i]) @ (inv(T[i - 1]) @ T[i])
            st[i], sr[i] = np.linalg.norm(E[:3, 3]), angle_deg(E[:3, :3])
            sv_t[i], sv_r[i] = E[:3, 3], np.degrees(rot_vec(E[:3, :3]))
        self.step_t, self.step_r, self.step_vt, self.step_vr = st * 1e3, sr, sv_t * 1e3, sv_r
        self.col = lambda k: np.array([float(self.frames[i][k]) if self.frames[i][k] != "" else np.nan
                                       for i in range(n)])

    def hybrids(self, G):
        """Positions of the chain of the run's steps with (a) its rotations and the true
        translations, (b) the true rotations and its translations: which part of the
        step error makes the position error (a rotation error's lever arm is in (a))."""
        n = len(G)
        Ta, Tb = [G[0]], [G[0]]
        for i in range(1, n):
            Sg = inv(G[i - 1]) @ G[i]
            Se = inv(self.T[i - 1]) @ self.T[i]
            A = np.eye(4)
            A[:3, :3], A[:3, 3] = Se[:3, :3], Sg[:3, 3]
            B = np.eye(4)
            B[:3, :3], B[:3, 3] = Sg[:3, :3], Se[:3, 3]
            Ta.append(Ta[-1] @ A)
            Tb.append(Tb[-1] @ B)
        Pg = G[:, :3, 3]
        ea = np.linalg.norm(np.array(Ta)[:, :3, 3] - Pg, axis=1)
        eb = np.linalg.norm(np.array(Tb)[:, :3, 3] - Pg, axis=1)
        return ea, eb, np.array(Ta), np.array(Tb)


# ------------------------------------------------------------------ output

def fmt(x, d=1):
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "-"
    return "%.*f" % (d, x)


def gen_blocks(md_path, blocks, skeleton):
    text = open(md_path).read() if os.path.exists(md_path) else skeleton
    for name, body in blocks.items():
        pat = re.compile(r"(<!-- gen:%s -->\n).*?(<!-- /gen:%s -->)" % (name, name), re.S)
        if not pat.search(text):
            text += "\n<!-- gen:%s -->\n<!-- /gen:%s -->\n" % (name, name)
        text = pat.sub(lambda m: m.group(1) + body.rstrip("\n") + "\n" + m.group(2), text)
    open(md_path, "w").write(text)


def main():
    data, out, md, png = sys.argv[1:5]
    runs_tsv = [l.rstrip("\n").split("\t") for l in open(os.path.join(out, "runs.tsv")) if l.strip()]
    n = len([f for f in os.listdir(data) if f.endswith(".pose.txt")])
    G = read_gt(data, n)
    write_tum(os.path.join(out, "groundtruth.txt"), G, 0, n - 1)
    write_tum(os.path.join(out, "groundtruth.cut.txt"), G, 0, CUT)
    if len(sys.argv) > 5 and sys.argv[5] == "--gt-only":
        return
    ds = depth_stats(data, n, os.path.join(out, "depth_stats.csv"))
    runs = [Run(out, nm, lb, op, G) for nm, lb, op in runs_tsv
            if os.path.exists(os.path.join(out, nm, "stats.json"))]
    by = {r.name: r for r in runs}
    plain, fgt = by["plain"], by.get("fgt")
    blocks = {}

    # cross-check against eval-traj
    checks = []
    for r in runs:
        for part, mine in (("all", r.ate_all), ("cut", r.ate_cut)):
            ev = r.ev[part]
            if ev:
                theirs = ev["ate"]["trans_m"]["rmse"]
                checks.append(abs(theirs - mine) * 1e3)
                if abs(theirs - mine) > 1e-4:
                    print("warning: %s %s: ATE %.4f here, eval-traj %.4f" % (r.name, part, mine, theirs))
    gt_step = np.r_[np.nan, np.linalg.norm(np.diff(G[:, :3, 3], axis=0), axis=1) * 1e3]
    gt_rstep = np.r_[np.nan, [angle_deg(G[i - 1][:3, :3].T @ G[i][:3, :3]) for i in range(1, n)]]

    # --- summary table
    rows = ["| run | options | tracked / repeated (skipped) / lost / degenerate | ATE 0-499 mm | ATE 0-%d mm "
            "| max unaligned error mm (frame) | RPE per frame median trans mm / rot deg | time per frame median (p95) ms |" % CUT,
            "|---|---|---|---|---|---|---|---|"]
    for r in runs:
        t = r.stats["tracking"]
        k = int(np.argmax(r.e_pos))
        rows.append("| %s | `%s` | %d / %d / %d / %d | %s | %s | %s (%d) | %s / %s | %s (%s) |" % (
            r.label, r.opts or "(defaults)", t["tracked"], t.get("repeated", 0), t["lost"], t["degenerate"],
            fmt(1e3 * r.ate_all),
            fmt(1e3 * r.ate_cut), fmt(r.e_pos[k] * 1e3), k, fmt(np.nanmedian(r.step_t), 2),
            fmt(np.nanmedian(r.step_r), 3), fmt(r.stats["frame_ms"]["median"], 0), fmt(r.stats["frame_ms"]["p95"], 0)))
    rows.append("")
    rows.append("ATE: Horn-aligned RMSE (rotation + translation) over frames 0-499 and, aligned separately, 0-%d; "
                "eval-traj on the same files agrees within %.3f mm. Unaligned error: |p_est - p_true|, "
                "the runs starting at the first true pose. RPE per frame: the error of each step's relative pose "
                "(plain loop: TUM's RPE with delta one frame; fuse-at-groundtruth: the estimate against the "
                "frame's true pose, i.e. the one step from the previous true pose). fuse-at-groundtruth's ATE is "
                "that of its independent one-step estimates, not a drift." % (CUT, max(checks) if checks else float("nan")))
    blocks["summary"] = "\n".join(rows)

    # --- every run's unaligned error per 50 frames (the variants side by side)
    heads = ["%d-%d" % (b0, min(b0 + BLOCK, n) - 1) for b0 in range(0, n, BLOCK)]
    rows = ["| run | " + " | ".join(heads) + " |", "|---|" + "---|" * len(heads)]
    for r in runs:
        rows.append("| %s | %s |" % (r.label, " | ".join(fmt(np.mean(r.e_pos[b0:b0 + BLOCK]) * 1e3)
                                                         for b0 in range(0, n, BLOCK))))
    rows.append("")
    rows.append("Mean unaligned position error (mm) over each block of %d frames, for every run of the summary "
                "(fuse at ground truth: its one-step estimates, each from the previous true pose)." % BLOCK)
    blocks["run_blocks"] = "\n".join(rows)

    # --- per-50 table
    rows = ["| frames | plain ATE mm (in block, global alignment) | plain unaligned mean / max mm | "
            "plain rot unaligned deg (end) | plain step mm / deg (median) | plain step length / true (LS) | fgt step mm / deg (median) | "
            "true motion mm / deg per frame (median) | inliers plain / fgt | "
            "residual mm plain / fgt | eigen ratio min (plain) | depth valid % | depth median m |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    Sg_t = np.array([np.full(3, np.nan)] + [(inv(G[i - 1]) @ G[i])[:3, 3] * 1e3 for i in range(1, n)])
    Se_t = np.array([np.full(3, np.nan)] + [(inv(plain.T[i - 1]) @ plain.T[i])[:3, 3] * 1e3 for i in range(1, n)])
    inl_p, inl_f = plain.col("inlier_frac"), fgt.col("inlier_frac") if fgt else None
    res_p, res_f = plain.col("residual_mm"), fgt.col("residual_mm") if fgt else None
    eig_p = plain.col("eig_ratio")
    eig_p[[i for i in range(n) if plain.frames[i]["icp"] == ""]] = np.nan
    for b0 in range(0, n, BLOCK):
        s = slice(b0, min(b0 + BLOCK, n))
        ea = plain.e_aligned[s] * 1e3
        cells = ["%d-%d" % (b0, s.stop - 1), fmt(np.sqrt(np.mean(ea ** 2))),
                 "%s / %s" % (fmt(np.mean(plain.e_pos[s]) * 1e3), fmt(np.max(plain.e_pos[s]) * 1e3)),
                 fmt(plain.e_rot[s.stop - 1], 2),
                 "%s / %s" % (fmt(np.nanmedian(plain.step_t[s]), 2), fmt(np.nanmedian(plain.step_r[s]), 3)),
                 fmt(np.nansum(Se_t[s] * Sg_t[s]) / np.nansum(Sg_t[s] ** 2), 2)]
        if fgt:
            cells += ["%s / %s" % (fmt(np.nanmedian(fgt.step_t[s]), 2), fmt(np.nanmedian(fgt.step_r[s]), 3))]
        else:
            cells += ["-"]
        cells += ["%s / %s" % (fmt(np.nanmedian(gt_step[s]), 1), fmt(np.nanmedian(gt_rstep[s]), 2)),
                  "%s / %s" % (fmt(np.nanmedian(inl_p[s]) * 100, 0), fmt(np.nanmedian(inl_f[s]) * 100, 0) if fgt else "-"),
                  "%s / %s" % (fmt(np.nanmedian(res_p[s]), 1), fmt(np.nanmedian(res_f[s]), 1) if fgt else "-"),
                  "%.1e" % np.nanmin(eig_p[s]),
                  fmt(np.mean(ds["valid_share"][s]) * 100, 0), fmt(np.median(ds["median_m"][s]), 2)]
        rows.append("| " + " | ".join(cells) + " |")
    blocks["blocks"] = "\n".join(rows)

    # --- rotation against translation
    ea, eb, Ta, Tb = plain.hybrids(G)
    rows = ["| frames | plain unaligned position error mm (mean / end) | chain of its rotations + true "
            "translations | chain of true rotations + its translations | unaligned rotation error deg (end) |",
            "|---|---|---|---|---|"]
    for b0 in range(0, n, 100):
        s = slice(b0, min(b0 + 100, n))
        e = s.stop - 1
        rows.append("| %d-%d | %s / %s | %s / %s | %s / %s | %s |" % (
            b0, e, fmt(np.mean(plain.e_pos[s]) * 1e3), fmt(plain.e_pos[e] * 1e3),
            fmt(np.mean(ea[s]) * 1e3), fmt(ea[e] * 1e3), fmt(np.mean(eb[s]) * 1e3), fmt(eb[e] * 1e3),
            fmt(plain.e_rot[e], 2)))
    ate_a, _ = ate_rmse(Ta[:, :3, 3], G[:, :3, 3])
    ate_b, _ = ate_rmse(Tb[:, :3, 3], G[:, :3, 3])
    ate_a_c, _ = ate_rmse(Ta[:CUT + 1, :3, 3], G[:CUT + 1, :3, 3])
    ate_b_c, _ = ate_rmse(Tb[:CUT + 1, :3, 3], G[:CUT + 1, :3, 3])
    rows.append("")
    rows.append("ATE of the two chains: rotations only %s mm (0-%d: %s), translations only %s mm (0-%d: %s); "
                "the plain loop %s (%s). The plain loop's unaligned rotation error peaks at %s deg (frame %d); "
                "the rotations-only chain's unaligned position error at %s mm." % (
                    fmt(ate_a * 1e3), CUT, fmt(ate_a_c * 1e3), fmt(ate_b * 1e3), CUT, fmt(ate_b_c * 1e3),
                    fmt(plain.ate_all * 1e3), fmt(plain.ate_cut * 1e3), fmt(np.max(plain.e_rot), 2),
                    int(np.argmax(plain.e_rot)), fmt(np.max(ea) * 1e3)))
    # signed step errors: bias against spread (camera axes: x right, y down, z forward)
    rows.append("")
    rows.append("Signed per-step error, camera axes of the step's end (x right, y down, z forward), frames 1-%d "
                "(sum over the frames / mean / std / what the spread alone would sum to, std x sqrt(n)):" % CUT)
    rows.append("")
    rows.append("| run | component | sum | mean | std | std x sqrt(n) |")
    rows.append("|---|---|---|---|---|---|")
    for r in (plain,):
        for nm, v, u in (("t", r.step_vt, "mm"), ("rot", r.step_vr, "deg")):
            for a, ax in enumerate("xyz"):
                x = v[1:CUT + 1, a]
                rows.append("| %s | %s %s (%s) | %s | %s | %s | %s |" % (
                    r.label, nm, ax, u, fmt(np.sum(x), 2), fmt(np.mean(x), 3), fmt(np.std(x), 3),
                    fmt(np.std(x) * np.sqrt(len(x)), 2)))
    # world-frame accumulation of the step rotation errors (plain)
    blocks["rot_trans"] = "\n".join(rows)

    # --- frames where the step error jumps
    med_t, med_r = np.nanmedian(plain.step_t), np.nanmedian(plain.step_r)
    mad_t = np.nanmedian(np.abs(plain.step_t - med_t))
    mad_r = np.nanmedian(np.abs(plain.step_r - med_r))
    thr_t, thr_r = med_t + 6 * 1.4826 * mad_t, med_r + 6 * 1.4826 * mad_r
    sel = [i for i in range(1, n) if plain.step_t[i] > thr_t or plain.step_r[i] > thr_r]

    def plane_cell(i):
        nrm, share = dominant_plane(data, i, Kc)
        e1 = plain.step_vt[i]
        e10 = np.nansum(plain.step_vt[max(1, i - 9):i + 1], axis=0)
        a1 = np.degrees(np.arccos(min(1.0, abs(e1 @ nrm) / np.linalg.norm(e1))))
        a10 = np.degrees(np.arccos(min(1.0, abs(e10 @ nrm) / np.linalg.norm(e10))))
        return "%s%% / %s deg (%s deg, %s mm)" % (fmt(100 * share, 0), fmt(a1, 0), fmt(a10, 0),
                                                 fmt(np.linalg.norm(e10), 0))
    rows = ["Frames whose plain-loop step error is above median + 6 x 1.4826 MAD (%s mm or %s deg; "
            "%d of %d frames), with the fuse-at-groundtruth step error of the same frame, the true motion of "
            "that step and what frames.csv and the depth PNG say:" % (fmt(thr_t, 2), fmt(thr_r, 3), len(sel), n - 1),
            "",
            "| frame | plain step mm / deg | fgt step mm / deg | true step mm / deg | plain inliers % / residual mm "
            "/ eigen ratio / degenerate | fgt inliers % / residual mm | depth valid % / median m / >3 m % | "
            "largest plane: share of pixels / angle of the step error (this frame; summed over its last 10 frames) "
            "to its normal |",
            "|---|---|---|---|---|---|---|---|"]
    Kc = read_intrinsics(data)
    for i in sel:
        f = plain.frames[i]
        g = fgt.frames[i] if fgt else None
        rows.append("| %d | %s / %s | %s | %s / %s | %s / %s / %s / %s | %s | %s / %s / %s | %s |" % (
            i, fmt(plain.step_t[i], 1), fmt(plain.step_r[i], 2),
            ("%s / %s" % (fmt(fgt.step_t[i], 1), fmt(fgt.step_r[i], 2))) if fgt else "-",
            fmt(gt_step[i], 1), fmt(gt_rstep[i], 2),
            fmt(float(f["inlier_frac"]) * 100, 0), fmt(float(f["residual_mm"]), 1), "%.1e" % float(f["eig_ratio"]),
            f["degenerate"],
            ("%s / %s" % (fmt(float(g["inlier_frac"]) * 100, 0), fmt(float(g["residual_mm"]), 1))) if g else "-",
            fmt(ds["valid_share"][i] * 100, 0), fmt(ds["median_m"][i], 2), fmt(ds["beyond_3m_share"][i] * 100, 0),
            plane_cell(i)))
    # the contribution of these frames to the end error: chain without their step errors
    rows.append("")
    Tc = [G[0]]
    for i in range(1, n):
        S = inv(G[i - 1]) @ G[i] if i in sel else inv(plain.T[i - 1]) @ plain.T[i]
        Tc.append(Tc[-1] @ S)
    Tc = np.array(Tc)
    ate_c, _ = ate_rmse(Tc[:, :3, 3], G[:, :3, 3])
    ate_cc, _ = ate_rmse(Tc[:CUT + 1, :3, 3], G[:CUT + 1, :3, 3])
    rows.append("The plain loop's steps chained with %s replaced by the true one%s: ATE %s mm "
                "(0-%d: %s) against %s (%s)." % ("this step" if len(sel) == 1 else "these %d steps" % len(sel),
                                                 "" if len(sel) == 1 else "s", fmt(ate_c * 1e3), CUT, fmt(ate_cc * 1e3),
                                                 fmt(plain.ate_all * 1e3), fmt(plain.ate_cut * 1e3)))
    for lo, hi in ((250, 349), (200, 399)):
        Tc = [G[0]]
        for i in range(1, n):
            S = inv(G[i - 1]) @ G[i] if lo <= i <= hi else inv(plain.T[i - 1]) @ plain.T[i]
            Tc.append(Tc[-1] @ S)
        Tc = np.array(Tc)
        a1, _ = ate_rmse(Tc[:, :3, 3], G[:, :3, 3])
        a2, _ = ate_rmse(Tc[:CUT + 1, :3, 3], G[:CUT + 1, :3, 3])
        rows.append("With all its steps of frames %d-%d replaced by the true ones: ATE %s mm (0-%d: %s)." % (
            lo, hi, fmt(a1 * 1e3), CUT, fmt(a2 * 1e3)))
    # correlations over all frames
    def corr(a, b):
        m = np.isfinite(a) & np.isfinite(b)
        return np.corrcoef(a[m], b[m])[0, 1]
    rows.append("")
    rows.append("Correlation over frames 1-%d of the plain step error (mm) with: the true step length %s, "
                "the true step rotation %s, the fgt step error %s, 1 - inlier fraction %s, residual %s, "
                "depth valid share %s, median depth %s. Of the fgt step error with the true step length %s, "
                "the true rotation %s, median depth %s." % (
                    n - 1, fmt(corr(plain.step_t, gt_step), 2), fmt(corr(plain.step_t, gt_rstep), 2),
                    fmt(corr(plain.step_t, fgt.step_t), 2) if fgt else "-", fmt(corr(plain.step_t, 1 - inl_p), 2),
                    fmt(corr(plain.step_t, res_p), 2), fmt(corr(plain.step_t, ds["valid_share"]), 2),
                    fmt(corr(plain.step_t, ds["median_m"]), 2),
                    fmt(corr(fgt.step_t, gt_step), 2) if fgt else "-", fmt(corr(fgt.step_t, gt_rstep), 2) if fgt else "-",
                    fmt(corr(fgt.step_t, ds["median_m"]), 2) if fgt else "-"))
    blocks["jumps"] = "\n".join(rows)

    # --- agreement of the poses with the depth images (no ground truth involved)
    fx, fy, cx, cy = read_intrinsics(data)
    agree = DepthAgreement(data, (fx, fy, cx, cy))
    cols = [("true", None)] + [(r.label, r) for r in runs]
    rows = ["Share of depth pixels (%%) that agree within 1%% after mapping frame i-k into frame i with each "
            "run's poses (every 4th pixel; frames i of the block, every 2nd; fuse at ground truth: frame i-k at "
            "its true pose, frame i at the estimate, as its map had them). Higher is a better fit to the data; it "
            "does not say which pose is true (the ground truth was made by KinectFusion, and Kinect v1's "
            "uncorrected depth distortion moves the best-fitting pose). Order in each cell: %s." % (
                " / ".join(c[0] for c in cols)), "",
            "| frames | " + " | ".join("k = %d" % k for k in K_CONSIST) + " |",
            "|---|" + "---|" * len(K_CONSIST)]

    def pose(c, i, first):
        if c is None:
            return G[i]
        return G[i] if (c.fgt and first) else c.T[i]

    tot = {k: [[] for _ in cols] for k in K_CONSIST}
    for b0 in range(0, n, BLOCK):
        cells = ["%d-%d" % (b0, min(b0 + BLOCK, n) - 1)]
        for k in K_CONSIST:
            vals = [[] for _ in cols]
            for i in range(max(b0, k), min(b0 + BLOCK, n), 2):
                for j, (_, c) in enumerate(cols):
                    vals[j].append(agree.share(i - k, i, pose(c, i - k, True), pose(c, i, False)))
            for j in range(len(cols)):
                tot[k][j] += vals[j]
            cells.append(" / ".join(fmt(100 * np.nanmean(v), 1) for v in vals))
        rows.append("| " + " | ".join(cells) + " |")
    rows.append("| all | " + " | ".join(" / ".join(fmt(100 * np.nanmean(v), 1) for v in tot[k])
                                        for k in K_CONSIST) + " |")
    rows.append("")
    kk = K_CONSIST[1]
    g, p_ = np.array(tot[kk][0]), np.array(tot[kk][1])
    rows.append("At k = %d the plain loop's poses fit better than the true ones in %d%% of the pairs." % (
        kk, round(100 * np.nanmean(p_ > g))))
    blocks["agreement"] = "\n".join(rows)

    # --- per-frame csv for the record
    with open(os.path.join(out, "per_frame.csv"), "w") as f:
        w = csv.writer(f)
        hdr = ["frame", "gt_step_mm", "gt_step_deg", "valid_share", "median_depth_m"]
        for r in runs:
            hdr += [r.name + s for s in ("_unaligned_mm", "_unaligned_deg", "_aligned_mm", "_step_mm", "_step_deg")]
        w.writerow(hdr)
        for i in range(n):
            row = [i, gt_step[i], gt_rstep[i], ds["valid_share"][i], ds["median_m"][i]]
            for r in runs:
                row += [r.e_pos[i] * 1e3, r.e_rot[i], r.e_aligned[i] * 1e3, r.step_t[i], r.step_r[i]]
            w.writerow(["%.5g" % x if isinstance(x, float) else x for x in row])

    # --- plot
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(4, 1, figsize=(11, 12), sharex=True)
    x = np.arange(n)
    for r, c in [(plain, "C0")] + ([(fgt, "C3")] if fgt else []):
        ax[0].plot(x, r.e_pos * 1e3, c, lw=1.2, label=r.label)
        ax[1].plot(x, r.e_rot, c, lw=1.2, label=r.label)
        ax[2].plot(x, r.step_t, c, lw=0.8, label=r.label)
        ax[3].plot(x, r.step_r, c, lw=0.8, label=r.label)
    ax[0].plot(x, ea * 1e3, "k--", lw=1, label="plain: its rotations + true translations")
    ax[0].plot(x, eb * 1e3, color="darkorange", ls=":", lw=1.8, label="plain: true rotations + its translations")
    ax[2].plot(x, gt_step / 10, "k", lw=0.6, alpha=0.5, label="true step / 10")
    ax[0].set_ylabel("unaligned position error (mm)")
    ax[1].set_ylabel("unaligned rotation error (deg)")
    ax[2].set_ylabel("step error, translation (mm)")
    ax[3].set_ylabel("step error, rotation (deg)")
    ax[3].set_xlabel("frame (7-Scenes dev frames 0-%d)" % (n - 1))
    for a in ax:
        a.axvline(CUT + 0.5, color="grey", ls="--", lw=0.8)
        a.grid(alpha=0.3)
        a.legend(loc="upper left", fontsize=8)
    ax[2].set_yscale("log")
    ax[3].set_yscale("log")
    ax[0].set_title("bitfuse on 500 real Kinect v1 frames: plain loop against tracking a map fused at the true poses")
    fig.tight_layout()
    fig.savefig(png, dpi=80)
    from PIL import Image
    Image.open(png).convert("RGB").quantize(colors=64, dither=Image.Dither.NONE).save(png, optimize=True)  # ~10x smaller

    # --- probes (options other than plain / fgt)
    skeleton = ("# Real frames: where the trajectory error comes from\n\n<!-- gen:summary -->\n<!-- /gen:summary -->\n\n"
                "<!-- gen:run_blocks -->\n<!-- /gen:run_blocks -->\n\n<!-- gen:blocks -->\n<!-- /gen:blocks -->\n\n<!-- gen:rot_trans -->\n<!-- /gen:rot_trans -->\n\n"
                "<!-- gen:jumps -->\n<!-- /gen:jumps -->\n\n<!-- gen:agreement -->\n<!-- /gen:agreement -->\n")
    gen_blocks(md, blocks, skeleton)
    for r in runs:
        print("%-10s ATE %.1f mm (0-%d %.1f), max unaligned %.1f mm, step median %.2f mm %.3f deg, %.0f ms/frame" % (
            r.name, r.ate_all * 1e3, CUT, r.ate_cut * 1e3, r.e_pos.max() * 1e3, np.nanmedian(r.step_t),
            np.nanmedian(r.step_r), r.stats["frame_ms"]["median"]))


if __name__ == "__main__":
    main()
