#!/usr/bin/env bash
# The scene store as a user meets it: replay --store, info, export, a
# corrupt chunk file, resuming in two halves, kill -9 at 20 random moments
# (the store reopens, exports and resumes every time), and a full disk.
# Usage: test_store.sh path/to/bitfuse
set -u
B=$1
T=$(mktemp -d)
trap 'umount "$T/tiny" 2>/dev/null; rm -rf "$T"' EXIT
. "$(dirname "$0")/common.sh"
json_get() { py -c "import json,sys; d=json.load(open(sys.argv[1])); print(eval(sys.argv[2]))" "$1" "$2"; }
# before it flushes its output.

# A 60-frame synthetic sequence, 2 s at 30 Hz: a slow sideways move and turn.
py - "$T/traj.txt" <<'PY'
import sys, math
with open(sys.argv[1], "w") as f:
    for i in range(70):
        a = 0.003 * i
        f.write("%.6f %.6f 0 0 0 %.6f 0 %.6f\n" % (1305031098.6659 + i / 30.0, 0.004 * i, math.sin(a / 2), math.cos(a / 2)))
PY
mkdir "$T/nodata"
expect 0 "$B" synth --trajectory "$T/traj.txt" --frames 60 --size 160x120 --camera 131.25,131.25,79.5,59.5 \
    --data "$T/nodata" --noise none --out "$T/seq"
SEQ="$T/seq"

# One uninterrupted scan into a store.
expect 0 "$B" replay "$SEQ" --out "$T/full" --no-mesh --store "$T/S"
cp "$T/out" "$T/full.out"
[ -f "$T/S/store.json" ] && [ -f "$T/S/trajectory.bin" ] || fail "the store has no index or trajectory"
writes=$(json_get "$T/full/stats.json" "d['store']['writes']")
[ "${writes:-0}" -ge 1 ] || fail "stats.json store.writes is '$writes'"
expect 0 "$B" info "$T/S" --json
json_get "$T/out" "d['frames']" | grep -qx 60 || fail "info: frames is not 60: $(head -c 300 "$T/out")"
chunks=$(json_get "$T/out" "d['chunks']")
bricks=$(json_get "$T/out" "d['bricks']")
mapb=$(json_get "$T/full/stats.json" "d['bricks']")
# (each compare also needs its lookups to have found a number: "" = "" is no match)
[ -n "$bricks" ] && [ "$bricks" = "$mapb" ] || fail "the store holds '$bricks' bricks, the scan's map '$mapb'"
mapc=$(json_get "$T/full/stats.json" "d['chunks_with_bricks']")
[ -n "$chunks" ] && [ "$chunks" = "$mapc" ] || fail "the store holds '$chunks' chunks, the scan's map '$mapc' holding bricks"
# The summary names the store and what it holds, as info counts it.
grep -q "^  store  *$T/S: $chunks chunks, $bricks bricks" "$T/full.out" || fail "replay's summary does not name the store: $(cat "$T/full.out")"
expect 0 "$B" info "$T/S"
grep -q "last pose" "$T/out" || fail "info does not print the last pose"
expect 2 "$B" info "$T/S" --frames 3
mentions "is a scene store"
# A run's folder holding its store as DIR/store, as export takes it; a
# sequence folder holding one is still the sequence.
mkdir "$T/run" && cp -r "$T/S" "$T/run/store"
expect 0 "$B" info "$T/run" --json
json_get "$T/out" "d['kind']" | grep -qx bitfuse-store || fail "info DIR does not read DIR/store: $(head -c 300 "$T/out")"
cp -r "$SEQ" "$T/seqstore" && cp -r "$T/S" "$T/seqstore/store"
expect 0 "$B" info "$T/seqstore" --json
json_get "$T/out" "d['kind']" | grep -qx tum || fail "info of a sequence holding a store/ is not the sequence's"
rm -rf "$T/run" "$T/seqstore"

