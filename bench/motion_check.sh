#!/usr/bin/env bash
# Trajectories against the motion the colour images show (bitfuse
# eval-motion, docs/eval.md): the sequence's ground truth and the loop's own
# trajectory over pairs 5, 10, 20 and 30 frames apart, and per 5-frame pair
# along the sequence.
# Writes OUT/motion_check.md (a table), OUT/motion_check.png (the per-pair
# error of each against the frame) and OUT/em-K.{json,csv}.
# Usage: [LABEL=NAME] bench/motion_check.sh SEQUENCE OUT [TRAJ]   (TRAJ: a replay's
# trajectory.txt; without it, `bitfuse replay SEQUENCE --no-mesh` makes one
# in OUT/replay)
set -euo pipefail
. "$(dirname "$0")/common.sh"
SEQ=$1
OUT=$2
TRAJ=${3:-}
mkdir -p "$OUT"
if [ -z "$TRAJ" ]; then
    "$BIN" replay "$SEQ" --out "$OUT/replay" --no-mesh >"$OUT/replay.log" 2>&1
    TRAJ=$OUT/replay/trajectory.txt
fi
for k in 5 10 20 30; do
    "$BIN" eval-motion "$SEQ" groundtruth "$TRAJ" --span "$k" --json --csv "$OUT/em-$k.csv" >"$OUT/em-$k.json"
    echo "  span $k" >&2
done
"$BIN" eval-motion "$SEQ" groundtruth "$TRAJ" --span 5 --every 1 --json --csv "$OUT/em-5-all.csv" >/dev/null
"$PY" "$(dirname "$0")/plot_motion.py" "$OUT" "${LABEL:-bitfuse replay}"
