#!/usr/bin/env python3
"""Ray insertion side by side: troupe's LocalGrid against OctoMap on the same points.

Runs the Rust example (which times LocalGrid and writes the points it used), then
inserts the same points into an OctoMap OcTree at the same resolution with
insertPointCloud (C++ under pyoctomap; per scan, OctoMap updates each crossed cell
once, while LocalGrid updates a cell once per ray that crosses it), and prints both
rates and their ratio. Needs `pip install pyoctomap numpy`.

Usage: python3 scripts/bench_grid_vs_octomap.py
"""
import json
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


def main():
    with tempfile.TemporaryDirectory() as tmp:
        points_file = pathlib.Path(tmp) / "points.bin"
        out = subprocess.run(
            ["cargo", "run", "--quiet", "--release", "-p", "troupe-sims", "--example",
             "grid_insertion", "--", str(points_file)],
            cwd=ROOT, check=True, capture_output=True, text=True)
        troupe = json.loads(out.stdout.strip().splitlines()[-1])
        frames = read_frames(points_file)
    per_frame = []
    for origin, points in frames:
        times = []
        for _ in range(REPEATS):
            tree = pyoctomap.OcTree(troupe["resolution_m"])
            start = time.perf_counter()
            tree.insertPointCloud(points, origin, max_range=-1.0)
            times.append(time.perf_counter() - start)
        per_frame.append(sorted(times)[REPEATS // 2])
    rays = sum(len(p) for _, p in frames)
    octomap_rate = rays / sum(per_frame)
    result = {
        "frames": len(frames),
        "rays": rays,
        "resolution_m": troupe["resolution_m"],
        "troupe_rays_per_s": troupe["rays_per_s"],
        "octomap_rays_per_s": round(octomap_rate),
        "troupe_median_frame_s": troupe["median_frame_s"],
        "octomap_median_frame_s": round(sorted(per_frame)[len(per_frame) // 2], 6),
        "ratio": round(troupe["rays_per_s"] / octomap_rate, 2),
    }
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    sys.exit(main())
