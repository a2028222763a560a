#!/usr/bin/env bash
# bitfuse calibrate-depth as a user runs it: a synthetic sequence (Kinect v1
# noise, no fixed pattern) calibrated from its ground truth gives
# multipliers within the noise of 1; one spoiled by a known pattern fixed in
# the image (bands along x) gives that pattern's inverse; replay and fuse
# take the file (stats.json echoes it), live --record keeps the frames
# uncorrected; a missing trajectory, a malformed
# file and one for another image size are refused with the exit code and
# the file named, before any output is made.
# Usage: test_calibrate_depth.sh path/to/bitfuse
set -u
B=$1
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
. "$(dirname "$0")/common.sh"

# 61 frames of 160x120 turning and moving about the procedural room.
py - "$T/traj.txt" <<'PY'
import math, sys
with open(sys.argv[1], "w") as f:
    for i in range(61):
        s = i / 60.0
        yaw, pitch = -0.6 + 1.2 * s, 0.15 * math.sin(6 * s)
        cy, sy, cp, sp = math.cos(yaw / 2), math.sin(yaw / 2), math.cos(pitch / 2), math.sin(pitch / 2)
        # q = q_yaw (about y) * q_pitch (about x)
        qw, qx, qy, qz = cy * cp, cy * sp, sy * cp, -sy * sp
        f.write("%.6f %.4f %.4f %.4f %.6f %.6f %.6f %.6f\n" % (i / 30.0, -0.3 + 0.6 * s, 0.1 * math.sin(9 * s),
                0.2 * math.cos(5 * s), qx, qy, qz, qw))
PY
mkdir "$T/nodata"
expect 0 "$B" synth --trajectory "$T/traj.txt" --frames 61 --size 160x120 --camera 131.25,131.25,79.5,59.5 \
    --data "$T/nodata" --out "$T/seq"

# From the ground truth: no pattern to find, multipliers near 1.
expect 0 "$B" calibrate-depth "$T/seq" --poses groundtruth --cell 8 --out "$T/flat.json"
grep -qF "pairs" "$T/out" || fail "the summary does not count pairs: $(cat "$T/out")"
# Not over what it reads: a file of the sequence, the poses, or a pipe.
sum0=$(md5sum <"$T/seq/depth.txt")
expect 2 "$B" calibrate-depth "$T/seq" --poses groundtruth --out "$T/seq/depth.txt"
mentions "which is being read"
[ "$(md5sum <"$T/seq/depth.txt")" = "$sum0" ] || fail "calibrate-depth wrote over the sequence's depth.txt"
cp "$T/seq/groundtruth.txt" "$T/gt.txt"
expect 2 "$B" calibrate-depth "$T/seq" --poses "$T/gt.txt" --out "$T/gt.txt"
mentions "which is being read"
mkfifo "$T/pipe.json"
expect 5 "$B" calibrate-depth "$T/seq" --poses groundtruth --out "$T/pipe.json"
mentions "not a regular file"
[ -p "$T/pipe.json" ] || fail "calibrate-depth replaced a pipe at its --out"
# A replay's lost frames keep the last good pose: frames 20-29 held at frame
# 19's are no measurement of where their depth was taken, and are left out.
py - "$T/seq/groundtruth.txt" "$T/held.txt" <<'PY'
import sys
rows = [l.split() for l in open(sys.argv[1]) if l.strip() and not l.startswith("#")]
for i in range(20, 30):
    rows[i][1:] = rows[19][1:]
open(sys.argv[2], "w").write("".join(" ".join(r) + "\n" for r in rows))
PY
expect 0 "$B" calibrate-depth "$T/seq" --poses "$T/held.txt" --cell 8 --out "$T/held.json" --json
mentions "frames left out: their pose repeats the one before"
py -c "import json,sys; d=json.load(open(sys.argv[1])); assert d['frames_held_pose'] > 0 and d['pairs'] < 27, d" \
    "$T/out" || fail "calibrate-depth used held poses: $(head -c 300 "$T/out")"
py - "$T/flat.json" <<'PY' || fail "calibrate-depth of unspoiled depth is not flat"
import json, sys
d = json.load(open(sys.argv[1]))
m = [v for row in d["multipliers"] for v in row]
assert d["grid_w"] == 20 and d["grid_h"] == 15 and len(m) == 300, d
assert d["pairs"] == 27, d["pairs"]
# What the synthetic Kinect v1 depth leaves (its disparity steps of 1/8 px
# are errors that follow depth, and so the room's layout in the image):
# about 1.2 per mille RMS over 27 pairs of 160x120 frames. A pattern like
# the bands below is 5.7 per mille RMS.
rms = (sum((v - 1) ** 2 for v in m) / len(m)) ** 0.5
assert rms < 2e-3 and max(abs(v - 1) for v in m) < 6e-3, (rms, min(m), max(m))
PY

