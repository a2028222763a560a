#!/usr/bin/env python3
"""Tables and a plot of bench/motion_check.sh's eval-motion runs.

usage: bench/plot_motion.py OUT LABEL

Reads OUT/em-{5,10,20,30}.json and OUT/em-5-all.csv; writes OUT/motion_check.md
and OUT/motion_check.png (each trajectory's translation error against the
colour's motion per 5-frame pair, against the pair's first frame).
"""
import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np


def row(span, d):
    g, l = d["trajectories"]
    cells = []
    for t in (g, l):
        e = t["trans_err_m"]
        cells.append("%.1f / %.1f / %.1f, %.2f" % (1e3 * e["median"], 1e3 * e["mean"], 1e3 * e["p90"],
                                                   t["rot_err_deg"]["median"]))
    share = 100.0 * l["closest_pairs"] / d["pairs_compared"]
    return "| %d | %d | %.1f | %s | %s | %.0f%% |" % (span, d["pairs_compared"], 1e3 * d["colour"]["step_m_median"],
                                                     cells[0], cells[1], share)


def main():
    if len(sys.argv) < 3:
        print(__doc__.strip(), file=sys.stderr)
        return 2
    out, traj = sys.argv[1], sys.argv[2]  # traj: the trajectory's name in the plot
    lines = ["| span (frames) | pairs compared | colour step median mm | ground truth: median / mean / p90 mm, "
             "rotation median deg | the trajectory: the same | the trajectory closer in |", "|---|---|---|---|---|---|"]
    for k in (5, 10, 20, 30):
        lines.append(row(k, json.load(open("%s/em-%d.json" % (out, k)))))
    open(out + "/motion_check.md", "w").write("\n".join(lines) + "\n")
    print("\n".join(lines))
    a, eg, el = [], [], []
    for line in open(out + "/em-5-all.csv"):
        if line.startswith("#"):
            continue
        v = line.strip().split(",")
        if v[12] != "1":
            continue
        a.append(int(v[0]))
        eg.append(1e3 * float(v[13]))
        el.append(1e3 * float(v[16]))
    a, eg, el = np.array(a), np.array(eg), np.array(el)
    fig, ax = plt.subplots(figsize=(9, 3.6))
    def smooth(v):  # the mean over 9 pairs, for the eye; the raw values are drawn faintly
        return np.convolve(v, np.ones(9) / 9, mode="same")
    ax.plot(a, eg, lw=0.5, color="tab:red", alpha=0.3)
    ax.plot(a, el, lw=0.5, color="tab:blue", alpha=0.3)
    ax.plot(a, smooth(eg), lw=1.6, color="tab:red", label="ground truth (median %.1f mm)" % np.median(eg))
    ax.plot(a, smooth(el), lw=1.6, color="tab:blue", label="%s (median %.1f mm)" % (traj, np.median(el)))
    ax.set_xlabel("first frame of the pair")
    ax.set_ylabel("mm")
    ax.set_title("error of the motion over 5 frames against the colour images' (eval-motion; 9-pair mean)")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left")
    fig.tight_layout()
    fig.savefig(out + "/motion_check.png", dpi=110)
    return 0


if __name__ == "__main__":
    sys.exit(main())
