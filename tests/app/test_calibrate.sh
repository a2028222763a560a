#!/usr/bin/env bash
# bitfuse calibrate as a user runs it: checkerboard views rendered by
# synth --board at known intrinsics, distortion and T_colour_depth are
# calibrated and compared with the truth (calib_compare.py --check: focal
# lengths within 0.5%, principal points within 2 px, the transform within
# 2 mm and 0.2 degrees); images without a board, a wrong command line and
# malformed calibration files are refused with the right exit code and
# the file named, before any output is made; replay and fuse read a folder
# with the file's depth camera and scale its colour camera to the frames,
# and a log through the file's depth lens as a folder is read.
# Usage: test_calibrate.sh path/to/bitfuse path/to/calib_compare.py
set -u
B=$1
CMP=$2
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
. "$(dirname "$0")/common.sh"
# The interpreter itself, not a version manager's shim script: under the
# sanitizer build every shell the shim starts loads the sanitizer runtime.
PY=$(python3 -c 'import sys; print(sys.executable)')

# 12 views of a 9x6 board; the colour lens has radial distortion.
expect 0 "$B" synth --board 9x6 --square 0.04 --views 12 --distortion 0.1,-0.2 --seed 7 --out "$T/b"
[ -f "$T/b/truth.json" ] && [ -f "$T/b/ir/011.png" ] || fail "synth --board did not write truth.json and ir/011.png"

