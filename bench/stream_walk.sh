#!/usr/bin/env bash
# Streaming along a long walk (docs/streaming.md): a row of ROOMS rooms
# (bitfuse synth --scene rooms:N, bench/rooms_walk.py: out and back), replayed
# three ways: default pools without streaming, small pools (--gpu-budget)
# with streaming, and small pools with streaming into a scene store. Samples
# the process's resident memory every 0.25 s, then writes OUT/summary.md (a
# table) and OUT/stream_walk.png (resident memory and time per frame along
# the walk).
#   bench/stream_walk.sh OUT [ROOMS=7] [STEP_M=0.06] [BUDGET_MIB=2.5] [RADIUS_M=2.5]
set -euo pipefail
cd "$(dirname "$0")/.."
. bench/common.sh
OUT=${1:?usage: bench/stream_walk.sh OUT [ROOMS] [STEP_M] [BUDGET_MIB] [RADIUS_M]}
ROOMS=${2:-7}
STEP=${3:-0.06}
BUDGET=${4:-2.5}
RADIUS=${5:-2.5}
mkdir -p "$OUT"
export BITFUSE_VALIDATION=0 BITFUSE_PROGRESS=0
SEQ="$OUT/rooms$ROOMS-$STEP"
if [ ! -f "$SEQ/depth.txt" ]; then
  $PY bench/rooms_walk.py "$OUT/walk.txt" "$ROOMS" "$STEP" 30 0
  $BIN synth --scene "rooms:$ROOMS" --trajectory "$OUT/walk.txt" --frames 100000 --size 320x240 \
      --camera 262.5,262.5,159.5,119.5 --noise none --out "$SEQ" >/dev/null
fi

# run NAME OPTIONS...: one replay with its resident memory sampled.
run() {
  local name=$1
  shift
  rm -rf "$OUT/$name" "$OUT/$name.store"
  $BIN replay "$SEQ" --out "$OUT/$name" --no-mesh --fuse-at-groundtruth "$@" >"$OUT/$name.log" 2>&1 &
  local pid=$! t0
  t0=$(date +%s.%N)
  : >"$OUT/$name.rss"
  while kill -0 "$pid" 2>/dev/null; do
    awk -v t="$(date +%s.%N)" -v t0="$t0" '/VmRSS/ {print t - t0, $2}' "/proc/$pid/status" 2>/dev/null >>"$OUT/$name.rss" || true
    sleep 0.25
  done
  wait "$pid"
  echo "stream_walk: $name done"
}
run big --stream off
run small --gpu-budget "$BUDGET" --stream-radius "$RADIUS"
run store --gpu-budget "$BUDGET" --stream-radius "$RADIUS" --store "$OUT/store.store" --store-every 1
$BIN info "$OUT/store.store" --json >"$OUT/store-info.json"

$PY - "$OUT" "$ROOMS" "$STEP" "$BUDGET" "$RADIUS" <<'PY'
import csv, json, os, sys
out, rooms, step, budget, radius = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4], sys.argv[5]
def load(name):
    st = json.load(open(os.path.join(out, name, "stats.json")))
    rows = list(csv.DictReader(open(os.path.join(out, name, "frames.csv"))))
    rss = [tuple(map(float, l.split())) for l in open(os.path.join(out, name + ".rss")) if l.strip()]
    return st, rows, rss
runs = {n: load(n) for n in ("big", "small", "store")}
info = json.load(open(os.path.join(out, "store-info.json")))
lines = ["| run | options | frames | ATE (one-step, mm) | surface voxels | time per frame median / p95 ms | "
         "streaming ms per frame (mean) / max | chunks out / in | peak resident MiB |", "|---|---|---|---|---|---|---|---|---|"]
opts = {"big": "`--stream off`", "small": "`--gpu-budget %s --stream-radius %s`" % (budget, radius),
        "store": "the same `--store S --store-every 1`"}
for n, (st, rows, rss) in runs.items():
    s = st.get("stream") or {}
    sm = [float(r["stream_ms"]) for r in rows]
    lines.append("| %s | %s | %d | %.1f | %d | %.1f / %.1f | %.2f / %.1f | %s / %s | %.0f |" % (
        n, opts[n], st["frames"], 1e3 * st["ate_m"]["rmse"], st["surface_voxels"], st["frame_ms"]["median"],
        st["frame_ms"]["p95"], sum(sm) / max(len(sm), 1), max(sm or [0]), s.get("chunks_out", "-"),
        s.get("chunks_in", "-"), max(r for _, r in rss) / 1024 if rss else float("nan")))
pv = info["bricks"] and info["bytes_on_disk"] / info["bricks"]
st = runs["store"][0]
surf = st["surface_voxels"]
lines.append("")
lines.append("Store: %d chunks, %d bricks, %.2f MiB on disk (%.1f bytes a brick, %.2f bits a voxel, %.1f bytes a surface "
             "voxel; the bit planes alone are 128 bytes a brick); %d writes, the writer's longest %.0f ms, the loop's "
             "longest flush (its host copy of the map) %.0f ms." % (
                 info["chunks"], info["bricks"], info["bytes_on_disk"] / 2**20, pv, 8 * pv / 512,
                 info["bytes_on_disk"] / max(surf, 1), st["store"]["writes"], st["store"]["write_ms_max"],
                 st["store"]["loop_flush_ms_max"]))
open(os.path.join(out, "summary.md"), "w").write("\n".join(lines) + "\n")
print("\n".join(lines))
try:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(2, 1, figsize=(8, 6))
    for n, (st, rows, rss) in runs.items():
        ax[0].plot([t for t, _ in rss], [r / 1024 for _, r in rss], label=n)
        ax[1].plot([int(r["index"]) for r in rows], [float(r["frame_ms"]) for r in rows], label=n, lw=0.7)
    ax[0].set_xlabel("seconds"); ax[0].set_ylabel("resident MiB"); ax[0].legend()
    ax[1].set_xlabel("frame"); ax[1].set_ylabel("ms per frame"); ax[1].legend()
    ax[0].set_title("rooms:%s walk out and back, %s m a frame, 320x240" % (rooms, step))
    fig.tight_layout()
    fig.savefig(os.path.join(out, "stream_walk.png"), dpi=90)
except ImportError:
    print("no matplotlib: no plot")
PY
