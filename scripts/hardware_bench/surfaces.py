#!/usr/bin/env python3
"""Ground truth for the hardware benchmark: how much of a room's surfaces a camera saw.

The room is a troupe scenario's `[world.room]` (room.py). Its surfaces — the four
walls, floor and ceiling (less what the pillars cover) and the faces of every pillar
that face free space — are cut into square patches of about --patch-m (0.15 m). A
patch counts as seen once some camera pose has its centre

- inside the image (the pinhole of the camera's intrinsics: 640×480, fx = fy = 382,
  cx = 320, cy = 240 by default, what the camera stand-in renders and
  `sims/scenarios/pillar_room.toml` flies),
- at a z-depth in (0, --max-depth-m] (5 m: what the depth camera returns),
- facing the camera, and
- unoccluded: the segment from the camera to the centre crosses no pillar (the walls
  of a box room cannot hide one another).

The camera is at the body origin looking along body +x (image x = -body y, image y =
-body z): the mount of troupe's simulated camera, and of the camera stand-in with the
robot file's default `[ros2] extrinsics`. So a body pose is a camera pose.

Poses come from one of:
  --autopilot REPORT.json   px4_like_autopilot.py's report: its "track" [unix s, x, y,
                            z (NED), yaw (NED)], the true state of the hardware path;
  --poses POSES.json        [[t, x, y, z, qx, qy, qz, qw], ...] in the world frame (ENU);
  --mcap RUN.mcap           `/robot<i>/pose` (foxglove.PoseInFrame) of a troupe recording
                            (troupe run: sim time; troupe robot / troupe-robot: Unix
                            time); needs the `mcap` package (.venv-mcap), and numpy is
                            not needed for `--dump-poses`, which writes POSES.json.
Times are taken relative to the first pose. Prints one JSON object: the fraction seen
at --at-s (90 s) and at the end, by surface class, and the fraction against time
(every --curve-step-s).

  .venv-mcap/bin/python scripts/hardware_bench/surfaces.py --mcap runs/x/run.mcap \\
      --dump-poses /tmp/poses.json
  .venv-ros2/bin/python scripts/hardware_bench/surfaces.py \\
      --scenario sims/scenarios/pillar_room.toml --poses /tmp/poses.json
"""
import argparse
import json
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from room import load_room  # noqa: E402

# Camera intrinsics of the stand-in and of pillar_room.toml.
WIDTH, HEIGHT, FX, FY, CX, CY = 640, 480, 382.0, 382.0, 320.0, 240.0


# --- poses ---------------------------------------------------------------------------

def yaw_quaternion(yaw):
    return (0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0))


def poses_from_autopilot(path):
    """[t, x, y, z, qx, qy, qz, qw] (ENU) from the autopilot's NED track."""
    with open(path, encoding="utf-8") as f:
        track = json.load(f)["track"]
    out = []
    for t, n, e, d, yaw_ned in track:
        out.append([t, e, n, -d, *yaw_quaternion(math.pi / 2.0 - yaw_ned)])
    return out


def poses_from_mcap(path, robot=0):
    """[t, x, y, z, qx, qy, qz, qw] from /robot<i>/pose (log time, seconds)."""
    from mcap.reader import make_reader

    topic = f"/robot{robot}/pose"
    out = []
    with open(path, "rb") as f:
        for _schema, _channel, message in make_reader(f).iter_messages(topics=[topic]):
            pose = json.loads(message.data)["pose"]
            p, q = pose["position"], pose["orientation"]
            out.append([message.log_time * 1e-9, p["x"], p["y"], p["z"],
                        q["x"], q["y"], q["z"], q["w"]])
    if not out:
        raise SystemExit(f"{path}: no messages on {topic}")
    return out


def thin(poses, min_dt_s):
    """Poses at least min_dt_s apart (the first and last kept)."""
    out = []
    for p in poses:
        if not out or p[0] - out[-1][0] >= min_dt_s:
            out.append(p)
    if poses and out[-1] is not poses[-1]:
        out.append(poses[-1])
    return out


