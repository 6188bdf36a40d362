#!/usr/bin/env python3
"""Checks a `troupe run` recording with an independent reader (the `mcap` and
`jsonschema` packages from PyPI), against the run's own outputs:

- every channel: JSON messages, a `jsonschema` schema of the expected name for its
  topic, and every message valid under its channel's schema;
- messages per robot: poses = odometry published, plans = committed plans, own
  keyframes = the robot's map, received keyframes = `peer/keyframe` deliveries, link
  statuses = `link/status` publications, samples = rows of `timeseries.csv`
  (all from `summary.json` / `timeseries.csv`);
- the pose at each sample time (the last pose logged at or before it) equals the
  position in `timeseries.csv` within 1e-6 m;
- the ellipsoids of each own keyframe match `maps/robot<i>.troupe`: one per
  component, centred on the mean, and the covariance rebuilt from the ellipsoid's
  axes (2 sigma) equals the component's spatial covariance;
- the point cloud drawn from each keyframe (own and received) lies within 6 sigma of
  one of that keyframe's ellipsoids, with intensities in [0, 1];
- the local grid clouds: occupied cells on one lattice of the grid's resolution,
  frontier cells none of them, at most `[metrics] record_grid_hz` a second; the
  remembered frontiers on the memory's 1 m lattice, each set with a route over that
  lattice, neighbour to neighbour, ending on one of them; depth images only when
  `[metrics] record_depth_hz` asks, each `32FC1` of the camera's size;
- the world surface (`/world`): one message at time 0, a triangle list whose
  indices all name a vertex, and every robot pose inside its bounds;
- the chunks' compression (reported: `zstd` by default; the reader decompresses
  them with the `zstandard` and `lz4` packages).

A process or base-station recording (FILE.mcap) gets the schema checks, and the
world and depth checks where it has those channels (`/world` once at its first
message time; depth images `32FC1` of a consistent size).

Usage: check_run.py RUN_DIR   (prints one JSON line of counts; exits 1 on a mismatch)
       check_run.py FILE.mcap  (prints the messages per channel and the chunks'
                                compression; exits 1 on a mismatch)
"""

import base64
import csv
import json
import math
import re
import struct
import sys
import tomllib
from pathlib import Path

import jsonschema
from mcap.reader import make_reader
from quaternion import rotation

POSE_TOLERANCE_M = 1e-6
SIGMAS = 2.0

# Topic pattern -> schema name.
SCHEMAS = [
    (r"/tf", "foxglove.FrameTransform"),
    (r"/robot\d+/pose", "foxglove.PoseInFrame"),
    (r"/robot\d+/(plan|candidates|keyframes|peer_keyframes|peer_plans|route)", "foxglove.SceneUpdate"),
    (r"/robot\d+/link", "troupe.LinkStatus"),
    (r"/robot\d+/vehicle", "troupe.VehicleStatus"),
    (r"/robot\d+/mission", "troupe.MissionStatus"),
    (r"/robot\d+/sample", "troupe.Sample"),
    (r"/team/coverage", "troupe.Coverage"),
    (r"/robot\d+/peers/robot\d+/pose", "foxglove.PoseInFrame"),
    (r"/robot\d+/(keyframe_points|peer_keyframe_points|grid|frontiers|remembered_frontiers)", "foxglove.PointCloud"),
    (r"/robot\d+/depth", "foxglove.RawImage"),
    (r"/world", "foxglove.SceneUpdate"),
]
CLOUD_FIELDS = [("x", 0, 7), ("y", 4, 7), ("z", 8, 7), ("intensity", 12, 7)]
CLOUD_SIGMAS = 6.0


class Mismatch(Exception):
    pass


def expect(condition, message):
    if not condition:
        raise Mismatch(message)


def read_map(path):
    """Keyframes of a troupe map file (format in actors/algorithms/src/mapfile.rs)."""
    data = path.read_bytes()
    expect(data[:8] == b"TROUPEMP", f"{path}: bad magic")
    (version,) = struct.unpack_from("<I", data, 8)
    expect(version == 1, f"{path}: version {version}")
    (count,) = struct.unpack_from("<I", data, 16)
    offset = 28
    keyframes = []
    for _ in range(count):
        stamp_s, *pose = struct.unpack_from("<8d", data, offset)
        offset += 64
        _support, _free_support, m, f = struct.unpack_from("<QQII", data, offset)
        offset += 24
        components = []
        for _ in range(m):
            values = struct.unpack_from("<21d", data, offset)
            offset += 168
            mean = values[1:4]
            cov = [[values[5 + 4 * r + c] for c in range(3)] for r in range(3)]
            components.append((mean, cov))
        offset += f * 8 * 13
        keyframes.append((stamp_s, components))
    return keyframes


