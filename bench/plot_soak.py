#!/usr/bin/env python3
"""Plots a bench_soak TSV (docs/bench_replay.md, "Soak"): per block of
frames, the process's resident memory and the map's bytes, the time per
frame (median and p95), and, when the stream moved chunks, the chunks
spilled to disk and reloaded from it with the bytes written.

    plot_soak.py SOAK.tsv OUT.png [TITLE] [TRACE]

TRACE (bench_soak --trace): also prints, per block, the error of the frames
the tracker placed (median, p95, max, in mm) and where along the walk or
loop the frames beyond 20 mm were.
"""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

tsv, out = sys.argv[1], sys.argv[2]
title = sys.argv[3] if len(sys.argv) > 3 else tsv
rows = list(csv.DictReader(open(tsv), delimiter="\t"))


def trace_summary(path, ends):
    """Per block ending at each of ends: placed frames' error and the far ones' places."""
    frames = [f for f in (line.rstrip("\n").split("\t") for line in open(path)) if len(f) == 8]
    start = 0
    print("block\tplaced\terr_median_mm\terr_p95_mm\terr_max_mm\tover_20mm\tat_walk_frames")
    for end in ends:
        blk = [f for f in frames if start <= int(f[0]) < end and f[3] in ("tracked", "relocalised", "first")]
        e = sorted(float(f[4]) for f in blk)
        q = lambda p: e[min(len(e) - 1, int(p * len(e)))] if e else float("nan")  # noqa: E731
        far = sorted({int(f[2]) for f in blk if float(f[4]) > 20})
        print("%d-%d\t%d\t%.1f\t%.1f\t%.1f\t%d\t%s" % (start, end - 1, len(e), q(0.5), q(0.95), e[-1] if e else 0,
                                                        sum(float(f[4]) > 20 for f in blk), ",".join(map(str, far))))
        start = end


if len(sys.argv) > 4:
    trace_summary(sys.argv[4], [int(r["frames"]) for r in rows])
x = [int(r["frames"]) for r in rows]
col = lambda k: [float(r[k]) for r in rows]  # noqa: E731
has_spill = "spilled" in rows[0]
fig, ax = plt.subplots(3 if has_spill else 2, 1, figsize=(8, 9 if has_spill else 6), sharex=True)
ax[0].plot(x, col("rss_mib"), "o-", label="resident memory (MiB)")
if "records_mib" in rows[0]:
    ax[0].plot(x, [r - k for r, k in zip(col("rss_mib"), col("records_mib"))], "x:", color="tab:blue",
               label="resident less the run's per-frame records")
ax[0].set_ylabel("resident MiB")
# A narrow range: a creep of a few MiB must show.
lo = min(col("rss_mib") + ([r - k for r, k in zip(col("rss_mib"), col("records_mib"))] if "records_mib" in rows[0] else []))
ax[0].set_ylim(lo - 10, max(col("rss_mib")) + 10)
m = ax[0].twinx()
m.plot(x, col("map_mib"), "s--", color="tab:green", label="map in the pools (MiB)")
if has_spill:
    m.plot(x, col("cache_mib"), "^:", color="tab:olive", label="CPU cache (MiB)")
m.set_ylabel("map / cache MiB")
m.set_ylim(0, max(col("map_mib")) * 1.6)
h0, l0 = ax[0].get_legend_handles_labels()
h1, l1 = m.get_legend_handles_labels()
ax[0].legend(h0 + h1, l0 + l1, loc="lower right", fontsize=8)
ax[1].plot(x, col("ms_median"), "o-", label="median")
ax[1].plot(x, col("ms_p95"), "v--", label="p95")
ax[1].set_ylabel("ms per frame (per block)")
ax[1].set_ylim(0, max(col("ms_p95")) * 1.15)
if "load" in rows[0]:
    ld = ax[1].twinx()
    ld.plot(x, col("load"), "k:", label="machine load (1 min)")
    ld.set_ylabel("load")
    ld.set_ylim(0, max(col("load")) * 1.5)
    ld.legend(loc="upper right", fontsize=8)
ax[1].legend(loc="lower left", fontsize=8)
if has_spill:
    w = (x[1] - x[0]) * 0.35 if len(x) > 1 else 10
    ax[2].bar([v - w / 2 for v in x], col("spilled"), w, label="chunks spilled to disk")
    ax[2].bar([v + w / 2 for v in x], col("reloaded"), w, label="chunks reloaded from disk")
    ax[2].set_ylabel("chunks per block")
    k = ax[2].twinx()
    k.plot(x, [b / 1024 for b in col("spill_bytes")], "k.:", label="KiB written")
    k.set_ylabel("KiB written per block")
    k.set_ylim(0, max(1, max(col("spill_bytes")) / 1024) * 1.3)
    h0, l0 = ax[2].get_legend_handles_labels()
    h1, l1 = k.get_legend_handles_labels()
    ax[2].legend(h0 + h1, l0 + l1, loc="lower right", fontsize=8)
ax[-1].set_xlabel("frames")
fig.suptitle(title, fontsize=10)
fig.tight_layout()
fig.savefig(out, dpi=90)
print("wrote", out)
