#!/usr/bin/env bash
# A resumed scan finds a camera that starts somewhere else: the store keeps
# its relocalisation keyframes with their colour's keypoints
# (keyframes.bin), and the first frame of the resumed scan, 0.36 m from
# every pose of the stored scan, is found from colour. Without the file, or
# with a corrupt one (named, and the scan resumes anyway), it is lost.
# Usage: test_store_reloc.sh path/to/bitfuse
set -u
B=$1
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
. "$(dirname "$0")/common.sh"
json_get() { py -c "import json,sys; d=json.load(open(sys.argv[1])); print(eval(sys.argv[2]))" "$1" "$2"; }

# 30 frames of a slow sideways move and turn, then 10 frames 0.36 m behind
# and above the middle of that path, looking down 12 degrees more (the
# carried-away camera of tests/recon/test_reloc.c): a camera put down
# elsewhere before the scan is resumed.
py - "$T/traj.txt" <<'PY'
import sys, math
def quat_mul(a, b):
    ax, ay, az, aw = a; bx, by, bz, bw = b
    return (aw*bx + ax*bw + ay*bz - az*by, aw*by - ax*bz + ay*bw + az*bx, aw*bz + ax*by - ay*bx + az*bw,
            aw*bw - ax*bx - ay*by - az*bz)
def rot(q, v):
    x, y, z, w = quat_mul(quat_mul(q, (v[0], v[1], v[2], 0.0)), (-q[0], -q[1], -q[2], q[3]))
    return (x, y, z)
with open(sys.argv[1], "w") as f:
    for i in range(40):
        k = min(i, 15) if i >= 30 else i
        a = math.radians(0.8 * k)
        q = (0.0, math.sin(a / 2), 0.0, math.cos(a / 2))
        t = (0.006 * k, 0.0, 0.0)
        if i >= 30:
            p = math.radians(-12.0)
            q = quat_mul(q, (math.sin(p / 2), 0.0, 0.0, math.cos(p / 2)))
            d = rot(quat_mul(q, (-math.sin(p / 2), 0.0, 0.0, math.cos(p / 2))), (0.0, -0.1, -0.35))
            t = (t[0] + d[0], t[1] + d[1], t[2] + d[2])
        f.write("%.6f %.6f %.6f %.6f %.6f %.6f %.6f %.6f\n" % ((1305031098.6659 + i / 30.0,) + t + q))
PY
mkdir "$T/nodata"
expect 0 "$B" synth --trajectory "$T/traj.txt" --frames 40 --size 320x240 --camera 262.5,262.5,159.5,119.5 \
    --data "$T/nodata" --noise none --out "$T/seq"
SEQ="$T/seq"

# The first 30 frames into a store: its keyframes are kept at the end.
expect 0 "$B" replay "$SEQ" --out "$T/a" --no-mesh --frames 30 --store "$T/S"
[ -f "$T/S/keyframes.bin" ] || fail "the store keeps no keyframes.bin"
kf=$(json_get "$T/a/stats.json" "d['store']['keyframes_written']")
[ "${kf:-0}" -ge 1 ] || fail "stats.json store.keyframes_written is '$kf'"
# On a disk too small for the first write no keyframes were written.
mkdir "$T/tiny"
if mount -t tmpfs -o size=16k tmpfs "$T/tiny" 2>/dev/null; then
    expect 5 "$B" replay "$SEQ" --out "$T/a-full" --no-mesh --frames 30 --store "$T/tiny/S"
    [ "$(json_get "$T/a-full/stats.json" "d['store']['keyframes_written']")" = 0 ] ||
        fail "a failed write counts $(json_get "$T/a-full/stats.json" "d['store']['keyframes_written']") keyframes written"
    umount "$T/tiny"
fi
expect 0 "$B" info "$T/S" --json
n=$(json_get "$T/out" "d['keyframes']")
[ "$n" = "$kf" ] || fail "info: $n keyframes where $kf were written"
[ "$(json_get "$T/out" "d['keyframe_keypoints'] > 0 and d['keyframes_ok']")" = True ] || fail "info: no keypoints"
cp -r "$T/S" "$T/N" && rm "$T/N/keyframes.bin"
cp -r "$T/S" "$T/C"
printf '\377\377\377\377' | dd of="$T/C/keyframes.bin" bs=1 seek=200 conv=notrunc 2>/dev/null

# State and source of frame 30, the first of the resumed scan.
frame30() { awk -F, '$1 == 30 {print $3 "/" $16}' "$1/frames.csv"; }

# Resumed: found from colour at once, and tracked on.
expect 0 "$B" replay "$SEQ" --out "$T/r" --no-mesh --store "$T/S" --resume
[ "$(frame30 "$T/r")" = "relocalised/features" ] || fail "resumed: frame 30 is '$(frame30 "$T/r")'"
n=$(json_get "$T/r/stats.json" "d['store']['reopened']['keyframes']")
[ "$n" = "$kf" ] || fail "reopened $n keyframes, $kf were written"
lost=$(json_get "$T/r/stats.json" "d['tracking']['lost']")
[ "$lost" = 0 ] || fail "resumed: $lost frames lost"
# Its poses against the truth (the loop starts at the first frame's).
py - "$T/r/trajectory.txt" "$SEQ/groundtruth.txt" <<'PY' || fail "the relocalised poses are off"
import sys
def rows(path):
    return [list(map(float, l.split())) for l in open(path) if l.strip() and not l.startswith("#")]
est, gt = rows(sys.argv[1]), {round(r[0], 4): r for r in rows(sys.argv[2])}
err = [sum((e[k] - gt[round(e[0], 4)][k]) ** 2 for k in (1, 2, 3)) ** 0.5 for e in est[30:]]
print("resumed: frames 30-39 off by %.1f-%.1f mm" % (1e3 * min(err), 1e3 * max(err)))
sys.exit(0 if len(err) == 10 and max(err) < 0.02 else 1)
PY

# Without keyframes.bin (an older store): the trajectory's poses alone, lost.
expect 0 "$B" replay "$SEQ" --out "$T/n" --no-mesh --store "$T/N" --resume
[ "$(frame30 "$T/n")" = "lost/" ] || fail "without keyframes.bin: frame 30 is '$(frame30 "$T/n")'"

# A session that holds no colour keypoints (relocalisation off) leaves the
# file an earlier one wrote.
cp -r "$T/S" "$T/O"
expect 0 "$B" replay "$SEQ" --out "$T/o" --no-mesh --store "$T/O" --resume --reloc off
cmp -s "$T/S/keyframes.bin" "$T/O/keyframes.bin" || fail "a resume with --reloc off rewrote keyframes.bin"

# A corrupt keyframes.bin is named, and the scan resumes without it.
expect 0 "$B" info "$T/C"
grep -q "keyframes.bin unreadable" "$T/out" || fail "info does not report the corrupt keyframes.bin"
expect 0 "$B" replay "$SEQ" --out "$T/c" --no-mesh --store "$T/C" --resume
mentions "keyframes.bin"
[ "$(frame30 "$T/c")" = "lost/" ] || fail "corrupt keyframes.bin: frame 30 is '$(frame30 "$T/c")'"
finish test_store_reloc