def ellipsoid_covariance(sphere):
    r = rotation(sphere["pose"]["orientation"])
    size = sphere["size"]
    var = [(size[k] / (2 * SIGMAS)) ** 2 for k in "xyz"]
    return [[sum(r[i][k] * var[k] * r[j][k] for k in range(3)) for j in range(3)] for i in range(3)]


def read_checked(path):
    """Checks every channel's schema and every message; returns topic -> [(log_time, message)]."""
    messages = {}
    with open(path, "rb") as f:
        validators = {}
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=True):
            topic = channel.topic
            if channel.id not in validators:
                expect(channel.message_encoding == "json", f"{topic}: encoding {channel.message_encoding}")
                expect(schema is not None and schema.encoding == "jsonschema", f"{topic}: not a jsonschema schema")
                wanted = [name for pattern, name in SCHEMAS if re.fullmatch(pattern, topic)]
                expect(wanted == [schema.name], f"{topic}: schema {schema.name}, expected {wanted}")
                document = json.loads(schema.data)
                jsonschema.Draft202012Validator.check_schema(document)
                validators[channel.id] = jsonschema.Draft202012Validator(document)
            decoded = json.loads(message.data)
            errors = list(validators[channel.id].iter_errors(decoded))
            expect(not errors, f"{topic}: message at {message.log_time} breaks its schema: {errors[:1]}")
            messages.setdefault(topic, []).append((message.log_time, decoded))
    expect(messages, f"{path}: no message")
    return messages


def cloud_points(cloud, what):
    """The (x, y, z, intensity) points of a foxglove.PointCloud as troupe writes it."""
    fields = [(f["name"], f["offset"], f["type"]) for f in cloud["fields"]]
    expect(fields == CLOUD_FIELDS and cloud["point_stride"] == 16, f"{what}: fields {fields}")
    data = base64.b64decode(cloud["data"], validate=True)
    expect(len(data) % 16 == 0, f"{what}: {len(data)} bytes is not whole points")
    points = [struct.unpack_from("<4f", data, k) for k in range(0, len(data), 16)]
    expect(all(math.isfinite(v) for p in points for v in p), f"{what}: a non-finite point")
    return points


def mahalanobis2(p, sphere):
    """Squared Mahalanobis distance of p from an ellipsoid's Gaussian (2 sigma axes)."""
    r = rotation(sphere["pose"]["orientation"])
    c = sphere["pose"]["position"]
    d = (p[0] - c["x"], p[1] - c["y"], p[2] - c["z"])
    local = [sum(r[i][k] * d[i] for i in range(3)) for k in range(3)]
    sigma = [sphere["size"][k] / (2 * SIGMAS) for k in "xyz"]
    return sum((local[k] / sigma[k]) ** 2 for k in range(3))


def check_keyframe_clouds(messages, ellipsoid_topic, cloud_topic):
    """Each keyframe's cloud (one per keyframe message, in order) lies near its ellipsoids."""
    updates = messages.get(ellipsoid_topic, [])
    clouds = messages.get(cloud_topic, [])
    expect(len(clouds) == len(updates), f"{cloud_topic}: {len(clouds)} clouds for {len(updates)} keyframes")
    points = 0
    for (t_e, update), (t_c, cloud) in zip(updates, clouds):
        expect(t_e == t_c, f"{cloud_topic}: cloud at {t_c}, keyframe at {t_e}")
        (entity,) = update["entities"]
        spheres = entity["spheres"]
        for p in cloud_points(cloud, cloud_topic):
            expect(0.0 <= p[3] <= 1.0, f"{cloud_topic}: intensity {p[3]}")
            nearest = min(mahalanobis2(p, s) for s in spheres)
            expect(nearest <= CLOUD_SIGMAS**2, f"{cloud_topic}: point {p} is {math.sqrt(nearest):.1f} sigma from {entity['id']}")
            points += 1
    return points


