#!/usr/bin/env python3
"""A depth camera and VIO stand-in for troupe's hardware loop test (robot/tests/hardware_loop.rs).

It receives the vehicle's state from the pymavlink autopilot (px4_like_autopilot.py
--state-to, JSON datagrams on --state-port), publishes nav_msgs/Odometry (ENU world,
FLU body) for every state, and at --rate-hz a 16UC1 depth image (with its CameraInfo)
of an axis-aligned box room rendered with numpy from the newest state, stamped with
that state's time. Messages are serialised with rclpy and put on zenoh with rmw_zenoh
keys and attachments (the helpers of ros_peer.py). It deserialises every nav_msgs/Path
troupe publishes back with rclpy. After --duration-s it prints one JSON report: frame
publish times, the paths received (time and poses), the last status and, with
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
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header, String
from builtin_interfaces.msg import Time

from ros_peer import key

# The room, ENU metres: [x0, x1], [y0, y1], [z0, z1].
ROOM = ((-3.0, 5.0), (-3.0, 3.0), (0.0, 3.0))


def stamp(t):
    ns = int(t * 1e9)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def render_mm(args, pos, yaw):
    """z-depth in millimetres of the room's walls, floor and ceiling (camera body
    frame looks along +x; image x is -y, image y is -z; pixel centres at +0.5)."""
    u = (np.arange(args.width) + 0.5 - args.width / 2) / args.f
    v = (np.arange(args.height) + 0.5 - args.height / 2) / args.f
    a, b = -u[None, :], -v[:, None]  # body y, z per unit depth
    c, s = math.cos(yaw), math.sin(yaw)
    rays = (c - s * a, s + c * a, b + 0.0 * a)
    t = np.full((args.height, args.width), np.inf)
    for k, (lo, hi) in enumerate(ROOM):
        d = np.broadcast_to(rays[k], t.shape)
        with np.errstate(divide="ignore", invalid="ignore"):
            hit = np.where(d > 0, (hi - pos[k]) / d, np.where(d < 0, (lo - pos[k]) / d, np.inf))
        t = np.minimum(t, hit)
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
    p.add_argument("--team-connect", default=None, help="the robot's team-link endpoint")
    args = p.parse_args()
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

    paths, status, team = [], {}, {}

    def on_path(sample):
        path = deserialize_message(bytes(sample.payload.to_bytes()), Path)
        paths.append({"t": time.time(), "frame_id": path.header.frame_id,
                      "poses": [[q.pose.position.x, q.pose.position.y, q.pose.position.z]
                                for q in path.poses]})

    def on_status(sample):
        status.update(json.loads(deserialize_message(bytes(sample.payload.to_bytes()),
                                                     String).data))

    def on_team(sample):  # troupe/<team>/<robot>/<class>: count what the link sends
        k = str(sample.key_expr)
        team[k] = team.get(k, 0) + 1

    subs = [session.declare_subscriber("troupe/*/*/*", on_team),
            session.declare_subscriber(key(args, "/troupe/plan", "nav_msgs/msg/Path", "*"),
                                       on_path),
            session.declare_subscriber(key(args, "/troupe/status", "std_msgs/msg/String", "*"),
                                       on_status)]
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
            state = json.loads(state_sock.recv(4096))
        except socket.timeout:
            pass
        else:
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
        if state is not None and now >= next_frame:
            next_frame += 1.0 / args.rate_hz
            header = Header(stamp=stamp(state["t"]), frame_id="camera_depth_optical_frame")
            depth = render_mm(args, state["enu"], state["yaw"])
            info.header = header
            put("/camera/depth/camera_info", "sensor_msgs/msg/CameraInfo", info)
            put("/camera/depth/image_rect_raw", "sensor_msgs/msg/Image",
                Image(header=header, height=args.height, width=args.width, encoding="16UC1",
                      is_bigendian=0, step=2 * args.width, data=depth.tobytes()))
            frames.append(time.time())
    for sub in subs:
        sub.undeclare()
    session.close()
    print(json.dumps({"frames": frames, "paths": paths, "status": status, "team": team}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
