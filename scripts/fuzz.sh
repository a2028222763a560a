#!/usr/bin/env bash
# Builds the libFuzzer targets (tests/fuzz/, clang, ASan + UBSan) and runs
# each for SECONDS (default 60), JOBS at a time (default 1), each from a
# fresh copy of its seed corpus with its dictionary. Prints a table of
# executions, coverage (libFuzzer's cov: edges, ft: features), corpus size
# and findings per target and, unless --no-doc, writes it into docs/fuzz.md.
# A crash, leak, hang (an input over 10 s) or out-of-memory (2 GiB) is saved
# under $BUILD_DIR/fuzz/crashes/TARGET/ and makes the script fail.
#
#   scripts/fuzz.sh [SECONDS] [--jobs N] [--no-doc] [--targets "a b"] [--seed S]
#
# CI (scripts/test.sh) runs scripts/fuzz.sh 20 --jobs 2 --no-doc --seed 1: a
# fixed seed makes a run repeat the inputs of the last one (as far as its
# 20 s reach), so a new finding there comes from a change of code, not from
# chance; without --seed every run explores afresh.
set -euo pipefail
cd "$(dirname "$0")/.."

SECONDS_EACH=60
JOBS=1
WRITE_DOC=1
ALL_TARGETS="image text folder bflog mesh store calib depthcorr v4l2 expect"
TARGETS=$ALL_TARGETS
SEED=0
while [ $# -gt 0 ]; do
  case "$1" in
    --jobs) JOBS=$2; shift 2 ;;
    --no-doc) WRITE_DOC=0; shift ;;
    --targets) TARGETS=$2; shift 2 ;;
    --seed) SEED=$2; shift 2 ;;
    [0-9]*) SECONDS_EACH=$1; shift ;;
    *) echo "usage: scripts/fuzz.sh [SECONDS] [--jobs N] [--no-doc] [--targets \"a b\"] [--seed S]" >&2; exit 2 ;;
  esac
done

BUILD_DIR=${BUILD_DIR:-build-fuzz}
t0=$(date +%s)
cmake -S . -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DBITFUSE_WERROR=ON -DBITFUSE_FUZZ=ON \
  -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ >/dev/null
# Only the targets and the libraries they read with (no shaders, no GPU code).
cmake --build "$BUILD_DIR" -j "$(nproc)" --target fuzz_all >/dev/null
t_build=$(( $(date +%s) - t0 ))