def on_lattice(points, cell_m, what):
    """All points are cell centres of one lattice of edge cell_m."""
    if not points:
        return
    x0 = points[0]
    for p in points:
        for k in range(3):
            steps = (p[k] - x0[k]) / cell_m
            expect(abs(steps - round(steps)) < 1e-2, f"{what}: {p} is off the {cell_m} m lattice of {x0}")


def check_grids(messages, robots, scenario, duration_s):
    metrics = scenario.get("metrics", {})
    grid_hz = metrics.get("record_grid_hz", 1.0)
    depth_hz = metrics.get("record_depth_hz", 0.0)
    resolution_m = scenario.get("robot", {}).get("grid", {}).get("resolution_m", 0.2)
    camera = scenario.get("camera", {})
    counts = {}
    for i in range(robots):
        grids = messages.get(f"/robot{i}/grid", [])
        frontiers = messages.get(f"/robot{i}/frontiers", [])
        memory = messages.get(f"/robot{i}/remembered_frontiers", [])
        depth = messages.get(f"/robot{i}/depth", [])
        most = math.floor(duration_s * grid_hz) + 1
        if grid_hz > 0:
            expect(0 < len(grids) <= most, f"robot{i}: {len(grids)} grids in {duration_s} s at {grid_hz} Hz")
            expect(0 < len(memory) <= most, f"robot{i}: {len(memory)} remembered-frontier sets")
        else:
            expect(not grids and not memory, f"robot{i}: grids recorded with record_grid_hz = 0")
        expect(len(frontiers) == len(grids), f"robot{i}: {len(frontiers)} frontier clouds, {len(grids)} grids")
        occupied_total = 0
        for (t, grid), (t_f, front) in zip(grids, frontiers):
            expect(t == t_f, f"robot{i}: frontiers at {t_f}, grid at {t}")
            occupied = cloud_points(grid, f"/robot{i}/grid")
            expect(all(0.5 < p[3] <= 1.0 for p in occupied), f"robot{i}: an occupied cell with probability <= 0.5")
            cells = cloud_points(front, f"/robot{i}/frontiers")
            on_lattice(occupied + cells, resolution_m, f"robot{i} grid at {t}")
            key = lambda p: tuple(round(v / resolution_m) for v in p[:3])
            expect(not {key(p) for p in occupied} & {key(p) for p in cells}, f"robot{i}: a frontier cell is occupied at {t}")
            occupied_total += len(occupied)
        expect(grid_hz == 0 or occupied_total > 0, f"robot{i}: no occupied cell recorded")
        remembered = 0
        routes = messages.get(f"/robot{i}/route", [])
        expect(len(routes) == len(memory), f"robot{i}: {len(routes)} routes, {len(memory)} remembered-frontier sets")
        routed = 0
        for (t, cloud), (t_r, update) in zip(memory, routes):
            cells = cloud_points(cloud, f"/robot{i}/remembered_frontiers")
            if cells:
                on_lattice(cells, cells[0][3], f"robot{i} remembered frontiers at {t}")
            remembered += len(cells)
            # The route: passable memory cells, neighbour to neighbour, to a remembered frontier.
            expect(t == t_r, f"robot{i}: route at {t_r}, remembered frontiers at {t}")
            (entity,) = update["entities"]
            route = [(p["x"], p["y"], p["z"]) for line in entity["lines"] for p in line["points"]]
            if route:
                cell_m = cells[0][3]
                on_lattice(cells + [(*p, cell_m) for p in route], cell_m, f"robot{i} route at {t}")
                steps = [math.dist(a, b) for a, b in zip(route, route[1:])]
                expect(all(0 < d <= math.sqrt(3) * cell_m + 1e-6 for d in steps), f"robot{i}: route at {t} jumps")
                goal = min(math.dist(route[-1], c[:3]) for c in cells)
                expect(goal < 1e-6, f"robot{i}: route at {t} ends {goal} m from a remembered frontier")
                routed += 1
        expect(not memory or routed > 0, f"robot{i}: no route to a remembered frontier")
        if depth_hz > 0:
            expect(0 < len(depth) <= math.floor(duration_s * depth_hz) + 1, f"robot{i}: {len(depth)} depth frames")
        else:
            expect(not depth, f"robot{i}: depth frames recorded with record_depth_hz = 0")
        size = (camera.get("width", 160), camera.get("height", 120))
        for t, image in depth:
            check_depth(image, f"robot{i} at {t}", size)
        counts[i] = {"grids": len(grids), "occupied_cells": occupied_total, "remembered_frontiers": remembered, "routes": routed, "depth": len(depth)}
    return counts


