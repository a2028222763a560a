#!/usr/bin/env bash
# The viewer window under Xvfb (docs/view.md): replay --view draws the map
# while scanning and its screenshot, read back from the swapchain, equals
# the headless ray-cast PNG of the same frame (--view-every) byte for byte;
# --exit-after ends the scan as closing the window does, everything kept;
# bitfuse view shows the stored map; no display is a clear exit 4.
# Skips (77) without a display or a device that presents to it; ctest runs
# it under its own Xvfb (with_xvfb.sh).
# Usage: test_view.sh path/to/bitfuse path/to/png_compare.py
set -u
B=$1
CMP=$2
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
fails=0
fail() { echo "FAIL: $*"; fails=$((fails + 1)); }
command -v python3 >/dev/null || { echo "skip: no python3"; exit 77; }
export BITFUSE_PROGRESS=0

[ -n "${DISPLAY:-}" ] || { echo "skip: no display (run under with_xvfb.sh)"; exit 77; }

# A 12-frame synthetic sequence at 160x120 (half a second to make).
python3 - "$T/traj.txt" <<'PY'
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
if [ $rc = 4 ] && grep -qE "cannot present|no display|cannot make a Vulkan surface" "$T/err"; then
    echo "skip: no presentation: $(grep -m1 error "$T/err")"
    exit 77
fi
[ $rc = 0 ] || fail "replay --view: exit $rc: $(head -c 600 "$T/err")"
grep -q "vulkan validation" "$T/err" && fail "replay --view: validation messages: $(grep -m1 'vulkan validation' "$T/err")"
frames=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['frames'])" "$T/rep/stats.json" 2>/dev/null)
[ "$frames" = 5 ] || fail "replay --view --exit-after 5 handled '$frames' frames, not 5"
[ "$(grep -vc '^#' "$T/rep/trajectory.txt")" = 5 ] || fail "trajectory.txt: not 5 poses"
[ -e "$T/rep/store/store.json" ] || fail "the store was not written at the stop"
# The same ray-cast's bytes on both sides (recon_render_view at the frame's
# pose, the window's size is the sequence's): tolerance 0. A wrong byte
# order, row pitch, scaling or a stale image all break it.
python3 "$CMP" "$T/shot_replay.png" "$T/rep/views/000004.png" 0 0 || fail "the window's screenshot differs from views/000004.png"

# 2. bitfuse view of the stored map at the scan's last pose. Not the same
# bytes: the store holds the map after the end-of-scan flush (the owed
# window integrated: colour and confidence appear) and view shows confident
# voxels only, while the scan's view of frame 5 showed every sign bit
# shaded by level (no window done yet). So the hit masks are compared (lit
# against black), which both share where the surface is confident.
# Required: at most 30% of the pixels differ (measured on this sequence: 21%).
P=$(grep -v '^#' "$T/rep/trajectory.txt" | tail -1 | cut -d' ' -f2-8)
"$B" view --map "$T/rep" --pose "$P" --size 160x120 --camera 131.25,131.25,79.5,59.5 --exit-after 2 \
    --overlay off --screenshot "$T/shot_view.png" >"$T/out" 2>"$T/err"
rc=$?
[ $rc = 0 ] || fail "view: exit $rc: $(head -c 600 "$T/err")"
grep -q "vulkan validation" "$T/err" && fail "view: validation messages: $(grep -m1 'vulkan validation' "$T/err")"
python3 "$CMP" "$T/shot_view.png" "$T/rep/views/000004.png" -1 0.3 || fail "view's screenshot is not the stored map at that pose"

# 3. Refusals: no display (exit 4, said so), --screenshot without --exit-after, a missing map.
env -u DISPLAY "$B" view --map "$T/rep" --exit-after 1 >"$T/out" 2>"$T/err"
rc=$?
[ $rc = 4 ] || fail "view without DISPLAY: exit $rc, expected 4"
grep -q "no display" "$T/err" || fail "view without DISPLAY: $(head -c 300 "$T/err")"
env -u DISPLAY "$B" replay "$T/seq" --out "$T/nodisplay" --view >"$T/out" 2>"$T/err"
rc=$?
[ $rc = 4 ] || fail "replay --view without DISPLAY: exit $rc, expected 4"
[ -e "$T/nodisplay" ] && fail "replay --view without DISPLAY made its output folder"
"$B" view --map "$T/rep" --screenshot "$T/x.png" >"$T/out" 2>"$T/err"
[ $? = 2 ] || fail "--screenshot without --exit-after: not a usage error"
"$B" view --map "$T/nothing" --exit-after 1 >"$T/out" 2>"$T/err"
rc=$?
[ $rc = 3 ] && grep -q "$T/nothing" "$T/err" || fail "a missing map: exit $rc: $(head -c 300 "$T/err")"
"$B" replay "$T/seq" --out "$T/r2" --exit-after 3 >"$T/out" 2>"$T/err"
[ $? = 2 ] || fail "replay --exit-after without --view: not a usage error"

[ $fails = 0 ] && echo "test_view: all passed"
exit $((fails > 0))