# The same depth spoiled by a pattern fixed in the image: its inverse comes back.
cp -r "$T/seq" "$T/spoiled"
py - "$T/spoiled" <<'PY'
import math, os, struct, sys, zlib
# 16-bit grey PNGs: read, multiply, write (no imaging library needed).
def read_png(p):
    b = open(p, "rb").read()
    pos, idat, w, h = 8, b"", 0, 0
    while pos < len(b):
        n, t = struct.unpack(">I4s", b[pos:pos + 8])
        d = b[pos + 8:pos + 8 + n]
        if t == b"IHDR": w, h = struct.unpack(">II", d[:8]); assert d[8] == 16 and d[9] == 0
        if t == b"IDAT": idat += d
        pos += 12 + n
    raw, rows, prev = zlib.decompress(idat), [], bytearray(2 * w)
    for y in range(h):
        f, line = raw[y * (2 * w + 1)], bytearray(raw[y * (2 * w + 1) + 1:(y + 1) * (2 * w + 1)])
        for i in range(len(line)):
            a = line[i - 2] if i >= 2 else 0
            up, c = prev[i], prev[i - 2] if i >= 2 else 0
            if f == 1: line[i] = (line[i] + a) & 255
            elif f == 2: line[i] = (line[i] + up) & 255
            elif f == 3: line[i] = (line[i] + (a + up) // 2) & 255
            elif f == 4:
                pa, pb, pc = abs(up - c), abs(a - c), abs(a + up - 2 * c)
                pr = a if pa <= pb and pa <= pc else up if pb <= pc else c
                line[i] = (line[i] + pr) & 255
        rows.append(list(struct.unpack(">%dH" % w, bytes(line))))
        prev = line
    return w, h, rows
def write_png(p, w, h, rows):
    raw = b"".join(b"\0" + struct.pack(">%dH" % w, *r) for r in rows)
    chunk = lambda t, d: struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xffffffff)
    open(p, "wb").write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 16, 0, 0, 0, 0))
                        + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))
d = os.path.join(sys.argv[1], "depth")
for n in sorted(os.listdir(d)):
    w, h, rows = read_png(os.path.join(d, n))
    for y in range(h):
        for x in range(w):
            v = rows[y][x]
            if v: rows[y][x] = min(65535, round(v * (1 + 0.008 * math.sin(2 * math.pi * 2 * (x + 0.5) / w))))
    write_png(os.path.join(d, n), w, h, rows)
PY
expect 0 "$B" calibrate-depth "$T/spoiled" --poses groundtruth --cell 8 --out "$T/bands.json" --json
py - "$T/bands.json" "$T/out" <<'PY' || fail "calibrate-depth did not find the bands"
import json, math, sys
d = json.load(open(sys.argv[1]))
out = json.load(open(sys.argv[2]))
assert out["command"] == "calibrate-depth" and out["pairs"] == 27 and out["rms_after"] < out["rms_before"], out
assert out["config"]["cell_px"] == 8 and out["config"]["gaps"] == [15, 30] and out["config"]["iterations"] == 10, out
w, m = d["grid_w"], d["multipliers"]
# Each column of cells against the inverse of the bands at its centre (x
# 8 i + 3.5), both divided by their mean over the image (pairs of frames
# do not see the image's mean).
col = [sum(r[i] for r in m) / len(m) for i in range(w)]
want = [1 / (1 + 0.008 * math.sin(2 * math.pi * 2 * (8 * i + 4) / 160)) for i in range(w)]
mc, mw = sum(col) / w, sum(want) / w
err = max(abs(c / mc - v / mw) for c, v in zip(col, want))
amp = max(abs(v / mw - 1) for v in want)
print("bands %.2f per mille, left %.2f" % (1000 * amp, 1000 * err))
assert err < 0.3 * amp, (err, amp)
PY

# replay and fuse take it; stats.json echoes it.
expect 0 "$B" replay "$T/spoiled" --out "$T/rp" --depth-correction "$T/bands.json" --no-mesh --frames 10
py -c "
import json, sys
c = json.load(open(sys.argv[1]))['depth_correction']
assert c['file'] == sys.argv[2] and c['grid_w'] == 20 and c['min_multiplier'] < 0.995 < 1.005 < c['max_multiplier'], c
" "$T/rp/stats.json" "$T/bands.json" || fail "replay's stats.json does not echo --depth-correction"
# The file says where its pattern lies: in frames read as a pinhole
# ("undistorted": null). The same frames read through a lens put that
# pattern in other pixels: refused before any output (exit 3), the lenses
# named. A file that does not say (written before the field) is taken.
py -c "
import json, sys
d = json.load(open(sys.argv[1]))
assert 'undistorted' in d and d['undistorted'] is None, d.get('undistorted', 'absent')
del d['undistorted']
json.dump(d, open(sys.argv[2], 'w'))" "$T/bands.json" "$T/unsaid.json" || fail "calibrate-depth does not say which lens its frames had"
expect 3 "$B" replay "$T/spoiled" --out "$T/rp_lens" --depth-correction "$T/bands.json" --no-mesh --frames 3 \
    --camera 131.25,131.25,79.5,59.5,0.05,0,0,0,0