# Colour and depth: every board found, the truth recovered.
expect 0 "$B" calibrate --board 9x6 --square 0.04 "$T"/b/colour/*.png --depth "$T"/b/ir/*.png --out "$T/calib.json"
mentions "colour 12/12"
mentions "board found"
grep -qF "T_colour_depth" "$T/out" || fail "the summary has no T_colour_depth: $(head -c 400 "$T/out")"
"$PY" "$CMP" "$T/calib.json" "$T/b/truth.json" --check >"$T/cmp" 2>&1 || fail "calibration off the truth: $(cat "$T/cmp")"
# synth's boards stay within the middle half of the image: the lens beyond
# them is extrapolated, and the warning says by how much it is uncertain.
mentions "colour: the boards reached"
mentions "beyond them the lens is a guess"
"$PY" -c "
import json, sys
d = json.load(open(sys.argv[1]))
for cam in ('colour', 'depth'):
    c = d[cam]
    assert 0.3 < c['coverage'] < 0.8 and c['extrapolation_px'] > 1 and c['dist'][4] != 0, c
" "$T/calib.json" || fail "calib.json's coverage: $(head -c 600 "$T/calib.json")"
# Two radial terms: k3 held at 0, the truth still met within the boards.
expect 0 "$B" calibrate --board 9x6 --square 0.04 "$T"/b/colour/*.png --depth "$T"/b/ir/*.png --radial 2 --out "$T/r2.json"
"$PY" "$CMP" "$T/r2.json" "$T/b/truth.json" --check >"$T/cmp" 2>&1 || fail "--radial 2 off the truth: $(cat "$T/cmp")"
"$PY" -c "import json, sys; d = json.load(open(sys.argv[1])); assert d['colour']['dist'][4] == 0 == d['depth']['dist'][4]" \
    "$T/r2.json" || fail "--radial 2 fitted k3"
expect 2 "$B" calibrate --board 9x6 --square 0.04 "$T"/b/colour/*.png --radial 4 --out "$T/r4.json"
mentions "--radial"

# --depth first and the colour images after '--'; --json: the calibration and every image.
expect 0 "$B" calibrate --board 9x6 --square 0.04 --depth "$T"/b/ir/*.png -- "$T"/b/colour/*.png --out "$T/c2.json" --json
"$PY" -c "
import json, sys
d = json.load(open(sys.argv[1]))
assert d['calibration']['views'] == 12 and 'T_colour_depth' in d['calibration'], d['calibration']
assert len(d['images']) == 24 and all(i['found'] for i in d['images']), d['images']
" "$T/out" || fail "calibrate --json: $(head -c 400 "$T/out")"
cmp -s "$T/calib.json" "$T/c2.json" || fail "the same views in another argument order gave another calibration"

# Colour alone: no depth camera, no transform in the file.
expect 0 "$B" calibrate --board 9x6 --square 0.04 "$T"/b/colour/*.png --out "$T/colour.json"
# --out written before the glob names the first image: refused, the image kept.
first=$(ls "$T"/b/colour/*.png | head -n 1)
sum0=$(md5sum <"$first")
# The same image three times is one view, not three: refused, each repeat named.
expect 3 "$B" calibrate --board 9x6 --square 0.04 "$T/b/colour/000.png" "$T/b/colour/000.png" "$T/b/colour/000.png" \
    --out "$T/same.json"
mentions "at 1 different places"
mentions "shows the board where $T/b/colour/000.png does"
[ -e "$T/same.json" ] && fail "calibrate from one view repeated wrote a file"
# A repeat among distinct views is left out of the fit: the calibration of
# 000 000 001 002 is that of 000 001 002, and it counts 3 views.
expect 0 "$B" calibrate --board 9x6 --square 0.04 "$T"/b/colour/00[0-2].png --out "$T/three.json"
expect 0 "$B" calibrate --board 9x6 --square 0.04 "$T/b/colour/000.png" "$T"/b/colour/00[0-2].png --out "$T/rep.json"
mentions "it adds nothing and is left out"
cmp -s "$T/three.json" "$T/rep.json" || fail "a repeated view changed the calibration (weighed twice)"
# PNG images through pipes (no seeking back) give the same calibration.
expect 0 "$B" calibrate --board 9x6 --square 0.04 <(cat "$T/b/colour/000.png") <(cat "$T/b/colour/001.png") \
    <(cat "$T/b/colour/002.png") --out "$T/piped.json"
cmp -s "$T/three.json" "$T/piped.json" || fail "images through pipes gave another calibration"
# Depth views in another order than the colour ones: written, but warned.
expect 0 "$B" calibrate --board 9x6 --square 0.04 "$T"/b/colour/00[0-3].png \
    --depth "$T/b/ir/001.png" "$T/b/ir/000.png" "$T/b/ir/003.png" "$T/b/ir/002.png" --out "$T/swapped.json"
mentions "are the --depth images in the same order as the colour ones"
expect 2 "$B" calibrate --board 9x6 --square 0.04 --out "$T"/b/colour/*.png
mentions "is not a JSON file"
[ "$(md5sum <"$first")" = "$sum0" ] || fail "calibrate wrote over an image it read"
"$PY" -c "import json,sys; d=json.load(open(sys.argv[1])); assert 'depth' not in d and 'T_colour_depth' not in d" \
    "$T/colour.json" || fail "a colour-only calibration has a depth camera"

# Images without a board: exit 3, naming them; nothing written.
"$PY" - "$T" <<'PY'
import struct, sys, zlib
def png(path, w, h, value):
    raw = b"".join(b"\0" + bytes([value]) * w for _ in range(h))
    chunk = lambda t, d: struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xffffffff)
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0))
                + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))
for i in range(3):
    png("%s/blank%d.png" % (sys.argv[1], i), 640, 480, 40 + 60 * i)
png("%s/small.png" % sys.argv[1], 32, 24, 128)
PY
expect 3 "$B" calibrate --board 9x6 --square 0.04 "$T"/blank*.png --out "$T/none.json"
mentions "found in 0 of 3 colour images"
mentions "blank0.png"
mentions "blank2.png"
[ ! -e "$T/none.json" ] || fail "a failed calibration wrote its --out"
# Two views with the board and one without: still too few.
expect 3 "$B" calibrate --board 9x6 --square 0.04 "$T/b/colour/000.png" "$T/b/colour/001.png" "$T/blank0.png" \
    --out "$T/none.json"
mentions "found in 2 of 3"
mentions "not in: $T/blank0.png"
# Images of different sizes, an unreadable one.
expect 3 "$B" calibrate --board 9x6 --square 0.04 "$T/blank0.png" "$T/small.png" "$T/blank1.png" --out "$T/none.json"
mentions "small.png: 32x24"
expect 3 "$B" calibrate --board 9x6 --square 0.04 "$T/missing.png" --out "$T/none.json"
mentions "missing.png"

# Bad command lines: exit 2.
expect 2 "$B" calibrate --board 9 --square 0.04 "$T/blank0.png" --out "$T/none.json"
mentions "COLSxROWS"
expect 2 "$B" calibrate --board 9x6 "$T/blank0.png" --out "$T/none.json"
mentions "--square is required"
expect 2 "$B" calibrate --board 9x6 --square 0.04 "$T"/b/colour/00*.png --depth "$T/b/ir/000.png" --out "$T/none.json"
mentions "1 depth images for 10 colour images"
expect 2 "$B" calibrate --board 9x6 --square 0.04 --depth "$T"/b/ir/*.png --out "$T/none.json"
mentions "no colour images"
expect 0 "$B" calibrate --help
grep -qF -- "--depth IMAGES..." "$T/out" || fail "calibrate --help does not show --depth"

# replay --calibration: a malformed file is refused by name and field
# before the sequence opens or the output folder is made (exit 3).
bad() { printf '%s' "$2" >"$T/$1.json"; }
bad nofx '{"colour": {"width": 640, "height": 480, "fy": 525, "cx": 319.5, "cy": 239.5}}'
bad negfx '{"colour": {"width": 640, "height": 480, "fx": -1, "fy": 525, "cx": 319.5, "cy": 239.5}}'
bad inf '{"colour": {"width": 640, "height": 480, "fx": 525, "fy": 1e999, "cx": 319.5, "cy": 239.5}}'
bad notjson '{"colour": '
"$PY" -c "
import json, sys
d = json.load(open(sys.argv[1])); del d['T_colour_depth']
json.dump(d, open(sys.argv[2], 'w'))" "$T/calib.json" "$T/noT.json"
for f in nofx:colour.fx negfx:colour.fx inf:colour.fy notjson:"not JSON" noT:T_colour_depth; do
    name=${f%%:*}
    field=${f#*:}
    expect 3 "$B" replay "$T/no-such-seq" --out "$T/rp_$name" --calibration "$T/$name.json"
    mentions "$T/$name.json"
    mentions "$field"
    [ ! -e "$T/rp_$name" ] || fail "replay --calibration $name.json made the output folder"
done
expect 3 "$B" live --device "$T/no-such-seq" --out "$T/lv" --calibration "$T/nofx.json"
mentions "colour.fx: missing"
[ ! -e "$T/lv" ] || fail "live --calibration nofx.json made the output folder"
expect 3 "$B" replay "$T/no-such-seq" --out "$T/rp_x" --calibration "$T/absent.json"
mentions "absent.json"
expect 2 "$B" replay "$T/no-such-seq" --out "$T/rp_x" --calibration "$T/calib.json" --camera fr1
mentions "both give the depth camera"

# A sequence of 160x120 frames: a 640x480 depth camera does not fit it
# (exit 3, no output); one of its size replaces its pinhole, and
# stats.json's config echoes the file.
printf '0 0 0 0 0 0 0 1\n1 0.002 0 0 0 0 0 1\n' >"$T/traj.txt"
mkdir "$T/nodata"
expect 0 "$B" synth --trajectory "$T/traj.txt" --frames 2 --size 160x120 --camera 131.25,131.25,79.5,59.5 \
    --data "$T/nodata" --out "$T/seq"
expect 3 "$B" replay "$T/seq" --out "$T/rp_size" --calibration "$T/calib.json"
mentions "the depth camera is 640x480, the depth images of $T/seq are 160x120"
mentions "(camera from the depth camera of $T/calib.json)"
[ ! -e "$T/rp_size" ] || fail "replay with a calibration of another size made the output folder"
"$PY" -c "
import json, sys
d = json.load(open(sys.argv[1]))
for cam in ('colour', 'depth'):
    c = d[cam]
    c.update(width=160, height=120, fx=c['fx'] / 4, fy=c['fy'] / 4, cx=(c['cx'] + 0.5) / 4 - 0.5, cy=(c['cy'] + 0.5) / 4 - 0.5)
json.dump(d, open(sys.argv[2], 'w'))" "$T/calib.json" "$T/small.json"
expect 0 "$B" replay "$T/seq" --out "$T/rp" --calibration "$T/small.json" --no-mesh
mentions "small.json: the colour camera's lens is uncertain by" # calibrate's warning, kept with the file
"$PY" -c "
import json, sys
c = json.load(open(sys.argv[1]))['config']['calibration']
f = json.load(open(sys.argv[2]))
assert c['depth']['fx'] == f['depth']['fx'] and c['T_colour_depth'] == f['T_colour_depth'], c
" "$T/rp/stats.json" "$T/small.json" || fail "stats.json does not echo --calibration: $(head -c 400 "$T/rp/stats.json")"
# The file's depth camera, lens included, is the one the folder's depth is
# read with (a lens the calibration found, or none).
"$PY" -c "
import json, sys
cam = json.load(open(sys.argv[1]))['camera']
d = json.load(open(sys.argv[2]))['depth']
assert cam['fx'] == d['fx'] and cam['cy'] == d['cy'], cam
want = d['dist'] if any(d['dist']) else None
assert cam['undistorted'] == want, (cam, d['dist'])
" "$T/rp/stats.json" "$T/small.json" || fail "replay --calibration does not read the depth with the file's depth camera: $(head -c 400 "$T/rp/stats.json")"
# A colour camera calibrated at its own size (640x360) where the frames'
# colour is 160x120: scaled to the frames, each axis by its own ratio
# (1/4 and 1/3), pixel centres kept, and said so; the echo holds the
# scaled camera.
"$PY" -c "
import json, sys
d = json.load(open(sys.argv[1]))
d['colour'].update(width=640, height=360, fx=500.0, fy=510.0, cx=320.2, cy=180.7)
json.dump(d, open(sys.argv[2], 'w'))" "$T/small.json" "$T/mixed.json"
expect 0 "$B" replay "$T/seq" --out "$T/rp_mixed" --calibration "$T/mixed.json" --no-mesh
mentions "the colour camera is 640x360, the frames' colour 160x120: its intrinsics scaled to them"
"$PY" -c "
import json, sys
c = json.load(open(sys.argv[1]))['config']['calibration']['colour']
want = dict(fx=500.0 / 4, fy=510.0 / 3, cx=(320.2 + 0.5) / 4 - 0.5, cy=(180.7 + 0.5) / 3 - 0.5)
for k, v in want.items():
    assert abs(c[k] - v) < 1e-9, (k, c, want)
assert (c['width'], c['height']) == (160, 120), c
" "$T/rp_mixed/stats.json" ||
    fail "replay does not scale a colour camera of another size: $(head -c 600 "$T/rp_mixed/stats.json")"
# fuse takes the file as replay does: the same checks, the colour camera
# scaled, the file echoed.
expect 3 "$B" fuse "$T/seq" --poses groundtruth --out "$T/fu_size" --calibration "$T/calib.json"
mentions "the depth camera is 640x480, the depth images of $T/seq are 160x120"
[ ! -e "$T/fu_size" ] || fail "fuse with a calibration of another size made the output folder"
expect 2 "$B" fuse "$T/seq" --poses groundtruth --out "$T/fu_x" --calibration "$T/small.json" --camera fr1
mentions "both give the depth camera"
expect 0 "$B" fuse "$T/seq" --poses groundtruth --out "$T/fu" --calibration "$T/mixed.json" --no-mesh
"$PY" -c "
import json, sys
c = json.load(open(sys.argv[1]))['calibration']
assert (c['colour']['width'], c['colour']['height']) == (160, 120) and abs(c['colour']['fy'] - 510.0 / 3) < 1e-9, c
" "$T/fu/stats.json" || fail "fuse does not take --calibration: $(head -c 600 "$T/fu/stats.json")"
# A log gives its depth as the camera's lens made it (a folder is read
# through the file's lens): the loop takes the lens out itself, so the log
# and the folder give the same map, bit for bit, and without the lens a
# different one. live --record keeps the frames as the camera gave them:
# its log, replayed through the lens, gives that map again.
"$PY" -c "
import json, sys
d = json.load(open(sys.argv[1]))
d['depth']['dist'] = [0.15, -0.1, 0.0, 0.0, 0.0]
json.dump(d, open(sys.argv[2], 'w'))
d['depth']['dist'] = [0.0] * 5
json.dump(d, open(sys.argv[3], 'w'))" "$T/small.json" "$T/lens.json" "$T/nolens.json"
expect 0 "$B" convert "$T/seq" --out "$T/seq.bflog"
expect 0 "$B" replay "$T/seq" --out "$T/lf" --calibration "$T/lens.json" --no-mesh
expect 0 "$B" replay "$T/seq.bflog" --out "$T/ll" --calibration "$T/lens.json" --no-mesh
mentions "the depth camera's lens is taken out of each frame's depth"
expect 0 "$B" replay "$T/seq.bflog" --out "$T/ln" --calibration "$T/nolens.json" --no-mesh
expect 0 "$B" live --device "$T/seq.bflog" --out "$T/lv" --calibration "$T/lens.json" --no-mesh --record "$T/rec.bflog"
# (The recording's colour is JPEG: its map is compared without colour,
# and tracked without it.)
nocolour="--colour off --photometric 0 --reloc-features 0"
expect 0 "$B" replay "$T/rec.bflog" --out "$T/lr" --calibration "$T/lens.json" --no-mesh $nocolour
expect 0 "$B" replay "$T/seq" --out "$T/lfg" --calibration "$T/lens.json" --no-mesh $nocolour
"$PY" -c "
import json, sys
dig = [json.load(open(p + '/stats.json'))['map_digest'] for p in sys.argv[1:]]
folder, log, nolens, live, recorded, folder_geometry = dig
assert log == folder, ('log through the lens', log, folder)
assert nolens != folder, ('the lens changes nothing', nolens)
assert live == folder, ('live', live, folder)
assert recorded == folder_geometry, ('its recording', recorded, folder_geometry)
# stats.json says which lens was taken out, whoever took it.
for p in sys.argv[1:3] + sys.argv[4:5]:
    cam = json.load(open(p + '/stats.json'))['camera']
    assert cam['undistorted'] == [0.15, -0.1, 0.0, 0.0, 0.0] and cam['undistort_max_shift_px'] > 0, (p, cam)
" "$T/lf" "$T/ll" "$T/ln" "$T/lv" "$T/lr" "$T/lfg" ||
    fail "a log's depth is not read through the calibration's lens as a folder's is"
# fuse and eval-motion read a log through the lens too: the same map, the
# same motion as from the folder.
expect 0 "$B" fuse "$T/seq" --poses groundtruth --out "$T/ff" --calibration "$T/lens.json" --no-mesh
expect 0 "$B" fuse "$T/seq.bflog" --poses groundtruth --out "$T/fl" --calibration "$T/lens.json" --no-mesh
expect 0 "$B" eval-motion "$T/seq" groundtruth --span 1 --calibration "$T/lens.json" --json
cp "$T/out" "$T/em_folder.json"
expect 0 "$B" eval-motion "$T/seq.bflog" groundtruth --span 1 --calibration "$T/lens.json" --json
"$PY" -c "
import json, sys
a, b = (json.load(open(p + '/stats.json'))['map_digest'] for p in sys.argv[1:3])
assert a == b, ('fuse', a, b)
m, n = (json.load(open(p)) for p in sys.argv[3:5])
assert m['pairs'] == n['pairs'] and m['trajectories'] == n['trajectories'], (m, n)
" "$T/ff" "$T/fl" "$T/em_folder.json" "$T/out" || fail "fuse or eval-motion does not read a log through the lens"
# A lens that folds the image over itself within its corners is refused
# before any output, for a log as for a folder (exit 3, the file named).
"$PY" -c "
import json, sys
d = json.load(open(sys.argv[1]))
d['depth']['dist'] = [-1.0, 0.0, 0.0, 0.0, 0.0]
json.dump(d, open(sys.argv[2], 'w'))" "$T/small.json" "$T/fold.json"
for seq in "$T/seq" "$T/seq.bflog"; do
    expect 3 "$B" replay "$seq" --out "$T/rp_fold" --calibration "$T/fold.json"
    mentions "fold.json"
    [ ! -e "$T/rp_fold" ] || fail "replay of $seq with a folding lens made the output folder"
done
expect 0 "$B" replay --help
grep -qF -- "--calibration FILE" "$T/out" || fail "replay --help does not show --calibration"

finish test_calibrate.sh
