#!/usr/bin/env bash
# Speed against error of the fusion (issue 3): fuses one synthetic room
# sequence with ground-truth poses at several voxel-to-pixel ratios and
# window sizes, measures each reconstruction against the reference mesh, and
# writes docs/bench_fusion.md (table) and docs/bench_fusion.png (plot).
#
#   bench/fusion_sweep.sh [FRAMES] [OUT_DIR]      (defaults 300, /tmp/bitfuse-sweep)
#
# The sequence is rendered once (bitfuse synth, Kinect v1 noise, seed 1,
# along the real fr1_xyz trajectory when ../shared/data is present).
set -euo pipefail
cd "$(dirname "$0")/.."
FRAMES=${1:-300}
OUT=${2:-/tmp/bitfuse-sweep}
source bench/common.sh
mkdir -p "$OUT"
SEQ="$OUT/seq"
bench_room_sequence "$SEQ" "$FRAMES"

RESULTS="$OUT/results.tsv"
printf "ratio\twindow\tframe_ms_median\tframe_ms_p95\talloc_ms\tsubcache_ms\twindow_ms\tmap_mib\tbits_per_voxel\tbricks\tacc_median_mm\tacc_p90_mm\tcompleteness_1cm\n" > "$RESULTS"
for cfg in "1 40" "2 40" "1 20" "2 20"; do
  set -- $cfg
  RUN="$OUT/r$1-w$2"
  $BIN fuse "$SEQ" --poses groundtruth --out "$RUN" --ratio "$1" --window "$2" > "$RUN.log" 2>&1
  $BIN eval-surface --reference "$SEQ/scene.ply" --reconstruction "$RUN/mesh.ply" --visible "$SEQ/seen.ply" \
       --json > "$RUN/surface.json"
  $PY - "$RUN" "$1" "$2" >> "$RESULTS" <<'EOF'
import sys
sys.path.insert(0, "bench")
from benchlib import run_outputs
run, ratio, window = sys.argv[1:4]
s, e = run_outputs(run)
g = {k: v["median"] for k, v in s["gpu_stage_ms"].items()}
acc = e["accuracy"]
print("\t".join(str(x) for x in [ratio, window, round(s["frame_ms"]["median"], 1), round(s["frame_ms"]["p95"], 1),
      round(g["alloc"], 1), round(g["subcache"], 1), round(g["window"], 1),
      round(s["map_bytes"]["total"] / 2**20, 2), round(s["bits_per_allocated_voxel"], 3), s["bricks"],
      round(1e3 * acc["median_m"], 2), round(1e3 * acc["p90_m"], 2), round(e["completeness"]["ratio"], 4)]))
EOF
done

$PY - "$RESULTS" "${SWEEP_COMMIT:-$(git rev-parse --short HEAD)}" "$FRAMES" <<'EOF'
import sys
sys.path.insert(0, "bench")
from benchlib import pyplot, read_rows, write_table
path, commit, frames = sys.argv[1:4]
rows = read_rows(path)
write_table("docs/bench_fusion.md", "Fusion: speed against error",
            f"`bench/fusion_sweep.sh {frames}`, commit {commit}, synthetic room (Kinect v1 noise, seed 1) "
            "along the fr1_xyz trajectory, ground-truth poses, lavapipe on 2 cores. Surface error of "
            "`mesh.ply` against `scene.ply`; completeness over `seen.ply` within 1 cm.", rows)
plt = pyplot()
if plt:
    fig, ax = plt.subplots(figsize=(6, 4))
    for r in rows:
        ax.scatter(float(r["frame_ms_median"]), float(r["acc_median_mm"]))
        ax.annotate(f"ratio {r['ratio']}, n {r['window']}", (float(r["frame_ms_median"]), float(r["acc_median_mm"])))
    ax.set_xlabel("time per frame, median [ms]")
    ax.set_ylabel("surface error, median [mm]")
    ax.set_title("bitfuse fusion on lavapipe: speed against error")
    fig.tight_layout()
    fig.savefig("docs/bench_fusion.png", dpi=100)
else:
    print("matplotlib missing: no plot", file=sys.stderr)
EOF
cat docs/bench_fusion.md
