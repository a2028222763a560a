#!/usr/bin/env bash
# The loop on a real TUM RGB-D sequence from several starts (docs/real_frames.md, "A second real
# sequence"): for each start N the sequence's first N depth frames are left out (a folder of links
# whose depth.txt begins at frame N, named after the sequence so its sensor's calibration is found),
# `bitfuse replay` runs from that frame's true pose, and the trajectory is scored against TUM's
# motion-capture ground truth: ATE (`bitfuse eval-traj`, Horn-aligned) and the largest unaligned
# position error. Writes OUT/tum_starts.md (a table, one row per start and their mean) and
# OUT/tum_starts.tsv. Extra options go to replay.
#
#   bench/tum_starts.sh SEQ OUT [replay options]        # STARTS="0 100 200 300", JOBS=2, BIN=...
#   bench/tum_starts.sh /data/rgbd_dataset_freiburg1_rpy /tmp/ts --camera 517.3,516.5,318.6,255.3
set -euo pipefail
cd "$(dirname "$0")/.."
[ $# -ge 2 ] || { echo "usage: bench/tum_starts.sh SEQ OUT [replay options]" >&2; exit 2; }
SEQ=$(cd "$1" && pwd) OUT=$2
shift 2
STARTS=${STARTS:-0 100 200 300}
JOBS=${JOBS:-2}
OPTS=("$@")
# shellcheck source=bench/common.sh
. bench/common.sh
for f in depth.txt rgb.txt groundtruth.txt; do
  [ -f "$SEQ/$f" ] || { echo "tum_starts.sh: $SEQ: no $f (a TUM RGB-D folder with ground truth)" >&2; exit 1; }
done
export BITFUSE_VALIDATION=0 BITFUSE_PROGRESS=0
mkdir -p "$OUT/starts"
name=$(basename "$SEQ")

# The folder of start N: links to the images, the depth list from frame N on.
make_start() {
  local d=$OUT/starts/${name}_from$1
  rm -rf "$d"
  mkdir -p "$d"
  for f in rgb depth rgb.txt groundtruth.txt camera.txt; do
    [ -e "$SEQ/$f" ] && ln -s "$SEQ/$f" "$d/$f"
  done
  { grep '^#' "$SEQ/depth.txt" || true; grep -v '^#' "$SEQ/depth.txt" | tail -n +$(($1 + 1)); } >"$d/depth.txt"
  echo "$d"
}

run_start() {
  local d r
  d=$(make_start "$1")
  r=$OUT/run_from$1
  rm -rf "$r"
  if ! "$BIN" replay "$d" --out "$r" --no-mesh "${OPTS[@]}" >"$r.log" 2>&1; then
    echo "tum_starts.sh: replay from frame $1 failed: $(tail -n 2 "$r.log")" >&2
    return 1
  fi
  "$BIN" eval-traj "$SEQ/groundtruth.txt" "$r/trajectory.txt" --json >"$r/eval.json" 2>"$r/eval.log"
}

# shellcheck disable=SC2086 # STARTS is a list of words
bench_each "$JOBS" run_start $STARTS || exit 1

# shellcheck disable=SC2086 # STARTS is a list of words
"$PY" - "$OUT" "$SEQ/groundtruth.txt" "$*" $STARTS <<'PYEOF'
import json, sys
import numpy as np
from scipy.spatial.transform import Rotation, Slerp

out, gt_path, opts, starts = sys.argv[1], sys.argv[2], sys.argv[3], [int(s) for s in sys.argv[4:]]
g = np.loadtxt(gt_path)
slerp = Slerp(g[:, 0], Rotation.from_quat(g[:, 4:8]))
rows = []
for s in starts:
    run = "%s/run_from%d" % (out, s)
    st = json.load(open(run + "/stats.json"))
    ev = json.load(open(run + "/eval.json"))
    e = np.loadtxt(run + "/trajectory.txt")
    e = e[(e[:, 0] >= g[0, 0]) & (e[:, 0] <= g[-1, 0])]
    p = np.stack([np.interp(e[:, 0], g[:, 0], g[:, k]) for k in (1, 2, 3)], 1)
    un = np.linalg.norm(e[:, 1:4] - p, axis=1) * 1e3
    rot = np.degrees((Rotation.from_quat(e[:, 4:8]) * slerp(e[:, 0]).inv()).magnitude())
    tr = st["tracking"]
    rows.append((s, st["frames"], tr["tracked"], tr["lost"], tr["relocalised"], ev["ate"]["trans_m"]["rmse"] * 1e3,
                 un.max(), int(un.argmax()), rot.max(), st["frame_ms"]["median"]))
with open(out + "/tum_starts.tsv", "w") as f:
    f.write("start\tframes\ttracked\tlost\trelocalised\tate_mm\tmax_unaligned_mm\tat_frame\tmax_rot_deg\tframe_ms\n")
    for r in rows:
        f.write("%d\t%d\t%d\t%d\t%d\t%.2f\t%.1f\t%d\t%.2f\t%.1f\n" % r)
with open(out + "/tum_starts.md", "w") as f:
    f.write("`bitfuse replay SEQ %s` from each start (frames left out before it):\n\n" % opts)
    f.write("| start | frames | tracked / lost (relocalised) | ATE mm | max unaligned mm (frame) | max rotation error deg | ms/frame |\n")
    f.write("|---|---|---|---|---|---|---|\n")
    for r in rows:
        f.write("| %d | %d | %d / %d (%d) | %.2f | %.1f (%d) | %.2f | %.1f |\n" % r)
    f.write("| mean | | | %.2f | %.1f | | |\n" % (np.mean([r[5] for r in rows]), np.mean([r[6] for r in rows])))
print(open(out + "/tum_starts.md").read())
PYEOF
