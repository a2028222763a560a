#!/usr/bin/env python3
"""Compares a calibration (bitfuse calibrate's calib.json) with the truth
that synth --board wrote: prints one JSON object of errors, and with
--check exits 1 when an error exceeds the bounds of docs/calibration.md,
or when the calibration lacks a camera or the transform the truth has."""
import json
import math
import sys


def rot_angle_deg(A, B):
    # Angle of A^T B, both row-major 3x3 lists of 9.
    tr = sum(A[3 * k + i] * B[3 * k + i] for i in range(3) for k in range(3))
    return math.degrees(math.acos(max(-1.0, min(1.0, (tr - 1) / 2))))


def shift_px(c, x, y):
    # How far the lens moves the ray (x, y) in c's image, in pixels.
    k1, k2, p1, p2, k3 = c["dist"]
    r2 = x * x + y * y
    rad = k1 * r2 + k2 * r2 * r2 + k3 * r2 ** 3
    dx = x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    dy = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return c["fx"] * dx, c["fy"] * dy


def lens_px(e, t):
    # The largest difference of the two lenses' shifts over the rays through
    # a grid of the image (by the truth's pinhole) that lie within the
    # estimate's coverage: the distortion where the boards measured it (the
    # focal lengths and principal point have bounds of their own).
    far = max(math.hypot(u / t["fx"], v / t["fy"])
              for u in (-0.5 - t["cx"], t["width"] - 0.5 - t["cx"]) for v in (-0.5 - t["cy"], t["height"] - 0.5 - t["cy"]))
    worst = 0.0
    for i in range(33):
        for j in range(25):
            x = (t["width"] * i / 32.0 - 0.5 - t["cx"]) / t["fx"]
            y = (t["height"] * j / 24.0 - 0.5 - t["cy"]) / t["fy"]
            if math.hypot(x, y) > e.get("coverage", 0) * far:
                continue
            (ue, ve), (ut, vt) = shift_px(e, x, y), shift_px(t, x, y)
            worst = max(worst, math.hypot(ue - ut, ve - vt))
    return worst


def errors(est, truth):
    out = {}
    for cam in ("colour", "depth"):
        if cam not in est:
            continue
        e, t = est[cam], truth[cam]
        out[cam] = {
            "fx_rel": abs(e["fx"] - t["fx"]) / t["fx"],
            "fy_rel": abs(e["fy"] - t["fy"]) / t["fy"],
            "cx_px": abs(e["cx"] - t["cx"]),
            "cy_px": abs(e["cy"] - t["cy"]),
            "k1": abs(e["dist"][0] - t["dist"][0]),
            "coverage": e.get("coverage", 0),
            "lens_px": lens_px(e, t),
            "rms_px": e["rms_px"],
        }
    if "T_colour_depth" in est:
        te, tt = est["T_colour_depth"]["t"], truth["T_colour_depth"]["t"]
        out["t_mm"] = 1e3 * math.sqrt(sum((a - b) ** 2 for a, b in zip(te, tt)))
        out["rot_deg"] = rot_angle_deg(est["T_colour_depth"]["R"], truth["T_colour_depth"]["R"])
        out["stereo_rms_px"] = est["rms_px"]
    return out


def main():
    args = [a for a in sys.argv[1:] if a != "--check"]
    est, truth = (json.load(open(p)) for p in args)
    err = errors(est, truth)
    print(json.dumps(err, indent=1))
    if "--check" not in sys.argv:
        return 0
    # Bounds: the 0.5% of focal length and 2 mm; the principal point
    # within 2 px and the rotation within 0.2 degrees (docs/calibration.md
    # measures about a tenth of each); a sub-pixel corner error gives an
    # RMS well below 0.3 px.
    bad = ["no %s camera" % cam for cam in ("colour", "depth") if cam in truth and cam not in err]
    if "T_colour_depth" in truth and "t_mm" not in err:
        bad.append("no T_colour_depth")
    for cam in ("colour", "depth"):
        if cam in err:
            c = err[cam]
            # Within the boards' reach the whole camera model puts a ray
            # within half a pixel of the truth (the corners are found to
            # a few hundredths); beyond it the lens is extrapolated.
            if c["coverage"] < 0.3 or c["lens_px"] > 0.5:
                bad.append("%s lens off by %.3f px within the boards' reach (%.0f%% of the way to the corners)"
                           % (cam, c["lens_px"], 100 * c["coverage"]))
            if c["fx_rel"] > 0.005 or c["fy_rel"] > 0.005:
                bad.append("%s focal length off by %.3f%% / %.3f%%" % (cam, 100 * c["fx_rel"], 100 * c["fy_rel"]))
            if c["cx_px"] > 2 or c["cy_px"] > 2:
                bad.append("%s principal point off by %.2f, %.2f px" % (cam, c["cx_px"], c["cy_px"]))
            if c["rms_px"] > 0.3:
                bad.append("%s RMS %.3f px" % (cam, c["rms_px"]))
    if "t_mm" in err:
        if err["t_mm"] > 2:
            bad.append("T_colour_depth translation off by %.2f mm" % err["t_mm"])
        if err["rot_deg"] > 0.2:
            bad.append("T_colour_depth rotation off by %.3f deg" % err["rot_deg"])
        if err["stereo_rms_px"] > 0.3:
            bad.append("stereo RMS %.3f px" % err["stereo_rms_px"])
    for b in bad:
        print("FAIL: " + b, file=sys.stderr)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
