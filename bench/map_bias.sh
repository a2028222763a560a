#!/usr/bin/env bash
# Where the map's surface lies against the newest frame's depth, by depth band (real-frames issue,
# "What is left" in docs/real_frames.md): replays the first N frames of a pose-per-frame folder
# (7-Scenes layout, ../shared/tools/get-7scenes-dev.sh) into a scene store, ray-casts the stored
# map's depth at the last frame's pose with the depth camera's intrinsics (`bitfuse render
# --depth`), and prints the median of (map - frame) over the frame's smooth pixels (5x5 spread
# under 2% of the depth) per half-metre band. A map consistent with its newest frame gives
# medians near 0 in every band. Extra options go to replay (e.g. --fuse-at-groundtruth).
#
#   bench/map_bias.sh DATA N OUT [replay options]
#   BIN=build/app/bitfuse bench/map_bias.sh /work/bench-data/7scenes-dev 300 /tmp/mb300
set -euo pipefail
cd "$(dirname "$0")/.."
[ $# -ge 3 ] || { echo "usage: bench/map_bias.sh DATA N OUT [replay options]" >&2; exit 2; }
DATA=$1 N=$2 OUT=$3
shift 3
BIN=${BIN:-build/app/bitfuse}
PY=python3
[ -x /usr/bin/python3 ] && PY=/usr/bin/python3
[ -f "$DATA/camera-intrinsics.txt" ] || { echo "map_bias.sh: $DATA: no camera-intrinsics.txt (a 7-Scenes folder)" >&2; exit 1; }
export BITFUSE_VALIDATION=0 BITFUSE_PROGRESS=0
rm -rf "$OUT"
"$BIN" replay "$DATA" --out "$OUT" --no-mesh --frames "$N" --store "$OUT/store" "$@" >"$OUT.log" 2>&1 ||
  { tail -3 "$OUT.log" >&2; exit 1; }
pose=$(grep -v '^#' "$OUT/trajectory.txt" | tail -n 1 | cut -d' ' -f2-)
cam=$(awk 'NR == 1 {fx = $1; cx = $3} NR == 2 {fy = $2; cy = $3} END {print fx "," fy "," cx "," cy}' \
  "$DATA/camera-intrinsics.txt")
"$BIN" render --map "$OUT/store" --pose "$pose" --camera "$cam" --size 640x480 --out "$OUT/view.png" \
  --depth "$OUT/map_depth.png" >/dev/null
PYTHONPATH=bench "$PY" - "$OUT/map_depth.png" "$DATA/frame-$(printf %06d $((N - 1))).depth.png" <<'PYEOF'
import sys
import cv2
import numpy as np
from frame_consistency import smooth_mask
r = cv2.imread(sys.argv[1], -1).astype(np.float32) / 5000  # render's depth: TUM's 5000 a metre
d = cv2.imread(sys.argv[2], -1).astype(np.float32) / 1000  # 7-Scenes: millimetres, 65535 none
d[d >= 65] = 0
v = (r > 0) & smooth_mask(d)
print("map - frame on %d smooth pixels, median mm by the frame's depth:" % v.sum())
for a in np.arange(0.5, 4.5, 0.5):
    s = v & (d >= a) & (d < a + 0.5)
    if s.sum() >= 200:
        e = (r - d)[s] * 1e3
        print("  %.1f-%.1f m  %6d px  median %+6.1f  p10 %+6.1f  p90 %+6.1f" % (
            a, a + 0.5, s.sum(), np.median(e), np.percentile(e, 10), np.percentile(e, 90)))
PYEOF
