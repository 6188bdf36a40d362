#!/usr/bin/env python3
"""A depth camera and VIO stand-in for troupe's hardware loop test (robot/tests/hardware_loop.rs)
and the hardware benchmark (scripts/hardware_bench/run.py).

It receives the vehicle's state from the pymavlink autopilot (px4_like_autopilot.py
--state-to, JSON datagrams on --state-port), publishes nav_msgs/Odometry (ENU world,
FLU body) for every state, and at --rate-hz a 16UC1 depth image (with its CameraInfo)
of an axis-aligned box room rendered with numpy from the newest state, stamped with
that state's time. With --scenario FILE the room is that troupe scenario's
`[world.room]` (walls, floor, ceiling and solid boxes, hit by slab intersection;
scripts/hardware_bench/room.py reads it), the room `troupe run FILE` flies.
--static-ned stands in for the autopilot's state (a vehicle that does not move).
--pause-depth-at-s/--pause-depth-s stop the depth images (odometry goes on) for a
while, to test what the robot does when its camera stops and comes back. Messages are serialised with rclpy and put on zenoh with rmw_zenoh
keys and attachments (the helpers of ros_peer.py). It deserialises every nav_msgs/Path
troupe publishes back with rclpy, and every diagnostic_msgs/DiagnosticArray on
/diagnostics (the vehicle's state) when the venv has diagnostic_msgs. After --duration-s it prints one JSON report: frame
publish times, the paths received (time and poses), the last status, the diagnostics
received and, with
--team-connect, the samples of troupe's team link by key.
"""
import argparse
import json
import math
import os
import socket
import struct
import sys
import time

import numpy as np
import zenoh
from nav_msgs.msg import Odometry, Path
try:  # ros-diagnostic-msgs: the robot's /diagnostics, when the venv has it
    from diagnostic_msgs.msg import DiagnosticArray
except ImportError:
    DiagnosticArray = None
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header, String
from builtin_interfaces.msg import Time

from ros_peer import key

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..",
                                "hardware_bench"))
from room import load_room  # noqa: E402

# The room without --scenario, ENU metres: [x0, x1], [y0, y1], [z0, z1].
ROOM = ((-3.0, 5.0), (-3.0, 3.0), (0.0, 3.0))


