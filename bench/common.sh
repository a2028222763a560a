# Shared by the bench scripts (sourced after `cd` to the source root):
# BIN and PY, and bench_room_sequence SEQ FRAMES which renders the synthetic
# room (Kinect v1 noise, seed 1) along the real fr1_xyz trajectory (the
# demo's built-in one when ../shared/data is absent) into SEQ once.
BIN=${BITFUSE_BIN:-build/app/bitfuse}
# Debian's python3 has numpy and matplotlib (scripts/install-deps.sh); a
# python3 earlier on PATH may not.
PY=python3
[ -x /usr/bin/python3 ] && PY=/usr/bin/python3
[ -x "$BIN" ] || bash scripts/build.sh

bench_room_sequence() {
  local seq=$1 frames=$2 traj=../shared/data/tum/fr1_xyz/groundtruth.txt
  [ -f "$seq/depth.txt" ] && return 0
  if [ ! -f "$traj" ]; then
    $BIN demo --frames 2 --out "$seq.demo-traj" >/dev/null
    traj="$seq.demo-traj/trajectory_input.txt"
  fi
  $BIN synth --scene room --trajectory "$traj" --frames "$frames" --noise kinect1 --seed 1 --out "$seq"
}