def check_depth(image, what, size=None):
    w, h = image["width"], image["height"]
    expect(size is None or (w, h) == size, f"{what}: depth image {w} x {h}, expected {size}")
    expect(image["encoding"] == "32FC1" and image["step"] == 4 * w, f"{what}: depth encoding")
    data = base64.b64decode(image["data"], validate=True)
    expect(len(data) == 4 * w * h, f"{what}: depth image of {len(data)} bytes")
    depths = struct.unpack(f"<{w * h}f", data)
    expect(all(math.isfinite(d) and d >= 0 for d in depths), f"{what}: a depth not finite or negative")
    return (w, h)


def check_world(messages, start=0):
    worlds = messages.get("/world", [])
    expect(len(worlds) == 1 and worlds[0][0] == start, f"/world: {[t for t, _ in worlds]}, expected one at {start}")
    (entity,) = worlds[0][1]["entities"]
    (mesh,) = entity["triangles"]
    points, indices = mesh["points"], mesh["indices"]
    expect(points and len(indices) % 3 == 0 and indices, f"/world: {len(points)} points, {len(indices)} indices")
    expect(all(0 <= k < len(points) for k in indices), "/world: an index names no vertex")
    low = [min(p[a] for p in points) for a in "xyz"]
    high = [max(p[a] for p in points) for a in "xyz"]
    for topic, poses in messages.items():
        if re.fullmatch(r"/robot\d+/pose", topic):
            for _, pose in poses:
                p = pose["pose"]["position"]
                expect(all(low[k] <= p[a] <= high[k] for k, a in enumerate("xyz")), f"{topic}: {p} outside the world")
    return len(indices) // 3


def check_schemas(path):
    messages = read_checked(path)
    if "/world" in messages:
        check_world(messages, min(t for m in messages.values() for t, _ in m))
    for topic, images in messages.items():
        if re.fullmatch(r"/robot\d+/depth", topic):
            sizes = {check_depth(image, f"{topic} at {t}") for t, image in images}
            expect(len(sizes) == 1, f"{topic}: images of sizes {sizes}")
    return {
        "channels": {topic: len(m) for topic, m in messages.items()},
        "compression": chunk_compression(path),
    }


def chunk_compression(path):
    """The compressions the file's chunks name ("" for uncompressed ones)."""
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    return sorted({c.compression for c in summary.chunk_indexes}) if summary else []


