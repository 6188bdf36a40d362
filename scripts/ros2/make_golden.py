#!/usr/bin/env python3
"""Writes the golden CDR files under robot/tests/data/ros2/ with rclpy's own serializer.

Run once (the files are committed) with the venv that scripts/ros2/install.sh makes:

    .venv-ros2/bin/python scripts/ros2/make_golden.py

Every value here is checked field by field by robot/tests/ros2_golden.rs; change both together.
"""
import pathlib
import struct
import sys

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion, Vector3
from nav_msgs.msg import Odometry, Path
from rclpy.serialization import serialize_message
from sensor_msgs.msg import CameraInfo, Image, PointCloud2, PointField
from std_msgs.msg import Header, String

OUT = pathlib.Path(__file__).resolve().parents[2] / "robot" / "tests" / "data" / "ros2"
STAMP = Time(sec=1_700_000_000, nanosec=123_456_789)


def header(frame_id):
    return Header(stamp=STAMP, frame_id=frame_id)


def depth_16uc1():
    # 4 wide, 3 high, row-major millimetres; 0 = no return.
    mm = [0, 1000, 1500, 2000, 2500, 3000, 65535, 1, 250, 500, 750, 4999]
    return Image(header=header("camera_depth_optical_frame"), height=3, width=4,
                 encoding="16UC1", is_bigendian=0, step=8,
                 data=struct.pack("<12H", *mm))


def depth_32fc1():
    m = [0.0, 1.0, 1.5, 2.0, 2.5, 3.0, float("nan"), 0.001, 0.25, 0.5, 0.75, 4.999]
    return Image(header=header("camera_depth_optical_frame"), height=3, width=4,
                 encoding="32FC1", is_bigendian=0, step=16,
                 data=struct.pack("<12f", *m))


def camera_info():
    return CameraInfo(header=header("camera_depth_optical_frame"), height=3, width=4,
                      distortion_model="plumb_bob", d=[0.1, -0.2, 0.001, 0.002, 0.0],
                      k=[2.0, 0.0, 2.0, 0.0, 2.5, 1.5, 0.0, 0.0, 1.0],
                      r=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                      p=[2.0, 0.0, 2.0, 0.0, 0.0, 2.5, 1.5, 0.0, 0.0, 0.0, 1.0, 0.0],
                      binning_x=1, binning_y=2)


def points():
    # Fields out of the usual order (intensity first) and a padded 20-byte point.
    fields = [PointField(name="intensity", offset=0, datatype=PointField.FLOAT32, count=1),
              PointField(name="x", offset=4, datatype=PointField.FLOAT32, count=1),
              PointField(name="y", offset=8, datatype=PointField.FLOAT32, count=1),
              PointField(name="z", offset=12, datatype=PointField.FLOAT32, count=1)]
    pts = [(0.5, 0.0, 0.0, 2.0), (0.25, 1.0, -0.5, 4.0), (1.0, -1.0, 0.75, 3.0)]
    data = b"".join(struct.pack("<4f", *p) + b"\xee" * 4 for p in pts)
    return PointCloud2(header=header("camera_depth_optical_frame"), height=1, width=3,
                       fields=fields, is_bigendian=False, point_step=20, row_step=60,
                       data=data, is_dense=True)


def odometry():
    m = Odometry(header=header("odom"), child_frame_id="base_link")
    m.pose.pose = Pose(position=Point(x=1.0, y=-2.0, z=3.5),
                       orientation=Quaternion(x=0.0, y=0.0, z=0.7071067811865476,
                                              w=0.7071067811865476))
    m.pose.covariance = [float(i) for i in range(36)]
    m.twist.twist.linear = Vector3(x=0.5, y=0.0, z=-0.1)
    m.twist.twist.angular = Vector3(x=0.0, y=0.0, z=0.2)
    m.twist.covariance = [float(-i) for i in range(36)]
    return m


def path():
    poses = [PoseStamped(header=header("odom"),
                         pose=Pose(position=Point(x=float(i), y=2.0 * i, z=1.0),
                                   orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)))
             for i in range(2)]
    return Path(header=header("odom"), poses=poses)


def status():
    return String(data='{"robot":"r0","state":"exploring"}')


def diagnostics():
    status = DiagnosticStatus(level=DiagnosticStatus.WARN, name="troupe/robot0/vehicle",
                              message="holding: sensor timeout",
                              hardware_id="MAVLink system 1 component 1",
                              values=[KeyValue(key="armed", value="true"),
                                      KeyValue(key="mode", value="OFFBOARD")])
    return DiagnosticArray(header=header(""), status=[status])


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    for name, make in [("depth_16uc1", depth_16uc1), ("depth_32fc1", depth_32fc1),
                       ("camera_info", camera_info), ("points", points),
                       ("odometry", odometry), ("path", path), ("status", status),
                       ("diagnostics", diagnostics)]:
        (OUT / f"{name}.cdr").write_bytes(serialize_message(make()))
        print(f"wrote {OUT / name}.cdr", file=sys.stderr)


if __name__ == "__main__":
    main()
