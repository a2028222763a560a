#!/usr/bin/env bash
# bitfuse as a user runs it: a tiny synthetic sequence, then info, eval-traj
# and eval-surface on it and on broken copies of it. Each check names what
# it expected. Usage: test_cli.sh path/to/bitfuse
set -u
B=$1
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
fails=0
fail() { echo "FAIL: $*"; fails=$((fails + 1)); }
# expect RC CMD...: runs CMD, keeps stdout in $T/out and stderr in $T/err.
expect() {
    local want=$1
    shift
    "$@" >"$T/out" 2>"$T/err"
    local rc=$?
    [ "$rc" = "$want" ] || fail "exit $rc, expected $want: $* ($(head -c 300 "$T/err"))"
}
mentions() { grep -qF -- "$1" "$T/err" || fail "stderr does not mention '$1': $(head -c 300 "$T/err")"; }
is_json() { python3 -m json.tool "$1" >/dev/null 2>&1 || fail "$1 is not valid JSON: $(head -c 300 "$1")"; }
command -v python3 >/dev/null || { echo "no python3"; exit 77; }

# A trajectory of 1.5 s at 30 Hz: a slow sideways move. A copy sits in a
# folder whose name needs escaping in JSON (stats.json names the file).
python3 - "$T/traj.txt" <<'PY'
import sys
with open(sys.argv[1], "w") as f:
    for i in range(46):
        f.write("%.6f %.6f 0 0 0 0 0 1\n" % (1305031098.6659 + i / 30.0, 0.002 * i))
PY
Q="$T/a \"quoted\" \\ dir"
mkdir "$Q" && cp "$T/traj.txt" "$Q/traj.txt"

# synth: a small sequence (the room without the shared meshes, small images).
mkdir "$T/nodata"
expect 0 "$B" synth --trajectory "$Q/traj.txt" --frames 3 --size 160x120 --camera 131.25,131.25,79.5,59.5 \
    --data "$T/nodata" --out "$T/seq"
is_json "$T/seq/stats.json"
python3 -c "import json,sys; assert json.load(open(sys.argv[1]))['trajectory'] == sys.argv[2]" \
    "$T/seq/stats.json" "$Q/traj.txt" || fail "stats.json does not name the trajectory $Q/traj.txt"

# info: JSON parses and keeps the timestamps' microseconds.
expect 0 "$B" info "$T/seq" --json
is_json "$T/out"
t0=$(awk '!/^#/ {print $1; exit}' "$T/seq/depth.txt")
python3 -c "import json,sys; d=json.load(open(sys.argv[1])); assert abs(d['t_first_s'] - float(sys.argv[2])) < 1e-6, d['t_first_s']" \
    "$T/out" "$t0" || fail "info --json t_first_s differs from depth.txt's first stamp $t0"

# eval-traj: a sequence shorter than the RPE delta still gets its ATE.
expect 0 "$B" eval-traj "$T/seq/groundtruth.txt" "$T/seq/groundtruth.txt" --json
is_json "$T/out"
expect 0 "$B" eval-traj "$T/traj.txt" "$T/traj.txt" --json
is_json "$T/out"

# eval-surface: the seen points lie on the reference.
expect 0 "$B" eval-surface --reference "$T/seq/scene.ply" --reconstruction "$T/seq/seen.ply" --max-samples 2000 --json
is_json "$T/out"

# Bad command lines: exit 2, naming the culprit.
expect 2 "$B" info
expect 2 "$B" eval-surface rec.ply
mentions "unknown argument 'rec.ply'"
expect 2 "$B" synth --trajectory "$T/traj.txt" --frames 1 --out "$T/x" --verbose
mentions "unknown option '--verbose'"

# Bad input: exit 3 and the message names the file (and line or frame).
expect 3 "$B" info "$T/missing"
mentions "$T/missing"
mkdir "$T/empty"
expect 3 "$B" info "$T/empty"
mentions "$T/empty"
printf '1 2 3\n' >"$T/garbage.txt"
expect 3 "$B" eval-traj "$T/garbage.txt" "$T/traj.txt"
mentions "$T/garbage.txt:1"
cp -r "$T/seq" "$T/cut"
f=$(ls "$T/cut/depth" | head -n 2 | tail -n 1)
head -c 200 "$T/seq/depth/$f" >"$T/cut/depth/$f"
expect 3 "$B" info "$T/cut"
mentions "$f"
mentions "frame 1"
expect 0 "$B" info "$T/cut" --skip-bad-frames
# Every frame unreadable: skipping them all is not a success.
cp -r "$T/seq" "$T/allcut"
for g in "$T/allcut"/depth/*.png; do head -c 200 "$T/seq/depth/$(basename "$g")" >"$g"; done
expect 3 "$B" info "$T/allcut" --skip-bad-frames
mentions "no frame could be read (3 skipped)"
expect 3 "$B" eval-surface --reference "$T/garbage.txt" --reconstruction "$T/seq/seen.ply"
mentions "$T/garbage.txt"

[ $fails = 0 ] && echo "all CLI checks passed"
[ $fails = 0 ]
