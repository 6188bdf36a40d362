#!/usr/bin/env python3
"""Renders a troupe recording headlessly, from the recording alone (Python `mcap` +
matplotlib): a top view of the team at time T — each robot's trajectory so far
(`/robot<i>/pose`), its keyframe ellipsoids (`/robot<i>/keyframes`, the 2-sigma
ellipsoids projected on the xy plane), its committed plan and its last planning round's
candidates coloured by verdict — next to the team's coverage over time
(`/team/coverage`). This is the picture of docs/recordings.md; Foxglove's 3D panel
shows the same channels.

Usage: render.py RUN.mcap OUT.png [--time SECONDS]   (default: the end of the recording)
"""

import argparse
import base64
import json
import math
import struct

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import Ellipse  # noqa: E402
from mcap.reader import make_reader  # noqa: E402
from quaternion import rotation  # noqa: E402


def projected_ellipse(sphere):
    """The xy shadow of a 3D ellipsoid: centre, width, height, angle (degrees)."""
    r = rotation(sphere["pose"]["orientation"])
    half = [sphere["size"][k] / 2 for k in "xyz"]
    # Covariance-like shape matrix A = R diag(half^2) R^T, restricted to xy.
    a = [[sum(r[i][k] * half[k] ** 2 * r[j][k] for k in range(3)) for j in range(2)] for i in range(2)]
    tr, det = a[0][0] + a[1][1], a[0][0] * a[1][1] - a[0][1] ** 2
    gap = math.sqrt(max(tr * tr / 4 - det, 0.0))
    l1, l2 = tr / 2 + gap, max(tr / 2 - gap, 0.0)
    angle = 0.5 * math.degrees(math.atan2(2 * a[0][1], a[0][0] - a[1][1]))
    c = sphere["pose"]["position"]
    return (c["x"], c["y"]), 2 * math.sqrt(l1), 2 * math.sqrt(l2), angle


def cloud_xyz(cloud):
    data = base64.b64decode(cloud["data"])
    stride = cloud["point_stride"]
    return [struct.unpack_from("<3f", data, k) for k in range(0, len(data), stride)]


def rgba(c):
    return (c["r"], c["g"], c["b"], c["a"])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("recording")
    parser.add_argument("out")
    parser.add_argument("--time", type=float, default=None, help="seconds on the recording's clock")
    args = parser.parse_args()

    poses, keyframes, plans, candidates, coverage = {}, {}, {}, {}, []
    clouds, world = {}, []
    with open(args.recording, "rb") as f:
        reader = make_reader(f)
        end_ns = reader.get_summary().statistics.message_end_time
        until = end_ns if args.time is None else int(args.time * 1e9)
        for _, channel, message in reader.iter_messages(ending_at=until, log_time_order=True):
            parts = channel.topic.strip("/").split("/")
            data = json.loads(message.data)
            if channel.topic == "/team/coverage":
                coverage.append((data["time_s"], 100 * data["fraction"]))
            elif channel.topic == "/world":
                world = data["entities"][0]["triangles"][0]["points"]
                continue
            elif len(parts) != 2 or not parts[0].startswith("robot"):
                continue
            robot, kind = parts
            if kind == "pose":
                p = data["pose"]["position"]
                poses.setdefault(robot, []).append((p["x"], p["y"], p["z"]))
            elif kind == "keyframes":
                keyframes.setdefault(robot, []).extend(data["entities"][0]["spheres"])
            elif kind == "plan":
                plans[robot] = data["entities"][0]["lines"][0]
            elif kind == "candidates":
                candidates[robot] = data["entities"][0]["lines"]
            elif kind in ("grid", "frontiers", "remembered_frontiers"):
                clouds[(robot, kind)] = cloud_xyz(data)

    fig, (top, cov) = plt.subplots(1, 2, figsize=(13, 6), gridspec_kw={"width_ratios": [2, 1]})
    if world and poses:
        zs = [p[2] for robot in poses for p in poses[robot]]
        low, high = min(zs) - 1.5, max(zs) + 1.5
        rock = [(p["x"], p["y"]) for p in world if low <= p["z"] <= high]
        if rock:
            top.scatter(*zip(*rock), s=1, color="0.75", lw=0, label="rock (/world, robots' height)")
    for robot in sorted(poses):
        colour = rgba(plans[robot]["color"]) if robot in plans else None
        for kind, marker, size in (("grid", ".", 2), ("frontiers", "x", 8), ("remembered_frontiers", "s", 12)):
            points = clouds.get((robot, kind), [])
            if points:
                xs, ys, _ = zip(*points)
                top.scatter(xs, ys, s=size, marker=marker, color=colour, alpha=0.5 if kind == "grid" else 0.9,
                            lw=0.6 if kind == "frontiers" else 0, label=f"{robot} {kind.replace('_', ' ')}")
        for sphere in keyframes.get(robot, []):
            centre, w, h, angle = projected_ellipse(sphere)
            top.add_patch(Ellipse(centre, w, h, angle=angle, color=rgba(sphere["color"]), alpha=0.12, lw=0))
        for line in candidates.get(robot, []):
            xs = [p["x"] for p in line["points"]]
            ys = [p["y"] for p in line["points"]]
            top.plot(xs, ys, color=rgba(line["color"]), lw=0.8)
        xs, ys, _ = zip(*poses[robot])
        top.plot(xs, ys, color=colour, lw=1.5, label=f"{robot} path")
        top.plot(xs[-1:], ys[-1:], "o", color=colour, ms=8)
        if robot in plans:
            line = plans[robot]
            top.plot([p["x"] for p in line["points"]], [p["y"] for p in line["points"]],
                     color=colour, lw=3, ls="--", label=f"{robot} committed plan")
    top.set_aspect("equal")
    top.set_xlabel("x (m)")
    top.set_ylabel("y (m)")
    top.set_title(f"Top view at {until / 1e9:.1f} s: rock, paths, keyframe ellipsoids (2σ), grid, frontiers, plans")
    top.legend(loc="best", fontsize=7, markerscale=2)
    if coverage:
        t, c = zip(*coverage)
        cov.plot(t, c)
    cov.set_xlabel("time (s)")
    cov.set_ylabel("team coverage (%)")
    cov.set_title("/team/coverage")
    cov.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)


if __name__ == "__main__":
    main()