# One writer a store: a scan into a store another process holds (flock(1) here, as a running scan
# holds it) is refused before it touches it, and the store is left as it was.
if command -v flock >/dev/null; then
    cp -r "$T/S" "$T/locked"
    before=$(cd "$T/locked" && find . -type f | sort | xargs md5sum | md5sum)
    expect 2 flock "$T/locked" "$B" replay "$SEQ" --out "$T/locked-run" --no-mesh --store "$T/locked" --resume
    mentions "$T/locked: another bitfuse is writing this store"
    [ "$(cd "$T/locked" && find . -type f | sort | xargs md5sum | md5sum)" = "$before" ] || fail "a refused scan changed the locked store"
    [ -e "$T/locked-run" ] && fail "a refused scan made its output folder"
    # Without --resume too: the store being written is what is said, not "resume it".
    expect 2 flock "$T/locked" "$B" replay "$SEQ" --out "$T/locked-run" --no-mesh --store "$T/locked"
    mentions "$T/locked: another bitfuse is writing this store"
    [ "$(cd "$T/locked" && find . -type f | sort | xargs md5sum | md5sum)" = "$before" ] || fail "a refused scan changed the locked store"
    rm -rf "$T/locked"
fi
# A store of a newer version: unreadable input for this build (exit 3), by every reader.
cp -r "$T/S" "$T/newer"
py - "$T/newer/store.json" <<'PY'
import json, sys
d = json.load(open(sys.argv[1])); d["version"] = 9; json.dump(d, open(sys.argv[1], "w"))
PY
expect 3 "$B" info "$T/newer"
mentions "store version 9; this bitfuse reads version"
expect 3 "$B" export "$T/newer" --out "$T/newer.ply"
mentions "store version 9; this bitfuse reads version"
expect 3 "$B" render --map "$T/newer" --pose "0 0 0 0 0 0 1" --size 64x48 --out "$T/newer.png"
mentions "store version 9; this bitfuse reads version"
expect 3 "$B" replay "$SEQ" --out "$T/newer-run" --no-mesh --store "$T/newer" --resume
mentions "store version 9; this bitfuse reads version"
{ [ -e "$T/newer.ply" ] || [ -e "$T/newer.png" ]; } && fail "a newer store was exported or rendered"
rm -rf "$T/newer" "$T/newer-run"

# export: a mesh and the points, without the loop.
expect 0 "$B" export "$T/S" --out "$T/m.ply"
head -c 400 "$T/m.ply" | grep -aq "element face [1-9]" || fail "export wrote no mesh"
expect 0 "$B" export "$T/S" --out "$T/p.ply" --points --json
pts=$(json_get "$T/out" "d['vertices']")
ref=$(head -c 300 "$T/full/points.ply" | awk '/element vertex/ {print $3}')
[ -n "$pts" ] && [ "$pts" = "$ref" ] || fail "export --points wrote '$pts' points, replay's points.ply '$ref'"
# A run's folder holding its store as DIR/store, as render and view take it.
mkdir "$T/run" && cp -r "$T/S" "$T/run/store"
expect 0 "$B" export "$T/run" --out "$T/p2.ply" --points --json
pts=$(json_get "$T/out" "d['vertices']")
[ -n "$pts" ] && [ "$pts" = "$ref" ] || fail "export of DIR holding DIR/store wrote '$pts' points, not '$ref'"
[ "$(json_get "$T/out" "d['store']")" = "$T/run/store" ] || fail "export of DIR: the store is not named DIR/store"

