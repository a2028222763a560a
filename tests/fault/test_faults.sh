#!/usr/bin/env bash
# Faults as a user meets them (docs/faults.md): bitfuse fuse, replay and
# export on a few tiny synthetic frames under fault_shim.so (LD_PRELOAD),
# which fails the N-th file write, fsync or close under the output folder
# (ENOSPC, EIO, a short write then ENOSPC, a short write alone) or the N-th
# Vulkan allocation (out of device memory), or loses the device at the N-th
# submit. Every faulted run must exit with its documented code, name the
# file (or the Vulkan call and buffer) and the reason, leave no temporary or
# half-written file (each output absent or whole: the same bytes as a clean
# run's where the run is deterministic, else a file that parses), keep the
# outputs the command promises (every other output is still written; after
# a GPU failure mid-scan the trajectory so far), and draw no Vulkan
# validation message (leaked objects included).
#
# By default each output file is failed once (the kinds and the point in
# it, write / fsync / close, rotate) and a sample of the Vulkan allocations;
# FAULT_FULL=1 walks every point with every kind.
# Usage: test_faults.sh path/to/bitfuse path/to/fault_shim.so
set -u
B=$1
SHIM=$2
FULL=${FAULT_FULL:-0}
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
. "$(dirname "$0")/../app/common.sh"
export BITFUSE_CACHE_DIR="$T/cache"
# Validation (leaked objects included) where Vulkan faults are injected and
# in the clean runs; the file faults come after the GPU work.
VALIDATION=1
O="$T/o" # every output of a faulted run lies under it: the shim's folder
mkdir -p "$O" "$T/nodata"
t0=$(date +%s)
runs=0

# 6 frames of 64x48 along a slow sideways move, noise-free: tracked, and
# fuse, replay and export give the same bytes run after run (frames.csv and
# stats.json hold times: they are checked for being whole instead).
py - "$T/traj.txt" <<'PY'
import sys
with open(sys.argv[1], "w") as f:
    for i in range(8):
        f.write("%.6f %.6f 0 0 0 0 0 1\n" % (1305031098.6659 + i / 30.0, 0.002 * i))
PY
expect 0 "$B" synth --trajectory "$T/traj.txt" --frames 6 --size 64x48 --camera 52.5,52.5,31.5,23.5 --data "$T/nodata" \
    --noise none --out "$T/seq"

# A fresh $O/run: absent for the commands that make their folder, empty
# for export (MKRUN=1).
MKRUN=0
ONE_OUTPUT=0
fresh() {
    rm -rf "$O/run"
    [ "$MKRUN" = 1 ] && mkdir -p "$O/run"
    return 0
}

# shim N KIND VK_N VK_KIND CMD...: CMD under the shim; rc, $T/out, $T/err, $T/rep.
shim() {
    local n=$1 kind=$2 vkn=$3 vkkind=$4
    shift 4
    rm -f "$T/rep"
    env BITFUSE_VALIDATION=$VALIDATION LD_PRELOAD="$SHIM" FAULT_DIR="$O" FAULT_N="$n" FAULT_KIND="$kind" FAULT_VK_N="$vkn" FAULT_VK_KIND="$vkkind" \
        FAULT_REPORT="$T/rep" "$@" >"$T/out" 2>"$T/err"
    rc=$?
    runs=$((runs + 1))
}
report() { awk -v k="$1" '$1 == k {$1 = ""; sub(/^ /, ""); print; exit}' "$T/rep" 2>/dev/null; }
# whole FILE: a PLY whose size is what its header says, JSON that parses,
# text that ends in a newline.
whole() {
    py - "$1" <<'PY'
import json, struct, sys
p = sys.argv[1]
data = open(p, "rb").read()
if p.endswith(".json"):
    json.loads(data)
elif p.endswith(".ply"):
    end = data.index(b"end_header\n") + len(b"end_header\n")
    size = {"char": 1, "uchar": 1, "short": 2, "ushort": 2, "int": 4, "uint": 4, "float": 4, "double": 8}
    body, elements = 0, []
    for line in data[:end].decode().splitlines():
        w = line.split()
        if w[0] == "element":
            elements.append([w[1], int(w[2]), 0, None])
        elif w[0] == "property" and w[1] == "list":
            elements[-1][3] = (size[w[2]], size[w[3]])
        elif w[0] == "property":
            elements[-1][2] += size[w[1]]
    off = end
    for name, n, stride, lst in elements:
        if lst is None:
            off += n * stride
        else:
            for _ in range(n):
                k = int.from_bytes(data[off:off + lst[0]], "little")
                off += lst[0] + k * lst[1]
    assert off == len(data), "%s: %d bytes, the header says %d" % (p, len(data), off)
else:
    assert data.endswith(b"\n"), "%s: no final newline" % p
PY
}
no_temp() { local t; t=$(find "$O" -name '*.tmp*' | head -n 3); [ -z "$t" ] || fail "$1: temporary files left: $t"; }
no_validation() { ! grep -q "vulkan validation" "$T/err" || fail "$1: validation messages: $(grep -m 2 "vulkan validation" "$T/err")"; }

