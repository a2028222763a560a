#!/usr/bin/env bash
# A spill failure mid-scan (docs/faults.md): bitfuse replay walks down a row
# of three rooms and back with a small stream radius and no CPU cache
# (--cache-budget 0), so every chunk that leaves the GPU pools goes to a
# chunk file in the stream's spill folder under $TMPDIR and comes back on
# the way back. Under fault_shim.so (FAULT_DIR=$TMPDIR) the first spill
# write fails with ENOSPC, or a later chunk's fsync with EIO. The spill
# folder is scratch, not an output: the scan must go on with the chunk in
# memory, warn once naming the chunk file and the reason, say so in
# stats.json (stream.spill_error), spill nothing more, and give the same
# map, trajectory and points as the clean run; nothing is left in $TMPDIR.
# Usage: test_spill_fault.sh path/to/bitfuse path/to/fault_shim.so
set -u
B=$1
SHIM=$2
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
. "$(dirname "$0")/../app/common.sh"
export BITFUSE_CACHE_DIR="$T/cache"
t0=$(date +%s)

# rooms_walk.py's walk (bench/), 0.15 m a frame: down 3 rooms and back, 121
# noise-free frames of 80x60. Fused at the true poses: the spill, not the
# tracker on frames this small, is under test.
awk -v rooms=3 -v step=0.15 'BEGIN {
    L = (rooms - 1) * 4 + 1; n = int(L / step + 0.5); pi = 3.14159265358979
    for (i = 0; i <= 2 * n; i++) {
        z = i <= n ? i * step : L - (i - n) * step
        yaw = 15 * pi / 180 * sin(2 * pi * i / 120)
        printf "%.6f 0 0 %.6f 0 %.9f 0 %.9f\n", 1305031100 + i / 30.0, z, sin(yaw / 2), cos(yaw / 2)
    }
}' >"$T/walk.txt"
expect 0 "$B" synth --scene rooms:3 --trajectory "$T/walk.txt" --frames 121 --size 80x60 \
    --camera 65.625,65.625,39.5,29.5 --noise none --out "$T/seq"
[ -f "$T/seq/depth.txt" ] || { finish test_spill_fault; exit 1; }

# run NAME [FAULT_N KIND]: the replay under the shim, its spill folder under $T/tmp.
run() {
    local name=$1 n=${2:-0} kind=${3:-enospc}
    rm -rf "$T/tmp" "$T/$name.rep"
    mkdir -p "$T/tmp"
    env TMPDIR="$T/tmp" LD_PRELOAD="$SHIM" FAULT_DIR="$T/tmp" FAULT_N="$n" FAULT_KIND="$kind" \
        FAULT_REPORT="$T/$name.rep" "$B" replay "$T/seq" --out "$T/$name" --no-mesh --fuse-at-groundtruth \
        --stream-radius 1 --cache-budget 0 >"$T/out" 2>"$T/err"
    rc=$?
    cp "$T/err" "$T/$name.err"
    [ -z "$(ls -A "$T/tmp")" ] || fail "$name: left in TMPDIR: $(ls -R "$T/tmp" | head -5)"
}

# field NAME KEY: stats.json's stream.KEY of run NAME ("" when absent).
field() {
    py - "$T/$1/stats.json" "$2" <<'PY'
import json, sys
v = json.load(open(sys.argv[1]))["stream"].get(sys.argv[2])
print("" if v is None else v)
PY
}

run clean
[ "$rc" = 0 ] || fail "clean run: exit $rc: $(tail -c 400 "$T/clean.err")"
points=$(awk '/^points/ {print $2}' "$T/clean.rep")
to_disk=$(field clean chunks_to_disk)
from_disk=$(field clean chunks_from_disk)
# The walk must exercise the disk tier both ways, or the faults test nothing.
[ "${to_disk:-0}" -ge 3 ] && [ "${from_disk:-0}" -ge 1 ] && [ "${points:-0}" -ge 12 ] ||
    fail "clean run: $to_disk chunks to disk, $from_disk back, $points fault points in the spill folder"
[ -z "$(field clean spill_error)" ] || fail "clean run: a spill error: $(field clean spill_error)"
grep -q "spill folder" "$T/clean.err" && fail "clean run warns about the spill folder"

# faulted NAME N KIND REASON: the N-th spill write/fsync/close fails.
faulted() {
    local name=$1 n=$2 kind=$3 reason=$4
    run "$name" "$n" "$kind"
    [ "$rc" = 0 ] || fail "$name: exit $rc, expected 0 (the scan goes on): $(tail -c 400 "$T/$name.err")"
    local fired
    fired=$(sed -n 's/^fired //p' "$T/$name.rep")
    [ -n "$fired" ] || { fail "$name: fault point $n never reached"; return; }
    case "$fired" in */bitfuse-spill-*/chunks/c_*.bfc*) ;; *) fail "$name: fired outside the spill folder: $fired" ;; esac
    fired=${fired%.tmp} # messages name the chunk file, not its temporary name
    # One warning, naming the chunk file and the reason.
    [ "$(grep -c "spill folder is not used again" "$T/$name.err")" = 1 ] ||
        fail "$name: expected one warning about the spill folder: $(grep -i spill "$T/$name.err" | head -3)"
    grep -qF "$fired" "$T/$name.err" && grep -qF "$reason" "$T/$name.err" ||
        fail "$name: the warning does not name $fired and '$reason': $(grep -i spill "$T/$name.err" | head -2)"
    local err
    err=$(field "$name" spill_error)
    case "$err" in *"$fired"*"$reason"*) ;; *) fail "$name: stats.json stream.spill_error is '$err'" ;; esac
    # Nothing spilled after the failure; every chunk still came back.
    [ "$(field "$name" chunks_to_disk)" -lt "$to_disk" ] || fail "$name: spilled on after the failure"
    [ "$(field "$name" chunks_in)" = "$(field clean chunks_in)" ] || fail "$name: chunks in differ from the clean run"
    # The same scan: map digest, trajectory and points as the clean run's.
    local d0 d1
    d0=$(py -c 'import json, sys; print(json.load(open(sys.argv[1]))["map_digest"])' "$T/clean/stats.json")
    d1=$(py -c 'import json, sys; print(json.load(open(sys.argv[1]))["map_digest"])' "$T/$name/stats.json")
    [ -n "$d0" ] && [ "$d0" = "$d1" ] || fail "$name: map_digest $d1, clean $d0"
    for f in trajectory.txt points.ply; do
        cmp -s "$T/clean/$f" "$T/$name/$f" || fail "$name: $f differs from the clean run's"
    done
}
# The first write of the first chunk file (a disk full from the start);
# the fsync of the third chunk file (4 points a file: write, write, fsync,
# close), after two chunks are on disk: those still come back from it.
faulted enospc 1 enospc "No space left on device"
faulted eio 11 eio "Input/output error"
[ "$(field eio chunks_from_disk)" -ge 1 ] || fail "eio: the chunks spilled before the failure did not come back"

echo "test_spill_fault: $to_disk chunks to disk and $from_disk back in the clean run, $points fault points; $(($(date +%s) - t0)) s"
finish test_spill_fault
