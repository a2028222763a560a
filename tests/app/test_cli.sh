#!/usr/bin/env bash
# bitfuse as a user runs it: a tiny synthetic sequence, then info, eval-traj
# and eval-surface on it and on broken copies of it. Each check names what
# it expected. Usage: test_cli.sh path/to/bitfuse [sanitized]
# ("sanitized": the ASan/UBSan build, where the checks that only add GPU
# runs are left out for CI's 20 minutes; their host code runs sanitized in
# test_recon_runner and test_replay).
set -u
B=$1
SANITIZED=0
[ "${2:-}" = sanitized ] && SANITIZED=1
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
. "$(dirname "$0")/common.sh"
is_json() { python3 -m json.tool "$1" >/dev/null 2>&1 || fail "$1 is not valid JSON: $(head -c 300 "$1")"; }
python3() { py "$@"; }

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

# A lens in camera.txt (k1 k2 p1 p2 k3 after the depth scale): info says
# its frames come undistorted; a lens that folds the image is bad input (3)
# naming camera.txt; the same numbers typed with --camera are a usage error.
python3 - "$T/out" <<'PY' || fail "info --json of the plain sequence has a lens: $(cat "$T/out")"
import json, sys
assert json.load(open(sys.argv[1]))["undistorted"] is None
PY
cp -r "$T/seq" "$T/lens"
read -r fx fy cx cy sc < "$T/seq/camera.txt"
echo "$fx $fy $cx $cy ${sc:-5000} 0.2624 -0.9531 -0.0054 0.0026 1.1633" > "$T/lens/camera.txt"
expect 0 "$B" info "$T/lens" --json
python3 - "$T/out" <<'PY' || fail "info --json does not report camera.txt's lens: $(cat "$T/out")"
import json, sys
assert json.load(open(sys.argv[1]))["undistorted"] == [0.2624, -0.9531, -0.0054, 0.0026, 1.1633]
PY
expect 0 "$B" info "$T/lens"
grep -q "^lens .*taken out of every frame" "$T/out" || fail "info does not show the lens: $(cat "$T/out")"
if [ "$SANITIZED" = 0 ]; then
  expect 0 "$B" replay "$T/lens" --out "$T/lens_run" --no-mesh
  python3 - "$T/lens_run/stats.json" "$fx" <<'PY' || fail "stats.json's camera does not hold the lens: $(head -c 600 "$T/lens_run/stats.json")"
import json, sys
c = json.load(open(sys.argv[1]))["camera"]
assert c["undistorted"] == [0.2624, -0.9531, -0.0054, 0.0026, 1.1633], c
assert c["fx"] == float(sys.argv[2]) and c["width"] == 160 and c["undistort_max_shift_px"] > 0, c
PY
fi
echo "$fx $fy $cx $cy ${sc:-5000} -0.9 0 0 0 0" > "$T/lens/camera.txt"
expect 3 "$B" info "$T/lens"
mentions "camera.txt"
mentions "folds"
expect 2 "$B" info "$T/seq" --camera "$fx,$fy,$cx,$cy,-0.9,0,0,0,0"
mentions "--camera"
# Numbers no depth camera has for these images (they spread a map over
# thousands of chunks at seconds a frame): typed, a usage error; in
# camera.txt, bad input naming the folder and the file.
expect 2 "$B" info "$T/seq" --camera 0.001,0.001,79.5,59.5
mentions "more than 85 degrees off its axis"
expect 2 "$B" info "$T/seq" --camera "$fx,$fy,1e6,-1e6"
mentions "cx 1e+06, cy -1e+06 px, from --camera"
expect 2 "$B" info "$T/seq" --camera 1e7,1e7,79.5,59.5
mentions "field of view under 0.1 degree"
echo "0.001 0.001 $cx $cy ${sc:-5000}" > "$T/lens/camera.txt"
expect 3 "$B" info "$T/lens"
mentions "from camera.txt"
# Images of 15x15 (a 16-bit PNG written by hand) with their own camera:
# read, but too small for the tracker's pyramid: bad input naming the folder.
mkdir -p "$T/tiny/depth"
py - "$T/tiny" <<'PY'
import struct, sys, zlib
def chunk(t, d): return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xffffffff)
w = h = 15
raw = b"".join(b"\0" + struct.pack(">%dH" % w, *([6000] * w)) for _ in range(h))
png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 16, 0, 0, 0, 0)) + \
      chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b"")
with open(sys.argv[1] + "/depth.txt", "w") as f:
    for i in range(3):
        open(sys.argv[1] + "/depth/%d.png" % i, "wb").write(png)
        f.write("%.6f depth/%d.png\n" % (1 + i / 30, i))
open(sys.argv[1] + "/camera.txt", "w").write("12 12 7 7 5000\n")
PY
expect 0 "$B" info "$T/tiny"
grep -q "15x15" "$T/out" || fail "info of 15x15 images: $(cat "$T/out")"
# A camera for images twice the size (its principal point at the corner of
# these) is warned about; a hex float in a pose is refused by file and line.
py -c "import sys; fx, fy, cx, cy = map(float, sys.argv[1:5]); print(2 * fx, 2 * fy, 2 * cx + 0.5, 2 * cy + 0.5, 5000)" \
    "$fx" "$fy" "$cx" "$cy" >"$T/lens/camera.txt"
expect 0 "$B" info "$T/lens"
mentions "far from the centre of the 160x120 images"
mentions "$T/lens: the camera's principal point"
cp "$T/seq/camera.txt" "$T/lens/camera.txt"
awk 'NR == 4 && !/^#/ { $2 = "0x1p-3" } { print }' "$T/seq/groundtruth.txt" >"$T/lens/groundtruth.txt"
expect 3 "$B" info "$T/lens"
mentions "groundtruth.txt:4: tx '0x1p-3' is not a number"
expect 0 "$B" info "$T/seq" --json # $T/out again: the plain sequence's, for the checks below

# info: a depth image handed on twice (a driver's late frame) counts as a
# repeat; the colour of that frame is new, and the sequence itself has none.
# repeats_are DEPTH COLOUR FIRST: info --json's counts in $T/out.
repeats_are() {
    python3 -c "import json,sys; d=json.load(open(sys.argv[1])); assert (d['repeated_depth_frames'], d['repeated_colour_frames'], d['repeated_depth_first']) == (int(sys.argv[2]), int(sys.argv[3]), json.loads(sys.argv[4])), d" \
        "$T/out" "$1" "$2" "$3"
}
repeats_are 0 0 "[]" || fail "info counts repeats in a sequence without any"
cp -r "$T/seq" "$T/rep"
repeat_frame "$T/rep" depth 2
expect 0 "$B" info "$T/rep" --json
repeats_are 1 0 "[2]" || fail "info does not find frame 2's depth repeating frame 1's: $(cat "$T/out")"
expect 0 "$B" info "$T/rep"
grep -q "1 depth frame repeats the one before byte for byte (frame 2)" "$T/out" || fail "info's repeats line: $(cat "$T/out")"
# A colour image handed on twice, the depth new.
cp -r "$T/seq" "$T/reprgb"
repeat_frame "$T/reprgb" rgb 2
expect 0 "$B" info "$T/reprgb" --json
repeats_are 0 1 "[]" || fail "info does not find frame 2's colour repeating frame 1's: $(cat "$T/out")"
python3 -c "import json,sys; d=json.load(open(sys.argv[1])); assert d['repeated_colour_first'] == [2], d" "$T/out" ||
    fail "info --json does not list the repeated colour frames"

# eval-traj: a sequence shorter than the RPE delta still gets its ATE (all 3
# poses, of a trajectory against itself: 0), its RPE left out; the 1.5 s
# trajectory gets both RPEs.
# ate_is PAIRS RPE_UNITS: eval-traj --json's ATE pairs, zero error, the RPE kept.
ate_is() {
    python3 -c "import json,sys; d=json.load(open(sys.argv[1])); a=d['ate']; assert a['pairs'] == int(sys.argv[2]) and a['trans_m']['rmse'] == 0 and [r['unit'] for r in d['rpe']] == json.loads(sys.argv[3]), d" \
        "$T/out" "$1" "$2"
}
expect 0 "$B" eval-traj "$T/seq/groundtruth.txt" "$T/seq/groundtruth.txt" --json
ate_is 3 "[]" || fail "eval-traj of 3 poses against themselves: $(head -c 400 "$T/out")"
expect 0 "$B" eval-traj "$T/traj.txt" "$T/traj.txt" --json
ate_is 46 '["s", "frame"]' || fail "eval-traj of 46 poses against themselves: $(head -c 400 "$T/out")"

# eval-surface: the seen points lie on the reference (closer than 1 mm, all
# within the 1 cm threshold).
expect 0 "$B" eval-surface --reference "$T/seq/scene.ply" --reconstruction "$T/seq/seen.ply" --max-samples 2000 --json
python3 -c "import json,sys; a=json.load(open(sys.argv[1]))['accuracy']; assert a['points'] > 0 and a['median_m'] < 1e-3 and a['within_threshold'] > 0.99, a" \
    "$T/out" || fail "eval-surface: the seen points are off the reference: $(head -c 400 "$T/out")"

# eval-surface: a reconstruction in millimetres against a reference in metres is warned about
# (every distance would be beyond the threshold); the same units are not.
for scale in 1 1000; do
    py - "$T/tet$scale.ply" "$scale" <<'PY'
import sys
s = float(sys.argv[2])
v = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)]
f = [(0, 2, 1), (0, 1, 3), (1, 2, 3), (0, 3, 2)]
open(sys.argv[1], "w").write("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
    "property float z\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n"
    + "".join("%g %g %g\n" % tuple(s * c for c in p) for p in v) + "".join("3 %d %d %d\n" % t for t in f))
PY
done
expect 0 "$B" eval-surface --reference "$T/tet1.ply" --reconstruction "$T/tet1000.ply" --max-samples 500
mentions "the reference spans 1.73 m and the reconstruction 1.73e+03 m: are both in metres?"
expect 0 "$B" eval-surface --reference "$T/tet1.ply" --reconstruction "$T/tet1.ply" --max-samples 500
! grep -q "are both in metres" "$T/err" || fail "eval-surface warned about units of the same mesh"