# Not a store among a run's results, nor anything inside a store (its chunks/ would hold a folder).
expect 2 "$B" replay "$SEQ" --out "$T/u1" --no-mesh --store "$T/full"
mentions "--store $T/full holds other files ("
expect 2 "$B" replay "$SEQ" --out "$T/u1" --no-mesh --store "$T/S/chunks/inner"
mentions "is inside the scene store $T/S"
expect 2 "$B" replay "$SEQ" --out "$T/S/results" --no-mesh
mentions "--out $T/S/results is inside the scene store $T/S"
[ -e "$T/u1" ] || [ -e "$T/S/results" ] || [ -e "$T/S/chunks/inner" ] && fail "a refused scan made a folder"
expect 2 "$B" replay "$SEQ" --out "$T/NS/results" --no-mesh --store "$T/NS"
mentions "--out $T/NS/results is inside --store $T/NS"
# A folder above that only looks like a store (a chunks/ of something else, any store.json) is no store.
mkdir -p "$T/proj/chunks" && echo '{}' >"$T/proj/store.json"
expect 0 "$B" replay "$SEQ" --out "$T/proj/run1" --no-mesh --frames 3
# Usage: a second scan into a used store, --resume without --store, no store at all.
expect 2 "$B" replay "$SEQ" --out "$T/x" --store "$T/S"
mentions "--resume"
expect 2 "$B" replay "$SEQ" --out "$T/x" --resume
expect 3 "$B" export "$T/nothing" --out "$T/x.ply"
# A run's outputs never go in among a store's files.
expect 2 "$B" replay "$SEQ" --out "$T/S" --no-mesh
mentions "is a scene store"
expect 2 "$B" fuse "$SEQ" --out "$T/S" --poses groundtruth
mentions "is a scene store"
expect 2 "$B" replay "$SEQ" --out "$T/same" --store "$T/same" --no-mesh
mentions "is --store's folder"
[ ! -e "$T/same" ] || fail "a refused run made its folder"
expect 2 "$B" replay "$SEQ" --out "$T/./same2" --store "$T/same2/" --no-mesh
mentions "is --store's folder"
expect 2 "$B" replay "$SEQ" --out "$T/same3" --store "$T/same3/." --no-mesh
mentions "is --store's folder"
expect 2 "$B" replay "$SEQ" --out "$T/same4" --store "$T/x/../same4" --no-mesh
mentions "is --store's folder"
# Nor a store's files among the sequence's (it would then read as a store).
expect 2 "$B" replay "$SEQ" --out "$T/seqstore" --store "$SEQ" --no-mesh
mentions "which is being read"
[ -e "$SEQ/chunks" ] && fail "a refused run wrote a store into the sequence"
expect 2 "$B" replay "$SEQ" --out "$T/seqstore" --store "" --no-mesh
mentions "--store needs a folder"
mkdir "$T/plain"
expect 3 "$B" export "$T/plain" --out "$T/x.ply"
mentions "$T/plain: not a scene store (bitfuse replay|live --store), nor a folder holding one as store/"
expect 2 "$B" export "$T/S"

# A corrupt chunk file is named, left out, and the rest still exports.
cp -r "$T/S" "$T/C"
f=$(ls "$T/C/chunks" | head -n 1)
printf 'XXXX' | dd of="$T/C/chunks/$f" bs=1 seek=120 conv=notrunc 2>/dev/null
expect 0 "$B" info "$T/C" --json
mentions "$f"
[ "$(json_get "$T/out" "d['bad_chunk_files']")" = 1 ] || fail "info: bad_chunk_files is not 1"
[ "$(json_get "$T/out" "d['chunks']")" = $((chunks - 1)) ] || fail "info: the other chunks were not loaded"
expect 0 "$B" export "$T/C" --out "$T/c.ply" --points
mentions "$f"
# A chunk the index lists whose file is gone is counted with the bad one
# as not loaded.
rm "$T/C/chunks/$(ls "$T/C/chunks" | tail -n 1)"
expect 0 "$B" export "$T/C" --out "$T/c2.ply" --json
mentions "the index lists were not loaded (a file missing or bad): left out"
py -c "import json,sys; d=json.load(open(sys.argv[1])); assert d['chunks_missing'] == 2 and d['chunk_files_left_out'] == 1, d" \
    "$T/out" || fail "export: a missing chunk file not counted"