def rotation(q):
    """Rotation matrix (body → world) of a unit quaternion (x, y, z, w)."""
    x, y, z, w = q
    return [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]


# --- patches -------------------------------------------------------------------------

def _grid(lo, hi, step):
    """Centres of about-step cells covering lo..hi exactly."""
    import numpy as np

    n = max(1, int(math.ceil((hi - lo) / step - 1e-9)))
    return lo + (np.arange(n) + 0.5) * (hi - lo) / n


def _face(axis, at, normal_sign, lo, hi, step):
    """Patch centres and normals of the axis-aligned face {p[axis] = at} over lo..hi
    (the other two axes)."""
    import numpy as np

    a, b = [k for k in range(3) if k != axis]
    ga, gb = np.meshgrid(_grid(lo[a], hi[a], step), _grid(lo[b], hi[b], step), indexing="ij")
    centres = np.zeros((ga.size, 3))
    centres[:, axis], centres[:, a], centres[:, b] = at, ga.ravel(), gb.ravel()
    normals = np.zeros_like(centres)
    normals[:, axis] = normal_sign
    return centres, normals


def patches(room, step=0.15):
    """(centres (N, 3), normals (N, 3), class names (N,)) of the room's surfaces:
    walls, floor, ceiling and pillar faces, less what lies inside a pillar or outside
    the room. Normals point into free space."""
    import numpy as np

    lo, hi = np.array(room.interior_min), np.array(room.interior_max)
    parts = []
    names = {0: ("wall", "wall"), 1: ("wall", "wall"), 2: ("floor", "ceiling")}
    for axis in range(3):
        parts.append((*_face(axis, lo[axis], 1.0, lo, hi, step), names[axis][0]))
        parts.append((*_face(axis, hi[axis], -1.0, lo, hi, step), names[axis][1]))
    for b_lo, b_hi in room.pillars:
        b_lo, b_hi = np.array(b_lo), np.array(b_hi)
        for axis in range(3):
            parts.append((*_face(axis, b_lo[axis], -1.0, b_lo, b_hi, step), "pillar"))
            parts.append((*_face(axis, b_hi[axis], 1.0, b_lo, b_hi, step), "pillar"))
    centres = np.concatenate([p[0] for p in parts])
    normals = np.concatenate([p[1] for p in parts])
    classes = np.concatenate([[p[2]] * len(p[0]) for p in parts])
    # A patch exists where the point just off it, into free space, is free.
    probe = centres + 1e-4 * normals
    free = np.all((probe > lo) & (probe < hi), axis=1)
    for b_lo, b_hi in room.pillars:
        free &= ~np.all((probe > np.array(b_lo)) & (probe < np.array(b_hi)), axis=1)
    return centres[free], normals[free], classes[free]


# --- visibility ----------------------------------------------------------------------

def _occluded(camera, targets, pillars):
    """Whether the segment camera → each target crosses a pillar (slab test)."""
    import numpy as np

    d = targets - camera
    hidden = np.zeros(len(targets), dtype=bool)
    with np.errstate(divide="ignore", invalid="ignore"):
        for b_lo, b_hi in pillars:
            t0 = (np.array(b_lo) - camera) / d
            t1 = (np.array(b_hi) - camera) / d
            near = np.where(d == 0, -np.inf, np.minimum(t0, t1))
            far = np.where(d == 0, np.inf, np.maximum(t0, t1))
            # A segment parallel to a slab outside it never enters the box.
            outside = (d == 0) & ((camera < np.array(b_lo)) | (camera > np.array(b_hi)))
            near, far = near.max(axis=1), far.min(axis=1)
            hidden |= (near <= far) & (far > 0.0) & (near < 1.0) & ~outside.any(axis=1)
    return hidden


