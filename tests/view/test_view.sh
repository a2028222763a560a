#!/usr/bin/env bash
# The viewer window under Xvfb (docs/view.md): replay --view draws the map
# while scanning and its screenshot, read back from the swapchain, equals
# the headless ray-cast PNG of the same frame (--view-every) byte for byte;
# --exit-after ends the scan as closing the window does, everything kept;
# bitfuse view of a map, a mesh and particles equals bitfuse render's image
# of the same view byte for byte; no display is a clear exit 4.
# Skips (77) without a display or a device that presents to it; ctest runs
# it under its own Xvfb (with_xvfb.sh).
# Usage: test_view.sh path/to/bitfuse path/to/png_compare.py
set -u
B=$1
CMP=$2
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
. "$(dirname "$0")/../app/common.sh" # expect, mentions, fail, py, finish

[ -n "${DISPLAY:-}" ] || { echo "skip: no display (run under with_xvfb.sh)"; exit 77; }

# A 12-frame synthetic sequence at 160x120 (half a second to make).
py - "$T/traj.txt" <<'PY'
import sys, math
with open(sys.argv[1], "w") as f:
    for i in range(14):
        a = 0.003 * i
        f.write("%.6f %.6f 0 0 0 %.6f 0 %.6f\n" % (1305031098.6659 + i / 30.0, 0.004 * i, math.sin(a / 2), math.cos(a / 2)))
PY
mkdir "$T/nodata"
"$B" synth --trajectory "$T/traj.txt" --frames 12 --size 160x120 --camera 131.25,131.25,79.5,59.5 \
    --data "$T/nodata" --noise none --out "$T/seq" >/dev/null 2>&1 || { echo "FAIL: synth"; exit 1; }

# 1. replay --view: the window follows the camera; after 5 frames shown the
# scan stops as a closed window stops it, and writes everything.
"$B" replay "$T/seq" --out "$T/rep" --store "$T/rep/store" --view-every 1 --no-mesh --view --exit-after 5 \
    --overlay off --screenshot "$T/shot_replay.png" >"$T/out" 2>"$T/err"
rc=$?
# Skip where the machine cannot show a window at all (the messages of
# view_open and gpu/ for those cases); any other exit 4 is a failure.
if [ $rc = 4 ] && grep -qE "cannot present|no display|cannot make a Vulkan surface|no usable Vulkan device|no Vulkan device|cannot load GLFW" "$T/err"; then
    echo "skip: no presentation: $(grep -m1 error "$T/err")"
    exit 77
fi
[ $rc = 0 ] || fail "replay --view: exit $rc: $(head -c 600 "$T/err")"
grep -q "vulkan validation" "$T/err" && fail "replay --view: validation messages: $(grep -m1 'vulkan validation' "$T/err")"
frames=$(py -c "import json,sys; print(json.load(open(sys.argv[1]))['frames'])" "$T/rep/stats.json" 2>/dev/null)
[ "$frames" = 5 ] || fail "replay --view --exit-after 5 handled '$frames' frames, not 5"
[ "$(grep -vc '^#' "$T/rep/trajectory.txt")" = 5 ] || fail "trajectory.txt: not 5 poses"
[ -e "$T/rep/store/store.json" ] || fail "the store was not written at the stop"
# The same ray-cast's bytes on both sides (recon_render_view at the frame's
# pose, the window's size is the sequence's): tolerance 0. A wrong byte
# order, row pitch, scaling or a stale image all break it.
py "$CMP" "$T/shot_replay.png" "$T/rep/views/000004.png" 0 0 || fail "the window's screenshot differs from views/000004.png"
# A scan that ends before --exit-after frames were shown still leaves its screenshot (the map at
# its end, from the window's camera), and says so.
"$B" replay "$T/seq" --out "$T/rep2" --no-mesh --view --exit-after 50 --overlay off \
    --screenshot "$T/shot_end.png" >"$T/out" 2>"$T/err" || fail "replay --view --exit-after 50: exit $?: $(head -c 400 "$T/err")"
grep -q "the scan ended after 12 frames shown; $T/shot_end.png is the map at its end" "$T/err" ||
    fail "no word of the early end: $(grep -v '^  ' "$T/err" | head -c 400)"
py -c "import sys; d=open(sys.argv[1],'rb').read(24); assert d[:8]==b'\x89PNG\r\n\x1a\n' and int.from_bytes(d[16:20],'big')==160, d" \
    "$T/shot_end.png" || fail "the early end's screenshot is not a 160-wide PNG"