# eval-surface --depth: noiseless depth at its true poses lies on the scene (within the 0.2 mm
# depth unit and the scene's triangles); the same depth at poses shifted 3 cm along each axis
# (off every wall of the room) does not.
expect 0 "$B" synth --trajectory "$T/traj.txt" --frames 3 --size 160x120 --camera 131.25,131.25,79.5,59.5 \
    --noise none --data "$T/nodata" --out "$T/clean"
expect 0 "$B" eval-surface --reference "$T/clean/scene.ply" --depth "$T/clean" --every 1 --json
python3 -c "import json,sys; d=json.load(open(sys.argv[1])); a=d['accuracy']; assert d['depth']['frames'] == 3 and a['median_m'] < 1e-3 and a['within_threshold'] > 0.99, a" \
    "$T/out" || fail "eval-surface --depth: noiseless depth at true poses is off the scene: $(head -c 400 "$T/out")"
awk '!/^#/ {$2 += 0.03; $3 += 0.03; $4 += 0.03} {print}' "$T/clean/groundtruth.txt" > "$T/shifted.txt"
expect 0 "$B" eval-surface --reference "$T/clean/scene.ply" --depth "$T/clean" --every 1 --poses "$T/shifted.txt" --json
python3 -c "import json,sys; a=json.load(open(sys.argv[1]))['accuracy']; assert a['median_m'] > 1e-2 and a['within_threshold'] < 0.5, a" \
    "$T/out" || fail "eval-surface --depth: poses 3 cm off still fit: $(head -c 400 "$T/out")"
# A trajectory without the middle frame's pose: the frame is interpolated across the one-frame
# gap (1/15 s), and left out, counted, where --max-gap is narrower.
awk '!/^#/ {n++; if (n == 2) next} {print}' "$T/clean/groundtruth.txt" >"$T/holed.txt"
expect 0 "$B" eval-surface --reference "$T/clean/scene.ply" --depth "$T/clean" --every 1 --poses "$T/holed.txt" --json
python3 -c "import json,sys; d=json.load(open(sys.argv[1])); assert d['depth']['frames'] == 3, d" "$T/out" ||
    fail "eval-surface: the frame in a one-frame gap not interpolated: $(head -c 300 "$T/out")"
expect 0 "$B" eval-surface --reference "$T/clean/scene.ply" --depth "$T/clean" --every 1 --poses "$T/holed.txt" \
    --max-gap 0.05 --json
python3 -c "import json,sys; d=json.load(open(sys.argv[1])); assert d['depth']['frames'] == 2, d" "$T/out" ||
    fail "eval-surface --max-gap: the frame in the gap was placed: $(head -c 300 "$T/out")"
mentions "1 frame in gaps of $T/holed.txt wider than --max-gap 0.05 s left out"
python3 -c "import json,sys; d=json.load(open(sys.argv[1]))['depth']; assert d['frames_in_gaps'] == 1 and d['max_gap_s'] == 0.05, d" \
    "$T/out" || fail "eval-surface --max-gap: frames_in_gaps not in the JSON"
expect 2 "$B" eval-surface --reference "$T/clean/scene.ply" --depth "$T/clean" --poses groundtruth --max-gap 0.05
mentions "--max-gap bridges gaps of a --poses TRAJ file"
expect 2 "$B" eval-surface --reference "$T/clean/scene.ply"
mentions "exactly one of --reconstruction and --depth"

# TUM files as TUM's scripts read them: a repeated timestamp (the published ground truth of
# rgbd_dataset_freiburg2_desk has one) keeps the first line, a quaternion off unit length is
# normalised; one warning per file names the first line. A zero quaternion cannot be used.
awk 'NR == 3 {print; print $1, 9, 9, 9, 0, 0, 0, 1; next} NR == 5 {$8 = 1.1} {print}' "$T/traj.txt" >"$T/tum_odd.txt"
expect 0 "$B" synth --trajectory "$T/tum_odd.txt" --frames 4 --size 32x24 --camera 26,26,15.5,11.5 --data "$T/nodata" \
    --noise none --out "$T/odd"
mentions "$T/tum_odd.txt:4: timestamp repeats"
mentions "$T/tum_odd.txt:6: quaternion norm is 1.1"
[ "$(grep -c "tum_odd.txt" "$T/err")" = 2 ] || fail "tum_odd.txt: expected one warning of each kind: $(cat "$T/err")"
python3 - "$T/odd/groundtruth.txt" "$T/traj.txt" <<'PY' || fail "synth on a repeated stamp: the first line was not the one kept"
import sys
gt = [[float(x) for x in l.split()] for l in open(sys.argv[1]) if l.strip() and l[0] != '#']
tr = [[float(x) for x in l.split()] for l in open(sys.argv[2])]
assert len(gt) == 4 and all(abs(g[0] - t[0]) < 1e-5 for g, t in zip(gt, tr)), (gt, tr[:4])
# The poses are moved into the scene's frame: compare the steps between them (2 mm each).
step = [sum((gt[i + 1][k] - gt[i][k]) ** 2 for k in (1, 2, 3)) ** 0.5 for i in range(3)]
assert all(abs(d - 0.002) < 1e-5 for d in step), step
PY
sed '3s/ 0 0 0 1$/ 0 0 0 0/' "$T/traj.txt" >"$T/tum_zero.txt"
expect 3 "$B" synth --trajectory "$T/tum_zero.txt" --frames 4 --size 32x24 --camera 26,26,15.5,11.5 --data "$T/nodata" \
    --out "$T/zero"
mentions "$T/tum_zero.txt:3: quaternion"
mentions "is zero"

# What a command prints must reach its reader: a full disk under
# `--json > FILE` is exit 5, named (it was exit 0 with the file cut short).
if [ -w /dev/full ]; then
    "$B" eval-traj "$T/seq/groundtruth.txt" "$T/seq/groundtruth.txt" --json >/dev/full 2>"$T/err"
    rc=$?
    [ $rc = 5 ] || fail "eval-traj --json to a full disk: exit $rc, expected 5"
    mentions "standard output: write failed"
fi
# --version: the program's and each command's; unknown options named as such.
expect 0 "$B" --version
grep -qE "^bitfuse [0-9]+\.[0-9]+\.[0-9]+$" "$T/out" || fail "bitfuse --version: $(cat "$T/out")"
version=$(cat "$T/out")
for c in replay synth calibrate; do
    expect 0 "$B" $c --version
    [ "$(cat "$T/out")" = "$version" ] || fail "$c --version: '$(cat "$T/out")', expected '$version'"
done
python3 -c "import json,sys; assert json.load(open(sys.argv[1]))['version'] == sys.argv[2].split()[1]" \
    "$T/seq/stats.json" "$version" || fail "synth stats.json: no version"
expect 2 "$B" --bogus
mentions "unknown option '--bogus'"
expect 2 "$B" replay "$T/seq" --out "$T/rpb" --bogus
mentions "unknown option '--bogus'"
expect 2 "$B" replay "$T/seq" --bogus 3 --out "$T/rpb"
mentions "unknown option '--bogus'"
[ ! -e "$T/rpb" ] || fail "replay --bogus: the output folder was made"
expect 2 "$B" replay "$T/seq" --out --ratio 2
mentions "--out needs a value"
[ ! -e "--ratio" ] || fail "replay --out --ratio: a folder named --ratio was made"

# Bad command lines: exit 2, naming the culprit.
expect 2 "$B" info
expect 2 "$B" eval-surface rec.ply
mentions "unknown argument 'rec.ply'"
expect 2 "$B" eval-surface --reference a.ply --reconstruction b.ply --frames 3
mentions "--frames needs --depth"
expect 2 "$B" eval-surface --reference a.ply --reconstruction b.ply --max-dist 0.001
mentions "--max-dist 0.001 is below --threshold 0.01"
expect 2 "$B" synth --trajectory "$T/traj.txt" --frames 1 --out "$T/x" --verbose
mentions "unknown option '--verbose'"
expect 2 "$B" synth --trajectory "$T/traj.txt" --frames 1 --out "$T/x" --size 8x8
mentions "16x16 to 8192x8192"

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
# record reads a sequence through its capture thread: the skipped frame is still counted.
expect 0 "$B" record --device "$T/cut" --out "$T/cutrec.bflog" --skip-bad-frames
grep -q "1 unreadable frame skipped" "$T/out" || fail "record --skip-bad-frames: no count in the summary: $(cat "$T/out")"
py -c "import json,sys; d=json.load(open(sys.argv[1])); assert d['frames_unreadable'] == 1 and d['frames'] == 2, d" \
    "$T/cutrec.stats.json" || fail "record --skip-bad-frames: stats.json does not count the skipped frame"
# A corrupt frame mid-fuse keeps the work done: the frames before it are written, exit 3
# names the file and frame; with --skip-bad-frames the frame is skipped and counted.
# (Small pools: the default pool's allocation is most of a 3-frame run's time.)
small="--no-mesh --bricks 20000 --window 4 --subcache 2"
if [ $SANITIZED = 0 ]; then
    expect 3 "$B" fuse "$T/cut" --poses groundtruth --out "$T/fucut" $small
    mentions "$f"
    mentions "frame 1"
    [ -s "$T/fucut/points.ply" ] || fail "fuse stopped by a corrupt frame: the frames before it were not written"
    python3 -c "import json,sys; d=json.load(open(sys.argv[1])); assert d['frames'] == 1 and 'frame 1' in d['input_error'] and d['version'], d" \
        "$T/fucut/stats.json" || fail "fuse stopped by a corrupt frame: stats.json"
    expect 0 "$B" fuse "$T/cut" --poses groundtruth --out "$T/fuskip" $small --skip-bad-frames
    grep -q "(1 skipped: 1 unreadable" "$T/out" || fail "fuse --skip-bad-frames: the summary does not count it: $(head -c 300 "$T/out")"
    python3 -c "import json,sys; d=json.load(open(sys.argv[1])); assert d['frames'] == 2 and d['frames_skipped'] == 1 and d['frames_unreadable'] == 1 and d['input_error'] is None, d" \
        "$T/fuskip/stats.json" || fail "fuse --skip-bad-frames: stats.json does not count the skipped frame"
    # A corrupt first frame: nothing to keep, and no empty folder left behind.
    cp -r "$T/seq" "$T/cut0"
    f0=$(ls "$T/cut0/depth" | head -n 1)
    head -c 200 "$T/seq/depth/$f0" >"$T/cut0/depth/$f0"
    expect 3 "$B" fuse "$T/cut0" --poses groundtruth --out "$T/fucut0" $small
    mentions "frame 0"
    [ ! -e "$T/fucut0" ] || fail "fuse stopped by a corrupt first frame left $T/fucut0 behind"
    # Frames without a depth sample are skipped and counted; with none that has
    # one, fuse says so as replay does (exit 3) and leaves no folder.
    cp -r "$T/seq" "$T/zd"
    py - "$T/zd/depth" <<'PY'