# Resuming such a store is refused, naming the bad file, and no chunk
# file is touched: the resumed scan's first write would have replaced or
# removed every chunk the index lists that did not load.
before=$(cd "$T/C/chunks" && md5sum * | md5sum)
expect 3 "$B" replay "$SEQ" --out "$T/cres" --no-mesh --store "$T/C" --resume
mentions "resuming would replace or remove them"
mentions "$f"
[ "$(cd "$T/C/chunks" && md5sum * | md5sum)" = "$before" ] || fail "a refused resume changed the chunk files"
# What the refusal advises: with the bad file moved aside (the index still
# lists it, and the one removed above), the scan resumes without them.
cp -r "$T/C" "$T/C2" && mv "$T/C2/chunks/$f" "$T/bad-$f"
expect 0 "$B" replay "$SEQ" --out "$T/c2res" --no-mesh --store "$T/C2" --resume
mentions "2 listed chunks are gone: the scan resumes without them"
# Every listed chunk gone (chunks/ emptied or not mounted): refused,
# saying so, with nothing bad to move aside.
cp -r "$T/S" "$T/E" && rm "$T/E/chunks/"*
before=$(cd "$T/E" && find . -type f | sort | xargs md5sum | md5sum)
expect 3 "$B" replay "$SEQ" --out "$T/eres" --no-mesh --store "$T/E" --resume
mentions "none of the"
grep -q "none bad" "$T/err" && fail "the all-gone refusal speaks of bad files: $(cat "$T/err")"
[ "$(cd "$T/E" && find . -type f | sort | xargs md5sum | md5sum)" = "$before" ] || fail "a refused resume of an emptied store changed it"
# The same when files remain that the index does not list (loaded as
# written after it): still nothing the index lists is there.
cp -r "$T/S" "$T/U"
py - "$T/U/store.json" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
d["chunks"] = [{"key": [99, 99, 99], "bricks": 1, "bytes": 100, "xxh3": "0" * 16}]
json.dump(d, open(sys.argv[1], "w"))
PY
expect 3 "$B" replay "$SEQ" --out "$T/ures" --no-mesh --store "$T/U" --resume
mentions "the one chunk file its index lists is not there"
# store.json has no checksum: one wrong level makes every chunk file
# inconsistent with it. Resume is refused with every file kept; export
# says there is nothing to export instead of writing an empty mesh.
cp -r "$T/S" "$T/M"
py - "$T/M/store.json" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
d["max_level"] = 2
json.dump(d, open(sys.argv[1], "w"))
PY
before=$(cd "$T/M/chunks" && md5sum * | md5sum)
expect 3 "$B" replay "$SEQ" --out "$T/mres" --no-mesh --store "$T/M" --resume
mentions "resuming would replace or remove them"
[ "$(cd "$T/M/chunks" && md5sum * | md5sum)" = "$before" ] || fail "a refused resume over a wrong index changed the chunk files"
expect 3 "$B" export "$T/M" --out "$T/mlevel.ply"
mentions "no chunk could be loaded"
[ -e "$T/mlevel.ply" ] && fail "export of a store with no loadable chunk wrote a file"
# Index and trajectory both damaged: a store that was written (not one
# killed before its first write, which starts anew), so not cleared.
cp -r "$T/S" "$T/D"
head -c 40 "$T/S/store.json" >"$T/D/store.json"
printf 'X' | dd of="$T/D/trajectory.bin" bs=1 seek=40 conv=notrunc 2>/dev/null
before=$(cd "$T/D" && find . -type f | sort | xargs md5sum | md5sum)
expect 3 "$B" replay "$SEQ" --out "$T/dres" --no-mesh --store "$T/D" --resume
mentions "no last pose to resume from"
[ "$(cd "$T/D" && find . -type f | sort | xargs md5sum | md5sum)" = "$before" ] || fail "a store with a damaged index and trajectory was changed"
# info of it: the write count lived in the index, so it is unknown, not 0.
expect 0 "$B" info "$T/D"
grep -q "writes unknown (store.json unreadable)" "$T/out" || fail "info of an unreadable index: $(head -1 "$T/out")"
expect 0 "$B" info "$T/D" --json
json_get "$T/out" "d['flush']" | grep -qx None || fail "info --json: flush is not null without an index"
# Index and trajectory both removed, keyframes.bin (written after the
# trajectory) still there: a store that was written, so not cleared either.
[ -e "$T/S/keyframes.bin" ] || fail "the test store has no keyframes.bin"
cp -r "$T/S" "$T/D2" && rm "$T/D2/store.json" "$T/D2/trajectory.bin"
before=$(cd "$T/D2" && find . -type f | sort | xargs md5sum | md5sum)
expect 3 "$B" replay "$SEQ" --out "$T/d2res" --no-mesh --store "$T/D2" --resume
mentions "unreadable or gone"
[ "$(cd "$T/D2" && find . -type f | sort | xargs md5sum | md5sum)" = "$before" ] || fail "a store without its index and trajectory was cleared"
# A new store whose scan fails before its first write (a corrupt first
# frame) is not left behind as an empty store the next run would refuse.
cp -r "$SEQ" "$T/badfirst"
first=$(awk '!/^#/ {print $2; exit}' "$T/badfirst/depth.txt")
rm "$T/badfirst/$first" && echo "not a png" >"$T/badfirst/$first"
expect 3 "$B" replay "$T/badfirst" --out "$T/bf" --no-mesh --store "$T/bf/store"
[ -e "$T/bf" ] && fail "a failed scan left its new output folder and store: $(find "$T/bf")"
expect 0 "$B" replay "$SEQ" --out "$T/bf" --no-mesh --frames 5 --store "$T/bf/store"