mentions "the pattern lies in other pixels"
[ ! -e "$T/rp_lens" ] || fail "replay with a depth correction made for other pixels left an output folder"
expect 3 "$B" fuse "$T/spoiled" --poses groundtruth --out "$T/fu_lens" --depth-correction "$T/bands.json" --no-mesh \
    --camera 131.25,131.25,79.5,59.5,0.05,0,0,0,0
mentions "made from frames read through no lens"
expect 0 "$B" replay "$T/spoiled" --out "$T/rp_unsaid" --depth-correction "$T/unsaid.json" --no-mesh --frames 3 \
    --camera 131.25,131.25,79.5,59.5,0.05,0,0,0,0
# With --calibration the depth is read through the file's depth camera, its
# lens taken out, as replay --calibration reads it; a log's lens is taken
# out by the command itself, so a folder and its log give the same file,
# bit for bit, which says the lens. replay of the log through that
# calibration takes it, and refuses the file made without the lens.
py -c "
import json, sys
cam = dict(width=160, height=120, fx=131.25, fy=131.25, cx=79.5, cy=59.5, rms_px=0)
json.dump({'format': 'bitfuse-calibration', 'version': 1, 'colour': dict(cam, dist=[0] * 5),
           'depth': dict(cam, dist=[0.05, 0, 0, 0, 0]),
           'T_colour_depth': {'R': [1, 0, 0, 0, 1, 0, 0, 0, 1], 't': [0, 0, 0]}, 'rms_px': 0, 'views': 0},
          open(sys.argv[1], 'w'))" "$T/lensd.json"
expect 0 "$B" convert "$T/spoiled" --out "$T/spoiled.bflog"
expect 0 "$B" calibrate-depth "$T/spoiled" --poses groundtruth --cell 8 --calibration "$T/lensd.json" --out "$T/lf.json"
expect 0 "$B" calibrate-depth "$T/spoiled.bflog" --poses groundtruth --cell 8 --calibration "$T/lensd.json" \
    --out "$T/ll.json"
py -c "
import json, sys
f, l = (json.load(open(p)) for p in sys.argv[1:3])
assert f['undistorted'] == [0.05, 0, 0, 0, 0] and l['undistorted'] == f['undistorted'], (f['undistorted'], l['undistorted'])
assert f['multipliers'] == l['multipliers'], 'the log and the folder through the lens give other patterns'
" "$T/lf.json" "$T/ll.json" || fail "calibrate-depth --calibration does not read a log through the lens as a folder"
expect 0 "$B" replay "$T/spoiled.bflog" --out "$T/rp_ll" --calibration "$T/lensd.json" --depth-correction "$T/ll.json" \
    --no-mesh --frames 3
expect 3 "$B" replay "$T/spoiled.bflog" --out "$T/rp_lb" --calibration "$T/lensd.json" \
    --depth-correction "$T/bands.json" --no-mesh --frames 3
mentions "the pattern lies in other pixels"
# live --record keeps the frames as the camera gave them, not corrected: its
# log replayed with the same file gives live's map (corrected twice, it
# would not). The recording's colour is JPEG, so both leave colour out.
nocolour="--colour off --photometric 0 --reloc-features 0"
expect 0 "$B" live --device "$T/spoiled" --out "$T/lv" --depth-correction "$T/bands.json" --no-mesh --frames 10 \
    --record "$T/rec.bflog" $nocolour
