#!/usr/bin/env bash
# Speed against error of the full loop (issue 4): `bitfuse replay` (ICP
# tracking + fusion + ray-cast + ROF) on one synthetic room sequence at
# 640x480 with several voxel-to-pixel ratios, ICP iteration counts and window
# sizes; ATE of each estimated trajectory and surface error of its mesh.
# Writes docs/bench_replay_sweep.md (table) and docs/bench_replay_sweep.png (plot).
#
#   bench/replay_sweep.sh [FRAMES] [OUT_DIR]      (defaults 600, /tmp/bitfuse-replay)
#   CONFIGS="1:10,5,4:40 2:10,5,4:40" bench/replay_sweep.sh   (ratio:icp:window)
#
# The sequence is rendered once (bitfuse synth, Kinect v1 noise, seed 1,
# along the real fr1_xyz trajectory when ../shared/data is present).
set -euo pipefail
cd "$(dirname "$0")/.."
FRAMES=${1:-600}
OUT=${2:-/tmp/bitfuse-replay}
CONFIGS=${CONFIGS:-"1:10,5,4:40 2:10,5,4:40 2:4,3,3:40 2:10,5,4:20 2:2,2,2:20"}
source bench/common.sh
mkdir -p "$OUT"
SEQ="$OUT/seq$FRAMES"
bench_room_sequence "$SEQ" "$FRAMES"

RESULTS="$OUT/results.tsv"
printf "ratio\ticp\twindow\tframe_ms_median\tframe_ms_p95\ttrack_ms\trof_ms\traycast_ms\talloc_ms\tsubcache_ms\twindow_ms\tate_rmse_mm\ttracked\tlost\tmap_mib\tacc_median_mm\tacc_p90_mm\tcompleteness_1cm\n" > "$RESULTS"
for cfg in $CONFIGS; do
  IFS=: read -r ratio icp window <<<"$cfg"
  RUN="$OUT/r$ratio-i${icp//,/-}-w$window"
  $BIN replay "$SEQ" --out "$RUN" --ratio "$ratio" --icp-iters "$icp" --window "$window" > "$RUN.log" 2>&1
  $BIN eval-surface --reference "$SEQ/scene.ply" --reconstruction "$RUN/mesh.ply" --visible "$SEQ/seen.ply" \
       --json > "$RUN/surface.json"
  $PY - "$RUN" "$ratio" "$icp" "$window" >> "$RESULTS" <<'PYEOF'
import sys
sys.path.insert(0, "bench")
from benchlib import run_outputs, stage_ms
run, ratio, icp, window = sys.argv[1:5]
s, e = run_outputs(run)
acc = e["accuracy"]
t = s["tracking"]
ate = s["ate_m"]["rmse"] if s["ate_m"] else float("nan")
print("\t".join(str(x) for x in [ratio, icp, window, round(s["frame_ms"]["median"], 1), round(s["frame_ms"]["p95"], 1),
      stage_ms(s, "track"), stage_ms(s, "rof"), stage_ms(s, "raycast"),
      stage_ms(s, "alloc"), stage_ms(s, "subcache"), stage_ms(s, "window"),
      round(1e3 * ate, 2), t["tracked"], t["lost"], round(s["map_bytes"]["total"] / 2**20, 2),
      round(1e3 * acc["median_m"], 2), round(1e3 * acc["p90_m"], 2), round(e["completeness"]["ratio"], 4)]))
PYEOF
  tail -n 1 "$RESULTS"
done

$PY - "$RESULTS" "${SWEEP_COMMIT:-$(git rev-parse --short HEAD)}" "$FRAMES" <<'PYEOF'
import sys
sys.path.insert(0, "bench")
from benchlib import pyplot, read_rows, write_table
path, commit, frames = sys.argv[1:4]
rows = read_rows(path)
write_table("docs/bench_replay_sweep.md", "Full loop: speed against error",
            f"`bench/replay_sweep.sh {frames}`, commit {commit}: `bitfuse replay` (ICP tracking against the "
            "ray-cast of the confident map, fusion, ray-cast) on a synthetic room (640x480, Kinect v1 noise, seed 1) "
            "along the real fr1_xyz trajectory, started at the first true pose; lavapipe on 2 cores. "
            "ATE RMSE as TUM's evaluate_ate.py; surface error of `mesh.ply` against `scene.ply`, completeness "
            "over `seen.ply` within 1 cm. Stage times are GPU timestamps (medians); frame_ms is wall time.", rows)
plt = pyplot()
if plt:
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for r in rows:
        x, y = float(r["frame_ms_median"]), float(r["ate_rmse_mm"])
        ax.scatter(x, y)
        ax.annotate(f"ratio {r['ratio']}, icp {r['icp']}, n {r['window']}", (x, y), fontsize=7)
    ax.axvline(80, ls="--", c="gray")
    ax.set_xlabel("time per frame, median [ms] (target 80)")
    ax.set_ylabel("ATE RMSE [mm]")
    ax.set_title("bitfuse full loop on lavapipe: speed against error")
    fig.tight_layout()
    fig.savefig("docs/bench_replay_sweep.png", dpi=100)
else:
    print("matplotlib missing: no plot", file=sys.stderr)
PYEOF
cat docs/bench_replay_sweep.md