def stamp(t):
    ns = int(t * 1e9)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def slab(lo, hi, origin, d):
    """Entry and exit ray parameters of the slab lo..hi along one axis (d: the rays'
    components on that axis; a ray parallel to the slab is inside it for all t or none)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t0, t1 = (lo - origin) / d, (hi - origin) / d
    inside = (lo <= origin) & (origin <= hi)
    near = np.where(d == 0, np.where(inside, -np.inf, np.inf), np.minimum(t0, t1))
    far = np.where(d == 0, np.where(inside, np.inf, -np.inf), np.maximum(t0, t1))
    return near, far


def render_mm(args, pos, yaw, room=ROOM, boxes=()):
    """z-depth in millimetres of the room's walls, floor and ceiling and of the solid
    `boxes` ((min_xyz, max_xyz) each) in it (camera body frame looks along +x; image x
    is -y, image y is -z; pixel centres at +0.5). A level camera's rays have x and y
    components that depend on the column only and z on the row only, so every slab is
    computed per column or per row and only the combination is per pixel."""
    u = (np.arange(args.width) + 0.5 - args.width / 2) / args.f
    v = (np.arange(args.height) + 0.5 - args.height / 2) / args.f
    c, s = math.cos(yaw), math.sin(yaw)
    dx, dy = c + s * u, s - c * u  # per column (body y = -u)
    dz = -v  # per row (body z = -v); the forward component is 1: t is the z-depth
    t_col = np.full(args.width, np.inf)
    for k, d in ((0, dx), (1, dy)):
        t_col = np.minimum(t_col, slab(room[k][0], room[k][1], pos[k], d)[1])
    t_row = slab(room[2][0], room[2][1], pos[2], dz)[1]
    t = np.minimum(t_row[:, None], t_col[None, :])
    for lo, hi in boxes:
        nx, fx = slab(lo[0], hi[0], pos[0], dx)
        ny, fy = slab(lo[1], hi[1], pos[1], dy)
        nz, fz = slab(lo[2], hi[2], pos[2], dz)
        near_col, far_col = np.maximum(nx, ny), np.minimum(fx, fy)
        if not np.any(near_col <= far_col):
            continue
        near = np.maximum(near_col[None, :], nz[:, None])
        far = np.minimum(far_col[None, :], fz[:, None])
        hit = (near <= far) & (near > 0)
        t = np.where(hit, np.minimum(t, near), t)
    return np.clip(np.rint(t * 1000.0), 0, 65535).astype("<u2")


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--connect", required=True)
    p.add_argument("--state-port", type=int, required=True)
    p.add_argument("--duration-s", type=float, required=True)
    p.add_argument("--rate-hz", type=float, default=15.0)
    p.add_argument("--width", type=int, default=640)
    p.add_argument("--height", type=int, default=480)
    p.add_argument("--f", type=float, default=382.0)
    p.add_argument("--static-ned", default=None,
                   type=lambda v: [float(x) for x in v.split(",")],
                   help="N,E,D: a vehicle that stays there (odometry at 30 Hz) when no "
                        "autopilot sends its state")
    p.add_argument("--team-connect", default=None, help="the robot's team-link endpoint")
    p.add_argument("--scenario", default=None,
                   help="a troupe scenario with [world] kind = \"room\": render its room")
    p.add_argument("--pause-depth-at-s", type=float, default=None,
                   help="stop publishing depth images this long after the start")
    p.add_argument("--pause-depth-s", type=float, default=0.0,
                   help="for this long (odometry goes on)")
    args = p.parse_args()
    room, boxes = ROOM, ()
    if args.scenario:
        scenario_room = load_room(args.scenario)
        room, boxes = scenario_room.boxes, scenario_room.pillars
    args.format, args.domain = "rmw_zenoh", 0

    state_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    state_sock.bind(("127.0.0.1", args.state_port))
    state_sock.settimeout(0.005)
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps("peer"))
    conf.insert_json5("connect/endpoints",
                      json.dumps([args.connect] + ([args.team_connect] if args.team_connect else [])))
    conf.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(conf)

    paths, status, team, diagnostics = [], {}, {}, []

    def on_path(sample):
        path = deserialize_message(bytes(sample.payload.to_bytes()), Path)
        paths.append({"t": time.time(), "frame_id": path.header.frame_id,
                      "poses": [[q.pose.position.x, q.pose.position.y, q.pose.position.z]
                                for q in path.poses]})

    def on_status(sample):
        status.update(json.loads(deserialize_message(bytes(sample.payload.to_bytes()),
                                                     String).data))

    def on_diagnostics(sample):  # the vehicle's state, decoded by rclpy
        array = deserialize_message(bytes(sample.payload.to_bytes()), DiagnosticArray)
        diagnostics.append({"t": time.time(), "status": [
            {"level": int.from_bytes(d.level, "little") if isinstance(d.level, bytes)
             else int(d.level), "name": d.name, "message": d.message,
             "hardware_id": d.hardware_id, "values": {v.key: v.value for v in d.values}}
            for d in array.status]})

    def on_team(sample):  # troupe/<team>/<robot>/<class>: count what the link sends
        k = str(sample.key_expr)
        team[k] = team.get(k, 0) + 1

    subs = [session.declare_subscriber("troupe/*/*/*", on_team),
            session.declare_subscriber(key(args, "/troupe/plan", "nav_msgs/msg/Path", "*"),
                                       on_path),
            session.declare_subscriber(key(args, "/troupe/status", "std_msgs/msg/String", "*"),
                                       on_status)]
    if DiagnosticArray is not None:
        subs.append(session.declare_subscriber(
            key(args, "/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", "*"),
            on_diagnostics))
    gid, sequence = os.urandom(16), {}

    def put(topic, ros_type, message):
        seq = sequence[topic] = sequence.get(topic, 0) + 1
        attachment = struct.pack("<qqB", seq, time.time_ns(), 16) + gid
        session.put(key(args, topic, ros_type), serialize_message(message),
                    attachment=attachment)

    info = CameraInfo(height=args.height, width=args.width, distortion_model="plumb_bob",
                      d=[0.0] * 5,
                      k=[args.f, 0.0, args.width / 2, 0.0, args.f, args.height / 2, 0.0, 0.0, 1.0],
                      r=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                      p=[args.f, 0.0, args.width / 2, 0.0, 0.0, args.f, args.height / 2, 0.0,
                         0.0, 0.0, 1.0, 0.0])
    frames, state = [], None
    start = time.time()
    next_frame = start
    print(f"ready {start:.6f}", flush=True)
    while time.time() - start < args.duration_s:
        try:
            received = json.loads(state_sock.recv(4096))
        except socket.timeout:
            received = None
            if args.static_ned is not None and (state is None or
                                                time.time() - state["t"] >= 1.0 / 30):
                received = {"t": time.time(), "ned": args.static_ned, "yaw_ned": 0.0,
                            "vel_ned": [0.0, 0.0, 0.0]}
        if received is not None:
            state = received
            n, e, d = state["ned"]
            yaw = math.pi / 2 - state["yaw_ned"]
            state["enu"], state["yaw"] = (e, n, -d), yaw
            odom = Odometry(header=Header(stamp=stamp(state["t"]), frame_id="odom"),
                            child_frame_id="base_link")
            odom.pose.pose.position.x, odom.pose.pose.position.y, odom.pose.pose.position.z = (
                e, n, -d)
            odom.pose.pose.orientation.z = math.sin(yaw / 2)
            odom.pose.pose.orientation.w = math.cos(yaw / 2)
            vn, ve, vd = state["vel_ned"]  # ENU velocity into the FLU body frame
            c, s = math.cos(yaw), math.sin(yaw)
            odom.twist.twist.linear.x = c * ve + s * vn
            odom.twist.twist.linear.y = -s * ve + c * vn
            odom.twist.twist.linear.z = -vd
            put("/odom", "nav_msgs/msg/Odometry", odom)
        now = time.time()
        paused = (args.pause_depth_at_s is not None
                  and 0.0 <= now - start - args.pause_depth_at_s < args.pause_depth_s)
        if state is not None and now >= next_frame:
            next_frame += 1.0 / args.rate_hz
            if paused:
                continue
            header = Header(stamp=stamp(state["t"]), frame_id="camera_depth_optical_frame")
            depth = render_mm(args, state["enu"], state["yaw"], room, boxes)
            info.header = header
            put("/camera/depth/camera_info", "sensor_msgs/msg/CameraInfo", info)
            put("/camera/depth/image_rect_raw", "sensor_msgs/msg/Image",
                Image(header=header, height=args.height, width=args.width, encoding="16UC1",
                      is_bigendian=0, step=2 * args.width, data=depth.tobytes()))
            frames.append(time.time())
    for sub in subs:
        sub.undeclare()
    session.close()
    print(json.dumps({"frames": frames, "paths": paths, "status": status, "team": team,
                      "diagnostics": diagnostics}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