# check_file_fault NAME REF OUT KIND DETERMINISTIC...: the run's outcome
# after a file fault in OUT (a fresh folder) against the clean run REF.
check_file_fault() {
    local name=$1 ref=$2 out=$3 kind=$4
    shift 4
    local fired final f
    fired=$(report fired)
    [ -n "$fired" ] || {
        fail "$name: the fault did not fire"
        return
    }
    final=$(echo "$fired" | sed -E 's/\.tmp(\.[0-9]+)?$//')
    if [ "$kind" = partial ]; then
        [ "$rc" = 0 ] || fail "$name: a short write alone must be continued: exit $rc ($(head -c 300 "$T/err"))"
    else
        [ "$rc" = 5 ] || fail "$name: exit $rc, expected 5 ($(head -c 300 "$T/err"))"
        grep -qF -- "$final" "$T/err" || fail "$name: stderr does not name $final: $(head -c 300 "$T/err")"
        case $kind in
        enospc) mentions "No space left on device" ;;
        eio) mentions "Input/output error" ;;
        short) grep -qE "No space left on device|Input/output error" "$T/err" || fail "$name: no reason: $(head -c 300 "$T/err")" ;;
        esac
        [ ! -e "$final" ] || fail "$name: the failed output $final exists"
    fi
    no_temp "$name"
    # Every other output is written, and whole.
    for f in $(ls "$ref"); do
        [ -d "$ref/$f" ] && continue
        if [ "$out/$f" = "$final" ] && [ "$kind" != partial ]; then continue; fi
        if [ ! -e "$out/$f" ]; then
            # One output in two files (export's m.obj and its m.mtl): none
            # of it when a part fails.
            [ "$ONE_OUTPUT" = 1 ] || fail "$name: $f was not written (the fault was in $(basename "$final"))"
            continue
        fi
        if [[ " $* " == *" $f "* ]]; then
            cmp -s "$ref/$f" "$out/$f" || fail "$name: $f differs from the clean run's"
        else
            whole "$out/$f" 2>>"$T/whole" || fail "$name: $f is not whole: $(tail -n 1 "$T/whole")"
        fi
    done
    # The loop above skips folders: a fault inside replay's store S/ (a
    # chunk, the trajectory, the index) fails its write, which renames none
    # of its files (docs/formats.md): a store written before opens as that
    # write; a new store whose only write failed is removed, and said so.
    if [[ "$final" == "$out/S/"* ]] && [ -e "$out/S" ]; then
        "$B" info "$out/S" --json >"$T/info" 2>&1 || fail "$name: the store does not open after a fault in $(basename "$final"): $(head -c 300 "$T/info")"
    elif [[ "$final" == "$out/S/"* ]]; then
        grep -q "^  store  *$out/S: not written" "$T/out" || fail "$name: the store is gone and the summary says: $(grep '^  store' "$T/out")"
    fi
}

# walk NAME REF DETERMINISTIC CMD...: the file faults of CMD (whose output
# folder is $O/run) against the clean run REF. Each file of these small
# runs is three points (its one write, fsync, close): by default every file
# of a run of up to 6 files, else the first, the middle one and the last
# four (replay: the trajectory, a store file, the mesh, the points,
# stats.json, frames.csv), each at one of its points with one kind, the
# point and the kind turning; FAULT_FULL walks each point with each kind.
KINDS=(enospc eio short)
walk() {
    local name=$1 ref=$2 det=$3
    shift 3
    local points n k kind files
    points=$(cat "$ref.points")
    files=$(((points + 2) / 3))
    VALIDATION=0
    for ((n = 1; n <= points; n++)); do
        for k in 0 1 2; do
            if [ "$FULL" = 1 ]; then
                kind=${KINDS[$k]}
            else
                local file=$(((n - 1) / 3)) in_file=$(((n - 1) % 3))
                [ "$files" -le 6 ] || [ "$file" = 0 ] || [ "$file" = $((files / 2)) ] || [ "$file" -ge $((files - 4)) ] ||
                    continue
                [ "$in_file" = $((file % 3)) ] && [ "$k" = 0 ] || continue
                kind=${KINDS[$((file % 3))]}
            fi
            fresh
            shim "$n" "$kind" 0 "" "$@"
            check_file_fault "$name point $n ($kind)" "$ref" "$O/run" "$kind" $det
        done
    done
    VALIDATION=1
}