import os, struct, sys, zlib
chunk = lambda t, x: struct.pack(">I", len(x)) + t + x + struct.pack(">I", zlib.crc32(t + x) & 0xffffffff)
for name in sorted(os.listdir(sys.argv[1]))[1:]:
    p = os.path.join(sys.argv[1], name)
    w, h = struct.unpack(">II", open(p, "rb").read()[16:24])
    raw = b"".join(b"\0" + bytes(2 * w) for _ in range(h))
    open(p, "wb").write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 16, 0, 0, 0, 0))
                        + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))
PY
    expect 0 "$B" fuse "$T/zd" --poses groundtruth --out "$T/fuzd" $small
    py -c "import json,sys; m = json.load(open(sys.argv[1]))['mesh']; assert m['file'] is None and m['skipped'], m" \
        "$T/fuzd/stats.json" || fail "fuse --no-mesh: stats.json's mesh does not say skipped"
    grep -q "2 frames without a depth sample in the sensor's range: not fused" "$T/out" || fail "fuse: frames without depth not counted: $(head -c 400 "$T/out")"
    mentions "no depth sample within the sensor's 4.5 m: skipped"
    f1=$(ls "$T/zd/depth" | head -n 1)
    py - "$T/zd/depth/$f1" "$T/zd/depth/$(ls "$T/zd/depth" | tail -n 1)" <<'PY'
import shutil, sys
shutil.copy(sys.argv[2], sys.argv[1])
PY
    expect 3 "$B" fuse "$T/zd" --poses groundtruth --out "$T/fuzd0" $small
    mentions "no frame with a pose and depth"
    [ ! -e "$T/fuzd0" ] || fail "fuse of frames without depth left $T/fuzd0 behind"
    # A poses file that no frame's time falls in: its span is named.
    awk '!/^#/ { $1 = sprintf("%.6f", $1 + 1000) } { print }' "$T/seq/groundtruth.txt" >"$T/late.txt"
    expect 3 "$B" fuse "$T/seq" --poses "$T/late.txt" --out "$T/fulate" $small
    mentions "late.txt's poses span t ="
    expect 3 "$B" replay "$T/cut" --out "$T/rpcut" $small
    mentions "frame 1"
    [ "$(grep -vc '^#' "$T/rpcut/trajectory.txt")" = 1 ] || fail "replay stopped by a corrupt frame: no trajectory of the frame before it"
    python3 -c "import json,sys; d=json.load(open(sys.argv[1])); assert d['frames'] == 1 and 'frame 1' in d['input_error'], d" \
        "$T/rpcut/stats.json" || fail "replay stopped by a corrupt frame: stats.json"
    # A repeated depth frame (info's case above): skipped with its pose kept by default,
    # tracked with --repeated track; stats.json echoes the choice and counts it.
    expect 0 "$B" replay "$T/rep" --out "$T/rprep" $small
    grep -q "1 frame repeated the depth before it" "$T/out" || fail "replay does not report the repeat: $(head -c 400 "$T/out")"
    python3 - "$T/rprep" skip <<'PY' || fail "replay of a repeated frame (default)"
import csv, json, sys
d = json.load(open(sys.argv[1] + "/stats.json"))
rows = list(csv.DictReader(open(sys.argv[1] + "/frames.csv")))
assert d["config"]["loop"]["skip_repeated"] is True and d["tracking"]["repeated"] == 1, d["tracking"]
assert [r["state"] for r in rows] == ["first", "tracked", "repeated"], [r["state"] for r in rows]
t = [l.split()[1:] for l in open(sys.argv[1] + "/trajectory.txt") if not l.startswith("#")]
assert t[2] == t[1], t
PY
    expect 0 "$B" replay "$T/rep" --out "$T/rptrack" $small --repeated track
    python3 - "$T/rptrack" <<'PY' || fail "replay --repeated track"
import csv, json, sys
d = json.load(open(sys.argv[1] + "/stats.json"))
rows = list(csv.DictReader(open(sys.argv[1] + "/frames.csv")))
assert d["config"]["loop"]["skip_repeated"] is False and d["tracking"]["repeated"] == 0, d["tracking"]
assert [r["state"] for r in rows] == ["first", "tracked", "tracked"], [r["state"] for r in rows]
PY
    # Every frame tracked, every second one fused (--fuse-every): frames.csv says which,
    # stats.json counts the others and echoes the cadence; 0 is refused by name.
    expect 0 "$B" replay "$T/seq" --out "$T/rpfe" $small --fuse-every 2
    grep -q "1 frame tracked only, not fused" "$T/out" || fail "replay --fuse-every: no summary line: $(head -c 400 "$T/out")"
    python3 - "$T/rpfe" <<'PY' || fail "replay --fuse-every 2"
import csv, json, sys
d = json.load(open(sys.argv[1] + "/stats.json"))
rows = list(csv.DictReader(open(sys.argv[1] + "/frames.csv")))
assert d["config"]["loop"]["fuse_every"] == 2 and d["config"]["loop"]["fuse_every_behind"] == 4, d["config"]["loop"]
assert d["tracking"]["unfused"] == 1 and d["tracking"]["behind"] == 0 and d["tracking"]["tracked"] == 3, d["tracking"]
assert [r["state"] for r in rows] == ["first", "tracked", "tracked"], [r["state"] for r in rows]
assert [r["fused"] for r in rows] == ["1", "0", "1"], [r["fused"] for r in rows]
PY
    expect 2 "$B" replay "$T/seq" --out "$T/rpfe0" $small --fuse-every 0
    mentions "--fuse-every"
    # The sensor's range (--max-depth): the room lies beyond 0.5 m, so no frame has depth
    # there (exit 3, nothing written); 4 m keeps it and is echoed; 0.1 m is refused.
    expect 3 "$B" replay "$T/seq" --out "$T/rpmd" $small --max-depth 0.5
    mentions "within the sensor's 0.5 m, fewer than the 193 a frame needs: skipped"
    [ ! -e "$T/rpmd" ] || fail "replay --max-depth 0.5 left $T/rpmd behind"
    expect 0 "$B" replay "$T/seq" --out "$T/rpmd4" $small --max-depth 4
    py -c "import json,sys; d=json.load(open(sys.argv[1])); assert d['config']['sensor']['max_depth_m'] == 4, d['config']['sensor']" \
        "$T/rpmd4/stats.json" || fail "replay --max-depth 4 not echoed in stats.json"
    expect 2 "$B" replay "$T/seq" --out "$T/rpmd0" $small --max-depth 0.1
    mentions "--max-depth"
    expect 3 "$B" fuse "$T/seq" --poses groundtruth --out "$T/fumd" $small --max-depth 0.5
    mentions "no frame with a pose and depth"
    # A colour repeated alone: the frame's depth is new, so it is tracked, without the
    # colour (an earlier moment's) in the photometric term or the map's colour. With the
    # term on, frames.csv's photo_sharpness is 0 where the term did not run: on that frame
    # (and the next, whose reference it made, if there were one); --repeated track uses it.
    expect 0 "$B" replay "$T/reprgb" --out "$T/rprgb" $small --photometric 0.3 --photometric-weak 0
    grep -q "1 frame repeated only the colour before it" "$T/out" || fail "replay does not report the colour repeat: $(head -c 400 "$T/out")"
    expect 0 "$B" replay "$T/reprgb" --out "$T/rprgbt" $small --photometric 0.3 --photometric-weak 0 --repeated track
    py - "$T/rprgb" "$T/rprgbt" <<'PY' || fail "replay of a repeated colour"
import csv, json, sys
def run(d):
    return json.load(open(d + "/stats.json"))["tracking"], list(csv.DictReader(open(d + "/frames.csv")))
t, rows = run(sys.argv[1])
assert t["repeated"] == 0 and t["colour_repeated"] == 1, t
assert [r["state"] for r in rows] == ["first", "tracked", "tracked"], [r["state"] for r in rows]
assert float(rows[1]["photo_sharpness"]) > 0 and float(rows[2]["photo_sharpness"]) == 0, rows
t, rows = run(sys.argv[2])
assert t["colour_repeated"] == 0 and float(rows[2]["photo_sharpness"]) > 0, (t, rows)
# In every frame (--photometric-weak 0): none is marked as brought in for weak depth.
assert all(r["photo_weak"] == "0" for r in rows) and t["photo_weak"] == 0, (t, rows)
assert json.load(open(sys.argv[2] + "/stats.json"))["config"]["track"]["photo_weak_ratio"] == 0
PY
    # The weak ratio is a share of the largest eigenvalue: above 0.5 is refused by name.
    expect 2 "$B" replay "$T/reprgb" --out "$T/rpweak" $small --photometric-weak 0.7
    mentions "--photometric-weak"
    # fuse at known poses: a repeated depth is not fused (its pose has moved on), unless
    # --repeated fuse; a colour repeated alone is fused without its colour.
    fused_are() { # DIR FRAMES REPEATED COLOUR_REPEATED
        py -c "import json,sys; d=json.load(open(sys.argv[1]+'/stats.json')); assert (d['frames'], d['repeated'], d['colour_repeated']) == tuple(map(int, sys.argv[2:5])), d" "$@"
    }
    expect 0 "$B" fuse "$T/rep" --poses groundtruth --out "$T/furep" $small
    grep -q "1 frame repeated the depth before it byte for byte: not fused" "$T/out" || fail "fuse does not report the repeat: $(head -c 400 "$T/out")"
    fused_are "$T/furep" 2 1 0 || fail "fuse fused a repeated depth"
    expect 0 "$B" fuse "$T/rep" --poses groundtruth --out "$T/furepf" $small --repeated fuse
    fused_are "$T/furepf" 3 0 0 || fail "fuse --repeated fuse did not fuse the repeat"
    expect 0 "$B" fuse "$T/reprgb" --poses groundtruth --out "$T/furgb" $small
    fused_are "$T/furgb" 3 0 1 || fail "fuse of a repeated colour"
    expect 0 "$B" fuse "$T/reprgb" --poses groundtruth --out "$T/furgbf" $small --repeated fuse
    fused_are "$T/furgbf" 3 0 0 || fail "fuse --repeated fuse left a repeated colour out"
    # A frame without a pose is not fused, but its images are still the ones the next
    # frame's are compared with: frame 1's colour, handed on from pose-less frame 0, is
    # stale. (The ground truth starts at frame 1: frame 0 is 33 ms before it, beyond the
    # 20 ms a pose may be carried.)
    cp -r "$T/seq" "$T/nopose"
    repeat_frame "$T/nopose" rgb 1
    awk -v t1="$(awk '!/^#/ {i++; if (i == 2) print $1}' "$T/seq/depth.txt")" '/^#/ || $1 >= t1 - 1e-4' \
        "$T/seq/groundtruth.txt" >"$T/nopose/groundtruth.txt"
    expect 0 "$B" fuse "$T/nopose" --poses groundtruth --out "$T/funopose" $small
    py -c "import json,sys; d=json.load(open(sys.argv[1]+'/stats.json')); assert (d['frames'], d['frames_without_pose'], d['colour_repeated']) == (2, 1, 1), d" \
        "$T/funopose" || fail "fuse: a pose-less frame's colour handed on to the next was not found stale"
