#!/usr/bin/env bash
# The particle renderer against the particle count: uniform random sets of
# N particles in a 2 x 1 x 1 m box (5 mm radius, the default cell: an
# eighth of the radius, a quarter where those bricks overflow one
# binding), each binned and ray-cast at 640x480 by `bitfuse render` (the
# median of 3 casts) from two poses: close (a corner of the set fills the
# image, every ray hits deep in the cloud) and whole (the set seen whole
# from its long side, 2 m away: it spans 525 of the 640 columns). Writes
# OUT/particles_sweep.md (a table, with the GPU memory each set takes) and
# OUT/particles_sweep.png (a plot).
# Usage: bench/particles_sweep.sh OUT [--cell M] [N ...]   (default N: 10000 100000 1000000 10000000)
set -euo pipefail
. "$(dirname "$0")/common.sh"
OUT=$1
shift
CELL=()
if [ "${1:-}" = "--cell" ]; then
    CELL=(--particle-cell "$2")
    shift 2
fi
NS=${*:-10000 100000 1000000 10000000}
B=$BIN
mkdir -p "$OUT"
T="$OUT/particles_sweep.md"
echo "| particles | cell [mm] | bricks with particles (+ coarse) | binning on the host [ms] | binning [CPU ms] | into the GPU pools [ms] | M particles/s binned | ray-cast 640x480, close [ms GPU] | ray-cast 640x480, whole [ms GPU] | GPU memory in use [MB] | bytes a particle |" >"$T"
echo "|---|---|---|---|---|---|---|---|---|---|---|" >>"$T"
for n in $NS; do
    bench_random_particles "$n" "$OUT/p$n.ply"
    "$B" render --particles "$OUT/p$n.ply" --particle-radius 0.005 "${CELL[@]}" \
        --pose "2 -0.8 0.9 -0.772625 -0.329703 0.212940 0.499002" --size 640x480 --out "$OUT/p$n.png" --repeat 3 \
        >"$OUT/p$n.txt" 2>/dev/null
    "$B" render --particles "$OUT/p$n.ply" --particle-radius 0.005 "${CELL[@]}" \
        --pose "1 -2 0.5 -0.70710678 0 0 0.70710678" --size 640x480 --out "$OUT/p$n-whole.png" --repeat 3 \
        >"$OUT/p$n-whole.txt" 2>/dev/null
    python3 - "$OUT/p$n.txt" "$n" "$OUT/p$n-whole.txt" >>"$T" <<'PY'
import re, sys
t = open(sys.argv[1]).read(); n = int(sys.argv[2])
b = re.search(r"cells, (\d+) bricks \(\+(\d+) coarse\)", t)
cell = 1e3 * float(re.search(r"cell ([\d.e-]+) m", t).group(1))
bin_ms, cpu_ms, load_ms = map(float, re.search(r"binning +([\d.]+) ms on the host .*?; ([\d.]+) ms CPU\), ([\d.]+) ms into the GPU pools", t).groups())
cast = float(re.search(r"ray-cast +([\d.]+) ms GPU", t).group(1))
whole = float(re.search(r"ray-cast +([\d.]+) ms GPU", open(sys.argv[3]).read()).group(1))
mem_mb, per = map(float, re.search(r"GPU memory +([\d.]+) MB in use, ([\d.]+) bytes a particle", t).groups())
print("| %d | %.3g | %s (+%s) | %.1f | %.1f | %.1f | %.2f | %.1f | %.1f | %.1f | %.0f |" % (n, cell, b.group(1), b.group(2), bin_ms, cpu_ms, load_ms, n / bin_ms / 1e3, cast, whole, mem_mb, per))
PY
    rm -f "$OUT/p$n.ply"
done
"$PY" - "$T" "$OUT/particles_sweep.png" <<'PY'
import sys
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
rows = [l.strip().strip("|").split("|") for l in open(sys.argv[1]) if l.startswith("| ") and not l.startswith("| particles")]
n = [int(r[0]) for r in rows]
fig, ax = plt.subplots(1, 3, figsize=(15, 4))
ax[0].plot(n, [float(r[6]) for r in rows], "o-", label="wall clock")
ax[0].plot(n, [int(r[0]) / float(r[4]) / 1e3 * 2 for r in rows], "s--", label="CPU time / 2 cores"); ax[0].axhline(5, color="grey", ls=":", label="issue goal 5 M/s")
ax[0].set_xscale("log"); ax[0].set_xlabel("particles"); ax[0].set_ylabel("M particles / s binned (host)"); ax[0].legend()
ax[1].plot(n, [float(r[7]) for r in rows], "o-", label="close (a corner fills the image)")
ax[1].plot(n, [float(r[8]) for r in rows], "s-", label="the set whole"); ax[1].axhline(250, color="grey", ls=":", label="issue goal 250 ms")
ax[1].set_xscale("log"); ax[1].set_yscale("log"); ax[1].set_xlabel("particles"); ax[1].set_ylabel("ray-cast 640x480 [ms GPU]"); ax[1].legend()
ax[2].plot(n, [float(r[10]) for r in rows], "o-", label="GPU memory in use")
ax[2].plot(n, [12.0] * len(n), "s--", label="the positions as 3 floats")
ax[2].set_xscale("log"); ax[2].set_yscale("log"); ax[2].set_xlabel("particles"); ax[2].set_ylabel("bytes a particle"); ax[2].legend()
for a in ax: a.grid(alpha=0.3)
fig.suptitle("particle renderer on lavapipe (bench/particles_sweep.sh; random sets in 2 x 1 x 1 m, 5 mm radius)")
fig.tight_layout(); fig.savefig(sys.argv[2], dpi=90)
PY
cat "$T"
