#!/usr/bin/env python3
"""Compares a calibration (bitfuse calibrate's calib.json) with the truth
that synth --board wrote: prints one JSON object of errors, and with
--check exits 1 when an error exceeds the bounds of docs/calibration.md."""
import json
import math
import sys


def rot_angle_deg(A, B):
    # Angle of A^T B, both row-major 3x3 lists of 9.
    tr = sum(A[3 * k + i] * B[3 * k + i] for i in range(3) for k in range(3))
    return math.degrees(math.acos(max(-1.0, min(1.0, (tr - 1) / 2))))


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
    bad = []
    for cam in ("colour", "depth"):
        if cam in err:
            c = err[cam]
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