def visible(pose, centres, normals, pillars, camera=None):
    """Boolean mask of the patches a camera at body pose [t, x, y, z, qx, qy, qz, qw]
    sees (see the module docs)."""
    import numpy as np

    width, height, fx, fy, cx, cy, max_depth = camera or (
        WIDTH, HEIGHT, FX, FY, CX, CY, 5.0)
    origin = np.array(pose[1:4])
    r = np.array(rotation(pose[4:8]))
    rel = centres - origin
    body = rel @ r  # world → body: Rᵀ·rel, row-wise
    z = body[:, 0]
    u = cx - fx * body[:, 1] / np.where(z > 0, z, 1.0)
    v = cy - fy * body[:, 2] / np.where(z > 0, z, 1.0)
    mask = (z > 0) & (z <= max_depth) & (u >= 0) & (u < width) & (v >= 0) & (v < height)
    mask &= np.einsum("ij,ij->i", normals, -rel) > 0
    idx = np.nonzero(mask)[0]
    if len(idx) and pillars:
        # Just off the surface, so a pillar's own face does not hide itself.
        targets = centres[idx] + 1e-3 * normals[idx]
        mask[idx[_occluded(origin, targets, pillars)]] = False
    return mask


def coverage(room, poses, step=0.15, at_s=90.0, curve_step_s=1.0, camera=None):
    """What the poses saw of the room (see the module docs)."""
    import numpy as np

    centres, normals, classes = patches(room, step)
    seen = np.zeros(len(centres), dtype=bool)
    t0 = poses[0][0]
    curve, at = [], None
    next_sample = 0.0
    for pose in poses:
        t = pose[0] - t0
        while next_sample < t:  # every pose up to next_sample is in
            curve.append([round(next_sample, 3), float(seen.mean())])
            next_sample += curve_step_s
        if at is None and t > at_s:
            at = float(seen.mean())
        todo = ~seen
        if todo.any():
            seen[todo] |= visible(pose, centres[todo], normals[todo], room.pillars, camera)
    curve.append([round(poses[-1][0] - t0, 3), float(seen.mean())])
    by_class = {c: float(seen[classes == c].mean()) for c in sorted(set(classes.tolist()))}
    return {
        "patches": int(len(centres)),
        "patch_m": step,
        "poses": len(poses),
        "span_s": poses[-1][0] - t0,
        "at_s": at_s,
        "fraction_at": at if at is not None else float(seen.mean()),
        "fraction_end": float(seen.mean()),
        "by_class_end": by_class,
        "curve": curve,
    }


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog=__doc__.split("\n", 2)[2])
    p.add_argument("--scenario", help="troupe scenario with [world.room]")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--autopilot", help="px4_like_autopilot.py report (its track)")
    src.add_argument("--poses", help="JSON [[t, x, y, z, qx, qy, qz, qw], ...]")
    src.add_argument("--mcap", help="a troupe recording (run.mcap)")
    p.add_argument("--robot", type=int, default=0, help="robot index in the recording")
    p.add_argument("--dump-poses", help="write the poses to this JSON file and stop")
    p.add_argument("--patch-m", type=float, default=0.15)
    p.add_argument("--at-s", type=float, default=90.0)
    p.add_argument("--curve-step-s", type=float, default=1.0)
    p.add_argument("--min-dt-s", type=float, default=1.0 / 15.0,
                   help="use poses at least this far apart (default: 15 Hz, the camera's rate)")
    p.add_argument("--max-depth-m", type=float, default=5.0)
    args = p.parse_args()
    if args.autopilot:
        poses = poses_from_autopilot(args.autopilot)
    elif args.mcap:
        poses = poses_from_mcap(args.mcap, args.robot)
    else:
        with open(args.poses, encoding="utf-8") as f:
            poses = json.load(f)
    if args.dump_poses:
        with open(args.dump_poses, "w", encoding="utf-8") as f:
            json.dump(poses, f)
        return 0
    if not args.scenario:
        p.error("--scenario is required to measure coverage")
    room = load_room(args.scenario)
    camera = (WIDTH, HEIGHT, FX, FY, CX, CY, args.max_depth_m)
    result = coverage(room, thin(poses, args.min_dt_s), args.patch_m, args.at_s,
                      args.curve_step_s, camera)
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
