#!/usr/bin/env python3
"""A PX4-like autopilot stand-in for troupe's MAVLink vehicle tests (pymavlink).

It speaks MAVLink 2 (common dialect) like a PX4 flight controller in offboard mode:
heartbeats (armed, OFFBOARD), LOCAL_POSITION_NED and ATTITUDE at 30 Hz. It flies a
point mass that follows the SET_POSITION_TARGET_LOCAL_NED setpoints it receives
(feed-forward acceleration plus a PD loop on position and velocity, honouring the
type mask), and after --duration-s writes a JSON report of everything it received.
With --lag-s TAU the achieved acceleration follows the commanded one through a
first-order lag of time constant TAU (a real multirotor's attitude and thrust loops
make it lag its setpoints; 0, the default, applies the command at once).

Usage: px4_like_autopilot.py --connection udpout:127.0.0.1:14540 --report out.json
       [--duration-s 8] [--heartbeat-hz 2] [--heartbeat-stop-after-s 4.5]
       [--start-ned 0,0,-1] [--start-yaw-ned-deg 0] [--lag-s 0]
       [--state-to 127.0.0.1:PORT] [--track-hz 10]

With --state-to it also sends its state as one JSON datagram per LOCAL_POSITION_NED
({"t": unix s, "ned": [x, y, z], "vel_ned": [...], "yaw_ned": rad}) to that UDP
address, for a camera stand-in that renders what the vehicle sees
(scripts/ros2/box_room_camera.py).

The report's "track" is the vehicle's state at --track-hz: [unix s, x, y, z (NED, m),
yaw (NED, rad)].

It prints "ready <unix time>" on stdout once its link is open; times in the report
are Unix seconds.
"""

import argparse
import json
import math
import os
import socket
import sys
import time

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

mavutil.set_dialect("common")
mavlink = mavutil.mavlink

PX4_OFFBOARD = 6 << 16  # PX4 main mode in bits 16-23 of custom_mode
KP = 4.0  # 1/s^2: natural frequency 2 rad/s, critically damped with KD
KD = 4.0  # 1/s
MAX_ACCEL = 15.0  # m/s^2
OFFBOARD_LOSS_S = 0.5  # PX4 leaves offboard when setpoints stop for this long


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--connection", required=True)
    p.add_argument("--report", required=True)
    p.add_argument("--duration-s", type=float, default=8.0)
    p.add_argument("--heartbeat-hz", type=float, default=2.0)
    p.add_argument("--heartbeat-stop-after-s", type=float, default=None)
    p.add_argument("--start-ned", default="0,0,-1")
    p.add_argument("--system-id", type=int, default=1)
    p.add_argument("--component-id", type=int, default=1)
    p.add_argument("--start-yaw-ned-deg", type=float, default=0.0,
                   help="initial heading, NED (degrees from north towards east)")
    p.add_argument("--lag-s", type=float, default=0.0,
                   help="time constant of the lag from commanded to achieved acceleration")
    p.add_argument("--track-hz", type=float, default=10.0,
                   help="rate of the report's track of the vehicle's state")
    p.add_argument("--state-to", default=None)
    args = p.parse_args()
    if not (math.isfinite(args.lag_s) and args.lag_s >= 0.0):
        p.error(f"--lag-s must be a number of seconds >= 0, got {args.lag_s}")
    if not args.track_hz > 0.0:
        p.error(f"--track-hz must be positive, got {args.track_hz}")
    return args