case "$BUILD_DIR" in /*) WORK="$BUILD_DIR/fuzz" ;; *) WORK="$PWD/$BUILD_DIR/fuzz" ;; esac
rm -rf "$WORK/corpus" "$WORK/logs" "$WORK/crashes"
mkdir -p "$WORK/logs"
# The targets write each input to files (fuzz_util.c): in memory where the
# machine has /dev/shm (5x the executions of a disk), removed at exit.
SCRATCH=$(mktemp -d "$( [ -d /dev/shm ] && echo /dev/shm || echo "${TMPDIR:-/tmp}")/bitfuse-fuzz.XXXXXX")
trap 'rm -rf "$SCRATCH"' EXIT

run_one() {
  local t=$1
  mkdir -p "$WORK/corpus/$t" "$WORK/crashes/$t"
  cp tests/fuzz/corpus/"$t"/* "$WORK/corpus/$t/"
  # The inputs that once broke a reader seed it too.
  if [ -d "tests/fuzz/regress/$t" ]; then
    find "tests/fuzz/regress/$t" -type f ! -name '*.expect' -exec cp {} "$WORK/corpus/$t/" \;
  fi
  local dict=()
  [ -f "tests/fuzz/$t.dict" ] && dict=(-dict="tests/fuzz/$t.dict")
  TMPDIR="$SCRATCH" ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
    "$BUILD_DIR/tests/fuzz/fuzz_$t" -max_total_time="$SECONDS_EACH" -timeout=10 -rss_limit_mb=2048 \
    -print_final_stats=1 -seed="$SEED" "${dict[@]}" -artifact_prefix="$WORK/crashes/$t/" \
    "$WORK/corpus/$t" >"$WORK/logs/$t.log" 2>&1 || true
}
export -f run_one
export WORK BUILD_DIR SECONDS_EACH SCRATCH SEED
t1=$(date +%s)
printf '%s\n' $TARGETS | xargs -P "$JOBS" -I{} bash -c 'run_one {}'
t_run=$(( $(date +%s) - t1 ))

table="| target | reads | seconds | executions | exec/s | cov | ft | corpus | crashes, leaks, hangs |
|---|---|---:|---:|---:|---:|---:|---:|---:|"
declare -A what=(
  [image]="depth/colour PNG, JPEG"
  [text]="TUM trajectory, camera.txt, pose matrix"
  [folder]="TUM, ICL-NUIM, pose folders + frames"
  [bflog]=".bflog header, records, index, seek"
  [mesh]="PLY, OFF, particle PLY"
  [store]="store.json, trajectory.bin, chunk files"
  [calib]="calib.json"
  [depthcorr]="depth_correction.json"
  [v4l2]="a V4L2 camera's formats, sizes, buffers, frames"
  [expect]="--expect's baseline stats.json, the gate"
)
found=0
for t in $TARGETS; do
  log="$WORK/logs/$t.log"
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)
  last=$(grep -E '^#[0-9]+.*cov: ' "$log" | tail -1 || true)
  cov=$(sed -n 's/.* cov: \([0-9]*\).*/\1/p' <<<"$last")
  ft=$(sed -n 's/.* ft: \([0-9]*\).*/\1/p' <<<"$last")
  corp=$(sed -n 's/.* corp: \([0-9]*\)\/.*/\1/p' <<<"$last")
  n_bad=$(find "$WORK/crashes/$t" -type f | wc -l)
  [ -n "$execs" ] || n_bad=$((n_bad + 1)) # no final stats: the target died
  found=$((found + n_bad))
  table+="
| fuzz_$t | ${what[$t]} | $SECONDS_EACH | ${execs:-?} | ${rate:-?} | ${cov:-?} | ${ft:-?} | ${corp:-?} | $n_bad |"
  if [ "$n_bad" -gt 0 ]; then
    echo "fuzz.sh: fuzz_$t found a problem: $WORK/crashes/$t/ (log $log)" >&2
    grep -E 'ERROR|SUMMARY|runtime error' "$log" | head -5 >&2 || true
  fi
done
echo "$table"
echo "fuzz.sh: build ${t_build} s, fuzzing ${t_run} s ($JOBS at a time), $(nproc) cores"

if [ "$WRITE_DOC" = 1 ]; then
  cmd="scripts/fuzz.sh $SECONDS_EACH --jobs $JOBS"
  [ "$TARGETS" = "$ALL_TARGETS" ] || cmd+=" --targets \"$TARGETS\""
  stamp="$(date -u +%Y-%m-%d), commit $(git rev-parse --short HEAD), clang $(clang -dumpversion), $(nproc) cores"
  python3 - "$table" "$cmd" "$stamp" <<'EOF'
import re, sys
table, cmd, stamp = sys.argv[1:4]
path = "docs/fuzz.md"
text = open(path).read()
block = f"<!-- fuzz.sh -->\n`{cmd}` ({stamp}):\n\n{table}\n<!-- /fuzz.sh -->"
text, n = re.subn(r"<!-- fuzz.sh -->.*?<!-- /fuzz.sh -->", lambda m: block, text, flags=re.S)
if n != 1:
    sys.exit("fuzz.sh: docs/fuzz.md has no <!-- fuzz.sh --> block")
open(path, "w").write(text)
EOF
  echo "fuzz.sh: docs/fuzz.md updated"
fi
[ "$found" -eq 0 ]
