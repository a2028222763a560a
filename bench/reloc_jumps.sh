#!/usr/bin/env bash
# A camera carried away while tracking failed, on real frames (docs/tracking.md, "Candidates from
# colour"): for each jump J a folder of links to a pose-per-frame sequence (7-Scenes layout,
# ../shared/tools/get-7scenes-dev.sh) holds its frames 0-149, then frames J..J+AFTER-1 renumbered
# 150 on, so in one frame the camera is where frame J was; `bitfuse replay` runs it from the first
# true pose. Per jump: how many frames after the jump were lost before one was relocalised, from
# which candidate, that frame's time, and the unaligned position error against the ground truth at
# frame 149, at the relocalised frame and over the frames after it. Writes OUT/reloc_jumps.md.
# Extra options go to replay (e.g. --reloc-features 0).
#
#   bench/reloc_jumps.sh DATA OUT [replay options]        # JUMPS="200 450", AFTER=50, BIN=...
set -euo pipefail
cd "$(dirname "$0")/.."
[ $# -ge 2 ] || { echo "usage: bench/reloc_jumps.sh DATA OUT [replay options]" >&2; exit 2; }
DATA=$(cd "$1" && pwd) OUT=$2
shift 2
BIN=${BIN:-build/app/bitfuse}
JUMPS=${JUMPS:-200 450}
AFTER=${AFTER:-50}
PY=python3
[ -x /usr/bin/python3 ] && PY=/usr/bin/python3
[ -f "$DATA/camera-intrinsics.txt" ] || { echo "reloc_jumps.sh: $DATA: no camera-intrinsics.txt (a 7-Scenes folder)" >&2; exit 1; }
export BITFUSE_VALIDATION=0 BITFUSE_PROGRESS=0
mkdir -p "$OUT"
echo "| jump | frames after the jump lost | relocalised at (from) | that frame ms | error at 149 mm | at the relocalised frame mm | after it: mean / max mm |" >"$OUT/reloc_jumps.md"
echo "|---|---|---|---|---|---|---|" >>"$OUT/reloc_jumps.md"
for J in $JUMPS; do
  seq_dir="$OUT/seq_$J" run="$OUT/run_$J"
  rm -rf "$seq_dir" "$run"
  mkdir -p "$seq_dir"
  cp "$DATA/camera-intrinsics.txt" "$seq_dir/"
  n=0
  for k in $(seq 0 149) $(seq "$J" $((J + AFTER - 1))); do
    src=$(printf '%s/frame-%06d' "$DATA" "$k") dst=$(printf '%s/frame-%06d' "$seq_dir" "$n")
    [ -e "$src.depth.png" ] || { echo "reloc_jumps.sh: $src.depth.png: no such frame" >&2; exit 1; }
    for f in "$src".*; do ln -s "$f" "$dst.${f#"$src".}"; done
    n=$((n + 1))
  done
  "$BIN" replay "$seq_dir" --out "$run" --no-mesh "$@" >"$run.log" 2>&1 || { tail -3 "$run.log" >&2; exit 1; }
  "$PY" - "$seq_dir" "$run" "$J" >>"$OUT/reloc_jumps.md" <<'PYEOF'
import csv, glob, sys
import numpy as np
seq, run, jump = sys.argv[1], sys.argv[2], sys.argv[3]
gt = np.array([np.loadtxt(f)[:3, 3] for f in sorted(glob.glob(seq + '/frame-*.pose.txt'))])
est = np.loadtxt(run + '/trajectory.txt')[:, 1:4]
err = np.linalg.norm(est - gt, axis=1) * 1e3
rows = list(csv.DictReader(open(run + '/frames.csv')))
lost, found = 0, None
for r in rows[150:]:
    if r['state'] == 'relocalised':
        found = r
        break
    if r['state'] == 'lost':
        lost += 1
if found is None:
    print('| %s | all %d | never | | %.1f | | |' % (jump, lost, err[149]))
else:
    k = int(found['index'])
    after = err[k + 1:]
    tail = '%.1f / %.1f' % (after.mean(), after.max()) if len(after) else 'none after it'
    print('| %s | %d | frame %d (%s) | %.0f | %.1f | %.1f | %s |' % (
        jump, lost, k, found['reloc_from'], float(found['frame_ms']), err[149], err[k], tail))
PYEOF
done
cat "$OUT/reloc_jumps.md"