# clean NAME CMD...: the clean run under the shim (the fault never fires),
# kept as $T/NAME; the number of file points and Vulkan calls beside it.
clean() {
    local name=$1
    shift
    fresh
    shim 0 enospc 1000000000 "" "$@"
    [ "$rc" = 0 ] || fail "$name: the clean run failed: exit $rc ($(head -c 300 "$T/err"))"
    [ -s "$T/rep" ] || {
        fail "$name: the shim did not load: $(head -c 300 "$T/err")"
        finish test_faults.sh
    }
    grep -q "fault_shim: stdio stream" "$T/err" && fail "$name: an output escapes the one write path: $(grep -m 1 fault_shim "$T/err")"
    no_validation "$name (clean)"
    rm -rf "$T/$name"
    mv "$O/run" "$T/$name"
    report points >"$T/$name.points"
    report vk >"$T/$name.vk"
    echo "$name: $(cat "$T/$name.points") file fault points, $(cut -d' ' -f1 "$T/$name.vk") Vulkan allocations, $(cut -d' ' -f2 "$T/$name.vk") submits"
}

# ---------------------------------------------------------------- fuse
clean fuse "$B" fuse "$T/seq" --poses groundtruth --out "$O/run"
walk fuse "$T/fuse" "mesh.ply points.ply" "$B" fuse "$T/seq" --poses groundtruth --out "$O/run"
# A short write alone is continued: the same files as the clean run.
rm -rf "$O/run"
shim 1 partial 0 "" "$B" fuse "$T/seq" --poses groundtruth --out "$O/run"
check_file_fault "fuse, a short write alone" "$T/fuse" "$O/run" partial mesh.ply points.ply

# ---------------------------------------------------------------- replay
# The store is written once, at the end (--store-every 0): its files' points
# come in the same order every run.
clean replay "$B" replay "$T/seq" --out "$O/run" --store "$O/run/S" --store-every 0
walk replay "$T/replay" "trajectory.txt mesh.ply points.ply" "$B" replay "$T/seq" --out "$O/run" --store "$O/run/S" \
    --store-every 0