def check(run_dir):
    summary = json.loads((run_dir / "summary.json").read_text())
    with open(run_dir / "timeseries.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    robots = summary["robots"]

    messages = read_checked(run_dir / "run.mcap")
    with open(run_dir / "run.mcap", "rb") as f:
        reader = make_reader(f)
        attachments = {a.name for a in reader.iter_attachments()}
    expect({"summary.json", "scenario.toml"} <= attachments, f"attachments {attachments}")
    with open(run_dir / "run.mcap", "rb") as f:
        (scenario_text,) = [a.data for a in make_reader(f).iter_attachments() if a.name == "scenario.toml"]
    scenario = tomllib.loads(scenario_text.decode())

    def count(topic):
        return len(messages.get(topic, []))

    counts = {}
    for i in range(robots):
        stats = summary["per_robot"][i]
        topics = stats["topics"]
        published = lambda name: topics.get(name, {}).get("messages", 0)
        expected = {
            f"/robot{i}/pose": published("odometry"),
            f"/robot{i}/plan": published("plan/committed"),
            f"/robot{i}/keyframes": summary["maps"][i]["keyframes"] if summary["maps"] else 0,
            f"/robot{i}/peer_keyframes": published("peer/keyframe"),
            f"/robot{i}/peer_plans": published("peer/plan"),
            f"/robot{i}/link": published("link/status"),
            f"/robot{i}/sample": sum(1 for r in rows if int(r["robot"]) == i),
        }
        expect(stats["plans"] == published("plan/committed"), f"robot{i}: plans")
        for topic, n in expected.items():
            expect(count(topic) == n, f"{topic}: {count(topic)} messages, the run says {n}")
        expect(count(f"/robot{i}/pose") > 0, f"robot{i}: no pose")
        expect(count(f"/robot{i}/candidates") > 0, f"robot{i}: no planning round")
        counts[f"robot{i}"] = {t.split("/")[-1]: n for t, n in expected.items()}
    expect(count("/tf") == sum(count(f"/robot{i}/pose") + 1 for i in range(robots)), "/tf count")

    # Poses at the sample times equal timeseries.csv.
    compared = 0
    for i in range(robots):
        poses = messages[f"/robot{i}/pose"]
        csv_rows = {r["time_s"]: r for r in rows if int(r["robot"]) == i}
        k = -1
        for log_time, sample in messages[f"/robot{i}/sample"]:
            while k + 1 < len(poses) and poses[k + 1][0] <= log_time:
                k += 1
            expect(k >= 0, f"robot{i}: no pose before the sample at {sample['time_s']} s")
            row = next(r for t, r in csv_rows.items() if float(t) == sample["time_s"])
            p = poses[k][1]["pose"]["position"]
            error = math.dist((p["x"], p["y"], p["z"]), (float(row["x_m"]), float(row["y_m"]), float(row["z_m"])))
            expect(error <= POSE_TOLERANCE_M, f"robot{i} at {sample['time_s']} s: pose {p} is {error} m from timeseries.csv")
            compared += 1

    # Own keyframe ellipsoids equal the map files.
    ellipsoids = 0
    for i in range(robots):
        path = run_dir / "maps" / f"robot{i}.troupe"
        recorded = messages.get(f"/robot{i}/keyframes", [])
        if not path.exists():
            expect(not recorded, f"robot{i}: keyframes recorded but no map")
            continue
        keyframes = read_map(path)
        expect(len(keyframes) == len(recorded), f"robot{i}: {len(recorded)} keyframes recorded, {len(keyframes)} in the map")
        for (stamp_s, components), (_, update) in zip(keyframes, recorded):
            (entity,) = update["entities"]
            meta = {kv["key"]: kv["value"] for kv in entity["metadata"]}
            expect(float(meta["stamp_s"]) == stamp_s, f"robot{i}: keyframe stamp {meta['stamp_s']} vs {stamp_s}")
            spheres = entity["spheres"]
            expect(len(spheres) == len(components), f"robot{i}: {len(spheres)} ellipsoids, {len(components)} components")
            for sphere, (mean, cov) in zip(spheres, components):
                c = sphere["pose"]["position"]
                expect(math.dist((c["x"], c["y"], c["z"]), mean) <= 1e-12, f"robot{i}: ellipsoid centre {c} vs {mean}")
                rebuilt = ellipsoid_covariance(sphere)
                scale = max(abs(v) for row in cov for v in row)
                worst = max(abs(rebuilt[r][s] - (cov[r][s] + cov[s][r]) / 2) for r in range(3) for s in range(3))
                expect(worst <= 1e-6 * scale, f"robot{i}: ellipsoid covariance off by {worst} (scale {scale})")
                ellipsoids += 1
    expect(ellipsoids > 0, "no keyframe ellipsoid to compare")

    cloud_points_checked = 0
    for i in range(robots):
        for own, cloud in [("keyframes", "keyframe_points"), ("peer_keyframes", "peer_keyframe_points")]:
            cloud_points_checked += check_keyframe_clouds(messages, f"/robot{i}/{own}", f"/robot{i}/{cloud}")
    expect(cloud_points_checked > 0, "no keyframe cloud point to check")
    grids = check_grids(messages, robots, scenario, summary["duration_s"])
    world_triangles = check_world(messages)

    return {
        "channels": len(messages),
        "messages": sum(len(v) for v in messages.values()),
        "per_robot": counts,
        "poses_compared": compared,
        "ellipsoids_compared": ellipsoids,
        "cloud_points_checked": cloud_points_checked,
        "grids": grids,
        "world_triangles": world_triangles,
        "bytes": (run_dir / "run.mcap").stat().st_size,
        "compression": chunk_compression(run_dir / "run.mcap"),
    }


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    try:
        path = Path(sys.argv[1])
        print(json.dumps(check_schemas(path) if path.suffix == ".mcap" else check(path)))
    except Mismatch as e:
        print(f"check_run: {e}", file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
