#!/usr/bin/env bash
# Level of detail within one mesh (bitfuse render --mesh-lod on|off): a row
# of N copies of a shared mesh (default the dragon, scaled to 0.6 m across)
# receding from 0.8 m to about 13 m in front of the camera, one mesh file,
# voxelised and ray-cast at 640x480 (the median of 3 casts) with level of
# detail and without (every part at the level of the nearest point), the
# two interleaved ROUNDS times (default 3; times are the medians over the
# rounds), and the two depth images compared. Writes OUT/mesh_lod.md (a
# table) and the two shaded views OUT/lod_on.png, OUT/lod_off.png.
# Usage: [ROUNDS=3] bench/mesh_lod.sh OUT [MESH.ply] [N]
set -euo pipefail
. "$(dirname "$0")/common.sh"
OUT=$1
MESH=${2:-$(dirname "$0")/../../shared/data/meshes/dragon.ply}
N=${3:-8}
mkdir -p "$OUT"
"$PY" - "$MESH" "$N" "$OUT/row.ply" <<'PY'
import struct, sys, numpy as np
src, n, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
data = open(src, "rb").read()
head, body = data.split(b"end_header\n", 1)
lines = head.decode().splitlines()
assert "binary_little_endian" in head.decode(), "a binary little-endian PLY"
nv = int([l for l in lines if l.startswith("element vertex")][0].split()[2])
nf = int([l for l in lines if l.startswith("element face")][0].split()[2])
props = []
sect = None
for l in lines:
    w = l.split()
    if w[:1] == ["element"]: sect = w[1]
    elif w[:1] == ["property"] and sect == "vertex": props.append(w[1])
size = {"float": 4, "double": 8, "uchar": 1, "int": 4, "uint": 4, "short": 2, "ushort": 2}
stride = sum(size[p] for p in props)
assert props[:3] == ["float"] * 3, "vertex x y z as float first"
v = np.frombuffer(body[: nv * stride], dtype=np.uint8).reshape(nv, stride)[:, :12].copy().view("<f4").reshape(nv, 3)
f = body[nv * stride :]
tris, o = [], 0
for i in range(nf):
    k = f[o]; idx = struct.unpack_from("<%di" % k, f, o + 1); o += 1 + 4 * k
    for j in range(1, k - 1): tris.append((idx[0], idx[j], idx[j + 1]))
tris = np.array(tris, dtype=np.uint32)
v = v - (v.max(0) + v.min(0)) / 2
v = v * np.array([-1, -1, 1], dtype=np.float32)  # turned about z: the file's up (+y) up in the image (y down)
v = v * (0.6 / (v.max(0) - v.min(0)).max())
V, T = [], []
for k in range(n):
    z = 0.8 * (13.0 / 0.8) ** (k / max(n - 1, 1))
    x = z * (-0.5 + 0.95 * k / max(n - 1, 1))
    V.append(v + np.array([x, 0.0, z], dtype=np.float32)); T.append(tris + k * nv)
V = np.concatenate(V).astype("<f4"); T = np.concatenate(T)
with open(out, "wb") as g:
    g.write(b"ply\nformat binary_little_endian 1.0\nelement vertex %d\nproperty float x\nproperty float y\nproperty float z\n"
            b"element face %d\nproperty list uchar int vertex_indices\nend_header\n" % (len(V), len(T)))
    g.write(V.tobytes())
    rec = np.zeros(len(T), dtype=[("n", "u1"), ("i", "<i4", 3)]); rec["n"] = 3; rec["i"] = T
    g.write(rec.tobytes())
print(f"{out}: {n} copies, {len(T)} triangles")
PY
ROUNDS=${ROUNDS:-3}
for r in $(seq "$ROUNDS"); do
    for lod in on off; do
        "$BIN" render --mesh "$OUT/row.ply" --mesh-lod $lod --pose "0 0 0 0 0 0 1" --size 640x480 --far 14 \
            --out "$OUT/lod_$lod.png" --depth "$OUT/lod_${lod}_d.png" --repeat 3 >"$OUT/lod_${lod}_$r.txt" 2>/dev/null
    done
