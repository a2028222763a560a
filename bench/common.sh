# shellcheck shell=bash
# Shared by the bench scripts (sourced after `cd` to the source root):
# BIN (BITFUSE_BIN or BIN from the environment) and PY, bench_each (runs
# jobs a few at a time), and bench_room_sequence SEQ FRAMES which renders the synthetic
# room (Kinect v1 noise, seed 1) along the real fr1_xyz trajectory (the
# demo's built-in one when ../shared/data is absent) into SEQ once.
BIN=${BITFUSE_BIN:-${BIN:-build/app/bitfuse}}
# Debian's python3 has numpy and matplotlib (scripts/install-deps.sh); a
# python3 earlier on PATH may not.
PY=python3
[ -x /usr/bin/python3 ] && PY=/usr/bin/python3
[ -x "$BIN" ] || bash scripts/build.sh

# bench_each JOBS FN ITEM...: FN ITEM for every item, JOBS at a time, oldest
# first; every item's status is collected, and the call fails when any did.
bench_each() {
  local jobs=$1 fn=$2 it p pids=() fails=0
  shift 2
  for it in "$@"; do
    "$fn" "$it" &
    pids+=($!)
    if [ "${#pids[@]}" -ge "$jobs" ]; then
      wait "${pids[0]}" || fails=$((fails + 1))
      pids=("${pids[@]:1}")
    fi
  done
  for p in "${pids[@]}"; do wait "$p" || fails=$((fails + 1)); done
  [ "$fails" -eq 0 ] || { echo "$(basename "$0"): $fails of $# failed" >&2; return 1; }
}

bench_room_sequence() {
  local seq=$1 frames=$2 traj=../shared/data/tum/fr1_xyz/groundtruth.txt
  [ -f "$seq/depth.txt" ] && return 0
  if [ ! -f "$traj" ]; then
    $BIN demo --frames 2 --out "$seq.demo-traj" >/dev/null
    traj="$seq.demo-traj/trajectory_input.txt"
  fi
  $BIN synth --scene room --trajectory "$traj" --frames "$frames" --noise kinect1 --seed 1 --out "$seq"
}

# bench_random_particles N FILE: N particles drawn uniformly in a 2 x 1 x 1 m
# box (numpy's generator, seed 1) as a binary PLY of float x y z; the sets
# of bench/particles_sweep.sh and bench/particles_views.sh.
bench_random_particles() {
  "$PY" -c 'import sys, numpy as np; n=int(sys.argv[1]); p=(np.random.default_rng(1).random((n,3))*np.array([2,1,1])).astype("<f4"); f=open(sys.argv[2],"wb"); f.write(b"ply\nformat binary_little_endian 1.0\nelement vertex %d\nproperty float x\nproperty float y\nproperty float z\nend_header\n"%n); f.write(p.tobytes())' "$1" "$2"
}