fi
# Images too small to track: bad input (3) naming the folder, nothing left behind.
expect 3 "$B" replay "$T/tiny" --out "$T/rtiny"
mentions "tiny: images of 15x15 are too small to track"
[ -e "$T/rtiny" ] && fail "replay of images too small to track left $T/rtiny"
# A lens that takes every pixel off the image is no lens: refused before
# any frame (a usage error from --camera; bad input from camera.txt).
expect 2 "$B" fuse "$T/seq" --poses groundtruth --camera "$fx,$fy,$cx,$cy,1e6,0,0,0,0" --out "$T/fnear" $small
mentions "pixels outside it (not a lens)"
[ -e "$T/fnear" ] && fail "fuse with a lens refused left $T/fnear"
# Frames with one depth sample each (a different pixel in each, so none
# repeats): fused, but too sparse for any surface. fuse writes its outputs
# and says the map has no surface, exit 3.
if [ $SANITIZED = 0 ]; then
    cp -r "$T/seq" "$T/sparse"
    py - "$T/sparse/depth" <<'PY'
import os, struct, sys, zlib
chunk = lambda t, x: struct.pack(">I", len(x)) + t + x + struct.pack(">I", zlib.crc32(t + x) & 0xffffffff)
for k, name in enumerate(sorted(os.listdir(sys.argv[1]))):
    p = os.path.join(sys.argv[1], name)
    w, h = struct.unpack(">II", open(p, "rb").read()[16:24])
    rows = [bytearray(2 * w) for _ in range(h)]
    rows[h // 2][2 * (w // 2 + k):2 * (w // 2 + k) + 2] = struct.pack(">H", 10000)  # 2 m at scale 5000
    raw = b"".join(b"\0" + bytes(r) for r in rows)
    open(p, "wb").write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 16, 0, 0, 0, 0))
                        + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))
PY
    expect 3 "$B" fuse "$T/sparse" --poses groundtruth --out "$T/fnear" $small
    mentions "the 3 frames fused gave the map no surface voxel"
    py -c "import json,sys; assert json.load(open(sys.argv[1]))['no_surface'] is True" "$T/fnear/stats.json" \
        || fail "fuse with no surface: stats.json does not say no_surface"
