#!/usr/bin/env bash
# The particle renderer against the image size and the distance, with level
# of detail on and off: the random set of N particles (default 10^6) in a
# 2 x 1 x 1 m box that bench/particles_sweep.sh draws (bench_random_particles; 5 mm
# radius, the default cell), ray-cast by `bitfuse render` (the median of 3
# casts):
#   - close and whole (particles_sweep.sh's two poses) at 320x240, 640x480
#     and 1280x960;
#   - from its long side at 2, 4, 8, 16 and 32 m, 640x480, with
#     --particle-lod on and off (the two images compared: the pixels shaded
#     differently, and how far the depths differ where both hit).
# Writes OUT/particles_views.md (two tables) and OUT/particles_views.png.
# Usage: [ROUNDS=3] bench/particles_views.sh OUT [N]   (the far casts, on and
# off interleaved, are run ROUNDS times: their times are the medians)
set -euo pipefail
. "$(dirname "$0")/common.sh"
OUT=$1
N=${2:-1000000}
ROUNDS=${ROUNDS:-3}
mkdir -p "$OUT"
P="$OUT/p$N.ply"
bench_random_particles "$N" "$P"
CLOSE="2 -0.8 0.9 -0.772625 -0.329703 0.212940 0.499002"
cast() { # name pose size lod
    "$BIN" render --particles "$P" --particle-radius 0.005 --particle-lod "$4" --pose "$2" --size "$3" --far 50 \
        --out "$OUT/$1.png" --depth "$OUT/$1-depth.png" --repeat 3 --json >"$OUT/$1.json" 2>/dev/null
    echo "  $1" >&2
}
for size in 320x240 640x480 1280x960; do
    cast "close-$size" "$CLOSE" "$size" on
    cast "whole-$size" "1 -2 0.5 -0.70710678 0 0 0.70710678" "$size" on
done
for r in $(seq "$ROUNDS"); do
    for d in 2 4 8 16 32; do
        for lod in on off; do cast "far$d-$lod-r$r" "1 -$d 0.5 -0.70710678 0 0 0.70710678" 640x480 "$lod"; done
    done
done
rm -f "$P"
"$PY" - "$OUT" "$N" "$ROUNDS" <<'PY'
import json, sys
import numpy as np
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
from PIL import Image
out, n, rounds = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
J = lambda name: json.load(open(f"{out}/{name}.json"))
D = lambda name: np.asarray(Image.open(f"{out}/{name}-depth.png"), dtype=np.float64) / 5000.0
sizes = ["320x240", "640x480", "1280x960"]
t = [f"{n} particles, 5 mm radius, cell {1e3 * J('close-640x480')['particles']['cell_m']:.3g} mm, "
     f"GPU memory {J('close-640x480')['particles']['gpu_bytes_used'] / 1e6:.1f} MB in use "
     f"({J('close-640x480')['particles']['gpu_bytes_per_particle']:.0f} bytes a particle)", "",
     "| image | pixels | close [ms GPU] | close [ns a pixel] | whole [ms GPU] | whole [ns a pixel] |", "|---|---|---|---|---|---|"]
res = []
for s in sizes:
    w, h = map(int, s.split("x"))
    c, wh = J(f"close-{s}")["raycast_ms"]["median"], J(f"whole-{s}")["raycast_ms"]["median"]
    res.append((w * h, c, wh))
    t.append(f"| {s} | {w * h} | {c:.1f} | {1e6 * c / (w * h):.0f} | {wh:.1f} | {1e6 * wh / (w * h):.0f} |")
t += ["", f"| distance [m] | pixels hit | lod on [ms GPU, median of {rounds}] | lod off [ms GPU] | on / off | pixels shaded differently | median depth difference where both hit and differ (depth image, to 13.1 m) [mm] |",
      "|---|---|---|---|---|---|---|"]
far = []
for d in [2, 4, 8, 16, 32]:
    on = J(f"far{d}-on-r1")
    a, b = D(f"far{d}-on-r1"), D(f"far{d}-off-r1")
    # The shaded images (the 16-bit depth ends at 13.1 m).
    ca = np.asarray(Image.open(f"{out}/far{d}-on-r1.png").convert("RGB"), dtype=np.int32)
    cb = np.asarray(Image.open(f"{out}/far{d}-off-r1.png").convert("RGB"), dtype=np.int32)
    diff = (ca != cb).any(axis=2)
    both = (a > 0) & (b > 0)
    dd = 1e3 * np.abs(a - b)[both & (a != b)]
    med = float(np.median(dd)) if dd.size else 0.0
    ton = float(np.median([J(f"far{d}-on-r{r}")["raycast_ms"]["median"] for r in range(1, rounds + 1)]))
    toff = float(np.median([J(f"far{d}-off-r{r}")["raycast_ms"]["median"] for r in range(1, rounds + 1)]))
    far.append((d, ton, toff))
    t.append(f"| {d} | {100 * on['hit_fraction']:.1f}% | {ton:.1f} | {toff:.1f} | {ton / toff:.2f} | "
             f"{100 * diff.mean():.2f}% | {med:.1f} |")
open(f"{out}/particles_views.md", "w").write("\n".join(t) + "\n")
fig, ax = plt.subplots(1, 2, figsize=(10, 4))
px = [r[0] for r in res]
ax[0].plot(px, [r[1] for r in res], "o-", label="close (a corner fills the image)")
ax[0].plot(px, [r[2] for r in res], "s-", label="the set whole from 2 m")
ax[0].axhline(250, color="grey", ls=":", label="issue goal at 640x480: 250 ms")
ax[0].set_xscale("log"); ax[0].set_yscale("log"); ax[0].set_xlabel("pixels (320x240, 640x480, 1280x960)")
ax[0].set_ylabel("ray-cast [ms GPU]"); ax[0].legend()
ax[1].plot([f[0] for f in far], [f[1] for f in far], "o-", label="level of detail on")
ax[1].plot([f[0] for f in far], [f[2] for f in far], "s--", label="off (every sphere exact)")
ax[1].set_xscale("log"); ax[1].set_yscale("log"); ax[1].set_xlabel("distance to the set's long side [m]")
ax[1].set_ylabel("ray-cast 640x480 [ms GPU]"); ax[1].legend()
for a in ax: a.grid(alpha=0.3, which="both")
fig.suptitle(f"particle renderer on lavapipe (bench/particles_views.sh; {n} random particles, 5 mm radius)")
fig.tight_layout(); fig.savefig(f"{out}/particles_views.png", dpi=90)
print("\n".join(t))
PY
