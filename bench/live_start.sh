#!/usr/bin/env bash
# Start-up of `bitfuse live` (docs/tracking.md, start-up): a recorded
# synthetic room played at its own 30 Hz through the capture thread
# (--realtime), as a camera would deliver it, with views every 10 frames.
# Runs once with empty caches (a fresh XDG_CACHE_HOME: bitfuse's pipeline
# cache and Mesa's shader cache both cold) and once more with what that run
# left (warm), and prints one row per run: time to the loop being ready,
# to the first frame done, the first frame's own time, the frame delivered
# after it, frames captured / dropped, tracked / lost.
#
#   bench/live_start.sh [FRAMES] [OUT_DIR]        (defaults 90, /tmp/bitfuse-live-start)
#   BITFUSE_BIN=/path/to/bitfuse bench/live_start.sh   (another build, e.g. an older one)
#   QUEUE=32 bench/live_start.sh                       (capture queue, default live's 8)
set -euo pipefail
cd "$(dirname "$0")/.."
FRAMES=${1:-90}
OUT=${2:-/tmp/bitfuse-live-start}
QUEUE=${QUEUE:-8}
source bench/common.sh
mkdir -p "$OUT"
SEQ="$OUT/seq$FRAMES"
bench_room_sequence "$SEQ" "$FRAMES" > /dev/null
CACHE="$OUT/cache.$$"
rm -rf "$CACHE"
mkdir -p "$CACHE"
printf "run\tready_s\tfirst_done_s\tfirst_frame_ms\tnext_frame\tcaptured\tdropped\ttracked\tlost\tload1\n"
for run in cold warm; do
  RUN="$OUT/$run"
  rm -rf "$RUN"
  XDG_CACHE_HOME="$CACHE" BITFUSE_CACHE_DIR= $BIN live --device "$SEQ" --realtime --queue "$QUEUE" --view-every 10 --no-mesh \
    --out "$RUN" > "$RUN.log" 2>&1
  $PY - "$RUN" "$run" <<'EOF'
import csv, json, os, sys
run, name = sys.argv[1], sys.argv[2]
s = json.load(open(os.path.join(run, "stats.json")))
rows = list(csv.DictReader(open(os.path.join(run, "frames.csv"))))
st = s.get("startup", {})
fmt = lambda v: "-" if v is None else "%.2f" % v
cap, tr = s["capture"], s["tracking"]
print("\t".join([name, fmt(st.get("ready_s")), fmt(st.get("first_frame_done_s")),
                 "%.0f" % float(rows[0]["frame_ms"]), rows[1]["index"] if len(rows) > 1 else "-",
                 str(cap["captured"]), str(cap["dropped"]), str(tr["tracked"]), str(tr["lost"]),
                 "%.1f" % os.getloadavg()[0]]))
EOF
done
rm -rf "$CACHE"
