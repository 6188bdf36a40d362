"""The room of a troupe scenario's `[world.room]` table (sims/src/world/room.rs), read
with Python 3.11's tomllib, so the simulator, the camera stand-in
(scripts/ros2/box_room_camera.py --scenario) and the ground truth
(scripts/hardware_bench/surfaces.py) share one room description.

The table must spell out `interior_min_m`, `interior_max_m` and `pillars` (the Rust
defaults are not repeated here); `starts_m` and `start_yaw_deg` are optional.
Coordinates are troupe's world frame: ENU, z up, metres.
"""
import math
import tomllib
from dataclasses import dataclass, field


class RoomError(ValueError):
    """A scenario whose room cannot be read; the message names the file and key."""


@dataclass
class Room:
    interior_min: tuple
    interior_max: tuple
    pillars: list  # [(min_xyz, max_xyz)]
    starts: list = field(default_factory=list)  # [(x, y, z)]
    start_yaws_rad: list = field(default_factory=list)

    @property
    def boxes(self):
        """The interior as ((x0, x1), (y0, y1), (z0, z1))."""
        return tuple((self.interior_min[k], self.interior_max[k]) for k in range(3))

    def start(self, i=0):
        """Start position and heading (radians from +x towards +y) of start i."""
        p = self.starts[i % len(self.starts)]
        yaw = self.start_yaws_rad[i % len(self.start_yaws_rad)] if self.start_yaws_rad else 0.0
        return tuple(p), yaw

    def sdf(self, p):
        """Signed distance (positive in free space) of point p: exact, like the Rust one."""
        inside = all(self.interior_min[k] <= p[k] <= self.interior_max[k] for k in range(3))
        if not inside:
            return -_box_distance(self.interior_min, self.interior_max, p)
        d = min(min(p[k] - self.interior_min[k], self.interior_max[k] - p[k]) for k in range(3))
        for lo, hi in self.pillars:
            if all(lo[k] <= p[k] <= hi[k] for k in range(3)):
                d = min(d, -min(min(p[k] - lo[k], hi[k] - p[k]) for k in range(3)))
            else:
                d = min(d, _box_distance(lo, hi, p))
        return d


def _box_distance(lo, hi, p):
    return math.sqrt(sum(max(lo[k] - p[k], 0.0, p[k] - hi[k]) ** 2 for k in range(3)))


def _triple(path, key, value):
    if not (isinstance(value, list) and len(value) == 3
            and all(isinstance(v, (int, float)) and math.isfinite(v) for v in value)):
        raise RoomError(f"{path}: key `world.room.{key}` must be three finite numbers, got {value!r}")
    return tuple(float(v) for v in value)


def load_room(path):
    """The room of scenario file `path`; RoomError naming the key if it has none."""
    with open(path, "rb") as f:
        scenario = tomllib.load(f)
    world = scenario.get("world", {})
    if world.get("kind") != "room":
        raise RoomError(f"{path}: key `world.kind` must be \"room\", got {world.get('kind')!r}")
    table = world.get("room")
    if not isinstance(table, dict):
        raise RoomError(f"{path}: a `[world.room]` table is required")
    for key in ("interior_min_m", "interior_max_m", "pillars"):
        if key not in table:
            raise RoomError(f"{path}: key `world.room.{key}` must be given (the benchmark "
                            "does not repeat the simulator's defaults)")
    lo = _triple(path, "interior_min_m", table["interior_min_m"])
    hi = _triple(path, "interior_max_m", table["interior_max_m"])
    if not all(hi[k] - lo[k] >= 1.0 for k in range(3)):
        raise RoomError(f"{path}: key `world.room.interior_max_m` must be at least 1 m above "
                        f"interior_min_m on every axis, got {list(hi)}")
    pillars = []
    for i, b in enumerate(table["pillars"]):
        b_lo = _triple(path, f"pillars[{i}].min_m", b.get("min_m"))
        b_hi = _triple(path, f"pillars[{i}].max_m", b.get("max_m"))
        if not all(b_hi[k] > b_lo[k] for k in range(3)):
            raise RoomError(f"{path}: key `world.room.pillars[{i}].max_m` must be above min_m "
                            f"on every axis, got {list(b_hi)}")
        pillars.append((b_lo, b_hi))
    starts = [_triple(path, f"starts_m[{i}]", s) for i, s in enumerate(table.get("starts_m", []))]
    yaws = [math.radians(float(y)) for y in table.get("start_yaw_deg", [])]
    return Room(lo, hi, pillars, starts, yaws)