# Not over the store it reads; not from a folder that only looks like one.
expect 2 "$B" export "$T/C" --out "$T/C/store.json" --format ply
mentions "which is being read"
mkdir "$T/fake" && echo hi >"$T/fake/store.json"
expect 3 "$B" export "$T/fake" --out "$T/fake.ply"
mentions "not a scene store"
# Not a new file among the store's either (a chunk file there is read as the store's).
expect 2 "$B" export "$T/C" --out "$T/C/chunks/c_9_9_9.bfc" --format ply
mentions "which is being read"
[ -e "$T/C/chunks/c_9_9_9.bfc" ] && fail "export wrote a new file into the store's chunks"
# A store stopped before its first write: an empty chunks/ and nothing else.
mkdir -p "$T/unwritten/chunks"
expect 3 "$B" export "$T/unwritten" --out "$T/unwritten.ply"
mentions "not a scene store (or one stopped before its first write)"
[ -e "$T/unwritten.ply" ] && fail "export of a store never written wrote a mesh"

# Resume: the scan in two halves ends within tracking tolerance of the
# uninterrupted one (both start at the true pose; noise-free frames). The
# resumed scan passes over the stored frames without reading their images:
# one damaged since (frame 10's depth here) does not stop it.
cp -r "$SEQ" "$T/seqh"
expect 0 "$B" replay "$T/seqh" --out "$T/h1" --no-mesh --frames 30 --store "$T/H"
printf 'not a PNG' >"$T/seqh/$(awk '!/^#/ {i++; if (i == 11) print $2}' "$T/seqh/depth.txt")"
# Not without colour over a store with colour (it would drop it for good).
expect 2 "$B" replay "$T/seqh" --out "$T/h2off" --no-mesh --store "$T/H" --resume --colour off
mentions "the store holds colour"
[ -e "$T/h2off" ] && fail "a refused resume made its output folder"
expect 0 "$B" replay "$T/seqh" --out "$T/h2" --no-mesh --store "$T/H" --resume
# The frames passed over are counted (a recording whose clock starts over would lose them: said).
grep -q "30 frames at or before the stored scan's last time passed over as already in the store" "$T/out" ||
    fail "the resumed scan's summary does not count the frames passed over: $(grep input "$T/out")"
