#!/usr/bin/env bash
# The loop on the 7-Scenes dev frames from four starts (docs/real_frames.md: "the four starts"):
#   dev     frames 0-499 as they are
#   rev     the same frames in reverse order (499 first)
#   from100 frames 100-499, renumbered from 0
#   from200 frames 200-499, renumbered from 0
# Each start is a folder of links (pose-per-frame layout, made under OUT; the frames are never
# copied), `bitfuse replay` runs from its first frame's true pose, and the trajectory is scored
# against the ground truth: ATE (Horn-aligned positions, as bench/real_frames.py) and the largest
# unaligned position error. Writes OUT/dev_starts.md (a table and the mean) and OUT/dev_starts.tsv.
# Extra options go to replay.
#
#   bench/dev_starts.sh DEV OUT [replay options]      # JOBS=2, BIN=..., STARTS="dev rev from100 from200"
#   bench/dev_starts.sh /data/7scenes-dev /tmp/ds --depth-correction dc.json
set -euo pipefail
cd "$(dirname "$0")/.."
[ $# -ge 2 ] || { echo "usage: bench/dev_starts.sh DEV OUT [replay options]" >&2; exit 2; }
DEV=$(cd "$1" && pwd) OUT=$2
shift 2
STARTS=${STARTS:-dev rev from100 from200}
JOBS=${JOBS:-2}
OPTS=("$@")
# shellcheck source=bench/common.sh
. bench/common.sh
[ -f "$DEV/frame-000000.pose.txt" ] || { echo "dev_starts.sh: $DEV: no frame-000000.pose.txt (a pose-per-frame folder)" >&2; exit 1; }
n=$(find "$DEV" -maxdepth 1 -name 'frame-*.depth.png' | wc -l)
export BITFUSE_VALIDATION=0 BITFUSE_PROGRESS=0
mkdir -p "$OUT/starts"

# The folder of a start: frame k of it links to frame src(k) of DEV.
make_start() {
  local d=$OUT/starts/$1 k=0 i
  rm -rf "$d"
  mkdir -p "$d"
  for f in "$DEV"/*.txt; do
    case $(basename "$f") in frame-*) ;; *) ln -s "$f" "$d/" ;; esac
  done
  case $1 in
  dev) seq 0 $((n - 1)) ;;
  rev) seq $((n - 1)) -1 0 ;;
  from*) seq "${1#from}" $((n - 1)) ;;
  *) echo "dev_starts.sh: unknown start $1 (dev, rev, fromN)" >&2; return 1 ;;
  esac >"$d.src"
  while read -r i; do
    for e in color.png color.jpg depth.png pose.txt; do
      [ -e "$DEV/$(printf 'frame-%06d' "$i").$e" ] && ln -s "$DEV/$(printf 'frame-%06d' "$i").$e" "$d/$(printf 'frame-%06d' "$k").$e"
    done
    k=$((k + 1))
  done <"$d.src"
  echo "$d"
}

run_start() {
  local d r
  d=$(make_start "$1")
  r=$OUT/run_$1
  rm -rf "$r"
  if ! "$BIN" replay "$d" --out "$r" --no-mesh "${OPTS[@]}" >"$r.log" 2>&1; then
    echo "dev_starts.sh: replay of $1 failed: $(tail -n 2 "$r.log")" >&2
    return 1
  fi
}

# shellcheck disable=SC2086 # STARTS is a list of words
bench_each "$JOBS" run_start $STARTS || exit 1

# shellcheck disable=SC2086 # STARTS is a list of words
"$PY" - "$OUT" "$*" $STARTS <<'PYEOF'
import json, sys
import numpy as np

out, opts, starts = sys.argv[1], sys.argv[2], sys.argv[3:]


def horn(a, b):
    """Rotation and translation taking points a onto b (least squares)."""
    ma, mb = a.mean(0), b.mean(0)
    u, _, vt = np.linalg.svd((a - ma).T @ (b - mb))
    d = np.eye(3)
    d[2, 2] = np.sign(np.linalg.det(vt.T @ u.T))
    r = vt.T @ d @ u.T
    return r, mb - r @ ma


rows = []
for s in starts:
    folder, run = "%s/starts/%s" % (out, s), "%s/run_%s" % (out, s)
    st = json.load(open(run + "/stats.json"))
    est = np.array([[float(x) for x in l.split()[1:4]] for l in open(run + "/trajectory.txt")
                    if l.strip() and not l.startswith("#")])
    # Trajectory lines are the frames in order (a skipped frame keeps the pose before it).
    gt = np.array([np.loadtxt("%s/frame-%06d.pose.txt" % (folder, k))[:3, 3] for k in range(len(est))])
    r, t = horn(est, gt)
    ate = np.sqrt((np.linalg.norm(est @ r.T + t - gt, axis=1) ** 2).mean()) * 1e3
    un = np.linalg.norm(est - gt, axis=1) * 1e3
    tr = st["tracking"]
    rows.append((s, len(est), tr["tracked"], tr["lost"], tr["relocalised"], ate, un.max(), int(un.argmax()),
                 st["frame_ms"]["median"]))
with open(out + "/dev_starts.tsv", "w") as f:
    f.write("start\tframes\ttracked\tlost\trelocalised\tate_mm\tmax_unaligned_mm\tat_frame\tframe_ms\n")
    for r in rows:
        f.write("%s\t%d\t%d\t%d\t%d\t%.2f\t%.1f\t%d\t%.1f\n" % r)
with open(out + "/dev_starts.md", "w") as f:
    f.write("`bitfuse replay START %s` from each start of the dev frames:\n\n" % opts)
    f.write("| start | frames | tracked / lost (relocalised) | ATE mm | max unaligned mm (frame of the start) | ms/frame |\n")
    f.write("|---|---|---|---|---|---|\n")
    for r in rows:
        f.write("| %s | %d | %d / %d (%d) | %.2f | %.1f (%d) | %.1f |\n" % r)
    f.write("| mean | | | %.2f | %.1f | |\n" % (np.mean([r[5] for r in rows]), np.mean([r[6] for r in rows])))
print(open(out + "/dev_starts.md").read())
PYEOF
