#!/usr/bin/env bash
# Export as a user meets it: a scene store written by replay, exported in
# each format (the format from the name or --format), simplified to a cap
# and to an error bound, the same options on replay's own mesh, and the
# refusals: an unknown format, an unwritable file (exit 5, nothing left
# behind), --points with a cap. glb files go through the Khronos validator
# when node has it (tests/mesh/validate_glb.js; a run that could validate
# none says so and ends skipped, 77).
# Usage: test_export.sh path/to/bitfuse path/to/validate_glb.js
set -u
B=$1
VALIDATE=$2
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
. "$(dirname "$0")/common.sh"
json_get() { py -c "import json,sys; d=json.load(open(sys.argv[1])); print(eval(sys.argv[2]))" "$1" "$2"; }
# Without node or the validator a glb is not validated: said and counted, and
# a run that validated none ends skipped (77), not passed.
validated=0
validate() {
    if ! command -v node >/dev/null; then
        echo "skip: glTF validation of $*: node absent"
        return
    fi
    env -u LD_PRELOAD -u ASAN_OPTIONS -u LSAN_OPTIONS node "$VALIDATE" "$@" >"$T/val" 2>&1
    local rc=$?
    case $rc in
    0) validated=$((validated + 1)) ;;
    77) echo "skip: glTF validation of $*: $(head -c 200 "$T/val")" ;;
    *) fail "glTF validator: $(head -c 600 "$T/val")" ;;
    esac
}

# 30 frames of the synthetic room, small images, into a store (as test_store.sh).
py - "$T/traj.txt" <<'PY'
import sys, math
with open(sys.argv[1], "w") as f:
    for i in range(40):
        a = 0.004 * i
        f.write("%.6f %.6f 0 0 0 %.6f 0 %.6f\n" % (1305031098.6659 + i / 30.0, 0.005 * i, math.sin(a / 2), math.cos(a / 2)))
PY
mkdir "$T/nodata"
expect 0 "$B" synth --trajectory "$T/traj.txt" --frames 30 --size 160x120 --camera 131.25,131.25,79.5,59.5 \
    --data "$T/nodata" --noise none --out "$T/seq"
# replay's own mesh: glb, capped.
expect 0 "$B" replay "$T/seq" --out "$T/run" --store "$T/S" --mesh-format glb --max-triangles 3000
[ -f "$T/run/mesh.glb" ] && [ ! -f "$T/run/mesh.ply" ] || fail "replay --mesh-format glb did not write mesh.glb alone"
n=$(json_get "$T/run/stats.json" "d['mesh']['triangles']")
full=$(json_get "$T/run/stats.json" "d['mesh']['triangles_full']")
[ "${n:-x}" -le 3000 ] 2>/dev/null && [ "$full" -gt 3000 ] || fail "replay mesh: $n of $full triangles, cap 3000"
json_get "$T/run/stats.json" "d['mesh']['file'], d['mesh']['simplify']['max_triangles']" | grep -qx "('mesh.glb', 3000)" ||
    fail "stats.json mesh: $(json_get "$T/run/stats.json" "d['mesh']")"
grep -q "simplified to" "$T/out" || fail "replay does not print the simplification: $(cat "$T/out")"
validate "$T/run/mesh.glb"

# export: the full mesh as PLY, then each format.
expect 0 "$B" export "$T/S" --out "$T/full.ply" --json
nfull=$(json_get "$T/out" "d['triangles']")
[ "$nfull" -gt 3000 ] || fail "the full mesh has $nfull triangles"
expect 0 "$B" export "$T/S" --out "$T/m.obj" --json
[ -f "$T/m.mtl" ] || fail "no m.mtl beside m.obj"
grep -q "^mtllib m.mtl$" "$T/m.obj" || fail "m.obj does not name m.mtl"
nv=$(json_get "$T/out" "d['vertices']")
[ "$(grep -c '^v ' "$T/m.obj")" = "$nv" ] || fail "m.obj: $(grep -c '^v ' "$T/m.obj") v lines, JSON says $nv"
[ "$(grep -c '^f ' "$T/m.obj")" = "$nfull" ] || fail "m.obj: $(grep -c '^f ' "$T/m.obj") faces, the PLY $nfull"
expect 0 "$B" export "$T/S" --out "$T/m.glb"
head -c 4 "$T/m.glb" | grep -q "glTF" || fail "m.glb has no glTF magic"
validate "$T/m.glb"
# --format wins over the name.
expect 0 "$B" export "$T/S" --out "$T/m.bin" --format glb
cmp -s "$T/m.bin" "$T/m.glb" || fail "--format glb --out m.bin differs from m.glb"

# A lattice finer than every brick is the finest bricks' own, said so.
expect 0 "$B" export "$T/S" --out "$T/l8.ply" --mesh-level 8 --json
mentions "the store's finest bricks are at level"
lv=$(json_get "$T/out" "d['mesh_level']")
[ "$lv" -lt 8 ] && [ "$(json_get "$T/out" "d['triangles']")" = "$nfull" ] ||
    fail "--mesh-level 8 over coarser bricks: level $lv, $(json_get "$T/out" "d['triangles']") triangles, not $nfull"

# A store whose only surface is a plate seen from one side: its band is
# thinner than a voxel, so no cell has all its corners known. The empty
# mesh is written and said to be empty; the room's export says nothing.
py - "$T/plate.ply" <<'PY'
import struct, sys
with open(sys.argv[1], "wb") as o:
    o.write(b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
            b"property float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n")
    for p in [(-0.5, -0.5, 0), (0.5, -0.5, 0), (0.5, 0.5, 0), (-0.5, 0.5, 0)]:
        o.write(struct.pack("<3f", *p))
    for t in [(0, 1, 2), (0, 2, 3)]:
        o.write(struct.pack("<B3i", 3, *t))