[ "$(json_get "$T/h2/stats.json" "d['frames_already_stored']")" = 30 ] || fail "stats.json frames_already_stored is not 30"
# Resumed again: every frame is the store's already, and that is said.
cp -r "$T/H" "$T/H3"
expect 0 "$B" replay "$T/seqh" --out "$T/h3" --no-mesh --store "$T/H3" --resume
mentions "are at or before the stored scan's last time"
# ... and with --frames 10 the ATE covers the 10 frames read, of the 60
# poses the trajectory holds: the summary says which.
cp -r "$T/H" "$T/H4"
expect 0 "$B" replay "$T/seqh" --out "$T/h4" --no-mesh --store "$T/H4" --resume --frames 10
grep -q "over 10 of the 60 poses in trajectory.txt" "$T/out" || fail "the summary after a resume with --frames 10: $(grep ATE "$T/out")"
[ "$(json_get "$T/h4/stats.json" "(d['ate_m']['pairs'], d['ate_m']['trajectory_poses'])")" = "(10, 60)" ] ||
    fail "stats.json ate_m after a resume with --frames 10: $(json_get "$T/h4/stats.json" "d['ate_m']")"
# The same from a log: the stored records' headers are read, not their
# payloads (one spoilt here, a quarter of the way in, past its header).
expect 0 "$B" convert "$SEQ" --out "$T/seq.bflog"
expect 0 "$B" replay "$T/seq.bflog" --out "$T/l1" --no-mesh --frames 30 --store "$T/L"
size=$(wc -c <"$T/seq.bflog")
printf '\377\377\377\377' | dd of="$T/seq.bflog" bs=1 seek=$((size / 4)) conv=notrunc 2>/dev/null
expect 3 "$B" info "$T/seq.bflog" --frames 30
cp -r "$T/L" "$T/L3"
expect 0 "$B" replay "$T/seq.bflog" --out "$T/l2" --no-mesh --store "$T/L" --resume
# The first frame after the stored ones spoilt: the resume fails on it
# (exit 3, the store kept) and does not say the log held nothing new.
expect 0 "$B" convert "$SEQ" --out "$T/seq3.bflog"
# Frame 30's record from the log's index (footer: u64 index offset; the
# index: "BFIX", n, then n x (u64 offset, f64 time)); 16 bytes into its
# depth payload, past the 152-byte record header.
at=$(py - "$T/seq3.bflog" <<'PY'
import struct, sys
d = open(sys.argv[1], "rb").read()
ix = struct.unpack_from("<Q", d, len(d) - 24)[0]
print(struct.unpack_from("<Q", d, ix + 8 + 16 * 30)[0] + 152 + 16)
PY
)
printf '\377\377\377\377' | dd of="$T/seq3.bflog" bs=1 seek="$at" conv=notrunc 2>/dev/null
expect 3 "$B" replay "$T/seq3.bflog" --out "$T/l3" --no-mesh --store "$T/L3" --resume
grep -q "nothing new" "$T/err" && fail "a resume that failed on a spoilt frame said the log held nothing new: $(cat "$T/err")"
expect 0 "$B" info "$T/L3" --json
[ "$(json_get "$T/out" "d['frames']")" = 30 ] || fail "the failed resume changed the store: $(head -c 300 "$T/out")"
[ "$(json_get "$T/l2/stats.json" "d['frames']")" = 30 ] || fail "the resumed scan of a log did not pass over the 30 stored frames"
[ "$(grep -vc '^#' "$T/h2/trajectory.txt")" = 60 ] || fail "the resumed scan's trajectory has not 60 poses"
[ "$(json_get "$T/h2/stats.json" "d['frames']")" = 30 ] || fail "the resumed scan did not skip the 30 stored frames"
py - "$T/full/stats.json" "$T/h2/stats.json" <<'PY' || fail "resumed ATE too far from the uninterrupted one"
import json, sys
a = json.load(open(sys.argv[1]))["ate_m"]["rmse"]
b = json.load(open(sys.argv[2]))["ate_m"]["rmse"]
# Tracking tolerance: the loop's own error on these frames is a few mm; a
# resume that lost the map would be centimetres off.
ok = b <= max(2 * a, a + 0.003)
print("ATE uninterrupted %.4f m, two halves %.4f m" % (a, b))
sys.exit(0 if ok else 1)
PY

