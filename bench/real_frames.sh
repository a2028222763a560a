#!/usr/bin/env bash
# Where the trajectory error on real Kinect v1 frames comes from (real-frames issue, item 1).
# Replays the 500 7-Scenes dev frames (pose-per-frame folder, ../shared/tools/get-7scenes-dev.sh;
# never copied into the repository) with
#   plain   the full loop, started at the first true pose
#   fgt     --fuse-at-groundtruth: every frame tracked against a map fused at the true poses, so
#           each estimate's error is one tracking step's
#   probes  replays with options changed (PROBES; the default set: one per variant of the
#           later sessions that is still an option, docs/real_frames.md)
# JOBS at a time (default 1: the times per frame are then the loop's own), evaluates each
# trajectory with `bitfuse eval-traj` over frames 0-499 and 0-420 (the ground truth jumps 27 mm
# between 420 and 421), and writes the generated tables of
# docs/real_frames.md (between <!-- gen:... --> markers; the analysis around them is kept) and
# docs/real_frames.png (bench/real_frames.py).
#
#   bench/real_frames.sh [OUT_DIR]                      (default /tmp/bitfuse-real-frames)
#   BIN=build/app/bitfuse DATA=/path/7scenes-dev bench/real_frames.sh /tmp/rf
#   PROBES="ratio1|--ratio 1" bench/real_frames.sh    (name|replay options, ';' between; '' for none)
#   REUSE=1 bench/real_frames.sh /tmp/rf                (keep runs whose stats.json exists)
#
# Each replay takes 30-80 s on the 2-core machine with lavapipe from Mesa 25 (54-157 ms a frame);
# the twelve of the default about 13 minutes with the tables (2026-12-06).
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-/tmp/bitfuse-real-frames}
BIN=${BIN:-build/app/bitfuse}
DATA=${DATA:-/work/bench-data/7scenes-dev}
# name|options; empty options: the plain loop again (replay is deterministic since the sixth
# session, so a second plain run should match the first byte for byte)
PROBES=${PROBES-"ratio3|--ratio 3;ratio1|--ratio 1;level8|--max-level 8;window20|--window 20;rof10|--rof-iters 10;photo|--photometric-weak 0;nophoto|--photometric 0;last|--guess last;repeats|--repeated track;all|--ref-voxels all"}
REUSE=${REUSE:-0}
JOBS=${JOBS:-1}
PY=python3
[ -x /usr/bin/python3 ] && PY=/usr/bin/python3
[ -x "$BIN" ] || { echo "no binary at $BIN (set BIN)" >&2; exit 1; }
[ -f "$DATA/frame-000000.pose.txt" ] || { echo "no frames at $DATA (set DATA)" >&2; exit 1; }
mkdir -p "$OUT/eval"

# name <TAB> label <TAB> options
{
  printf "plain\tplain loop\t\n"
  printf "fgt\tfuse at ground truth\t--fuse-at-groundtruth\n"
  IFS=';' read -ra P <<<"$PROBES"
  for p in "${P[@]}"; do
    [ -n "$p" ] || continue
    IFS='|' read -r name opts <<<"$p"
    if [ -n "$opts" ]; then label="probe $name"; else label="plain loop again ($name)"; fi
    printf "%s\t%s\t%s\n" "$name" "$label" "$opts"
  done
} > "$OUT/runs.tsv"

run_one() {
  local name=$1 opts=$2
  if [ "$REUSE" = 1 ] && [ -f "$OUT/$name/stats.json" ]; then return 0; fi
  rm -rf "${OUT:?}/$name"
  # shellcheck disable=SC2086
  "$BIN" replay "$DATA" --out "$OUT/$name" --no-mesh $opts > "$OUT/$name.log" 2>&1
  echo "$name: $(grep -E 'ATE|time per frame' "$OUT/$name.log" | tr -s ' ' | tr '\n' ' ')"
}

while IFS=$'\t' read -r name label opts; do
  while [ "$(jobs -rp | wc -l)" -ge "$JOBS" ]; do wait -n; done
  run_one "$name" "$opts" &
done < "$OUT/runs.tsv"
wait

# ground truth as TUM files (all frames, 0-420), then eval-traj of every run over both
$PY bench/real_frames.py "$DATA" "$OUT" docs/real_frames.md docs/real_frames.png --gt-only
while IFS=$'\t' read -r name label opts; do
  [ -f "$OUT/$name/stats.json" ] || continue
  "$BIN" eval-traj "$OUT/groundtruth.txt" "$OUT/$name/trajectory.txt" --json > "$OUT/eval/$name.all.json"
  awk '!/^#/ && n++ < 421' "$OUT/$name/trajectory.txt" > "$OUT/eval/$name.cut.txt"  # not grep | head: SIGPIPE under pipefail
  "$BIN" eval-traj "$OUT/groundtruth.cut.txt" "$OUT/eval/$name.cut.txt" --json > "$OUT/eval/$name.cut.json"
done < "$OUT/runs.tsv"

$PY bench/real_frames.py "$DATA" "$OUT" docs/real_frames.md docs/real_frames.png
