#!/usr/bin/python3
"""Open3D 0.16's TSDF integration (VoxelBlockGrid) at the true poses: the
surface of the reference system ../shared/BENCHMARKS.md calls "Open3D 0.16
dense SLAM (VoxelBlockGrid)", made from our own frames so that its surface
error sits beside bitfuse's, measured by the same `bitfuse eval-surface`.

    open3d_tsdf.py DATA --out DIR [--frames N] [--voxel M] [--depth-scale S]
                   [--depth-max M] [--trunc-mult K] [--block-count N]
                   [--weight-threshold W]

DATA: frame-NNNNNN.{depth.png,color.jpg,pose.txt} (camera to world) and
camera-intrinsics.txt, as ../shared/tools/get-7scenes-dev.sh writes them.
Every frame is integrated at its true pose, as Open3D's
t_reconstruction_system/integrate.py does, and the mesh
(extract_triangle_mesh) is written to DIR/mesh.ply, DIR/stats.json beside it
(time per frame, wall clock; the configuration).

The parameters are those of Open3D's reconstruction system
(t_reconstruction_system: integrate.py's voxel of 3/512 m and 16^3 blocks,
default_config.yml's depth up to 3.0 m, truncation of 8 voxels and surface
weight threshold of 3; the block count only sizes the hash). Its dense SLAM (frame-to-model tracking) does not
run on Debian's build: the odometry's bilateral filter has no CPU kernel
there. A bench tool: Debian's python3-open3d, not part of bitfuse.
"""
import argparse
import glob
import json
import os
import sys
import time

import numpy as np

try:
    import open3d as o3d
    import open3d.core as o3c
except ImportError:
    sys.exit("open3d_tsdf.py: needs Open3D (apt-get install python3-open3d)")


def read_intrinsics(data):
    path = os.path.join(data, "camera-intrinsics.txt")
    try:
        K = np.loadtxt(path)
    except OSError as e:
        sys.exit("open3d_tsdf.py: %s: %s" % (path, e.strerror))
    if K.shape != (3, 3):
        sys.exit("open3d_tsdf.py: %s: not a 3x3 matrix" % path)
    return K


def list_frames(data, limit):
    depths = sorted(glob.glob(os.path.join(data, "frame-*.depth.png")))
    if not depths:
        sys.exit("open3d_tsdf.py: %s: no frame-*.depth.png" % data)
    if limit:
        depths = depths[:limit]
    frames = []
    for d in depths:
        stem = d[: -len(".depth.png")]
        frames.append((d, stem + ".color.jpg", stem + ".pose.txt"))
    return frames


def read_pose(path):
    T = np.loadtxt(path)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        sys.exit("open3d_tsdf.py: %s: not a finite 4x4 pose" % path)
    # 7-Scenes' rotations are not quite orthonormal; their polar factor.
    u, _, vt = np.linalg.svd(T[:3, :3])
    T = T.copy()
    T[:3, :3] = u @ vt
    return T


def fuse(frames, K, a):
    dev = o3c.Device("CPU:0")
    intr = o3c.Tensor(K, o3c.float64)
    vbg = o3d.t.geometry.VoxelBlockGrid(
        attr_names=("tsdf", "weight", "color"),
        attr_dtypes=(o3c.float32, o3c.float32, o3c.float32),
        attr_channels=((1), (1), (3)),
        voxel_size=a.voxel, block_resolution=16, block_count=a.block_count, device=dev)
    times = []
    for i, (dp, cp, pp) in enumerate(frames):
        t0 = time.perf_counter()
        depth = o3d.t.io.read_image(dp).to(dev)
        color = o3d.t.io.read_image(cp).to(dev)
        extr = o3c.Tensor(np.linalg.inv(read_pose(pp)), o3c.float64)
        blocks = vbg.compute_unique_block_coordinates(depth, intr, extr, a.depth_scale, a.depth_max,
                                                      a.trunc_mult)
        vbg.integrate(blocks, depth, color, intr, intr, extr, a.depth_scale, a.depth_max, a.trunc_mult)
        times.append((time.perf_counter() - t0) * 1e3)
        if (i + 1) % 50 == 0:
            print("open3d_tsdf.py: fuse: %d frames, %.1f ms median" % (i + 1, np.median(times)),
                  file=sys.stderr, flush=True)
    return vbg, times


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("data")
    p.add_argument("--out", required=True)
    p.add_argument("--frames", type=int, default=0)
    p.add_argument("--voxel", type=float, default=3.0 / 512)
    p.add_argument("--depth-scale", type=float, default=1000.0)
    p.add_argument("--depth-max", type=float, default=3.0)
    p.add_argument("--trunc-mult", type=float, default=8.0)
    p.add_argument("--block-count", type=int, default=40000)
    p.add_argument("--weight-threshold", type=float, default=3.0)
    a = p.parse_args()
    os.makedirs(a.out, exist_ok=True)
    frames = list_frames(a.data, a.frames)
    K = read_intrinsics(a.data)
    t0 = time.perf_counter()
    grid, times = fuse(frames, K, a)
    total = time.perf_counter() - t0
    mesh = grid.extract_triangle_mesh(weight_threshold=a.weight_threshold).to_legacy()
    o3d.io.write_triangle_mesh(os.path.join(a.out, "mesh.ply"), mesh, write_ascii=False)
    stats = {"tool": "open3d_tsdf.py", "open3d": o3d.__version__, "frames": len(frames),
             "config": {k: v for k, v in vars(a).items() if k not in ("data", "out")},
             "frame_ms": {"median": float(np.median(times)), "p95": float(np.percentile(times, 95))},
             "total_s": total, "triangles": len(mesh.triangles),
             # voxel blocks in use, 16^3 voxels of tsdf, weight (float each) and colour (3 floats)
             "blocks": int(grid.hashmap().size()),
             "map_mib": grid.hashmap().size() * 16 ** 3 * 20 / 2 ** 20}
    with open(os.path.join(a.out, "stats.json"), "w") as f:
        json.dump(stats, f, indent=2)
    print("open3d_tsdf.py: %d frames, %.1f ms median, %d triangles" %
          (len(frames), stats["frame_ms"]["median"], stats["triangles"]))


if __name__ == "__main__":
    main()