# 2. bitfuse view of what bitfuse render draws (the stored map, a sphere
# mesh voxelised into it and a sheet of particles, in front of the scan's
# last camera) against bitfuse render's headless image of the same view:
# the same scene loading (app/scene.c) and the same cast, so tolerance 0.
# (The mesh and the particles are in the image: 2,391 pixels, 12%, differ
# from the map's alone, measured once; test_render_cli checks that render
# draws them, so a view leaving them out fails the comparison.)
P=$(grep -v '^#' "$T/rep/trajectory.txt" | tail -1 | cut -d' ' -f2-8)
py "$(dirname "$0")/../icosphere.py" "$T/sphere.off" 0.08 2 # an icosphere of radius 0.08 m, subdivided twice
py - "$P" "$T/sphere.off" "$T/p.ply" >"$T/mesh_pose" <<'PY'
import sys, math
tx, ty, tz, qx, qy, qz, qw = map(float, sys.argv[1].split())
R = [[1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
     [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
     [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)]]
def world(v):  # camera to world
    return tuple(sum(R[r][c] * v[c] for c in range(3)) + (tx, ty, tz)[r] for r in range(3))
pts = [world((0.05 + 0.02 * i, -0.1 + 0.02 * j, 0.7)) for i in range(8) for j in range(8)]
with open(sys.argv[3], "w") as o:
    o.write("ply\nformat ascii 1.0\nelement vertex %d\nproperty float x\nproperty float y\nproperty float z\n"
            "end_header\n" % len(pts))
    for p in pts: o.write("%.6f %.6f %.6f\n" % p)
print("%.6f %.6f %.6f 0 0 0 1" % world((-0.1, 0.0, 0.8)))  # the sphere's centre: left of the view's middle
PY
SCENE=(--map "$T/rep" --mesh "$T/sphere.off" --mesh-pose "$(cat "$T/mesh_pose")" --particles "$T/p.ply"
       --particle-radius 0.01 --pose "$P" --size 160x120 --camera 131.25,131.25,79.5,59.5)
"$B" render "${SCENE[@]}" --out "$T/render.png" >"$T/out" 2>"$T/err" || fail "render: $(head -c 600 "$T/err")"
"$B" view "${SCENE[@]}" --exit-after 2 --overlay off --screenshot "$T/shot_view.png" >"$T/out" 2>"$T/err"
rc=$?
[ $rc = 0 ] || fail "view: exit $rc: $(head -c 600 "$T/err")"
grep -q "vulkan validation" "$T/err" && fail "view: validation messages: $(grep -m1 'vulkan validation' "$T/err")"
py "$CMP" "$T/shot_view.png" "$T/render.png" 0 0 || fail "view's screenshot differs from bitfuse render's image"

# 2b. No pose: the whole scene, its detail from that view. A box 20 x 20 x 8 m
# is seen from 31 m back along -z (the rays reach past the 13.1 m default
# far plane), its near face a centred square of 21 px at 40x30 (a third of
# the image), drawn at the level that view needs (not "too large" from a
# camera at the origin, which sat on its face: level 7 on lavapipe).
py - >"$T/box.off" <<'PY'
h, t = 10.0, 8.0
v = [(-h, -h, 0), (h, -h, 0), (h, h, 0), (-h, h, 0), (-h, -h, t), (h, -h, t), (h, h, t), (-h, h, t)]
f = [(0, 2, 1), (0, 3, 2), (4, 5, 6), (4, 6, 7), (0, 1, 5), (0, 5, 4), (1, 2, 6), (1, 6, 5), (2, 3, 7), (2, 7, 6),
     (3, 0, 4), (3, 4, 7)]
print("\n".join(["OFF", "8 12 0"] + ["%g %g %g" % p for p in v] + ["3 %d %d %d" % t for t in f]))
PY
"$B" view --mesh "$T/box.off" --size 40x30 --overlay off --exit-after 1 --screenshot "$T/box.png" >"$T/out" 2>"$T/err" ||
    fail "view of a 20 m box without --pose: $(head -c 600 "$T/err")"
grep -q "too large" "$T/err" && fail "view of a 20 m box without --pose: $(grep -m1 'too large' "$T/err")"
py - "$CMP" "$T/box.png" <<'PY' || fail "view of a 20 m box without --pose: not a centred third of the image"
import os, sys
sys.path.insert(0, os.path.dirname(sys.argv[1]))
from png_compare import read_png
w, h, rgb = read_png(sys.argv[2])
lit = [(i % w, i // w) for i in range(w * h) if max(rgb[3 * i:3 * i + 3]) > 0]
xs, ys = [p[0] for p in lit], [p[1] for p in lit]
share = len(lit) / (w * h)
assert 0.25 <= share <= 0.42, share
assert abs((min(xs) + max(xs)) / 2 - (w - 1) / 2) <= 1 and abs((min(ys) + max(ys)) / 2 - (h - 1) / 2) <= 1, (xs, ys)
PY

# 3. Refusals: no display (exit 4, said so; replay makes no output folder),
# --screenshot without --exit-after, --exit-after without --view, a missing map.
env -u DISPLAY "$B" view --map "$T/rep" --exit-after 1 >"$T/out" 2>"$T/err"
rc=$?
[ $rc = 4 ] || fail "view without DISPLAY: exit $rc, expected 4"
mentions "no display"
env -u DISPLAY "$B" replay "$T/seq" --out "$T/nodisplay" --view >"$T/out" 2>"$T/err"
rc=$?
[ $rc = 4 ] || fail "replay --view without DISPLAY: exit $rc, expected 4"
[ -e "$T/nodisplay" ] && fail "replay --view without DISPLAY made its output folder"
expect 2 "$B" view --map "$T/rep" --screenshot "$T/x.png"
mentions "--screenshot needs --exit-after"
expect 2 "$B" replay "$T/seq" --out "$T/r2" --exit-after 3
mentions "--exit-after needs --view"
expect 3 "$B" view --map "$T/nothing" --exit-after 1
mentions "$T/nothing"
finish test_view
