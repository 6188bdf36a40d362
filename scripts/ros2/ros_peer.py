#!/usr/bin/env python3
"""A ROS 2 peer for troupe's ROS 2 driver test (robot/tests/ros2_zenoh.rs).

Builds real messages with the ROS 2 message packages and serialises them with rclpy's
`serialize_message`, then publishes them with zenoh's Python binding on the keys ROS 2
uses, written here independently of troupe's Rust code:

- rmw_zenoh: `<domain>/<topic>/<pkg>::msg::dds_::<Type>_/<RIHS01 hash from the wheel's
  type description>`, with rmw_zenoh's 33-byte attachment (sequence number, source
  timestamp, GID);
- bridge (zenoh-bridge-ros2dds): the topic without its leading slash, no attachment.

It keeps publishing (odometry, then the frame, every 50 ms, stamped now) until troupe's
`nav_msgs/Path`, `sensor_msgs/PointCloud2` map and `std_msgs/String` status have all
arrived; it deserialises them with rclpy's `deserialize_message` and prints one JSON line
with what it received (attachments included). Exits 1 if they did not all come within
--timeout seconds.
"""
import argparse
import json
import math
import os
import pathlib
import struct
import sys
import time

import zenoh
from geometry_msgs.msg import Point, Quaternion, Vector3
from nav_msgs.msg import Odometry, Path
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import CameraInfo, Image, PointCloud2, PointField
from std_msgs.msg import Header, String
from builtin_interfaces.msg import Time

SHARE = pathlib.Path(sys.prefix) / "share"


def type_hash(ros_type):
    pkg, kind, name = ros_type.split("/")
    with open(SHARE / pkg / kind / f"{name}.json") as f:
        for entry in json.load(f)["type_hashes"]:
            if entry["type_name"] == ros_type:
                return entry["hash_string"]
    raise KeyError(ros_type)


def key(args, topic, ros_type, hash_part=None):
    name = topic.lstrip("/")
    if args.format == "bridge":
        return name
    pkg, kind, type_name = ros_type.split("/")
    hash_part = hash_part or type_hash(ros_type)
    return f"{args.domain}/{name}/{pkg}::{kind}::dds_::{type_name}_/{hash_part}"


def stamp_now():
    ns = time.time_ns()
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


W, H = 8, 6


def depth_image(header):
    mm = [0 if (r, c) == (0, 0) else 1000 + 100 * r + 10 * c for r in range(H) for c in range(W)]
    return Image(header=header, height=H, width=W, encoding="16UC1", is_bigendian=0,
                 step=2 * W, data=struct.pack(f"<{W * H}H", *mm))


def intensity_image(header):
    return Image(header=header, height=H, width=W, encoding="mono8", is_bigendian=0, step=W,
                 data=bytes(10 * c + r for r in range(H) for c in range(W)))


def camera_info(header):
    return CameraInfo(header=header, height=H, width=W, distortion_model="plumb_bob",
                      d=[0.0] * 5, k=[4.0, 0.0, 3.5, 0.0, 4.0, 2.5, 0.0, 0.0, 1.0],
                      r=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                      p=[4.0, 0.0, 3.5, 0.0, 0.0, 4.0, 2.5, 0.0, 0.0, 0.0, 1.0, 0.0])


POINTS = [(0.0, 0.0, 2.0), (1.0, 0.5, 4.0), (-0.5, -0.25, 1.0)]


def point_cloud(header):
    # z first, then y and x, 16-byte points with 4 bytes of padding.
    fields = [PointField(name="z", offset=0, datatype=PointField.FLOAT32, count=1),
              PointField(name="y", offset=4, datatype=PointField.FLOAT32, count=1),
              PointField(name="x", offset=8, datatype=PointField.FLOAT32, count=1)]
    data = b"".join(struct.pack("<3f", z, y, x) + b"\0" * 4 for x, y, z in POINTS)
    return PointCloud2(header=header, height=1, width=len(POINTS), fields=fields,
                       is_bigendian=False, point_step=16, row_step=16 * len(POINTS),
                       data=data, is_dense=True)


