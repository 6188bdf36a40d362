#!/usr/bin/env python3
"""Ray insertion side by side: troupe's LocalGrid against OctoMap on the same points.

Runs the Rust example (which times LocalGrid three ways and writes the points it
used), then inserts the same points into an OctoMap OcTree at the same resolution
with insertPointCloud (C++ under pyoctomap; per scan, OctoMap updates each crossed
cell once, hits first), and prints every rate and its ratio to OctoMap's, all from
the same run:

- baseline: the first LocalGrid insertion (RayWalk iterator, per ray) — "before";
- per_ray: LocalGrid::insert_ray (same semantics, tight loop);
- per_scan: ScanScratch::insert_scan (OctoMap's semantics, rayon over rays; the
  thread count is printed);
- per_end_voxel: EndVoxelScratch::insert_scan (UpdateRule::PerEndVoxel: one ray per
  distinct end voxel, to its centre — the same idea as OctoMap's discretize=True; one
  thread). `end_voxels` is the number of rays it traced.

OctoMap is timed both ways: plain insertPointCloud (one ray per point, the same work
as troupe's per-scan rule) and with discretize=True (end points first merged per
voxel, one ray per occupied voxel: fewer rays, slightly different free space — the
counterpart of troupe's per_end_voxel).
Ratios are given against each, as `<name>_ratio` (plain) and
`<name>_ratio_discretize`; every rate counts the input points, not traced rays.

Needs `pip install pyoctomap numpy`.

Usage: python3 scripts/bench_grid_vs_octomap.py
(set GRID_INSERTION_BIN to a prebuilt `grid_insertion` example to skip `cargo run`).
"""
import json
import os
import pathlib
import struct
import subprocess
import sys
import tempfile
import time

import numpy as np
import pyoctomap

REPEATS = 15
ROOT = pathlib.Path(__file__).resolve().parent.parent


def read_frames(path):
    data = path.read_bytes()
    frames, at = [], 0
    while at < len(data):
        (n,) = struct.unpack_from("<I", data, at)
        at += 4
        origin = np.frombuffer(data, dtype="<f8", count=3, offset=at)
        at += 24
        points = np.frombuffer(data, dtype="<f8", count=3 * n, offset=at).reshape(n, 3)
        at += 24 * n
        frames.append((origin.copy(), np.ascontiguousarray(points)))
    return frames


def octomap_frame_times(frames, resolution_m, discretize):
    """Median over REPEATS of OctoMap's insertPointCloud time for each frame, s."""
    per_frame = []
    for origin, points in frames:
        times = []
        for _ in range(REPEATS):
            tree = pyoctomap.OcTree(resolution_m)
            start = time.perf_counter()
            tree.insertPointCloud(points, origin, max_range=-1.0, discretize=discretize)
            times.append(time.perf_counter() - start)
        per_frame.append(sorted(times)[REPEATS // 2])
    return per_frame


def main():
    with tempfile.TemporaryDirectory() as tmp:
        points_file = pathlib.Path(tmp) / "points.bin"
        prebuilt = os.environ.get("GRID_INSERTION_BIN")
        command = ([prebuilt] if prebuilt else
                   ["cargo", "run", "--quiet", "--release", "-p", "troupe-sims",
                    "--example", "grid_insertion", "--"])
        out = subprocess.run(
            command + [str(points_file)],
            cwd=ROOT, check=True, capture_output=True, text=True)
        troupe = json.loads(out.stdout.strip().splitlines()[-1])
        frames = read_frames(points_file)
    rays = sum(len(p) for _, p in frames)
    per_frame = octomap_frame_times(frames, troupe["resolution_m"], discretize=False)
    per_frame_d = octomap_frame_times(frames, troupe["resolution_m"], discretize=True)
    octomap_rate = rays / sum(per_frame)
    octomap_rate_d = rays / sum(per_frame_d)
    result = {
        "frames": len(frames),
        "rays": rays,
        "resolution_m": troupe["resolution_m"],
        "threads": troupe["threads"],
        "end_voxels": troupe["end_voxels"],
        "octomap_rays_per_s": round(octomap_rate),
        "octomap_median_frame_s": round(sorted(per_frame)[len(per_frame) // 2], 6),
        "octomap_discretize_rays_per_s": round(octomap_rate_d),
        "octomap_discretize_median_frame_s": round(
            sorted(per_frame_d)[len(per_frame_d) // 2], 6),
    }
    for name in ("baseline", "per_ray", "per_scan", "per_end_voxel"):
        rate = troupe[f"{name}_rays_per_s"]
        result[f"{name}_rays_per_s"] = rate
        result[f"{name}_median_frame_s"] = troupe[f"{name}_median_frame_s"]
        result[f"{name}_ratio"] = round(rate / octomap_rate, 2)
        result[f"{name}_ratio_discretize"] = round(rate / octomap_rate_d, 2)
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    sys.exit(main())