# A view that cannot be written mid-scan (--view-every 1; the 2nd view's
# write): the scan stops there, and the trajectory so far, the map, points,
# frames.csv and stats.json (with output_error) are written.
rm -rf "$O/run"
shim 4 enospc 0 "" "$B" replay "$T/seq" --out "$O/run" --view-every 1
fired=$(report fired)
[[ "$fired" == */views/* ]] || fail "mid-scan: the fault hit $fired, not a view"
[ "$rc" = 5 ] || fail "mid-scan view failure: exit $rc ($(head -c 300 "$T/err"))"
mentions "$(echo "$fired" | sed -E 's/\.tmp(\.[0-9]+)?$//')"
mentions "the scan stops here"
lines=$(grep -vc '^#' "$O/run/trajectory.txt" 2>/dev/null)
[ "${lines:-0}" -ge 1 ] && [ "${lines:-0}" -lt 6 ] || fail "mid-scan: the trajectory has '$lines' poses, expected 1..5"
head -n "$(grep -c . "$O/run/trajectory.txt")" "$T/replay/trajectory.txt" | cmp -s - "$O/run/trajectory.txt" ||
    fail "mid-scan: the trajectory so far is not the clean run's beginning"
for f in mesh.ply points.ply frames.csv stats.json; do
    [ -f "$O/run/$f" ] && whole "$O/run/$f" || fail "mid-scan: $f not written whole"
done
py -c "import json,sys; assert 'views/' in json.load(open(sys.argv[1]))['output_error']" "$O/run/stats.json" ||
    fail "mid-scan: stats.json has no output_error naming the view"
no_temp "mid-scan"

# The scene store cannot be written mid-scan (its first chunk file, at the
# first flush): the scan stops, the rest is written, exit 5 naming the
# chunk file; the new store, with no write whole, is removed (a rerun into
# the same folder is not refused), and the summary says it was not written.
rm -rf "$O/run"
shim 1 enospc 0 "" "$B" replay "$T/seq" --out "$O/run" --store "$O/run/S" --store-every 0.001
[ "$rc" = 5 ] || fail "mid-scan store failure: exit $rc ($(head -c 300 "$T/err"))"
mentions "$O/run/S/chunks/"
mentions "No space left on device"
for f in trajectory.txt mesh.ply points.ply frames.csv stats.json; do
    [ -f "$O/run/$f" ] && whole "$O/run/$f" || fail "mid-scan store failure: $f not written whole"
done
no_temp "mid-scan store failure"
[ ! -e "$O/run/S" ] || fail "mid-scan store failure: the new store without a whole write was left: $(find "$O/run/S")"
grep -q "^  store  *$O/run/S: not written" "$T/out" || fail "mid-scan store failure: $(grep '^  store' "$T/out")"

# ---------------------------------------------------------------- export
MKRUN=1 # export writes a file into a folder that exists
ONE_OUTPUT=1
for fmt in ply obj glb; do
    clean "export_$fmt" "$B" export "$T/replay/S" --out "$O/run/m.$fmt"
    walk "export_$fmt" "$T/export_$fmt" "m.$fmt m.mtl" "$B" export "$T/replay/S" --out "$O/run/m.$fmt"
done

# A disk the OBJ fills while it is written (an OBJ over the output
# buffer, 1 MiB, written as it grows) leaves its .mtl none either: the
# error names the OBJ, the file that failed first (it named the .mtl).
expect 0 "$B" synth --trajectory "$T/traj.txt" --frames 3 --size 320x240 --camera 262.5,262.5,159.5,119.5 \
    --data "$T/nodata" --noise none --out "$T/seq320"
expect 0 "$B" replay "$T/seq320" --out "$T/r320" --no-mesh --store "$T/r320/S"
fresh
shim 2 full 0 "" "$B" export "$T/r320/S" --out "$O/run/m.obj"
[[ "$(report fired)" == "$O/run/m.obj.tmp"* ]] || fail "full disk, export m.obj: the fault hit '$(report fired)', not the OBJ's second write"
[ "$rc" = 5 ] || fail "full disk, export m.obj: exit $rc, expected 5 ($(head -c 300 "$T/err"))"
mentions "$O/run/m.obj: "
grep -q "m\.mtl" "$T/err" && fail "full disk, export m.obj: the error names the .mtl: $(head -c 300 "$T/err")"
[ -z "$(ls "$O/run")" ] || fail "full disk, export m.obj: left $(ls "$O/run")"

MKRUN=0
ONE_OUTPUT=0

# ---------------------------------------------------------------- record
# A log streams into its final name by design: after a failed write the
# command exits 5 naming it, and the log replays up to its last whole frame
# (or is absent when its header never made it).
mkdir -p "$O/rec"
rm -f "$T/rep"
shim 0 enospc 0 "" "$B" record --device "$T/seq" --out "$O/rec/l.bflog"
[ "$rc" = 0 ] || fail "record: the clean run failed: exit $rc ($(head -c 300 "$T/err"))"
grep -q "fault_shim: stdio stream" "$T/err" && fail "record: the log escapes the injection: $(grep -m 1 fault_shim "$T/err")"
np=$(report points)
echo "record: $np file fault points"
for ((i = 3; i < 3 * (np + 1); i++)); do
    n=$((i / 3))
    # The header, frames spread over the log, its index and footer, and
    # the stats file beside it (its last three points), one kind each;
    # FAULT_FULL: every point with every kind.
    if [ "$FULL" = 1 ]; then
        kind=${KINDS[$((i % 3))]}
    else
        [ $((i % 3)) = 0 ] && { [ $((n % 5)) = 1 ] || [ "$n" -ge $((np - 4)) ]; } || continue
        kind=${KINDS[$((n % 3))]}
    fi
    rm -rf "$O/rec" && mkdir -p "$O/rec"
    shim "$n" "$kind" 0 "" "$B" record --device "$T/seq" --out "$O/rec/l.bflog"
    [ "$rc" = 5 ] || fail "record point $n ($kind): exit $rc, expected 5 ($(head -c 300 "$T/err"))"
    fired=$(report fired)
    mentions "$(echo "$fired" | sed -E 's/\.tmp(\.[0-9]+)?$//')"
    no_temp "record point $n"
    # The log replays to its last whole frame, and is absent without one:
    # its header is point 1 and each of the 6 frames three points more
    # (docs/faults.md), so a fault at point n leaves (n - 2) / 3 whole frames.
    want=$(((n - 2) / 3))
    [ "$want" -gt 6 ] && want=6
    if [ "$want" = 0 ]; then
        [ ! -e "$O/rec/l.bflog" ] || fail "record point $n: a log without a whole frame was left"
    elif "$B" info "$O/rec/l.bflog" --json >"$T/out" 2>"$T/err"; then
        got=$(py -c "import json,sys; print(json.load(open(sys.argv[1]))['frames'])" "$T/out")
        [ "$got" = "$want" ] || fail "record point $n: the log replays '$got' frames, expected $want"
    else
        fail "record point $n: the log does not read: $(head -c 300 "$T/err")"
    fi
done

# ---------------------------------------------------------------- Vulkan
# The N-th allocation fails: a clean error naming the call and the buffer
# (exit 1, out of memory), nothing half written, no validation message
# (leaked objects included), no crash. Sampled: the first, spread over the
# start-up, and the last (the map's read-back at the end, after the
# trajectory was written).
read -r n_alloc n_submit <"$T/replay.vk"
if [ "$FULL" = 1 ]; then
    sample=$(seq 1 "$n_alloc")
else
    sample="1 $((n_alloc / 3)) $((2 * n_alloc / 3)) $((n_alloc - 1)) $n_alloc"
fi
for k in $sample; do
    rm -rf "$O/run"
    shim 0 enospc "$k" "" "$B" replay "$T/seq" --out "$O/run"
    name="Vulkan allocation $k ($(report fired-vk))"
    [ -n "$(report fired-vk)" ] || fail "$name: did not fire"
    [ "$rc" = 1 ] || [ "$rc" = 4 ] || fail "$name: exit $rc, expected 1 or 4 ($(head -c 300 "$T/err"))"
    grep -qE "vk[A-Z][A-Za-z]+.*VK_ERROR_OUT_OF_DEVICE_MEMORY" "$T/err" ||
        fail "$name: the message does not say out of device memory: $(head -c 300 "$T/err")"
    no_validation "$name"
    no_temp "$name"
    [ -d "$O/run" ] && [ -z "$(ls -A "$O/run")" ] && fail "$name: an empty output folder was left behind"
    for f in $(ls "$O/run" 2>/dev/null); do
        [ -f "$O/run/$f" ] || continue
        whole "$O/run/$f" 2>>"$T/whole" || fail "$name: $f is not whole"
    done
    # Past the first frame the trajectory so far is kept.
    if grep -q "the scan stops after" "$T/err"; then
        [ -s "$O/run/trajectory.txt" ] || fail "$name: a GPU failure mid-scan lost the trajectory"
    fi
done

# The device is lost at the middle submit of a scan with --store: exit 4
# naming VK_ERROR_DEVICE_LOST; the trajectory of the frames before it is
# written (the clean run's beginning) and the store reopens with what its
# flushes kept.
rm -rf "$O/run"
shim 0 enospc $((n_submit / 2)) lost "$B" replay "$T/seq" --out "$O/run" --store "$O/run/S" --store-every 0.001
[ "$rc" = 4 ] || fail "device lost: exit $rc, expected 4 ($(head -c 300 "$T/err"))"
mentions "VK_ERROR_DEVICE_LOST"
no_validation "device lost"
no_temp "device lost"
[ -s "$O/run/trajectory.txt" ] || fail "device lost: no trajectory"
head -n "$(grep -c . "$O/run/trajectory.txt")" "$T/replay/trajectory.txt" | cmp -s - "$O/run/trajectory.txt" ||
    fail "device lost: the trajectory so far is not the clean run's beginning"
# Frames before the lost submit were flushed (--store-every 0.001: each
# frame while the writer is free): the store holds 1 to all of the frames
# of the trajectory written.
[ -d "$O/run/S" ] || fail "device lost: no store"
expect 0 "$B" info "$O/run/S" --json
py -c "import json,sys; assert 1 <= json.load(open(sys.argv[1]))['frames'] <= int(sys.argv[2])" "$T/out" \
    "$(grep -vc '^#' "$O/run/trajectory.txt")" || fail "device lost: the store keeps no frame: $(head -c 300 "$T/out")"

echo "test_faults.sh: $runs runs under the shim in $(($(date +%s) - t0)) s"
[ -n "${FAULT_SHOW:-}" ] && cat "$T/err"
finish test_faults.sh