PY
expect 0 "$B" synth --scene "$T/plate.ply" --trajectory "$T/traj.txt" --frames 8 --size 160x120 \
    --camera 131.25,131.25,79.5,59.5 --noise none --out "$T/plateseq"
expect 0 "$B" replay "$T/plateseq" --out "$T/platerun" --no-mesh --store "$T/PS"
expect 0 "$B" export "$T/PS" --out "$T/plate0.ply" --json
[ "$(json_get "$T/out" "d['triangles']")" = 0 ] || fail "the one-sided plate meshed triangles: the test needs an empty mesh"
mentions "has no triangle"
expect 0 "$B" export "$T/S" --out "$T/m2.ply"
grep -q "has no triangle" "$T/err" && fail "a room's export warned of an empty mesh"

# Detail: a cap, an error bound.
expect 0 "$B" export "$T/S" --out "$T/c.glb" --max-triangles 2000 --json
n=$(json_get "$T/out" "d['triangles']")
[ "$n" -le 2000 ] && [ "$n" -ge 1500 ] || fail "--max-triangles 2000 wrote $n triangles"
[ "$(json_get "$T/out" "d['triangles_full']")" = "$nfull" ] || fail "triangles_full is not the full mesh's"
[ "$(json_get "$T/out" "d['simplify']['max_error_m']")" = None ] || fail "simplify.max_error_m is not null without --max-error"
validate "$T/c.glb"
expect 0 "$B" export "$T/S" --out "$T/e.ply" --max-error 0.002 --json
n=$(json_get "$T/out" "d['triangles']")
est=$(json_get "$T/out" "d['simplify']['error_estimate_m']")
[ "$n" -lt "$nfull" ] || fail "--max-error 0.002 kept all $n triangles"
[ "$(json_get "$T/out" "d['simplify']['max_triangles']")" = None ] || fail "simplify.max_triangles is not null without --max-triangles"
py -c "import sys; sys.exit(0 if float(sys.argv[1]) <= 0.002 else 1)" "$est" || fail "error estimate $est above 0.002"
# Measured: the simplified mesh against the full one.
expect 0 "$B" eval-surface --reference "$T/full.ply" --reconstruction "$T/e.ply" --json
med=$(json_get "$T/out" "d['accuracy']['median_m']" 2>/dev/null || echo nan)
py -c "import sys; sys.exit(0 if float(sys.argv[1]) <= 0.002 else 1)" "$med" || fail "median distance to the full mesh $med m"
# Points in every format.
expect 0 "$B" export "$T/S" --out "$T/p.glb" --points
validate "$T/p.glb"
expect 0 "$B" export "$T/S" --out "$T/p.obj" --points
grep -q "^f " "$T/p.obj" && fail "a point cloud OBJ has faces"
# Point elements name every vertex once (assimp and Blender read no vertex without an element).
[ "$(awk '/^p /{n += NF - 1} END {print n + 0}' "$T/p.obj")" = "$(grep -c '^v ' "$T/p.obj")" ] ||
    fail "p.obj: its p elements do not name every vertex"

# Refusals: nothing written, the message says why.
expect 5 "$B" export "$T/S" --out "$T/nofolder/m.ply"
mentions "the folder $T/nofolder does not exist"
expect 2 "$B" export "$T/S" --out "$T/x.stl"
mentions ".ply, .obj, .glb"
[ -e "$T/x.stl" ] && fail "x.stl written"
expect 2 "$B" export "$T/S" --out "$T/x.ply" --format fbx
mentions "--format"
expect 2 "$B" export "$T/S" --out "$T/x.ply" --points --max-triangles 100
# A cap that leaves no triangle: refused by name, not an empty mesh.
expect 2 "$B" export "$T/S" --out "$T/x.ply" --max-triangles 1
mentions "leaves none"
[ -e "$T/x.ply" ] && fail "a cap of 1 triangle wrote x.ply"
expect 2 "$B" replay "$T/seq" --out "$T/r3" --max-triangles 1
mentions "leaves none"
[ -e "$T/r3/mesh.ply" ] && fail "replay --max-triangles 1 wrote a mesh"
for f in trajectory.txt points.ply stats.json; do [ -s "$T/r3/$f" ] || fail "replay --max-triangles 1 left out $f"; done
json_get "$T/r3/stats.json" "d['mesh']['error']" | grep -q "leaves none" || fail "stats.json's mesh.error does not say why"
expect 2 "$B" replay "$T/seq" --out "$T/r2" --mesh-format stl
[ -e "$T/r2" ] && fail "a refused replay made its folder"
expect 5 "$B" export "$T/S" --out "$T/no/such/dir/x.glb"
mentions "$T/no/such/dir/x.glb"
mkdir "$T/ro" && echo old >"$T/ro/x.obj" && chmod 555 "$T/ro"
if ! touch "$T/ro/probe" 2>/dev/null; then # root writes anyway: then this case says nothing
    expect 5 "$B" export "$T/S" --out "$T/ro/x.obj"
    [ "$(cat "$T/ro/x.obj")" = old ] || fail "a failed export changed the old file"
else
    echo "skip: a read-only folder (root writes anyway; tests/fault fails every write of an export in turn)"
fi
rm -f "$T/ro/probe"
ls "$T" "$T/run" | grep -q "\.tmp\." && fail "temporary files left behind: $(ls "$T" | grep '\.tmp\.')"

echo "nfull=$nfull"
if [ "$fails" = 0 ] && [ "$validated" = 0 ]; then
    echo "test_export.sh: all else passed, but no glb was validated: skipped"
    exit 77
fi
finish test_export.sh
