#!/usr/bin/env bash
# The surface with true poses, side by side (real-frames issue, item 3): bitfuse's `fuse` and
# Open3D 0.16's TSDF integration (bench/open3d_tsdf.py, its reconstruction system's defaults),
# both fed the sequence's own true poses, each mesh measured by the same `bitfuse eval-surface
# --depth` (the sensor's depth, every 10th frame, every 4th pixel, back-projected at the true
# poses) over samples up to 4.5 m (the loop's range) and up to 3.0 m (Open3D's).
# ../shared/BENCHMARKS.md gives Open3D's figure on the held-out frames (4.1 mm); this gives it on
# frames we may look at, by our evaluator, beside ours.
#
#   bench/surface_gt.sh [OUT_DIR]             (default /tmp/bitfuse-surface-gt)
#   BIN=build/app/bitfuse DATA=/path/7scenes-dev bench/surface_gt.sh /tmp/sg
#   FUSE_OPTS="--ratio 2" bench/surface_gt.sh  (bitfuse fuse's options; default: its defaults)
#   O3D_OPTS="--depth-max 4.5" bench/surface_gt.sh  (open3d_tsdf.py's options; default: its defaults)
#
# Prints a markdown table and writes OUT/surface_gt.md. bitfuse's fuse of the 500 dev frames at
# ratio 1 takes about 2 minutes on 2 cores, Open3D's about 30 s; each evaluation under a minute.
# The map's memory is counted as each keeps it: bitfuse's sign and confidence bits, bricks, nodes
# and hash (stats.json map_bytes) plus its colour (colour.bytes); Open3D's voxel blocks in use
# (tsdf, weight and colour as floats).
# Open3D is Debian's python3-open3d (apt-get install python3-open3d); without it its rows are
# left out.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-/tmp/bitfuse-surface-gt}
BIN=${BIN:-build/app/bitfuse}
DATA=${DATA:-/work/bench-data/7scenes-dev}
FUSE_OPTS=${FUSE_OPTS:-}
O3D_OPTS=${O3D_OPTS:-}
export BITFUSE_VALIDATION=0 BITFUSE_PROGRESS=0
PY=python3
[ -x /usr/bin/python3 ] && PY=/usr/bin/python3
[ -x "$BIN" ] || { echo "surface_gt.sh: no binary at $BIN (set BIN)" >&2; exit 1; }
[ -f "$DATA/frame-000000.pose.txt" ] || { echo "surface_gt.sh: no frames at $DATA (set DATA)" >&2; exit 1; }
mkdir -p "$OUT"

# shellcheck disable=SC2086
"$BIN" fuse "$DATA" --poses groundtruth --out "$OUT/bitfuse" $FUSE_OPTS
runs="bitfuse"
if "$PY" -c 'import open3d' 2>/dev/null; then
  # shellcheck disable=SC2086
  "$PY" bench/open3d_tsdf.py "$DATA" --out "$OUT/open3d" $O3D_OPTS
  runs="$runs open3d"
else
  echo "surface_gt.sh: no Open3D (python3-open3d): its rows are left out" >&2
fi
for r in $runs; do
  for md in 4.5 3.0; do
    "$BIN" eval-surface --reference "$OUT/$r/mesh.ply" --depth "$DATA" --poses groundtruth \
      --max-depth "$md" --json > "$OUT/$r.eval$md.json"
  done
done

# shellcheck disable=SC2086 # runs: one word per run
"$PY" - "$OUT" "$FUSE_OPTS" $runs <<'PYEOF' | tee "$OUT/surface_gt.md"
import json, sys
out, opts, runs = sys.argv[1], sys.argv[2], sys.argv[3:]
print("| system | fused | map in use: geometry + colour | samples to 4.5 m: median mm | within 1 cm | mesh area within 1 cm | samples to 3.0 m: median mm | within 1 cm | frame median ms |")
print("|---|---|---|---|---|---|---|---|---|")
for r in runs:
    st = json.load(open("%s/%s/stats.json" % (out, r)))
    if r == "bitfuse":
        name = "bitfuse fuse" + (" " + opts if opts else "")
        fused = "%d frames (%d repeats left out)" % (st["frames"], st.get("repeated", 0))
        geo = st["map_bytes"]["total"] / 2**20
        col = (st.get("colour") or {}).get("bytes", 0) / 2**20
        ms = st["frame_ms"]["median"]
    else:
        c = st["config"]
        name = "Open3D %s VoxelBlockGrid (%.2f mm voxels, depth to %.1f m)" % (st["open3d"], c["voxel"] * 1e3, c["depth_max"])
        fused = "%d frames" % st["frames"]
        geo = st["map_mib"] * 8 / 20  # tsdf and weight: 8 of a voxel's 20 bytes
        col = st["map_mib"] - geo
        ms = st["frame_ms"]["median"]
    e = [json.load(open("%s/%s.eval%s.json" % (out, r, md))) for md in ("4.5", "3.0")]
    print("| %s | %s | %.1f + %.1f MiB | %.2f | %.1f%% | %.1f%% | %.2f | %.1f%% | %.0f |" % (
        name, fused, geo, col, e[0]["accuracy"]["median_m"] * 1e3, e[0]["accuracy"]["within_threshold"] * 100,
        e[0]["completeness"]["ratio"] * 100, e[1]["accuracy"]["median_m"] * 1e3,
        e[1]["accuracy"]["within_threshold"] * 100, ms))
PYEOF