def odometry(header):
    m = Odometry(header=header, child_frame_id="base_link")
    m.pose.pose.position = Point(x=1.0, y=2.0, z=3.0)
    m.pose.pose.orientation = Quaternion(x=0.0, y=0.0, z=math.sin(math.pi / 4),
                                         w=math.cos(math.pi / 4))
    m.twist.twist.linear = Vector3(x=1.0, y=0.0, z=0.0)
    return m


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--format", choices=["rmw_zenoh", "bridge"], required=True)
    parser.add_argument("--connect", required=True)
    parser.add_argument("--domain", type=int, default=0)
    parser.add_argument("--timeout", type=float, default=30.0)
    args = parser.parse_args()

    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps("peer"))
    conf.insert_json5("connect/endpoints", json.dumps([args.connect]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(conf)

    received = {}

    def on_path(sample):
        attachment = sample.attachment
        path = deserialize_message(bytes(sample.payload.to_bytes()), Path)
        received["path"] = {
            "key": str(sample.key_expr),
            "frame_id": path.header.frame_id,
            "poses": [[p.pose.position.x, p.pose.position.y, p.pose.position.z,
                       p.pose.orientation.z, p.pose.orientation.w] for p in path.poses],
            "attachment": list(attachment.to_bytes()) if attachment is not None else None,
        }

    def on_map(sample):
        cloud = deserialize_message(bytes(sample.payload.to_bytes()), PointCloud2)
        points = [struct.unpack_from("<4f", cloud.data, i * cloud.point_step)
                  for i in range(cloud.width * cloud.height)]
        n = max(len(points), 1)
        received["map"] = {
            "key": str(sample.key_expr),
            "frame_id": cloud.header.frame_id,
            "width": cloud.width,
            "fields": [(f.name, f.offset, f.datatype) for f in cloud.fields],
            "mean": [sum(p[k] for p in points) / n for k in range(4)],
        }

    def on_status(sample):
        text = deserialize_message(bytes(sample.payload.to_bytes()), String).data
        received["status"] = json.loads(text)

    subs = [
        session.declare_subscriber(key(args, "/troupe/plan", "nav_msgs/msg/Path", "*"), on_path),
        session.declare_subscriber(
            key(args, "/troupe/map", "sensor_msgs/msg/PointCloud2", "*"), on_map),
        session.declare_subscriber(key(args, "/troupe/status", "std_msgs/msg/String", "*"),
                                   on_status),
    ]
    wanted = ("path", "map", "status")

    gid = os.urandom(16)
    sequence = {}

    def put(topic, ros_type, message):
        k = key(args, topic, ros_type)
        payload = serialize_message(message)
        if args.format == "rmw_zenoh":
            seq = sequence[topic] = sequence.get(topic, 0) + 1
            attachment = struct.pack("<qqB", seq, time.time_ns(), 16) + gid
            session.put(k, payload, attachment=attachment)
        else:
            session.put(k, payload)

    deadline = time.time() + args.timeout
    while not all(w in received for w in wanted) and time.time() < deadline:
        header = Header(stamp=stamp_now(), frame_id="camera_depth_optical_frame")
        put("/odom", "nav_msgs/msg/Odometry", odometry(Header(stamp=header.stamp, frame_id="odom")))
        if args.format == "rmw_zenoh":
            put("/camera/depth/camera_info", "sensor_msgs/msg/CameraInfo", camera_info(header))
            put("/camera/infra1/image_rect_raw", "sensor_msgs/msg/Image", intensity_image(header))
            put("/camera/depth/image_rect_raw", "sensor_msgs/msg/Image", depth_image(header))
        else:
            put("/camera/depth/points", "sensor_msgs/msg/PointCloud2", point_cloud(header))
        time.sleep(0.05)
    for sub in subs:
        sub.undeclare()
    session.close()
    missing = [w for w in wanted if w not in received]
    if missing:
        print(json.dumps({"error": f"nothing received for {missing}"}))
        return 1
    print(json.dumps(received))
    return 0


if __name__ == "__main__":
    sys.exit(main())
