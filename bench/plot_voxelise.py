#!/usr/bin/env python3
"""Plots bench_voxelise's table: voxelisation rate against triangles, and the
ray-cast's GPU time against pixels, per level.
Usage: plot_voxelise.py TABLE.md OUT.png"""
import sys
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt

rows = [l.strip().strip("|").split("|") for l in open(sys.argv[1]) if l.startswith("| ") and not l.startswith("| triangles")]
head = [h.strip() for h in open(sys.argv[1]).readline().strip().strip("|").split("|")]
casts = [(i, h) for i, h in enumerate(head) if h.startswith("ray-cast")]
fig, ax = plt.subplots(1, 2, figsize=(10, 4))
for level in sorted({r[1].strip() for r in rows}):
    rs = [r for r in rows if r[1].strip() == level]
    tris = [int(r[0]) for r in rs]
    voxel = rs[0][2].strip()
    ax[0].plot(tris, [float(r[8]) for r in rs], "o-", label="level %s (%s mm)" % (level, voxel))
    ax[1].plot([int(h.split()[1].split("x")[0]) * int(h.split()[1].split("x")[1]) for i, h in casts],
               [float(rs[-1][i]) for i, h in casts], "o-", label="%d triangles, level %s" % (tris[-1], level))
    ax[1].plot([int(h.split()[1].split("x")[0]) * int(h.split()[1].split("x")[1]) for i, h in casts],
               [float(rs[0][i]) for i, h in casts], "s--", label="%d triangles, level %s" % (tris[0], level))
ax[0].set_xscale("log"); ax[0].set_xlabel("triangles"); ax[0].set_ylabel("M triangles / s (binning + GPU pass)")
ax[0].axhline(5, color="grey", ls=":", label="issue goal 5 M/s"); ax[0].legend(fontsize=7); ax[0].grid(alpha=0.3)
ax[1].set_xscale("log"); ax[1].set_yscale("log"); ax[1].set_xlabel("pixels"); ax[1].set_ylabel("ray-cast GPU ms")
ax[1].axhline(250, color="grey", ls=":", label="issue goal 250 ms at 640x480"); ax[1].legend(fontsize=7); ax[1].grid(alpha=0.3)
fig.suptitle("mesh renderer on lavapipe, 2 shared cores (bench_voxelise, the bunny subdivided)")
fig.tight_layout()
fig.savefig(sys.argv[2], dpi=90)