done
"$PY" - "$OUT" "$ROUNDS" >"$OUT/mesh_lod.md" <<'PY'
import re, sys, zlib, struct, numpy as np
out = sys.argv[1]
def png16(p):
    d = open(p, "rb").read(); o = 8; idat = b""; w = h = 0
    while o < len(d):
        n, t = struct.unpack(">I4s", d[o:o + 8]); c = d[o + 8:o + 8 + n]; o += 12 + n
        if t == b"IHDR": w, h = struct.unpack(">II", c[:8])
        if t == b"IDAT": idat += c
    raw = zlib.decompress(idat); bpp = 2; stride = w * bpp; img = np.zeros((h, stride), np.uint8); prev = np.zeros(stride, np.int32)
    for y in range(h):
        ft = raw[y * (stride + 1)]; line = np.frombuffer(raw, np.uint8, stride, y * (stride + 1) + 1).astype(np.int32); cur = np.zeros(stride, np.int32)
        for x in range(stride):
            a = cur[x - bpp] if x >= bpp else 0; b = prev[x]; cc = prev[x - bpp] if x >= bpp else 0
            if ft == 0: p = 0
            elif ft == 1: p = a
            elif ft == 2: p = b
            elif ft == 3: p = (a + b) // 2
            else:
                pa, pb, pc = abs(b - cc), abs(a - cc), abs(a + b - 2 * cc); p = a if pa <= pb and pa <= pc else (b if pb <= pc else cc)
            cur[x] = (line[x] + p) & 255
        img[y] = cur; prev = cur
    return img.view(">u2").reshape(h, w).astype(np.float64) / 5000.0
def grab(t, pat, f=float):
    m = re.search(pat, t); return f(m.group(1)) if m else float("nan")
rows = {}
for lod in ("on", "off"):
    ts = [open(f"{out}/lod_{lod}_{r + 1}.txt").read() for r in range(int(sys.argv[2]))]
    t = ts[0]
    rows[lod] = dict(bricks=grab(t, r"(\d+) bricks[ ,(]", int),
                     vox=float(np.median([grab(u, r"voxelised in ([\d.]+) s") for u in ts])),
                     cast=float(np.median([grab(u, r"ray-cast +([\d.]+) ms GPU") for u in ts])),
                     levels=re.search(r"at levels? ([\d-]+)", t).group(1), tris=grab(t, r": (\d+) triangles", int))
on, off = png16(f"{out}/lod_on_d.png"), png16(f"{out}/lod_off_d.png")
a, b = on > 0, off > 0
iou = (a & b).sum() / max((a | b).sum(), 1)
d = np.abs(on - off)[a & b]; z = off[a & b]
print("| level of detail | triangles | levels | bricks | map (sign + confidence bits) | voxelised [s, median] | ray-cast 640x480 [ms GPU, median] |")
print("|---|---|---|---|---|---|---|")
for lod in ("on", "off"):
    r = rows[lod]
    print(f"| {lod} | {r['tris']} | {r['levels']} | {r['bricks']} | {r['bricks'] * 128 / 2**20:.2f} MiB | {r['vox']:.3f} | {r['cast']:.1f} |")
print()
print(f"On against off: hit masks agree on IoU {iou:.4f} ({(a ^ b).sum()} of {a.size} pixels differ); depth difference "
      f"over pixels both hit: median {1e3 * np.median(d):.2f} mm, p95 {1e3 * np.percentile(d, 95):.2f} mm, "
      f"p95 relative to the depth {np.percentile(d / z, 95) * 100:.3f}%.")
far = z > 3.5
if far.any():
    print(f"Beyond 3.5 m (the copies whose level differs, {far.sum()} pixels): median {1e3 * np.median(d[far]):.2f} mm, "
          f"p95 {1e3 * np.percentile(d[far], 95):.2f} mm, p95 relative {np.percentile(d[far] / z[far], 95) * 100:.3f}% "
          f"(a pixel there spans {1e3 * np.median(z[far]) / 525:.1f} mm at their median depth).")
PY
cat "$OUT/mesh_lod.md"
