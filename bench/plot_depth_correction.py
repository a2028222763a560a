#!/usr/bin/env python3
"""The depth camera's fixed pattern as bitfuse calibrate-depth measured it, as an image.

usage: bench/plot_depth_correction.py depth_correction.json OUT.png [TITLE]

Draws (multiplier - 1) in parts per thousand per cell (red: the sensor reads too
near and the correction lengthens the depth; blue: too far), with the column
means below it (Kinect v1's vertical bands). docs/calibration.md, docs/real_frames.md.
"""
import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np


def main():
    if len(sys.argv) < 3:
        print(__doc__.strip(), file=sys.stderr)
        return 2
    d = json.load(open(sys.argv[1]))
    m = (np.array(d["multipliers"], dtype=float) - 1.0) * 1000.0
    title = sys.argv[3] if len(sys.argv) > 3 else sys.argv[1]
    lim = max(abs(m.min()), abs(m.max()))
    fig, (a, b) = plt.subplots(2, 1, figsize=(6.4, 6.2), gridspec_kw={"height_ratios": [3, 1]})
    w, h = d["width"], d["height"]
    im = a.imshow(m, cmap="RdBu_r", vmin=-lim, vmax=lim, extent=(0, w, h, 0), interpolation="nearest")
    a.set_title(title, fontsize=9)
    a.set_xlabel("pixel x")
    a.set_ylabel("pixel y")
    fig.colorbar(im, ax=a, label="multiplier - 1 [per mille]")
    xs = (np.arange(d["grid_w"]) + 0.5) * d["cell_px"]
    b.plot(xs, m.mean(axis=0), "k.-")
    b.axhline(0, color="0.7", lw=0.8)
    b.set_xlim(0, w)
    b.set_xlabel("pixel x")
    b.set_ylabel("column mean [per mille]")
    fig.tight_layout()
    fig.savefig(sys.argv[2], dpi=100)
    return 0


if __name__ == "__main__":
    sys.exit(main())
