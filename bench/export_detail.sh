#!/usr/bin/env bash
# Export time, peak memory and file size against detail and format
# (docs/export.md, "Benchmark"): the synthetic room, 20 frames at ratio 1
# fused at their true poses into a store, exported in full and cut to 1 M
# and 100 k triangles, as PLY, OBJ and glb; each simplified mesh measured
# against the full one and both against the scene.
#   bash bench/export_detail.sh [OUT]          (default /tmp/bitfuse-export-bench)
#   STORE=path/to/store bash bench/export_detail.sh OUT   exports an existing store
#                                              instead (no reference: the scene rows are left out)
set -euo pipefail
cd "$(dirname "$0")/.."
source bench/common.sh
OUT=${1:-/tmp/bitfuse-export-bench}
mkdir -p "$OUT"
export BITFUSE_VALIDATION=0 BITFUSE_PROGRESS=0
REF=""
if [ -z "${STORE:-}" ]; then
  bench_room_sequence "$OUT/seq" 20 >/dev/null
  STORE="$OUT/store"
  [ -f "$STORE/store.json" ] ||
    $BIN replay "$OUT/seq" --out "$OUT/run" --store "$STORE" --ratio 1 --fuse-at-groundtruth --no-mesh >/dev/null
  REF="$OUT/seq/scene.ply"
fi
# One export: prints "seconds peak_MiB bytes triangles".
run_export() {
  local file=$1
  shift
  /usr/bin/time -f "%e %M" -o "$OUT/time" $BIN export "$STORE" --out "$file" --json "$@" >"$OUT/json"
  local t m
  read -r t m <"$OUT/time"
  local bytes=$(stat -c %s "$file")
  [ "${file%.obj}" != "$file" ] && bytes=$((bytes + $(stat -c %s "${file%.obj}.mtl")))
  echo "$t $((m / 1024)) $bytes $($PY -c "import json; print(json.load(open('$OUT/json'))['triangles'])")"
}
# Accuracy of a mesh against a reference: "median p90 max" in mm.
surface() {
  $BIN eval-surface --reference "$1" --reconstruction "$2" --json >"$OUT/eval.json"
  $PY -c "import json; a=json.load(open('$OUT/eval.json'))['accuracy']; print('%.2f %.2f %.2f' % (1e3*a['median_m'], 1e3*a['p90_m'], 1e3*a['max_m']))"
}
echo "| detail | format | triangles | export time [s] | peak memory [MiB] | file [MB] | vs the full mesh: median / p90 / max [mm] | vs the scene: median / p90 [mm] |"
echo "|---|---|---|---|---|---|---|---|"
for detail in full 1000000 100000; do
  opt=()
  [ "$detail" = full ] || opt=(--max-triangles "$detail")
  for fmt in ply obj glb; do
    read -r t m b n < <(run_export "$OUT/$detail.$fmt" "${opt[@]}")
    vs_full="" vs_ref=""
    if [ "$fmt" = ply ]; then
      [ "$detail" = full ] || vs_full=$(surface "$OUT/full.ply" "$OUT/$detail.ply" | awk '{print $1 " / " $2 " / " $3}')
      [ -n "$REF" ] && vs_ref=$(surface "$REF" "$OUT/$detail.ply" | awk '{print $1 " / " $2}')
    fi
    printf "| %s | %s | %s | %s | %s | %.1f | %s | %s |\n" "$detail" "$fmt" "$n" "$t" "$m" "$(echo "$b / 1000000" | bc -l)" \
      "$vs_full" "$vs_ref"
  done
done
