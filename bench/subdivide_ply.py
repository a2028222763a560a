#!/usr/bin/env python3
"""Midpoint subdivision of a triangle mesh PLY (binary little-endian, vertex
x y z float, faces as uchar-count int-index lists: the meshes of
../shared/data/meshes), for the mesh renderer's large-triangle-count runs
(docs/render.md, "Past 10^7 triangles"): each triangle split in four at its
edges' midpoints, shared midpoints made once.

usage: bench/subdivide_ply.py IN.ply OUT.ply TIMES
"""
import sys

import numpy as np


def read_ply(path):
    with open(path, "rb") as f:
        header = []
        while True:
            line = f.readline()
            if not line:
                sys.exit(f"{path}: no end_header")
            line = line.decode("ascii", "replace").strip()
            header.append(line)
            if line == "end_header":
                break
        if "format binary_little_endian 1.0" not in header:
            sys.exit(f"{path}: only binary little-endian PLY is read here")
        count = {l.split()[1]: int(l.split()[2]) for l in header if l.startswith("element")}
        vprops = []
        element = None
        for l in header:
            if l.startswith("element"):
                element = l.split()[1]
            elif l.startswith("property") and element == "vertex":
                vprops.append(l.split())
        if [p[1:] for p in vprops] != [["float", "x"], ["float", "y"], ["float", "z"]]:
            sys.exit(f"{path}: vertices must be float x y z only")
        nv, nf = count["vertex"], count["face"]
        v = np.frombuffer(f.read(nv * 12), dtype="<f4").reshape(nv, 3).copy()
        faces = np.frombuffer(f.read(nf * 13), dtype=[("n", "u1"), ("i", "<i4", 3)])
        if len(faces) != nf or (faces["n"] != 3).any():
            sys.exit(f"{path}: faces must be {nf} triangles")
        return v, faces["i"].astype(np.int64)


def subdivide(v, f):
    edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    edges.sort(axis=1)
    unique, inverse = np.unique(edges, axis=0, return_inverse=True)
    mid = inverse.reshape(3, -1).T + len(v)  # per face: the midpoints of ab, bc, ca
    v = np.concatenate([v, (v[unique[:, 0]] + v[unique[:, 1]]) / 2]).astype(np.float32)
    a, b, c = f.T
    ab, bc, ca = mid.T
    f = np.concatenate([np.stack(t, 1) for t in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])
    return v, f


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    v, f = read_ply(sys.argv[1])
    for _ in range(int(sys.argv[3])):
        v, f = subdivide(v, f)
    with open(sys.argv[2], "wb") as out:
        out.write(b"ply\nformat binary_little_endian 1.0\nelement vertex %d\nproperty float x\nproperty float y\n"
                  b"property float z\nelement face %d\nproperty list uchar int vertex_indices\nend_header\n"
                  % (len(v), len(f)))
        out.write(v.tobytes())
        rows = np.zeros(len(f), dtype=[("n", "u1"), ("i", "<i4", 3)])
        rows["n"], rows["i"] = 3, f
        out.write(rows.tobytes())
    print(f"{sys.argv[2]}: {len(v)} vertices, {len(f)} triangles")


if __name__ == "__main__":
    main()