expect 0 "$B" replay "$T/rec.bflog" --out "$T/lvr" --depth-correction "$T/bands.json" --no-mesh $nocolour
py -c "
import json, sys
a, b = (json.load(open(p + '/stats.json'))['map_digest'] for p in sys.argv[1:3])
assert a == b, (a, b)
" "$T/lv" "$T/lvr" || fail "live --record does not keep the camera's frames: its log replayed with the file differs"
# With the file the noise weight's exponent defaults to 2.5 (its far samples are corrected);
# without it, 3; a given --noise-exp stays what it says either way.
noise_exp_is() { # DIR E
    py -c "import json,sys; e=json.load(open(sys.argv[1]+'/stats.json'))['config']['track']['noise_weight_exp']; assert abs(e - float(sys.argv[2])) < 1e-6, e" "$1" "$2"
}
noise_exp_is "$T/rp" 2.5 || fail "replay --depth-correction: the noise exponent is not 2.5"
expect 0 "$B" replay "$T/spoiled" --out "$T/rp3" --depth-correction "$T/bands.json" --noise-exp 3 --no-mesh --frames 3
noise_exp_is "$T/rp3" 3 || fail "replay --depth-correction --noise-exp 3: the given exponent was not kept"
expect 0 "$B" replay "$T/spoiled" --out "$T/rpraw" --no-mesh --frames 3
noise_exp_is "$T/rpraw" 3 || fail "replay without --depth-correction: the noise exponent is not 3"
expect 0 "$B" fuse "$T/spoiled" --poses groundtruth --out "$T/fu" --depth-correction "$T/bands.json"
expect 0 "$B" fuse "$T/spoiled" --poses groundtruth --out "$T/fu_raw"
# The map fused from the corrected depth explains that depth better than
# the map fused as the depth came explains it (the bands, 16 mm at 2 m,
# smear surfaces seen from several places).
expect 0 "$B" eval-surface --reference "$T/fu/mesh.ply" --depth "$T/spoiled" --depth-correction "$T/bands.json" \
    --every 2 --pixel-step 2 --json
cp "$T/out" "$T/ev_fixed.json"
expect 0 "$B" eval-surface --reference "$T/fu_raw/mesh.ply" --depth "$T/spoiled" --every 2 --pixel-step 2 --json
py - "$T/ev_fixed.json" "$T/out" "$T/bands.json" <<'PY' || fail "eval-surface --depth-correction"
import json, sys
a, b = json.load(open(sys.argv[1])), json.load(open(sys.argv[2]))
assert a["depth"]["depth_correction"] == sys.argv[3] and b["depth"]["depth_correction"] is None, (a["depth"], b["depth"])
ma, mb = a["accuracy"]["median_m"], b["accuracy"]["median_m"]
print("depth to the map, median: %.2f mm corrected, %.2f mm as it came" % (1e3 * ma, 1e3 * mb))
assert ma < 0.85 * mb, (ma, mb)
PY
expect 2 "$B" eval-surface --reference "$T/fu/mesh.ply" --reconstruction "$T/fu/mesh.ply" --depth-correction "$T/bands.json"
py -c "import json,sys; assert json.load(open(sys.argv[1]))['depth_correction']['file'] == sys.argv[2]" \
    "$T/fu/stats.json" "$T/bands.json" || fail "fuse's stats.json does not echo --depth-correction"
py -c "import json,sys; assert json.load(open(sys.argv[1]))['depth_correction'] is None" "$T/fu_raw/stats.json" ||
    fail "fuse's stats.json without --depth-correction does not say null"

# Refusals: exit 3, the file named, no output folder.
expect 3 "$B" calibrate-depth "$T/seq" --poses "$T/absent.txt" --out "$T/x.json"
mentions "absent.txt"
[ ! -e "$T/x.json" ] || fail "calibrate-depth with a missing trajectory wrote a file"
expect 3 "$B" calibrate-depth "$T/seq" --poses groundtruth --frames 14 --out "$T/x.json"
mentions "no pair of frames"
# No depth within range where the pairs overlap: no cell measured, no file.
expect 3 "$B" calibrate-depth "$T/seq" --poses groundtruth --max-depth 0.3 --out "$T/x.json"
mentions "no cell of the"
[ ! -e "$T/x.json" ] || fail "calibrate-depth with no cell measured wrote a file"
expect 2 "$B" calibrate-depth "$T/seq" --poses groundtruth --stride 4 --out "$T/x.json"
mentions "must divide"
printf '{"format": "bitfuse-depth-correction", "version": 1, "width": 160}' >"$T/broken.json"
expect 3 "$B" replay "$T/seq" --out "$T/rp_broken" --depth-correction "$T/broken.json"
mentions "$T/broken.json"
mentions "height: missing"
[ ! -e "$T/rp_broken" ] || fail "replay with a broken depth correction made the output folder"
py -c "
import json, sys
d = json.load(open(sys.argv[1]))
d.update(width=320, height=240, cell_px=16)
json.dump(d, open(sys.argv[2], 'w'))" "$T/flat.json" "$T/big.json"
expect 3 "$B" replay "$T/seq" --out "$T/rp_big" --depth-correction "$T/big.json" --no-mesh
mentions "the depth correction is for 320x240 depth images, the sequence's are 160x120"
[ ! -e "$T/rp_big" ] || fail "replay with a depth correction of another size left an output folder"
expect 3 "$B" fuse "$T/seq" --poses groundtruth --out "$T/fu_big" --depth-correction "$T/big.json" --no-mesh
mentions "320x240"
expect 0 "$B" calibrate-depth --help
grep -qF -- "--poses P" "$T/out" || fail "calibrate-depth --help does not show --poses"

finish test_calibrate_depth.sh
