#!/usr/bin/env bash
# bitfuse calibrate as a user runs it: checkerboard views rendered by
# synth --board at known intrinsics, distortion and T_colour_depth are
# calibrated and compared with the truth (calib_compare.py --check: focal
# lengths within 0.5%, principal points within 2 px, the transform within
# 2 mm and 0.2 degrees); images without a board, a wrong command line and
# malformed calibration files are refused with the right exit code and
# the file named, before any output is made.
# Usage: test_calibrate.sh path/to/bitfuse path/to/calib_compare.py
set -u
B=$1
CMP=$2
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
fails=0
fail() { echo "FAIL: $*"; fails=$((fails + 1)); }
expect() {
    local want=$1
    shift
    "$@" >"$T/out" 2>"$T/err"
    local rc=$?
    [ "$rc" = "$want" ] || fail "exit $rc, expected $want: $* ($(head -c 400 "$T/err"))"
}
mentions() { grep -qF -- "$1" "$T/err" || fail "stderr does not mention '$1': $(head -c 400 "$T/err")"; }
command -v python3 >/dev/null || { echo "no python3"; exit 77; }

# 12 views of a 9x6 board; the colour lens has radial distortion.
expect 0 "$B" synth --board 9x6 --square 0.04 --views 12 --distortion 0.1,-0.2 --seed 7 --out "$T/b"
[ -f "$T/b/truth.json" ] && [ -f "$T/b/ir/011.png" ] || fail "synth --board did not write truth.json and ir/011.png"

# Colour and depth: every board found, the truth recovered.
expect 0 "$B" calibrate --board 9x6 --square 0.04 "$T"/b/colour/*.png --depth "$T"/b/ir/*.png --out "$T/calib.json"
mentions "colour 12/12"
mentions "board found"
grep -qF "T_colour_depth" "$T/out" || fail "the summary has no T_colour_depth: $(head -c 400 "$T/out")"
python3 "$CMP" "$T/calib.json" "$T/b/truth.json" --check >"$T/cmp" 2>&1 || fail "calibration off the truth: $(cat "$T/cmp")"

# --depth first and the colour images after '--'; --json: the calibration and every image.
expect 0 "$B" calibrate --board 9x6 --square 0.04 --depth "$T"/b/ir/*.png -- "$T"/b/colour/*.png --out "$T/c2.json" --json
python3 -c "
import json, sys
d = json.load(open(sys.argv[1]))
assert d['calibration']['views'] == 12 and 'T_colour_depth' in d['calibration'], d['calibration']
assert len(d['images']) == 24 and all(i['found'] for i in d['images']), d['images']
" "$T/out" || fail "calibrate --json: $(head -c 400 "$T/out")"
cmp -s "$T/calib.json" "$T/c2.json" || fail "the same views in another argument order gave another calibration"

# Colour alone: no depth camera, no transform in the file.
expect 0 "$B" calibrate --board 9x6 --square 0.04 "$T"/b/colour/*.png --out "$T/colour.json"
python3 -c "import json,sys; d=json.load(open(sys.argv[1])); assert 'depth' not in d and 'T_colour_depth' not in d" \
    "$T/colour.json" || fail "a colour-only calibration has a depth camera"

# Images without a board: exit 3, naming them; nothing written.
python3 - "$T" <<'PY'
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

echo "$fails failed"
[ "$fails" = 0 ]