fi
# Every frame unreadable: skipping them all is not a success.
cp -r "$T/seq" "$T/allcut"
for g in "$T/allcut"/depth/*.png; do head -c 200 "$T/seq/depth/$(basename "$g")" >"$g"; done
expect 3 "$B" info "$T/allcut" --skip-bad-frames
mentions "no frame could be read (3 skipped)"
# Not even a header reads: the same, with the last reason (not that file's error alone).
cp -r "$T/seq" "$T/allbad"
for g in "$T/allbad"/depth/*.png; do echo junk >"$g"; done
expect 3 "$B" info "$T/allbad" --skip-bad-frames
mentions "no frame could be read (3 skipped; the last: "
if [ $SANITIZED = 0 ]; then
    expect 3 "$B" fuse "$T/allcut" --poses groundtruth --out "$T/fuall" $small --skip-bad-frames
    mentions "no frame could be read (3 skipped)"
fi
expect 3 "$B" eval-surface --reference "$T/garbage.txt" --reconstruction "$T/seq/seen.ply"
mentions "$T/garbage.txt"

# record / convert / live / the bitfuse log (docs/formats.md). A recorded
# sequence stands in for the camera.
expect 0 "$B" record --device "$T/seq" --out "$T/rec.bflog" --colour zstd
is_json "$T/rec.stats.json"
python3 - "$T/rec.stats.json" <<'PY' || fail "record stats.json: wrong counts"
import json, sys
d = json.load(open(sys.argv[1]))
assert d["frames"] == 3 and d["dropped"] == 0 and d["captured"] == 3, d
assert d["depth_compression_ratio"] > 1 and d["bytes"] > 0 and d["fps"] > 0, d
PY
# Log -> TUM folder -> compare with the original: depth and colour PNGs
# decode to the same pixels (zstd colour is lossless), same stamps.
expect 0 "$B" convert "$T/rec.bflog" --out "$T/back"
is_json "$T/back/stats.json"
python3 - "$T/seq" "$T/back" <<'PY' || fail "record + convert round trip is not exact"
import sys, zlib, struct
def png_pixels(path):
    # Minimal PNG decoder for non-interlaced 8-bit RGB / 16-bit grey (what
    # the TUM writer produces): concatenated IDAT, inflate, undo filters.
    data = open(path, "rb").read()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    pos, idat, w = 8, b"", 0
    while pos < len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        if kind == b"IHDR": w, h, depth, ctype = struct.unpack(">IIBB", body[:10])
        if kind == b"IDAT": idat += body
        pos += 12 + n
    bpp = (3 if ctype == 2 else 1) * depth // 8
    raw, stride, out, prev = zlib.decompress(idat), w * bpp, [], bytearray(w * bpp)
    for y in range(h):
        f, row = raw[y * (stride + 1)], bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = row[i - bpp] if i >= bpp else 0
            b, c = prev[i], prev[i - bpp] if i >= bpp else 0
            if f == 1: row[i] = (row[i] + a) & 255
            elif f == 2: row[i] = (row[i] + b) & 255
            elif f == 3: row[i] = (row[i] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - c; pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                row[i] = (row[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        out.append(bytes(row)); prev = row
    return b"".join(out)
def listing(d, name):
    return [l.split() for l in open(d + "/" + name) if l.strip() and not l.startswith("#")]
for name in ("depth.txt", "rgb.txt"):
    a, b = listing(sys.argv[1], name), listing(sys.argv[2], name)
    assert len(a) == len(b) == 3, (name, len(a), len(b))
    for (ta, fa), (tb, fb) in zip(a, b):
        assert ta == tb, (name, ta, tb)
        assert png_pixels(sys.argv[1] + "/" + fa) == png_pixels(sys.argv[2] + "/" + fb), (name, fa)
PY
# JPEG colour, --frames, and the log as a sequence for other commands.
expect 0 "$B" record --device "$T/seq" --out "$T/jpeg.bflog" --frames 2
expect 0 "$B" info "$T/jpeg.bflog" --json
python3 -c "import json,sys; d=json.load(open(sys.argv[1])); assert d['kind'] == 'bflog' and d['frames'] == 2, d" \
    "$T/out" || fail "info on a recorded log: wrong kind or frame count"
expect 0 "$B" convert "$T/seq" --out "$T/conv.bflog" --colour jpeg --jpeg-quality 80
is_json "$T/conv.stats.json"
# Through a symbolic link the log goes to the file it names; the link stays.
ln -s conv_target.bflog "$T/conv_link.bflog"
expect 0 "$B" convert "$T/seq" --out "$T/conv_link.bflog"
[ -L "$T/conv_link.bflog" ] && [ -s "$T/conv_target.bflog" ] || fail "convert through a link replaced the link"

# A log cut off mid-frame (a crash) still replays its whole frames.
size=$(wc -c <"$T/rec.bflog")
head -c $((size * 2 / 3)) "$T/rec.bflog" >"$T/cut.bflog"
expect 0 "$B" info "$T/cut.bflog" --json
mentions "recording was cut off"
python3 -c "import json,sys; d=json.load(open(sys.argv[1])); assert 1 <= d['frames'] < 3, d" "$T/out" ||
    fail "cut log: expected 1 or 2 whole frames"
# Bytes appended after a whole log (or its footer cut off): every frame
# reads, and the missing footer is said.
{ cat "$T/rec.bflog"; echo garbage; } >"$T/appended.bflog"
expect 0 "$B" info "$T/appended.bflog"
mentions "its footer is not at the end of the file"
# A flipped byte in the last frame: named by file and frame, exit 3.
cp "$T/rec.bflog" "$T/flip.bflog"
python3 - "$T/flip.bflog" <<'PY'
import sys, struct
b = bytearray(open(sys.argv[1], "rb").read())
at, n = struct.unpack("<QI", b[-24:-12])
last = struct.unpack("<Q", b[at + 8 + 16 * (n - 1):at + 16 + 16 * (n - 1)])[0]
b[last + 400] ^= 0x5A
open(sys.argv[1], "wb").write(b)
PY
expect 3 "$B" info "$T/flip.bflog"
mentions "$T/flip.bflog: frame 2"
mentions "checksum"
# Converted to a folder, the frames before the bad one are indexed and read.
expect 3 "$B" convert "$T/flip.bflog" --out "$T/flipdir"
mentions "the 2 frames before it are in the folder"
# Its stats.json says so, as replay's and fuse's do (there was none).
py -c "import json,sys; d=json.load(open(sys.argv[1])); assert d['frames'] == 2 and 'frame 2' in d['input_error'], d" \
    "$T/flipdir/stats.json" || fail "convert stopped by a bad frame: stats.json without its frames and input_error"
expect 0 "$B" info "$T/flipdir" --json
python3 -c "import json,sys; d=json.load(open(sys.argv[1])); assert d['frames'] == 2, d" "$T/out" ||
    fail "the frames before a bad one are not a readable folder"
# A log's name that is a folder is refused before the work.
mkdir "$T/adir.bflog"
expect 2 "$B" convert "$T/seq" --out "$T/adir.bflog"
mentions "is a folder"
# A log into a missing folder: the folder named before the work (not the log's .partial).
expect 5 "$B" convert "$T/seq" --out "$T/nofolder/x.bflog"
mentions "--out $T/nofolder/x.bflog: the folder $T/nofolder does not exist"
expect 5 "$B" record --device "$T/seq" --out "$T/nofolder/x.bflog"
mentions "--out $T/nofolder/x.bflog: the folder $T/nofolder does not exist"
# Codec options that would be ignored are refused.
expect 2 "$B" convert "$T/seq" --out "$T/codecdir" --colour jpeg
mentions "a TUM folder keeps PNG images"
[ -e "$T/codecdir" ] && fail "a refused convert made its folder"
expect 2 "$B" record --device "$T/seq" --out "$T/q.bflog" --colour zstd --jpeg-quality 50
mentions "needs --colour jpeg"
printf 'not a log' >"$T/text.bflog"
expect 3 "$B" info "$T/text.bflog"
mentions "not a bitfuse log"

# Ctrl-C during a recording keeps a complete, indexed log. The sequence is
# the 3 frames listed 90 times, played at its 30 Hz (--realtime): 3 s.
mkdir "$T/long"
for f in depth rgb; do ln -s "$T/seq/$f" "$T/long/$f"; done
cp "$T/seq/camera.txt" "$T/long/"
python3 - "$T/seq" "$T/long" <<'PY'
import sys
for name in ("depth.txt", "rgb.txt"):
    rows = [l.split() for l in open(sys.argv[1] + "/" + name) if l.strip() and not l.startswith("#")]
    with open(sys.argv[2] + "/" + name, "w") as f:
        for i in range(90):
            f.write("%.6f %s\n" % (1000 + i / 30.0 + (0.001 if name == "rgb.txt" else 0), rows[i % 3][1]))
PY
# interrupt_after S CMD...: CMD in the background (stdout to $T/out, stderr
# to $T/err), SIGINT after S seconds; its exit code in rc.
interrupt_after() {
    local s=$1
    shift
    "$@" >"$T/out" 2>"$T/err" &
    local pid=$!
    sleep "$s"
    kill -INT $pid
    wait $pid
    rc=$?
}
interrupt_after 1 "$B" record --device "$T/long" --out "$T/int.bflog" --realtime
[ $rc = 0 ] || fail "record stopped by SIGINT: exit $rc, expected 0 ($(head -c 300 "$T/err"))"
grep -q "stopped by a signal" "$T/out" || fail "record did not say it was stopped: $(cat "$T/out")"
[ "$(tail -c 8 "$T/int.bflog")" = "BFLOGEND" ] || fail "interrupted log has no footer (not finished)"
python3 -c "import json,sys; d=json.load(open(sys.argv[1])); assert d['interrupted'] and 1 <= d['frames'] < 90, d" \
    "$T/int.stats.json" || fail "interrupted record: stats.json"
expect 0 "$B" info "$T/int.bflog"
# The Ctrl-C checks of convert, replay and fuse must see the signal land
# mid-run on any machine, however fast: $T/gated is $T/long with frame 45's
# depth a named pipe. The command blocks there reading it; the signal comes
# once it has opened the pipe (so long after start-up), then the pipe gets
# the image and the command goes on, sees the stop and ends.
mkdir "$T/gated" "$T/gated/gate"
for f in depth rgb camera.txt rgb.txt; do ln -s "$T/long/$f" "$T/gated/$f"; done
awk '!/^#/ { n++; if (n == 46) $2 = "gate/d.png" } { print }' "$T/long/depth.txt" >"$T/gated/depth.txt"
gate_png=$T/seq/$(awk '!/^#/ {print $2; exit}' "$T/seq/depth.txt")
# interrupt_at_gate CMD...: CMD in the background (stdout $T/out, stderr
# $T/err), SIGINT once it reads the gate, then the gate's image; rc its exit.
# With TWICE=1: a second SIGINT once the first was taken, and no image.
interrupt_at_gate() {
    rm -f "$T/gated/gate/d.png"
    mkfifo "$T/gated/gate/d.png"
    "$@" >"$T/out" 2>"$T/err" &
    local pid=$!
    python3 - "$T/gated/gate/d.png" "$pid" "$gate_png" "${TWICE:-0}" <<'PY' || { kill -9 $pid 2>/dev/null; fail "gate: $(tail -c 300 "$T/err")"; }
import errno, os, signal, sys, time
gate, pid, png, twice = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4] == "1"
deadline = time.time() + 300
while True:  # a writer's open without blocking succeeds once a reader has the pipe open
    try:
        fd = os.open(gate, os.O_WRONLY | os.O_NONBLOCK)
        break
    except OSError as e:
        if e.errno != errno.ENXIO:
            raise
    try:  # the command is the shell's child: ended, it is a zombie until waited for
        ended = open("/proc/%d/stat" % pid).read().rsplit(")", 1)[1].split()[0] == "Z"
    except FileNotFoundError:
        ended = True
    if ended:
        sys.exit("the command ended before it read the gate")
    if time.time() > deadline:
        sys.exit("the command did not read the gate in 300 s")
    time.sleep(0.01)
os.kill(pid, signal.SIGINT)
if twice:  # signals do not queue: the second after the first left the pending sets
    def pending():
        st = dict(l.split(":", 1) for l in open("/proc/%d/status" % pid) if ":" in l)
        return any(int(st[k], 16) & (1 << (signal.SIGINT - 1)) for k in ("SigPnd", "ShdPnd"))
    while pending() and time.time() < deadline:
        time.sleep(0.01)
    os.kill(pid, signal.SIGINT)
    os.close(fd)
    sys.exit(0)
os.set_blocking(fd, True)
os.write(fd, open(png, "rb").read())
os.close(fd)
PY
    wait $pid
    rc=$?
}
# interrupted NAME STATS: the run says it was stopped (stdout and
# stats.json) and ended before the frames after the gate.
interrupted() {
    [ $rc = 0 ] || fail "$1 stopped by SIGINT: exit $rc, expected 0 ($(head -c 300 "$T/err"))"
    grep -q "by a signal" "$T/out" || fail "$1 did not say it was stopped: $(cat "$T/out")"
    python3 -c "import json,sys; d=json.load(open(sys.argv[1])); assert d['interrupted'] and 1 <= d['frames'] <= 46, d" \
        "$2" || fail "$1 stopped by SIGINT: stats.json"
}
# convert too: a complete log of the frames converted.
interrupt_at_gate "$B" convert "$T/gated" --out "$T/cint.bflog"
interrupted convert "$T/cint.stats.json"
[ -e "$T/cint.bflog.partial" ] && fail "convert stopped by SIGINT left its .partial"
expect 0 "$B" info "$T/cint.bflog"
# Ctrl-C during a replay ends the scan, not the program: exit 0, the frames
# before it written (stats.json says interrupted), the store flushed.
interrupt_at_gate "$B" replay "$T/gated" --no-mesh --out "$T/rint" --store "$T/rintS"
interrupted replay "$T/rint/stats.json"
[ -s "$T/rint/trajectory.txt" ] && [ -s "$T/rint/points.ply" ] || fail "interrupted replay: outputs missing"
# Writing them can take seconds: the first Ctrl-C says so at once.
mentions "stopping: the frames so far are being written (a second Ctrl-C abandons them)"
expect 0 "$B" info "$T/rintS"
# A second Ctrl-C ends the program there and then (killed by SIGINT, as the
# default action), and removes the temporary files it had open: replay's
# frames.csv being written, convert's .partial.
TWICE=1 interrupt_at_gate "$B" replay "$T/gated" --no-mesh --out "$T/rint2"
[ $rc = 130 ] || fail "replay after two SIGINTs: exit $rc, expected 130 (killed by SIGINT) ($(tail -c 300 "$T/err"))"
# (the folder it made, with nothing written into it yet, goes too)
[ ! -e "$T/rint2" ] || fail "replay after two SIGINTs left: $(ls -A "$T/rint2")"
# With a store inside it (--store DIR/store) whose first write had not come (--store-every 0:
# only at the end): all of it goes.
TWICE=1 interrupt_at_gate "$B" replay "$T/gated" --no-mesh --out "$T/rint4" --store "$T/rint4/store" --store-every 0
[ $rc = 130 ] && [ ! -e "$T/rint4" ] || fail "replay --store DIR/store after two SIGINTs: exit $rc, left $(find "$T/rint4" 2>&1 | tr '\n' ' ')"
# A folder that was there before stays (empty).
mkdir "$T/rint3"
TWICE=1 interrupt_at_gate "$B" replay "$T/gated" --no-mesh --out "$T/rint3"
[ $rc = 130 ] && [ -d "$T/rint3" ] && [ -z "$(ls -A "$T/rint3")" ] ||
    fail "replay after two SIGINTs into an existing folder: exit $rc, left $(ls -A "$T/rint3" 2>&1)"
TWICE=1 interrupt_at_gate "$B" convert "$T/gated" --out "$T/cint2.bflog"
[ $rc = 130 ] || fail "convert after two SIGINTs: exit $rc, expected 130 ($(tail -c 300 "$T/err"))"
[ ! -e "$T/cint2.bflog.partial" ] && [ ! -e "$T/cint2.bflog" ] || fail "convert after two SIGINTs left $(ls "$T"/cint2*)"
# fuse too: the frames fused before the signal are written.
python3 -c "
for i in range(90): print('%.6f 0 0 0 0 0 0 1' % (1000 + i / 30.0))" >"$T/long_poses.txt"
interrupt_at_gate "$B" fuse "$T/gated" --poses "$T/long_poses.txt" --no-mesh --out "$T/fint"
interrupted fuse "$T/fint/stats.json"
[ -s "$T/fint/points.ply" ] || fail "interrupted fuse: points.ply missing"
# Stopped before any frame was fused (the frames up to the gate have no
# pose): nothing to write and no failure, and no folder left (it said "no
# frame with a pose", exit 3, or died during start-up leaving the folder).
python3 -c "
for i in range(46, 90): print('%.6f 0 0 0 0 0 0 1' % (1000 + i / 30.0))" >"$T/late_poses.txt"
interrupt_at_gate "$B" fuse "$T/gated" --poses "$T/late_poses.txt" --no-mesh --out "$T/fint0"
[ $rc = 0 ] || fail "fuse stopped before any frame: exit $rc, expected 0 ($(head -c 300 "$T/err"))"
grep -q "stopped before any frame was fused: no map written" "$T/out" || fail "fuse stopped early: $(cat "$T/out")"
[ ! -e "$T/fint0" ] || fail "fuse stopped before any frame left its output folder"

# Ctrl-C before any frame with depth came (a camera still dark, 10 s of
# frames without depth at 30 Hz): exit 0 as any Ctrl-C, nothing written,
# no folder left.
mkdir "$T/dark" "$T/dark/depth"
ln -s "$T/seq/rgb" "$T/dark/rgb"
cp "$T/seq/camera.txt" "$T/dark/"
python3 - "$T/seq" "$T/dark" <<'PY'
import struct, sys, zlib
first = [l.split()[1] for l in open(sys.argv[1] + "/depth.txt") if l.strip() and not l.startswith("#")][0]
w, h = struct.unpack(">II", open(sys.argv[1] + "/" + first, "rb").read()[16:24])
chunk = lambda t, d: struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xffffffff)
with open(sys.argv[2] + "/depth/0.png", "wb") as f:  # 16-bit grey, every pixel 0: no depth
    f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 16, 0, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"".join(b"\0" + bytes(2 * w) for _ in range(h)))) + chunk(b"IEND", b""))
rgb = [l.split()[1] for l in open(sys.argv[1] + "/rgb.txt") if l.strip() and not l.startswith("#")]
with open(sys.argv[2] + "/depth.txt", "w") as d, open(sys.argv[2] + "/rgb.txt", "w") as c:
    for i in range(300):
        d.write("%.6f depth/0.png\n" % (1000 + i / 30.0))
        c.write("%.6f %s\n" % (1000.001 + i / 30.0, rgb[i % len(rgb)]))
PY
interrupt_after 1.5 "$B" live --device "$T/dark" --realtime --out "$T/ldark" --no-mesh
[ $rc = 0 ] || fail "live stopped by SIGINT before any depth: exit $rc, expected 0 ($(tail -c 300 "$T/err"))"
grep -q "stopped before any frame with depth: no trajectory or map written" "$T/out" || fail "live stopped early: $(cat "$T/out")"
[ ! -e "$T/ldark" ] || fail "live stopped before any depth left its output folder"

# replay: the full loop; one trajectory line per input frame, stats.json
# with tracking counts and the ATE against the sequence's ground truth.
expect 0 "$B" replay "$T/seq" --out "$T/rp" --view-every 2
is_json "$T/rp/stats.json"
[ "$(grep -vc '^#' "$T/rp/trajectory.txt")" = 3 ] || fail "replay: trajectory.txt has not 3 poses"
[ -s "$T/rp/views/000000.png" ] || fail "replay --view-every 2: no view of frame 0"
grep -q "stats.json,views/ (2 images)}" "$T/out" || fail "replay --view-every 2: the summary does not name views/: $(grep wrote "$T/out")"
python3 -c "import json,sys; d=json.load(open(sys.argv[1])); t=d['tracking']; assert d['frames'] == 3 and t['tracked'] + t['lost'] + t['no_depth'] == 3 and d['ate_m'] is not None, d" \
    "$T/rp/stats.json" || fail "replay stats.json: frames/tracking/ate"
expect 0 "$B" eval-traj "$T/seq/groundtruth.txt" "$T/rp/trajectory.txt" --json
# A second run into the same folder says the first one's files stay.
expect 0 "$B" fuse "$T/seq" --poses groundtruth --out "$T/twice" --no-mesh
expect 0 "$B" fuse "$T/seq" --poses groundtruth --out "$T/twice" --no-mesh
mentions "holds an earlier run's outputs"
# eval-colour: the mesh seen from the run's poses; from poses 100 m away it
# is seen in no frame, which is no score (it printed PSNR nan, exit 0).
expect 0 "$B" eval-colour "$T/rp/mesh.ply" "$T/seq" --trajectory "$T/rp/trajectory.txt"
grep -q "^PSNR [0-9]" "$T/out" || fail "eval-colour: no PSNR: $(cat "$T/out")"
awk '/^#/ {print; next} {$2 += 100; print}' "$T/rp/trajectory.txt" >"$T/away.txt"
# Only the frames where the mesh is seen are in the score's count.
awk '/^#/ {print; next} NR > 2 {$2 += 100} {print}' "$T/rp/trajectory.txt" >"$T/partaway.txt"
expect 0 "$B" eval-colour "$T/rp/mesh.ply" "$T/seq" --trajectory "$T/partaway.txt" --every 1 --json
python3 -c "import json,sys; d=json.load(open(sys.argv[1])); assert d['frames'] >= 1 and d['frames_mesh_unseen'] >= 1 \
    and d['frames'] + d['frames_mesh_unseen'] == len(d['per_frame']) \
    and sum(p['in_score'] for p in d['per_frame']) == d['frames'], d" "$T/out" ||
    fail "eval-colour counts frames where the mesh is not seen: $(head -c 400 "$T/out")"
expect 3 "$B" eval-colour "$T/rp/mesh.ply" "$T/seq" --trajectory "$T/away.txt"
mentions "is seen in none of the"
expect 2 "$B" replay "$T/seq"
mentions "--out is required"
# An option that means nothing beside another is refused, not ignored.
expect 2 "$B" replay "$T/seq" --out "$T/nm" --no-mesh --max-triangles 100
mentions "--max-triangles means nothing with --no-mesh"
expect 2 "$B" fuse "$T/seq" --poses groundtruth --out "$T/nm" --colour off --colour-frames 3
mentions "--colour-frames means nothing with --colour off"
[ -e "$T/nm" ] && fail "a refused combination made its output folder"
# One frame with ground truth: no ATE, and the summary says why (not "no ground truth").
expect 0 "$B" replay "$T/seq" --out "$T/rp1f" --frames 1 --no-mesh
grep -qF "ATE not computed: one frame with a ground-truth pose: an ATE needs two" "$T/out" ||
    fail "replay --frames 1 does not say why there is no ATE: $(grep trajectory "$T/out")"
py -c "import json,sys; d=json.load(open(sys.argv[1])); assert d['ate_m'] is None and 'two' in d['ate_error'], d.get('ate_error')" \
    "$T/rp1f/stats.json" || fail "replay --frames 1: stats.json has no ate_error"
# An --out longer than the system takes: the reason, not just "bad path".
LONG="$T/$(printf 'a%.0s' $(seq 1 4200))"
expect 2 "$B" replay "$T/seq" --out "$LONG"
mentions "a folder path of ${#LONG} characters is too long (at most 4095)"
expect 2 "$B" replay "$T/seq" --out "$T/rp2" --icp-iters 10,x
expect 2 "$B" replay "$T/seq" --out "$T/rp2" --gpu-budget 8 --bricks 5000
mentions "give one"
# --bricks at fusion's own default value is still given.
expect 2 "$B" replay "$T/seq" --out "$T/rp2" --gpu-budget 8 --bricks 1048576
mentions "give one"
# Pools too small for the scene: the scan goes on, and the summary says what
# the map lacks (the per-frame warnings alone scrolled by).
expect 0 "$B" replay "$T/seq" --out "$T/rpfull" --bricks 64 --stream off --no-mesh
grep -q "pools full       requests for .* were dropped: the map lacks$" "$T/out" || fail "pools full: no summary line: $(cat "$T/out")"
py -c "import json,sys; d=json.load(open(sys.argv[1])); assert d['tracking']['pool_full'] > 0 and sum(d['pool_full_drops'].values()) > 0, d['pool_full_drops']" \
    "$T/rpfull/stats.json" || fail "pools full: stats.json"
# fuse too (it has no streaming): the frames fused are kept and written (it
# ended exit 1 with nothing written at the first full pool).
expect 0 "$B" fuse "$T/seq" --poses groundtruth --out "$T/fufull" --bricks 64 --no-mesh
grep -q "pools full       requests for .* were dropped: the map lacks$" "$T/out" || fail "fuse pools full: no summary line: $(cat "$T/out")"
[ -s "$T/fufull/points.ply" ] || fail "fuse with full pools wrote no points.ply"
py -c "import json,sys; d=json.load(open(sys.argv[1])); assert d['pool_full'] > 0 and sum(d['pool_full_drops'].values()) > 0, d" \
    "$T/fufull/stats.json" || fail "fuse pools full: stats.json"
# A pool of one brick: which request wins it is the GPU's atomics' choice,
# so the map holds a little surface (exit 0) or none, and then the pools,
# not the input, are blamed (exit 1).
"$B" fuse "$T/seq" --poses groundtruth --out "$T/fuone" --bricks 1 --no-mesh >"$T/out" 2>"$T/err"
case $? in
0) grep -q "pools full" "$T/out" || fail "fuse --bricks 1 (surface kept): no pools line: $(cat "$T/out")" ;;
1) grep -q "no surface .*the pools dropped what did not fit (--bricks 1 too small?)" "$T/out" ||
       fail "fuse --bricks 1: $(cat "$T/out")"
   mentions "held none of it" ;;
*) fail "fuse --bricks 1: exit $?, expected 0 or 1 ($(head -c 300 "$T/err"))" ;;
esac
expect 3 "$B" replay "$T/missing" --out "$T/rp3"
mentions "$T/missing"
[ ! -e "$T/rp3" ] || fail "replay on a missing input created its output folder"
expect 3 "$B" fuse "$T/missing" --poses groundtruth --out "$T/fu3"
mentions "$T/missing"
[ ! -e "$T/fu3" ] || fail "fuse on a missing input created its output folder"
# Bad values are refused before the GPU opens (it logs "gpu:") and before
# the output folder is made.
for bad in "--ratio -1" "--ratio 100" "--window 7" "--subcache 50 --window 20" "--angle-gate 95" "--frames 0" \
    "--camera fr9" "--init zero"; do
    expect 2 "$B" replay "$T/seq" --out "$T/rp5" $bad
    ! grep -q "gpu:" "$T/err" || fail "replay $bad: the GPU opened before the value was refused"
    [ ! -e "$T/rp5" ] || fail "replay $bad: the output folder was made"
done
mentions "--init takes groundtruth or identity, not 'zero'"
expect 2 "$B" fuse "$T/seq" --poses groundtruth --out "$T/fu5" --ratio=-1
mentions "--ratio: '-1'"
expect 2 "$B" live --device "$T/seq" --out "$T/lv5" --queue 0
expect 2 "$B" record --device "$T/seq" --out "$T/x.bflog" --jpeg-quality 101
# The tracker alone: fused at the true poses, one estimate per frame, the
# first one the true first pose; a sequence without ground truth is refused.
expect 0 "$B" replay "$T/seq" --out "$T/rpgt" --fuse-at-groundtruth --ray-start near --huber 1.5 --noise-weights off \
    --ref-level 0
[ "$(grep -vc '^#' "$T/rpgt/trajectory.txt")" = 3 ] || fail "replay --fuse-at-groundtruth: trajectory.txt has not 3 poses"
python3 - "$T/seq/groundtruth.txt" "$T/rpgt/trajectory.txt" <<'PYEOF' || fail "replay --fuse-at-groundtruth: first pose"
import sys
rows = [[float(x) for x in l.split()] for f in sys.argv[1:] for l in open(f) if l.strip() and l[0] != '#']
gt, est = rows[:len(rows) // 2], rows[len(rows) // 2:]
assert max(abs(a - b) for a, b in zip(gt[0][1:], est[0][1:])) < 1e-6, (gt[0], est[0])
PYEOF
# A frame past the ground truth's end is skipped and counted, not the end of
# the run; stats.json says how the run was made.
cp -r "$T/seq" "$T/seqgt2"
python3 - "$T/seqgt2" <<'PYEOF'
import sys
d = sys.argv[1]
t1 = float([l for l in open(d + "/depth.txt") if l.strip() and l[0] != "#"][1].split()[0])
rows = [l for l in open(d + "/groundtruth.txt") if l.strip() and l[0] != "#" and float(l.split()[0]) <= t1 + 1e-4]
open(d + "/groundtruth.txt", "w").writelines(rows)
PYEOF
expect 0 "$B" replay "$T/seqgt2" --out "$T/rpgt3" --fuse-at-groundtruth --no-mesh
mentions "no ground-truth pose (--fuse-at-groundtruth): skipped"
[ "$(grep -vc '^#' "$T/rpgt3/trajectory.txt")" = 2 ] || fail "replay --fuse-at-groundtruth past the ground truth: not 2 poses"
python3 -c "import json,sys; d=json.load(open(sys.argv[1])); assert d['tracking']['without_groundtruth'] == 1 and \
    d['config']['poses'] == 'track, fused at the ground truth' and d['config']['init'] == 'groundtruth', d['config']" \
    "$T/rpgt3/stats.json" || fail "replay --fuse-at-groundtruth past the ground truth: stats.json"
expect 3 "$B" replay "$T/int.bflog" --out "$T/rpgt2" --fuse-at-groundtruth
mentions "--fuse-at-groundtruth, but the sequence has no ground truth"
[ -e "$T/rpgt2" ] && fail "replay --fuse-at-groundtruth without ground truth made its output folder"
expect 2 "$B" replay "$T/seq" --out "$T/rp4" --ray-start middle
expect 2 "$B" replay "$T/seq" --out "$T/rp4" --huber -1
expect 2 "$B" replay "$T/seq" --out "$T/rp4" --ref-level 3

# live: the same loop on a device (here a recording standing in for one),
# recording what it consumed on the side.
expect 0 "$B" live --device "$T/seq" --out "$T/live" --record "$T/live.bflog"
is_json "$T/live/stats.json"
python3 -c "import json,sys; d=json.load(open(sys.argv[1])); c=d['capture']; assert d['command'] == 'live' and c['captured'] == 3 and c['recorded'] == 3 and c['unread_at_stop'] == 0, d" \
    "$T/live/stats.json" || fail "live stats.json: capture counts"
python3 -c "import json,sys; s=json.load(open(sys.argv[1]))['startup']; assert 0 < s['ready_s'] <= s['first_frame_done_s'] and s['first_frame_ms'] > 0, s" \
    "$T/live/stats.json" || fail "live stats.json: start-up times"
[ "$(grep -vc '^#' "$T/live/trajectory.txt")" = 3 ] || fail "live: trajectory.txt has not 3 poses"
expect 0 "$B" info "$T/live.bflog"
expect 2 "$B" live --out "$T/live2"
mentions "--device is required"
expect 4 "$B" live --device "v4l2:$T/no-such-video" --out "$T/live3"
mentions "$T/no-such-video"
# A recording that is not there is missing input (exit 3), not a missing
# camera (where OpenNI2 is in the build; else the URI names the package).
"$B" live --device "openni2:$T/no-such.oni" --out "$T/live4" >"$T/out" 2>"$T/err"
rc=$?
if grep -q "libopenni2" "$T/err"; then echo "openni2: not in this build, skipped"
else [ "$rc" = 3 ] || fail "live openni2:missing.oni: exit $rc, expected 3"; mentions "$T/no-such.oni: no such .oni file"; fi
[ -e "$T/live4" ] && fail "a refused live run made its output folder"
# One that is there but no recording: bad input too (3), OpenNI2's reason on one line.
printf 'not a recording' >"$T/junk.oni"
"$B" live --device "openni2:$T/junk.oni" --out "$T/live5" >"$T/out" 2>"$T/err"
rc=$?
if ! grep -q "libopenni2" "$T/err"; then
    [ "$rc" = 3 ] || fail "live openni2:junk.oni: exit $rc, expected 3"
    mentions "OpenNI2 cannot play $T/junk.oni (not an OpenNI recording, or a damaged one): "
    [ "$(wc -l <"$T/err")" = 1 ] && ! grep -q "$(printf '\t')" "$T/err" || fail "live openni2:junk.oni: not one line: $(cat -A "$T/err")"
fi
# Bad command lines and devices.
expect 2 "$B" record --device "$T/seq" --out "$T/x.ply"
mentions "--out must name a .bflog file"
expect 2 "$B" record --out "$T/x.bflog"
mentions "--device is required"
expect 2 "$B" convert "$T/seq" --out "$T/x.bflog" --colour png
mentions "--colour takes jpeg, zstd or none"
expect 3 "$B" record --device "$T/missing" --out "$T/x.bflog"
mentions "$T/missing"
expect 4 "$B" record --device "v4l2:$T/no-such-video" --out "$T/x.bflog"
mentions "$T/no-such-video"
# Writing over what is being read is refused before anything is opened, and
# a conversion that fails leaves the log already at its --out as it was.
cp "$T/rec.bflog" "$T/self.bflog"
sum0=$(md5sum <"$T/self.bflog")
expect 2 "$B" convert "$T/self.bflog" --out "$T/self.bflog"
mentions "which is being read"
expect 2 "$B" record --device "$T/self.bflog" --out "$T/self.bflog"
mentions "which is being read"
expect 2 "$B" live --device "$T/self.bflog" --out "$T/selflive" --record "$T/self.bflog"
mentions "which is being read"
[ "$(md5sum <"$T/self.bflog")" = "$sum0" ] || fail "a log written over itself changed"
expect 2 "$B" convert "$T/seq" --out "$T/seq/"
mentions "which is being read"
expect 2 "$B" replay "$T/seq" --out "$T/seq"
mentions "which is being read"
expect 3 "$B" convert "$T/cut" --out "$T/self.bflog"
mentions "$(ls "$T/cut/depth" | head -n 2 | tail -n 1)"
[ "$(md5sum <"$T/self.bflog")" = "$sum0" ] || fail "a failed conversion replaced the log at its --out"
[ -e "$T/self.bflog.partial" ] && fail "a failed conversion left its partial log"
# A recording is not written over unless asked (one that fails part-way
# would replace it with fewer frames), and a folder holding a sequence is
# not converted into (a failure part-way would mix two).
expect 2 "$B" record --device "$T/seq" --out "$T/self.bflog"
mentions "--overwrite"
expect 2 "$B" live --device "$T/seq" --out "$T/lvx" --record "$T/self.bflog"
mentions "--overwrite"
[ "$(md5sum <"$T/self.bflog")" = "$sum0" ] || fail "a refused recording changed the log at its --out"
expect 2 "$B" live --device "$T/seq" --out "$T/x" --overwrite
mentions "--overwrite needs --record"
expect 0 "$B" record --device "$T/seq" --out "$T/self.bflog" --overwrite --frames 2
[ "$(md5sum <"$T/self.bflog")" = "$sum0" ] && fail "record --overwrite did not replace the log"
# Over an earlier log, a recording that fails before its first frame leaves
# it and its stats.json as they were.
sum2=$(md5sum <"$T/self.bflog")
st2=$(md5sum <"$T/self.stats.json")
cp -r "$T/seq" "$T/cut0"
first=$(awk '!/^#/ {print $2; exit}' "$T/cut0/depth.txt")
head -c 300 "$T/seq/$first" >"$T/cut0/$first"
expect 3 "$B" record --device "$T/cut0" --out "$T/self.bflog" --overwrite
[ "$(md5sum <"$T/self.bflog")" = "$sum2" ] || fail "a recording that failed at its first frame replaced the log"
[ "$(md5sum <"$T/self.stats.json")" = "$st2" ] || fail "a recording that failed at its first frame replaced stats.json"
expect 0 "$B" convert "$T/seq" --out "$T/tumcopy"
sum1=$(md5sum <"$T/tumcopy/depth.txt")
for f in depth.txt rgb; do
    mkdir -p "$T/tumpart" && : >"$T/tumpart/$f"
    expect 2 "$B" convert "$T/self.bflog" --out "$T/tumpart"
    mentions "holds a sequence already ($f)"
    rm -rf "$T/tumpart"
done
expect 2 "$B" convert "$T/self.bflog" --out "$T/tumcopy"
[ "$(md5sum <"$T/tumcopy/depth.txt")" = "$sum1" ] || fail "a refused conversion changed the folder at its --out"
# A mesh that cannot be written (a folder in its place): exit 5, the summary
# names the failure instead of claiming the file, stats.json says so.
mkdir -p "$T/meshfail/mesh.ply/x"
expect 5 "$B" replay "$T/seq" --out "$T/meshfail" --frames 5
grep -q "not written      .*mesh.ply" "$T/out" || fail "replay with an unwritable mesh: no summary naming it: $(head -c 400 "$T/out")"
grep -q "^  wrote" "$T/out" && fail "replay with an unwritable mesh claims it wrote its files"
grep -q "not written      .*mesh.ply.*(the other outputs are written)" "$T/out" || fail "one failure: $(grep 'not written' "$T/out")"
# Two outputs that cannot be written: the summary does not claim the others were.
mkdir -p "$T/twofail/mesh.ply/x" "$T/twofail/trajectory.txt/x"
expect 5 "$B" replay "$T/seq" --out "$T/twofail" --frames 5
grep -q "not written      .*trajectory.txt.*, and 1 other output (the warnings above)" "$T/out" ||
    fail "two failures: $(grep 'not written' "$T/out")"
py -c "import json,sys; m = json.load(open(sys.argv[1]))['mesh']; assert m['file'] is None and 'mesh.ply' in m['error'], m" \
    "$T/meshfail/stats.json" || fail "replay with an unwritable mesh: stats.json's mesh does not say so"
# synth at another size keeps 640x480's field of view by default, as render does.
expect 0 "$B" synth --trajectory "$T/seq/groundtruth.txt" --frames 2 --size 160x120 --noise none --data "$T/nodata" \
    --out "$T/synth160"
[ "$(cat "$T/synth160/camera.txt")" = "131.25 131.25 79.5 59.5 5000" ] ||
    fail "synth --size 160x120's default camera: $(cat "$T/synth160/camera.txt")"
# view names a folder that is no store before it looks for a window.
mkdir -p "$T/notastore/x"
env -u DISPLAY "$B" view --map "$T/notastore" --exit-after 1 >"$T/out" 2>"$T/err"
[ $? = 3 ] || fail "view of a folder that is no store: not exit 3"
mentions "not a scene store"
# At another size the board's default cameras keep their field of view (a
# 9x6 board at 160x120 "did not fit"); options that change nothing are refused.
expect 0 "$B" synth --board 9x6 --views 2 --size 160x120 --depth-size 160x120 --out "$T/smallboard"
expect 2 "$B" synth --trajectory "$T/traj.txt" --frames 2 --scale 2 --out "$T/scaled"
mentions "--scale scales a MESH.ply scene"
expect 2 "$B" synth --trajectory "$T/traj.txt" --frames 2 --noise none --seed 5 --out "$T/seeded"
mentions "--seed seeds the noise"
# Not over a sequence (its frames past the new count would stay, unlisted),
# and rooms:N takes a count.
expect 2 "$B" synth --trajectory "$T/traj.txt" --frames 2 --out "$T/seq"
mentions "holds a sequence already"
# Nor over a run's outputs: its stats.json (an --expect baseline) would be
# replaced by the sequence's (synth and convert went on, exit 0).
st_rp=$(md5sum <"$T/rp/stats.json")
expect 2 "$B" synth --trajectory "$T/traj.txt" --frames 2 --size 32x24 --out "$T/rp"
mentions "--out $T/rp holds an earlier run's outputs (stats.json)"
expect 2 "$B" convert "$T/seq" --out "$T/rp"
mentions "--out $T/rp holds an earlier run's outputs (stats.json)"
[ "$(md5sum <"$T/rp/stats.json")" = "$st_rp" ] || fail "a refused synth or convert changed a run's stats.json"
[ -e "$T/rp/depth.txt" ] && fail "a refused synth or convert wrote a sequence among a run's outputs"
# A run's outputs not into another sequence's folder: its stats.json (synth's)
# was replaced and the run's files mixed with its frames.
cp -r "$T/seq" "$T/otherseq"
st_os=$(md5sum <"$T/otherseq/stats.json")
expect 2 "$B" replay "$T/seq" --out "$T/otherseq" --frames 2 --no-mesh
mentions "--out $T/otherseq holds a sequence already (depth.txt)"
expect 2 "$B" fuse "$T/seq" --poses groundtruth --out "$T/otherseq" --no-mesh
mentions "--out $T/otherseq holds a sequence already (depth.txt)"
[ "$(md5sum <"$T/otherseq/stats.json")" = "$st_os" ] || fail "a refused replay or fuse changed another sequence's stats.json"
[ -e "$T/otherseq/trajectory.txt" ] && fail "a refused replay or fuse wrote into another sequence's folder"
expect 2 "$B" synth --trajectory "$T/traj.txt" --frames 1 --size 32x24 --seed -1 --out "$T/negseed"
mentions "--seed: '-1' is below 0"
expect 2 "$B" synth --scene rooms:-1 --trajectory "$T/traj.txt" --frames 1 --size 32x24 --out "$T/rooms_neg"
mentions "rooms:N takes a count"
[ -e "$T/rooms_neg/depth.txt" ] && fail "synth rooms:-1 wrote a sequence"
# A board that does not fit, or shared data that is not there: exit 2, no folder.
expect 2 "$B" synth --board 64x64 --views 2 --size 160x120 --out "$T/bigboard"
mentions "does not fit"
[ -e "$T/bigboard" ] && fail "synth --board that does not fit left its folder"
# Not over an earlier demo (its frames past the new count would stay, unlisted).
expect 0 "$B" demo --frames 3 --no-gpu --out "$T/demo-twice"
before=$(cd "$T/demo-twice" && find . -type f | sort | xargs md5sum | md5sum)
expect 2 "$B" demo --frames 2 --no-gpu --out "$T/demo-twice"
mentions "--out $T/demo-twice holds an earlier run (seq/depth.txt)"
[ "$(cd "$T/demo-twice" && find . -type f | sort | xargs md5sum | md5sum)" = "$before" ] ||
    fail "a refused demo changed the earlier run's files"
st_seq=$(md5sum <"$T/seq/stats.json")
expect 2 "$B" demo --frames 2 --no-gpu --out "$T/seq"
mentions "--out $T/seq holds a sequence already (depth.txt)"
[ "$(md5sum <"$T/seq/stats.json")" = "$st_seq" ] || fail "a refused demo changed a sequence's stats.json"
expect 3 "$B" demo --data "$T/no-such-data" --no-gpu --out "$T/demo-nodata"
mentions "$T/no-such-data"
[ -e "$T/demo-nodata" ] && fail "demo with a missing --data made its folder"
# A mesh there that does not read: exit 3 naming it, and nothing left behind.
mkdir -p "$T/baddata/meshes" && echo junk >"$T/baddata/meshes/bunny.ply"
expect 3 "$B" demo --data "$T/baddata" --no-gpu --out "$T/demo-baddata"
mentions "bunny.ply"
[ -e "$T/demo-baddata" ] && fail "demo with an unreadable mesh in --data left $(ls "$T/demo-baddata")"
# An environment setting that is no value of its own is warned about.
BITFUSE_LOG=loud BITFUSE_THREADS=many "$B" --version >"$T/out" 2>"$T/err" || fail "--version with bad settings failed"
mentions "BITFUSE_LOG='loud' is not"
mentions "BITFUSE_THREADS='many' is not"
n_on=$(getconf _NPROCESSORS_ONLN)
mentions "threads: $((n_on < 64 ? n_on : 64)) used" # not a number: all cores online, as unset
# An option that means nothing without another is refused, not ignored.
expect 2 "$B" replay "$T/seq" --out "$T/x" --view-period 0
mentions "--view-period needs --view"
expect 2 "$B" replay "$T/seq" --out "$T/x" --store-every 5
mentions "--store-every needs --store STORE"
expect 2 "$B" eval-surface --reference "$T/seq/scene.ply" --reconstruction "$T/seq/scene.ply" --every 2
mentions "--every needs --depth SEQUENCE"
[ -e "$T/x" ] && fail "a usage error made the output folder"
for c in demo synth replay fuse info record convert live eval-traj eval-surface devices render; do
    expect 0 "$B" $c --help
    grep -q "^usage: bitfuse $c" "$T/out" || fail "$c --help: no usage line"
    grep -q -- "--help" "$T/out" || fail "$c --help: the help does not list --help"
done
grep -q -- "--ratio R .*default 2" <("$B" replay --help) || fail "replay --help: no --ratio default 2"
grep -q -- "--ratio R .*default 1" <("$B" fuse --help) || fail "fuse --help: no --ratio default 1"

# Pools larger than the device binds (lavapipe: 128 MiB a binding) are
# refused naming the option that sized them, not only fusion's fields.
"$B" replay "$T/seq" --out "$T/bigpool" --no-mesh --gpu-budget 4096 >"$T/out" 2>"$T/err"
rc=$?
if [ $rc = 2 ]; then
    mentions "--gpu-budget sizes those pools"
    [ -e "$T/bigpool" ] && fail "a refused pool size left its output folder"
elif [ $rc != 0 ]; then
    fail "replay --gpu-budget 4096: exit $rc, expected 2 (the pools refused) or 0 (a device that binds them)"
fi

# Under a file-size limit (ulimit -f): lavapipe keeps device memory in files,
# so pools past the limit are refused by name (they killed the program with
# SIGXFSZ, or SIGBUS with the signal ignored); a file output past it fails as
# a write (exit 5, EFBIG), its temporary file removed.
if "$B" devices 2>/dev/null | grep -qi "llvmpipe\|lavapipe"; then
    (ulimit -f 2048; exec "$B" replay "$T/seq" --out "$T/fsize" --no-mesh) >"$T/out" 2>"$T/err"
    rc=$?
    [ $rc = 1 ] || fail "replay under ulimit -f 2048: exit $rc, expected 1 ($(head -c 300 "$T/err"))"
    mentions "exceed the file-size limit (ulimit -f"
fi
expect 0 "$B" replay "$T/seq" --out "$T/fsrun" --no-mesh --store "$T/fsS"
(ulimit -f 1; exec "$B" export "$T/fsS" --out "$T/fsize.ply") >"$T/out" 2>"$T/err"
rc=$?
[ $rc = 5 ] || fail "export under ulimit -f 1: exit $rc, expected 5 ($(head -c 300 "$T/err"))"
mentions "File too large"
ls "$T" | grep -q "fsize.ply" && fail "export under ulimit -f 1 left $(ls "$T" | grep fsize.ply)"

finish test_cli.sh