# A store whose index is lost resumes at the loop's finest level (6 by
# default), which its bricks fit, not at the deepest the format allows; a
# --max-level coarser than its bricks is raised to theirs (these 160x120
# frames make bricks to level 4 or so).
expect 0 "$B" replay "$SEQ" --out "$T/n1" --no-mesh --frames 30 --store "$T/N"
rm "$T/N/store.json"
cp -r "$T/N" "$T/Nc"
expect 0 "$B" replay "$SEQ" --out "$T/n2" --no-mesh --store "$T/N" --resume
level=$(json_get "$T/n2/stats.json" "d['config']['fusion']['max_level']")
[ "$level" = 6 ] || fail "a store without its index resumed at level $level"
expect 0 "$B" info "$T/Nc" --json
finest=$(json_get "$T/out" "max(l for l, n in enumerate(d['bricks_per_level']) if n)")
expect 0 "$B" replay "$SEQ" --out "$T/n3" --no-mesh --store "$T/Nc" --resume --max-level $((finest - 1))
mentions "index is lost"
level=$(json_get "$T/n3/stats.json" "d['config']['fusion']['max_level']")
[ -n "$level" ] && [ "$level" = "$finest" ] || fail "--max-level $((finest - 1)) over a store of level-'$finest' bricks resumed at '$level'"

# kill -9 at random moments of a scan with --store: every time the store
# reopens (info), exports, and the next run resumes it; at the end one run
# finishes the scan.
K="$T/K"
# The kills land within an uninterrupted scan's own duration on this machine
# (a fixed 0.2-2 s window missed most scans on a faster one); a run that ends
# before its kill just makes the loop try again.
t0=$(date +%s.%N)
expect 0 "$B" replay "$SEQ" --out "$T/ktime" --no-mesh --store "$T/Ktime" --store-every 0.1
scan_s=$(py -c "import sys; print(max(0.3, float(sys.argv[2]) - float(sys.argv[1])))" "$t0" "$(date +%s.%N)")
kills=0
for i in $(seq 1 80); do
    [ "$kills" -ge 22 ] && break
    # Every other run resumes what the killed one left; the others start a
    # new scan, which lasts long enough to be killed mid-scan.
    extra=""
    if [ $((i % 2)) = 0 ] && [ -d "$K" ]; then extra="--resume"; else rm -rf "$K"; fi
    "$B" replay "$SEQ" --out "$T/k$i" --no-mesh --store "$K" --store-every 0.1 $extra >"$T/k.log" 2>&1 &
    pid=$!
    sleep "$(py -c "import random, sys; print(round(random.uniform(0.1, 0.9) * float(sys.argv[1]), 2))" "$scan_s")"
    if kill -9 "$pid" 2>/dev/null; then
        kills=$((kills + 1))
        wait "$pid" 2>/dev/null
    else
        wait "$pid" || fail "run $i of the kill test failed: $(tail -c 300 "$T/k.log")"
        continue
    fi
    [ -d "$K" ] || continue # killed before the store was made
    expect 0 "$B" info "$K" --json || true
    if [ -f "$T/out" ] && ! json_get "$T/out" "d['bad_chunk_files']" | grep -qx 0; then
        fail "kill $i: the store has bad chunk files"
    fi
    # A store killed before its first write holds nothing to export: said so.
    if json_get "$T/out" "int(d['chunks'] + d['bad_chunk_files'] + d['index_ok'] + d['trajectory_ok'])" 2>/dev/null |
        grep -qx 0; then
        expect 3 "$B" export "$K" --out "$T/k.ply" --points
        mentions "stopped before its first write"
    else
        expect 0 "$B" export "$K" --out "$T/k.ply" --points
    fi