def main():
    args = parse_args()
    conn = mavutil.mavlink_connection(
        args.connection,
        source_system=args.system_id,
        source_component=args.component_id,
        dialect="common",
    )
    pos = [float(v) for v in args.start_ned.split(",")]
    state_sock, state_to = None, None
    if args.state_to:
        host, port = args.state_to.rsplit(":", 1)
        state_sock, state_to = socket.socket(socket.AF_INET, socket.SOCK_DGRAM), (host, int(port))
    vel = [0.0, 0.0, 0.0]
    achieved = [0.0, 0.0, 0.0]  # acceleration after the lag
    yaw = math.radians(args.start_yaw_ned_deg)
    setpoint = None  # (message, receive time)
    received_types = {}
    setpoints = []
    track = []
    t0 = time.time()
    print(f"ready {t0:.6f}", flush=True)
    last_step = t0
    next_heartbeat = t0
    next_state = t0
    next_track = t0
    last_heartbeat_sent = None
    stopped_heartbeats_at = None

    while True:
        now = time.time()
        if now - t0 >= args.duration_s:
            break
        # Receive everything waiting.
        while True:
            try:
                m = conn.recv_match(blocking=False)
            except (ConnectionError, OSError):
                m = None
            if m is None:
                break
            kind = m.get_type()
            if kind == "BAD_DATA":
                continue
            received_types[kind] = received_types.get(kind, 0) + 1
            if kind == "SET_POSITION_TARGET_LOCAL_NED":
                setpoint = (m, now)
                setpoints.append(
                    {
                        "t": now,
                        "x": m.x, "y": m.y, "z": m.z,
                        "vx": m.vx, "vy": m.vy, "vz": m.vz,
                        "afx": m.afx, "afy": m.afy, "afz": m.afz,
                        "yaw": m.yaw, "yaw_rate": m.yaw_rate,
                        "type_mask": m.type_mask,
                        "frame": m.coordinate_frame,
                        "target_system": m.target_system,
                        "target_component": m.target_component,
                        "src_system": m.get_srcSystem(),
                        "src_component": m.get_srcComponent(),
                    }
                )

        # Physics: a point mass following the setpoint (or braking without one).
        dt = now - last_step
        last_step = now
        acc = [-KD * v for v in vel]
        if setpoint is not None and now - setpoint[1] < OFFBOARD_LOSS_S:
            m = setpoint[0]
            mask = m.type_mask
            sp_pos = (m.x, m.y, m.z)
            sp_vel = (m.vx, m.vy, m.vz)
            sp_acc = (m.afx, m.afy, m.afz)
            for i in range(3):
                a = 0.0
                if not mask & (1 << i):
                    a += KP * (sp_pos[i] - pos[i])
                if not mask & (8 << i):
                    a += KD * (sp_vel[i] - vel[i])
                if not mask & (64 << i):
                    a += sp_acc[i]
                acc[i] = a
            if not mask & mavlink.POSITION_TARGET_TYPEMASK_YAW_IGNORE:
                yaw = m.yaw
        keep = math.exp(-dt / args.lag_s) if args.lag_s > 0.0 else 0.0
        for i in range(3):
            a = max(-MAX_ACCEL, min(MAX_ACCEL, acc[i]))
            a = achieved[i] = keep * achieved[i] + (1.0 - keep) * a
            pos[i] += vel[i] * dt + 0.5 * a * dt * dt
            vel[i] += a * dt

        boot_ms = int((now - t0) * 1000) & 0xFFFFFFFF
        heartbeats_on = (
            args.heartbeat_stop_after_s is None or now - t0 < args.heartbeat_stop_after_s
        )
        if not heartbeats_on and stopped_heartbeats_at is None:
            stopped_heartbeats_at = now
        if heartbeats_on and now >= next_heartbeat:
            conn.mav.heartbeat_send(
                mavlink.MAV_TYPE_QUADROTOR,
                mavlink.MAV_AUTOPILOT_PX4,
                mavlink.MAV_MODE_FLAG_SAFETY_ARMED | mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                PX4_OFFBOARD,
                mavlink.MAV_STATE_ACTIVE,
            )
            last_heartbeat_sent = now
            next_heartbeat += 1.0 / args.heartbeat_hz
        if now >= next_state:
            conn.mav.local_position_ned_send(boot_ms, *pos, *vel)
            conn.mav.attitude_send(boot_ms, 0.0, 0.0, yaw, 0.0, 0.0, 0.0)
            if state_sock is not None:
                state = {"t": now, "ned": pos, "vel_ned": vel, "yaw_ned": yaw}
                state_sock.sendto(json.dumps(state).encode(), state_to)
            next_state += 1.0 / 30.0
        if now >= next_track:
            track.append([now, *pos, yaw])
            next_track += 1.0 / args.track_hz
        time.sleep(0.002)

    report = {
        "start": t0,
        "end": time.time(),
        "last_heartbeat_sent": last_heartbeat_sent,
        "heartbeats_stopped_at": stopped_heartbeats_at,
        "received_types": received_types,
        "setpoints": setpoints,
        "track": track,
        "final_position_ned": pos,
        "final_yaw_ned": yaw,
        "lag_s": args.lag_s,
    }
    with open(args.report, "w", encoding="utf-8") as f:
        json.dump(report, f)
    return 0


if __name__ == "__main__":
    sys.exit(main())
