#!/usr/bin/env bash
# bitfuse render as a user meets it: a scene store written by replay drawn
# from the sequence's own first pose (its depth image must agree with the
# frame's, noise-free), particles added in front of the map (nearer where
# they are, the map elsewhere), the particles alone, and the refusals: a bad
# pose, size, camera or image name (exit 2, the option named), a missing or
# corrupt file (exit 3, the file named), nothing to render; a mesh (a
# sphere whose depth and outline are known) and its refusals.
# Usage: test_render.sh path/to/bitfuse
set -u
B=$1
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
. "$(dirname "$0")/common.sh"

# A PNG reader (zlib and the five row filters) for the checks below: prints
# width, height, bit depth, and with a second file the comparison asked.
cat >"$T/png.py" <<'PY'
import struct, sys, zlib
def read(path):
    b = open(path, "rb").read()
    assert b[:8] == b"\x89PNG\r\n\x1a\n", path + ": not a PNG"
    i, idat = 8, b""
    while i < len(b):
        n, kind = struct.unpack(">I4s", b[i:i + 8])
        data = b[i + 8:i + 8 + n]
        if kind == b"IHDR": w, h, depth, ctype = struct.unpack(">IIBB", data[:10])
        if kind == b"IDAT": idat += data
        i += 12 + n
    ch = {0: 1, 2: 3, 6: 4}[ctype]
    bpp = ch * depth // 8
    raw, rows, prev = zlib.decompress(idat), [], bytearray(w * bpp)
    stride = w * bpp
    for y in range(h):
        f, line = raw[y * (stride + 1)], bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for x in range(stride):
            a = line[x - bpp] if x >= bpp else 0
            c = prev[x - bpp] if x >= bpp else 0
            up = prev[x]
            if f == 1: line[x] = (line[x] + a) & 255
            elif f == 2: line[x] = (line[x] + up) & 255
            elif f == 3: line[x] = (line[x] + (a + up) // 2) & 255
            elif f == 4:
                p = a + up - c
                pa, pb, pc = abs(p - a), abs(p - up), abs(p - c)
                line[x] = (line[x] + (a if pa <= pb and pa <= pc else up if pb <= pc else c)) & 255
        rows.append(line)
        prev = line
    if depth == 16:
        px = [[(r[2 * k] << 8) | r[2 * k + 1] for k in range(w * ch)] for r in rows]
    else:
        px = [list(r) for r in rows]
    return w, h, depth, ch, px
w, h, depth, ch, px = read(sys.argv[1])
if len(sys.argv) == 2:
    print(w, h, depth, ch)
    sys.exit(0)
mode = sys.argv[2]
if mode == "hits":          # share of non-zero depth pixels
    print("%.3f" % (sum(v > 0 for r in px for v in r) / float(w * h)))
elif mode == "agree":       # median |a - b| [m] where both have depth, and the share of such pixels
    _, _, _, _, q = read(sys.argv[3])
    d = sorted(abs(a - b) / 5000.0 for ra, rb in zip(px, q) for a, b in zip(ra, rb) if a and b)
    print("%.4f %.3f" % (d[len(d) // 2] if d else 9, len(d) / float(w * h)))
elif mode == "at":          # the value of pixel (x, y)
    print(px[int(sys.argv[4])][int(sys.argv[3])])
elif mode == "nearest":     # pixels of a that are not the nearest of b and c (0: none), and those where b is nearer than c
    _, _, _, _, q = read(sys.argv[3])
    _, _, _, _, r = read(sys.argv[4])
    bad = in_front = 0
    for ra, rb, rc in zip(px, q, r):
        for a, b, c in zip(ra, rb, rc):
            want = min(v for v in (b, c) if v) if (b or c) else 0
            bad += abs(a - want) > 1
            in_front += b > 0 and c > 0 and b < c
    print(bad, in_front)
PY

# 20 frames of the synthetic room, small images, noise-free, into a store (as test_export.sh).
py - "$T/traj.txt" <<'PY'
import sys, math
with open(sys.argv[1], "w") as f:
    for i in range(30):
        a = 0.004 * i
        f.write("%.6f %.6f 0 0 0 %.6f 0 %.6f\n" % (1305031098.6659 + i / 30.0, 0.005 * i, math.sin(a / 2), math.cos(a / 2)))
PY
mkdir "$T/nodata"
CAM=131.25,131.25,79.5,59.5
expect 0 "$B" synth --trajectory "$T/traj.txt" --frames 20 --size 160x120 --camera $CAM \
    --data "$T/nodata" --noise none --out "$T/seq"
expect 0 "$B" replay "$T/seq" --out "$T/run" --store "$T/S" --no-mesh
# The last frame's pose and depth image: the map is fused there.
POSE=$(grep -v '^#' "$T/seq/groundtruth.txt" | tail -n 1 | cut -d' ' -f2-8)
DEPTH=$T/seq/$(grep -v '^#' "$T/seq/depth.txt" | tail -n 1 | cut -d' ' -f2)

expect 0 "$B" render --help
grep -qF -- "--particle-radius" "$T/out" || fail "render --help does not list --particle-radius"

# A mesh: a sphere of radius 0.1 m (an icosphere of 5120 triangles, OFF),
# placed by --mesh-pose 0.5 m in front of the camera at the origin. The
# centre pixel's depth is 0.4 m within a voxel (the level is chosen for a
# third of a pixel: 1 mm here), the hit share that of the sphere's disc
# (radius f tan(asin(r / d)) = 26.8 px of 160x120: 11.7%) within a pixel of
# its outline.
py "$(dirname "$0")/../icosphere.py" "$T/sphere.off" 0.1 4
expect 0 "$B" render --mesh "$T/sphere.off" --mesh-pose "0 0 0.5 0 0 0 1" --pose "0 0 0 0 0 0 1" --camera $CAM \
    --size 160x120 --out "$T/sphere.png" --depth "$T/sphere_d.png"
grep -qF "level 8" "$T/out" || fail "sphere: not voxelised at level 8 (1 mm): $(cat "$T/out")"
read -r hits < <(py "$T/png.py" "$T/sphere_d.png" hits)
py -c "import sys; sys.exit(0 if 0.109 <= $hits <= 0.126 else 1)" || fail "sphere: $hits of the pixels hit, not 0.109-0.126"
read -r centre < <(py "$T/png.py" "$T/sphere_d.png" at 80 60)
py -c "import sys; sys.exit(0 if abs($centre - 2000) <= 5 else 1)" || fail "sphere: centre depth $centre / 5000 m, not 0.4 m within 1 mm"
! grep -q "may not be closed" "$T/err" || fail "the closed sphere was warned about as open"
# The sphere less its first face: warned about (its rim of 3 edges), drawn all the same.
py - "$T/sphere.off" "$T/open.off" <<'PYEOF'
import sys
lines = open(sys.argv[1]).read().split("\n")
nv, nf, ne = map(int, lines[1].split())
lines[1] = "%d %d %d" % (nv, nf - 1, ne)
del lines[2 + nv]
open(sys.argv[2], "w").write("\n".join(lines))
PYEOF
expect 0 "$B" render --mesh "$T/open.off" --mesh-pose "0 0 0.5 0 0 0 1" --pose "0 0 0 0 0 0 1" --camera $CAM \
    --size 40x30 --out "$T/open.png"
mentions "$T/open.off: the mesh may not be closed (3 edges that an odd number of triangles share"
# A slab 20 m wide seen from 0.3 m at one level (--mesh-lod off): 1.95 mm
# voxels would need 3.3 M bricks, beyond lavapipe's 128 MiB binding: drawn
# a level coarser, and said so (a device whose bindings hold it draws it at
# level 7). A slab 1 m wide seen from 0.1 m: the default near plane (0.2 m, a
# Kinect's) leaves it unseen; --near 0.05 sees it.
slab() { # EDGE: a closed box EDGE x EDGE x 0.2 m, its low face on z = 0
    py - "$1" <<'PYEOF'
import sys
h = float(sys.argv[1]) / 2
v = [(-h, -h, 0), (h, -h, 0), (h, h, 0), (-h, h, 0), (-h, -h, 0.2), (h, -h, 0.2), (h, h, 0.2), (-h, h, 0.2)]
f = [(0, 2, 1), (0, 3, 2), (4, 5, 6), (4, 6, 7), (0, 1, 5), (0, 5, 4), (1, 2, 6), (1, 6, 5), (2, 3, 7), (2, 7, 6),
     (3, 0, 4), (3, 4, 7)]
print("\n".join(["OFF", "8 12 0"] + ["%g %g %g" % p for p in v] + ["3 %d %d %d" % t for t in f]))
PYEOF
}
slab 20 >"$T/slab.off"
expect 0 "$B" render --mesh "$T/slab.off" --mesh-lod off --pose "0 0 -0.3 0 0 0 1" --size 40x30 --out "$T/slab.png" --json
py - "$T/out" "$T/err" <<'PYEOF' || fail "the 20 m slab from 0.3 m: $(head -c 300 "$T/out") $(head -c 300 "$T/err")"
import json, sys
d = json.load(open(sys.argv[1]))
assert "depth" in d and d["depth"] is None, "no depth: null without --depth"
warned = "too large for this device at level 7" in open(sys.argv[2]).read()
assert d["hit_fraction"] == 1, d
assert d["mesh"]["level_fine"] <= 6 if warned else d["mesh"]["level_fine"] == 7, (warned, d)
assert d["mesh"]["level_asked"] == 7, d
PYEOF
slab 1 >"$T/slab1.off"
expect 0 "$B" render --mesh "$T/slab1.off" --pose "0 0 -0.1 0 0 0 1" --size 40x30 --out "$T/slab.png" --json
py -c "import json,sys; d=json.load(open(sys.argv[1])); assert d['hit_fraction'] == 0, d" "$T/out" ||
    fail "the slab 0.1 m away was seen inside the 0.2 m near plane"
expect 0 "$B" render --mesh "$T/slab1.off" --pose "0 0 -0.1 0 0 0 1" --size 40x30 --out "$T/slab.png" --json --near 0.05
py -c "import json,sys; d=json.load(open(sys.argv[1])); assert d['hit_fraction'] == 1, d" "$T/out" ||
    fail "--near 0.05: the slab 0.1 m away not seen"
expect 2 "$B" render --mesh "$T/slab1.off" --pose "0 0 -0.1 0 0 0 1" --size 40x30 --out "$T/slab.png" --near 5 --far 4
mentions "--near 5 is not nearer than --far 4"

# The map from the frame's pose: its depth is the frame's (noise-free, the
# fused surface within a few voxels of 1-2 cm at these depths).
expect 0 "$B" render --map "$T/S" --pose "$POSE" --camera $CAM --size 160x120 --out "$T/map.png" --depth "$T/map_d.png"
[ "$(py "$T/png.py" "$T/map.png")" = "160 120 8 3" ] || fail "map.png: $(py "$T/png.py" "$T/map.png")"
[ "$(py "$T/png.py" "$T/map_d.png")" = "160 120 16 1" ] || fail "map_d.png: $(py "$T/png.py" "$T/map_d.png")"
read -r med share < <(py "$T/png.py" "$T/map_d.png" agree "$DEPTH")
py -c "import sys; sys.exit(0 if $med <= 0.02 and $share >= 0.8 else 1)" ||
    fail "the map's depth against the frame's: median $med m on $share of the pixels"
# A folder holding the store as DIR/store is a map too.
mkdir "$T/dir" && cp -r "$T/S" "$T/dir/store"
expect 0 "$B" render --map "$T/dir" --pose "$POSE" --camera $CAM --size 40x30 --out "$T/small.png"
[ "$(py "$T/png.py" "$T/small.png")" = "40 30 8 3" ] || fail "small.png: $(py "$T/png.py" "$T/small.png")"

# Particles 0.6 m in front of the camera, a 25 x 25 sheet of 4 cm spheres
# (binary little-endian PLY with extra properties, as simulations write).
py - "$POSE" "$T/p.ply" <<'PY'
import sys, struct
tx, ty, tz, qx, qy, qz, qw = map(float, sys.argv[1].split())
def rot(v):  # R(q) v + t
    x, y, z = v
    R = [[1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
         [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
         [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)]]
    return tuple(R[r][0] * x + R[r][1] * y + R[r][2] * z + (tx, ty, tz)[r] for r in range(3))
pts = [rot((-0.12 + 0.01 * i, -0.12 + 0.01 * j, 0.6)) for i in range(25) for j in range(25)]
with open(sys.argv[2], "wb") as f:
    f.write(b"ply\nformat binary_little_endian 1.0\nelement vertex %d\nproperty float x\nproperty float y\n"
            b"property float z\nproperty float density\nend_header\n" % len(pts))
    for p in pts: f.write(struct.pack("<4f", p[0], p[1], p[2], 1000.0))
PY
expect 0 "$B" render --map "$T/S" --particles "$T/p.ply" --particle-radius 0.02 --pose "$POSE" --camera $CAM \
    --size 160x120 --out "$T/both.png" --depth "$T/both_d.png"
grep -q "625 cells" "$T/out" || fail "render did not report 625 particle cells: $(cat "$T/out")"
# --json: the same image, and what the lines say as one object.
expect 0 "$B" render --map "$T/S" --particles "$T/p.ply" --particle-radius 0.02 --pose "$POSE" --camera $CAM \
    --size 160x120 --out "$T/both_j.png" --depth "$T/both_jd.png" --repeat 2 --json
cmp -s "$T/both_d.png" "$T/both_jd.png" || fail "render --json drew another depth image"
hits=$(py "$T/png.py" "$T/both_d.png" hits)
"$B" devices > "$T/devices.txt" 2>&1 || fail "bitfuse devices failed: $(cat "$T/devices.txt")"
py - "$T/out" "$hits" "$T/devices.txt" <<'PY' || fail "render --json: $(head -c 600 "$T/out")"
import json, sys
d = json.load(open(sys.argv[1]))
devices = open(sys.argv[3]).read()
# The device and its driver's version as `bitfuse devices` names them.
ok = (d["device_driver"] != "" and d["device"] in devices and d["device_driver"] in devices
      and d["command"] == "render" and d["width"] == 160 and d["particles"]["cells"] == 625
      and d["map"]["bricks"] > 0 and d["bricks"] == d["map"]["bricks"] and len(d["raycast_ms"]["sorted"]) == 2
      and d["raycast_ms"]["sorted"][0] <= d["raycast_ms"]["sorted"][1] and "particles_median" in d["raycast_ms"]
      and abs(d["hit_fraction"] - float(sys.argv[2])) <= 0.0005)  # png.py prints 3 decimals
# GPU memory: at least both bit planes (2 x 64 bytes), the record and the
# stamp (20 bytes) of every brick of both levels, at most what is allocated.
p = d["particles"]
ok = (ok and p["gpu_bytes_reserved"] >= p["gpu_bytes_used"] >= (p["bricks"] + p["coarse_bricks"]) * 148
      and abs(p["gpu_bytes_per_particle"] * p["count"] - p["gpu_bytes_used"]) <= 1e-6 * p["gpu_bytes_used"])
sys.exit(0 if ok else 1)
PY
expect 0 "$B" render --particles "$T/p.ply" --particle-radius 0.02 --pose "$POSE" --camera $CAM --size 160x120 \
    --out "$T/p.png" --depth "$T/p_d.png"
# The sheet covers about (0.28 * 131 / 0.6)^2 = 3700 pixels (a fifth).
hits=$(py "$T/png.py" "$T/p_d.png" hits)
py -c "import sys; sys.exit(0 if 0.15 <= $hits <= 0.25 else 1)" || fail "particles alone hit $hits of the pixels"
# A large image: the map drawn needs no per-pixel buffers of its own (a
# map made for frames did: 6 M pixels passed lavapipe's binding); beyond
# what the normals' binding holds, the size is refused naming the most.
expect 0 "$B" render --map "$T/S" --pose "$POSE" --size 3000x2000 --out "$T/large.png"
range=$("$B" devices --json 2>/dev/null |
    py -c "import json,sys; print([d for d in json.load(sys.stdin)['devices'] if d['is_chosen']][0]['limits']['max_storage_buffer_range'])")
side=$(py -c "import math,sys; print(math.isqrt(int(sys.argv[1]) // 16) + 1)" "$range")
if [ "$side" -le 8192 ]; then # a device whose binding holds 8192x8192 has no size to refuse
    expect 2 "$B" render --map "$T/S" --pose "$POSE" --size "${side}x$side" --out "$T/huge.png"
    mentions "at most"
    [ -e "$T/huge.png" ] && fail "a refused size wrote its image"
fi
# A store with a chunk file gone renders what is left, and says so (stderr, --json).
cp -r "$T/S" "$T/Sdmg"
rm "$(ls "$T"/Sdmg/chunks/*.bfc | head -n 1)"
expect 0 "$B" render --map "$T/Sdmg" --pose "$POSE" --size 40x30 --out "$T/dmg.png" --json
mentions "1 chunk the index lists was not loaded"
py -c "import json,sys; d=json.load(open(sys.argv[1])); assert d['map']['chunks_missing'] == 1 and d['map']['chunk_files_left_out'] == 0, d['map']" \
    "$T/out" || fail "render of a damaged store: $(head -c 300 "$T/out")"
# Options for what is not drawn are refused, not ignored.
expect 2 "$B" render --map "$T/S" --pose "$POSE" --size 40x30 --out "$T/x.png" --mesh-lod off
mentions "--mesh-lod needs --mesh"
expect 2 "$B" render --map "$T/S" --pose "$POSE" --size 40x30 --out "$T/x.png" --particle-radius 0.1
mentions "--particle-radius needs --particles"
# Two particles 283 m apart at 1.25 mm cells: 3500 coarse bricks along an
# axis (a Morton code of over 32 bits; it stopped with an internal error).
printf 'ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 2\n200 200 2\n' \
    >"$T/far2.ply"
expect 0 "$B" render --particles "$T/far2.ply" --pose "0 0 1.5 0 0 0 1" --size 160x120 --out "$T/far2.png" --json
py -c "import json,sys; d=json.load(open(sys.argv[1])); assert d['hit_fraction'] > 0 and d['particles']['cells'] == 2, d" \
    "$T/out" || fail "two particles far apart: $(head -c 300 "$T/out")"
# A radius whose cells would make chunks the map cannot hold is the option's fault (exit 2), not the file's.
expect 2 "$B" render --particles "$T/p.ply" --particle-radius 5 --pose "$POSE" --size 160x120 --out "$T/p5.png"
mentions "beyond 64 m"
# Together: each pixel the nearer of the two alone (to the PNG's 0.2 mm);
# the sheet lies in front of the map wherever both are.
read -r bad in_front < <(py "$T/png.py" "$T/both_d.png" nearest "$T/p_d.png" "$T/map_d.png")
[ "$bad" = 0 ] && [ "$in_front" -gt 1000 ] ||
    fail "map and particles: $bad pixels not the nearer of the two, particles in front on $in_front"

# Refusals: the option or the file named.
expect 2 "$B" render --map "$T/S" --pose "1 2 3 0 0 0" --size 160x120 --out "$T/x.png"
mentions "--pose"
expect 2 "$B" render --map "$T/S" --pose "0 0 0 0 0 0 2" --size 160x120 --out "$T/x.png"
mentions "norm"
expect 2 "$B" render --map "$T/S" --pose "$POSE" --size 160x --out "$T/x.png"
mentions "--size"
expect 2 "$B" render --map "$T/S" --pose "$POSE" --size 0x120 --out "$T/x.png"
mentions "--size"
expect 2 "$B" render --map "$T/S" --pose "$POSE" --size 1x1 --out "$T/x.png"
mentions "each 2..8192"
expect 2 "$B" render --map "$T/S" --pose "$POSE" --size 160x120 --out "$T/x.png" --depth "$T/x.png"
mentions "give each its own"
# A missing folder for either output is named before anything is drawn:
# no image is left without the depth asked beside it.
expect 5 "$B" render --map "$T/S" --pose "$POSE" --size 160x120 --out "$T/y.png" --depth "$T/nofolder/y.png"
mentions "--depth $T/nofolder/y.png: the folder $T/nofolder does not exist"
[ -e "$T/y.png" ] && fail "render wrote --out although --depth's folder is missing"
expect 5 "$B" render --map "$T/S" --pose "$POSE" --size 160x120 --out "$T/nofolder/y.png"
mentions "the folder $T/nofolder does not exist"
# A link is written through: its target's folder is the one checked, before anything is drawn.
ln -s "$T/nofolder/z.png" "$T/zlink.png"
expect 5 "$B" render --map "$T/S" --pose "$POSE" --size 160x120 --out "$T/zlink.png"
mentions "--out $T/zlink.png (a link to $T/nofolder/z.png): the folder $T/nofolder does not exist"
# A path longer than the system takes (4095 characters): refused before anything is written.
LONG="$T/$(printf 'a%.0s' $(seq 1 4200))/y.png"
expect 2 "$B" render --map "$T/S" --pose "$POSE" --size 160x120 --out "$T/y.png" --depth "$LONG"
mentions "--depth: a path of $((${#LONG})) characters is too long (at most 4095)"
[ -e "$T/y.png" ] && fail "render wrote --out although --depth's path is too long"
expect 2 "$B" render --map "$T/S" --pose "$POSE" --size 160x120 --camera 100,100 --out "$T/x.png"
mentions "--camera"
expect 2 "$B" render --map "$T/S" --pose "$POSE" --size 160x120 --out "$T/x.jpg"
mentions "--out"
expect 2 "$B" render --pose "$POSE" --size 160x120 --out "$T/x.png"
mentions "nothing to render"
expect 2 "$B" render --mesh-pose "0 0 0 0 0 0 1" --map "$T/S" --pose "$POSE" --size 160x120 --out "$T/x.png"
mentions "--mesh-pose without --mesh"
expect 3 "$B" render --mesh "$T/nope.off" --pose "$POSE" --size 160x120 --out "$T/x.png"
mentions "$T/nope.off"
printf 'OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 9\n' >"$T/bad.off"
expect 3 "$B" render --mesh "$T/bad.off" --pose "$POSE" --size 160x120 --out "$T/x.png"
mentions "$T/bad.off"
expect 3 "$B" render --map "$T/missing" --pose "$POSE" --size 160x120 --out "$T/x.png"
mentions "$T/missing"
expect 3 "$B" render --map "$T/nodata" --pose "$POSE" --size 160x120 --out "$T/x.png"
mentions "$T/nodata"
expect 3 "$B" render --particles "$T/nope.ply" --pose "$POSE" --size 160x120 --out "$T/x.png"
mentions "$T/nope.ply"
# An empty particle set (a simulation's first dump may hold none): drawn as nothing, said so.
printf 'ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\nend_header\n' \
    >"$T/none.ply"
expect 0 "$B" render --particles "$T/none.ply" --pose "$POSE" --size 40x30 --out "$T/none.png"
mentions "$T/none.ply: no particles (the PLY has no vertex)"
head -c 100 "$T/p.ply" >"$T/cut.ply"
expect 3 "$B" render --particles "$T/cut.ply" --pose "$POSE" --size 160x120 --out "$T/x.png"
mentions "$T/cut.ply"
[ ! -e "$T/x.png" ] || fail "a refused render left $T/x.png"
expect 5 "$B" render --particles "$T/p.ply" --pose "$POSE" --size 16x12 --out "$T/no/such/dir/x.png"

finish test_render.sh