done
[ "$kills" -ge 20 ] || fail "only $kills of the runs were killed mid-scan (the scan is too short?)"
[ -d "$K" ] || expect 0 "$B" replay "$SEQ" --out "$T/kstart" --no-mesh --frames 10 --store "$K"
expect 0 "$B" replay "$SEQ" --out "$T/kend" --no-mesh --store "$K" --resume
[ "$(grep -vc '^#' "$T/kend/trajectory.txt")" = 60 ] || fail "after the kills the scan does not end with 60 poses"
echo "kill -9: $kills kills, the store reopened and exported after each"

# A full disk: a tiny tmpfs (root only) ends the scan with an error naming
# the store's file, and what the store holds still reads.
mkdir "$T/tiny"
if mount -t tmpfs -o size=64k tmpfs "$T/tiny" 2>/dev/null; then
    # A write after every frame or so: the first (one frame's map) fits
    # whatever the machine's speed; the whole map never does.
    expect 5 "$B" replay "$SEQ" --out "$T/o-tiny" --no-mesh --store "$T/tiny/S" --store-every 0.01
    mentions "No space left on device"
    mentions "$T/tiny/S"
    # The summary does not claim the failed write's figures.
    grep -Eq "^  store  *$T/tiny/S: (the last write failed|not written)" "$T/out" ||
        fail "the summary's store line after a full disk: $(grep '^  store' "$T/out")"
    # (64 KiB: the first write fits, a later one does not)
    line=$(grep '^  store' "$T/out")
    expect 0 "$B" info "$T/tiny/S" --json
    # What it says the store holds is what the store holds (a failed write renames none of its files).
    held=$(printf '%s' "$line" | grep -o 'the one before holds [0-9]* chunks\?, [0-9]* bricks') ||
        fail "64 KiB: no write before the failed one: $line"
    if [ -n "$held" ]; then
        got="the one before holds $(json_get "$T/out" "d['chunks']") chunk"
        [ "${held%% chunk*} chunk" = "$got" ] && printf '%s' "$held" | grep -q ", $(json_get "$T/out" "d['bricks']") bricks" ||
            fail "after a full disk the summary says '$held', info finds $(json_get "$T/out" "(d['chunks'], d['bricks'])")"
    fi
    json_get "$T/o-tiny/stats.json" "d['store']['last_write_failed']" | grep -qx True ||
        fail "stats.json store.last_write_failed is not true after a full disk"
    umount "$T/tiny"
    # 48 KiB: the new store's first write fails: no empty store is left to refuse the next run.
    mount -t tmpfs -o size=48k tmpfs "$T/tiny"
    expect 5 "$B" replay "$SEQ" --out "$T/o-tiny2" --no-mesh --store "$T/tiny/S"
    grep -q "^  store  *$T/tiny/S: not written" "$T/out" || fail "48 KiB: $(grep '^  store' "$T/out")"
    [ ! -e "$T/tiny/S" ] || fail "a new store whose first write failed was left: $(find "$T/tiny/S")"
    json_get "$T/o-tiny2/stats.json" "(d['store']['last_write_failed'], d['store']['chunks'])" | grep -qx "(True, 0)" ||
        fail "48 KiB: stats.json store: $(json_get "$T/o-tiny2/stats.json" "d['store']")"
    umount "$T/tiny"
else
    echo "full disk: skipped (no tmpfs mount here; the injected ENOSPC of test_store covers it)"
fi

finish test_store.sh
