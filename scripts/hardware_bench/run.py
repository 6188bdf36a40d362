#!/usr/bin/env python3
"""Does the hardware robot explore? Fly one room three ways and compare.

For every start position (--starts) and path (--paths) it flies --duration-s (90 s):

  hardware  `target/release/troupe-robot` with a robot file written from
            docs/hardware*.md (geofence: the room less --fence-margin-m; camera
            intrinsics from CameraInfo), the camera stand-in
            (scripts/ros2/box_room_camera.py --scenario: 640×480 16UC1 depth at 15 Hz,
            odometry at 30 Hz, rmw_zenoh keys) and the pymavlink autopilot stand-in
            (scripts/mavlink/px4_like_autopilot.py --lag-s), all on this machine;
  run       `target/release/troupe run` of the same room, start and robot settings
            (sims/scenarios/pillar_room.toml with the start, lag, rate, size and
            lead_s of the flight), in simulated time;
  robot     `target/release/troupe robot`: the same scenario's robot as one process on
            the wall clock, its simulated camera and vehicle in it.

Per flight: the fraction of the room's surfaces the camera saw at --duration-s
(surfaces.py; the autopilot's track for the hardware path, the recording's poses
for the others), distance flown, planning rounds and stale rounds, depth frame →
setpoint latency (hardware: a frame's publication → the first plan committed after
it → the first setpoint after that plan, as robot/tests/hardware_loop.rs), the
robot's CPU (% of one core) and peak RSS, and the machine's 1-minute load average
(`uptime` before and after). Writes, under --out/<tag>/, one directory per flight
(robot file or scenario, logs, summary.json, the stand-ins' reports), results.json
and results.md (a markdown table). Flights are run one after another; a flight that
starts at a 1-minute load above --max-start-load waits for it to drop (up to
--load-wait-s).

Build first: cargo build --release -p troupe-robot -p troupe-sims --bins (with the
venvs .venv-ros2, .venv-pymavlink and .venv-mcap in the repository root).

Examples:
  scripts/hardware_bench/run.py                                  # baseline: 3 starts × 3 paths
  scripts/hardware_bench/run.py --paths hardware --starts 0 --lag-s 0 --tag lag0
  RUST_LOG=troupe_actors=debug scripts/hardware_bench/run.py --paths hardware --starts 0 \\
      --record --tag debug       # keeps robot.log (stderr) and out/run.mcap per flight
"""
import argparse
import bisect
import json
import math
import os
import re
import shutil
import socket
import statistics
import subprocess
import sys
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "..", ".."))
sys.path.insert(0, HERE)
from room import load_room  # noqa: E402

SCENARIO = os.path.join(ROOT, "sims", "scenarios", "pillar_room.toml")
# Start positions (x, y, z) and headings (degrees from +x towards +y) in the room.
STARTS = [
    ((2.0, 5.0, 1.5), 0.0),     # west end, facing the length of the room
    ((18.0, 2.0, 1.5), 180.0),  # south-east corner, facing west
    ((10.0, 8.5, 1.5), -90.0),  # middle of the north wall, facing south
]
PATHS = ("hardware", "run", "robot")


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog=__doc__.split("\n", 2)[2])
    p.add_argument("--scenario", default=SCENARIO,
                   help="scenario with [world.room] (default sims/scenarios/pillar_room.toml)")
    p.add_argument("--starts", default="0,1,2",
                   help="indices into the built-in starts (0: (2, 5) facing +x, 1: (18, 2) "
                        "facing -x, 2: (10, 8.5) facing -y; z = 1.5 m)")
    p.add_argument("--paths", default="hardware,run,robot",
                   help="comma-separated: hardware, run, robot")
    p.add_argument("--duration-s", type=float, default=90.0, help="flight length (wall or sim)")
    p.add_argument("--lag-s", type=float, default=0.3,
                   help="vehicle lag time constant (autopilot --lag-s, [vehicle] lag_s)")
    p.add_argument("--sensor-hz", type=float, default=15.0,
                   help="[robot] sensor_rate_hz (the camera stand-in publishes at 15 Hz)")
    p.add_argument("--camera-hz", type=float, default=15.0, help="camera stand-in rate")
    p.add_argument("--size", default="640x480",
                   help="image size WxH (fx = fy = 382·W/640, cx = W/2, cy = H/2)")
    p.add_argument("--odometry", choices=("external", "autopilot"), default="external",
                   help="hardware: [mavlink] odometry_source")
    p.add_argument("--lead-s", type=float, default=None,
                   help="[robot.planner] lead_s (default: the robot's default, 0.11)")
    p.add_argument("--robot-extra", default="",
                   help="TOML lines appended to the hardware robot file's [robot] table "
                        "and the scenario's (e.g. 'mapper.pixel_stride = 4')")
    p.add_argument("--fence-margin-m", type=float, default=0.5)
    p.add_argument("--record", action="store_true",
                   help="hardware: record = true (out/run.mcap); run/robot always record")
    p.add_argument("--pause-depth", default=None,
                   help="hardware: AT_S,FOR_S: the camera stops its depth images then")
    p.add_argument("--tag", default="baseline", help="subdirectory of --out for this batch")
    p.add_argument("--out", default=os.path.join(ROOT, "runs", "hardware_bench"))
    p.add_argument("--max-start-load", type=float, default=3.0,
                   help="wait before a flight while the 1-minute load is above this")
    p.add_argument("--load-wait-s", type=float, default=120.0)
    p.add_argument("--bin-dir", default=os.path.join(ROOT, "target", "release"))
    args = p.parse_args()
    args.starts = [int(s) for s in args.starts.split(",") if s]
    if any(not 0 <= s < len(STARTS) for s in args.starts):
        p.error(f"--starts: indices 0..{len(STARTS) - 1}")
    args.paths = [s for s in args.paths.split(",") if s]
    if any(s not in PATHS for s in args.paths):
        p.error(f"--paths: from {', '.join(PATHS)}")
    w, h = (int(v) for v in args.size.lower().split("x"))
    args.width, args.height = w, h
    return args


# --- small helpers -------------------------------------------------------------------

def free_port(udp=False):
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM if udp else socket.SOCK_STREAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def load1():
    with open("/proc/loadavg", encoding="utf-8") as f:
        return float(f.read().split()[0])


def uptime():
    return subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()


def wait_for_quiet(args):
    start = time.time()
    while load1() > args.max_start_load and time.time() - start < args.load_wait_s:
        time.sleep(5)
    return load1()


def percentile(values, q):
    v = sorted(values)
    return v[round((len(v) - 1) * q)] if v else None


def path_length(points):
    return sum(math.dist(a, b) for a, b in zip(points, points[1:]))


class ProcWatch:
    """Samples a process's CPU time and peak RSS (/proc/<pid>) and the load average
    until it exits."""

    def __init__(self, pid):
        self.pid, self.cpu_s, self.hwm_kb, self.loads = pid, 0.0, 0, []
        self.started = time.time()
        self.ticks = os.sysconf("SC_CLK_TCK")
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        next_load = time.time()
        while True:
            try:
                with open(f"/proc/{self.pid}/stat", encoding="utf-8") as f:
                    fields = f.read().rsplit(")", 1)[1].split()
                if fields[0] == "Z":
                    break
                self.cpu_s = (int(fields[11]) + int(fields[12])) / self.ticks
                with open(f"/proc/{self.pid}/status", encoding="utf-8") as f:
                    for line in f:
                        if line.startswith("VmHWM:"):
                            self.hwm_kb = max(self.hwm_kb, int(line.split()[1]))
            except (OSError, IndexError, ValueError):
                break
            if time.time() >= next_load:
                self.loads.append(load1())
                next_load += 10.0
            time.sleep(0.25)
        self.wall_s = time.time() - self.started

    def result(self):
        self.thread.join(timeout=5)
        wall = getattr(self, "wall_s", time.time() - self.started)
        return {
            "cpu_s": self.cpu_s,
            "wall_s": wall,
            "cpu_pct_one_core": 100.0 * self.cpu_s / wall if wall > 0 else None,
            "peak_rss_mb": self.hwm_kb / 1024.0,
            "load1_during": statistics.median(self.loads) if self.loads else None,
            "load1_max": max(self.loads) if self.loads else None,
        }


def venv_python(name):
    return os.path.join(ROOT, name, "bin", "python")


def surfaces(args, flight_dir, source_flag, source, t_from=None):
    """Runs surfaces.py on the poses of the flight: from t_from (default: the first
    pose) for --duration-s."""
    poses = os.path.join(flight_dir, "poses.json")
    if source_flag == "--mcap":
        subprocess.run([venv_python(".venv-mcap"), os.path.join(HERE, "surfaces.py"),
                        "--mcap", source, "--dump-poses", poses], check=True)
    else:
        subprocess.run([venv_python(".venv-ros2"), os.path.join(HERE, "surfaces.py"),
                        source_flag, source, "--dump-poses", poses], check=True)
    with open(poses, encoding="utf-8") as f:
        pose_list = json.load(f)
    t_from = pose_list[0][0] if t_from is None else t_from
    pose_list = [p for p in pose_list if t_from <= p[0] <= t_from + args.duration_s]
    with open(poses, "w", encoding="utf-8") as f:
        json.dump(pose_list, f)
    out = subprocess.run([venv_python(".venv-ros2"), os.path.join(HERE, "surfaces.py"),
                          "--scenario", args.scenario, "--poses", poses,
                          "--at-s", str(args.duration_s)],
                         check=True, capture_output=True, text=True).stdout
    result = json.loads(out)
    result["distance_m"] = path_length([p[1:4] for p in pose_list])
    return result


# --- the scenario of a flight --------------------------------------------------------

def replace_once(text, pattern, line):
    new, n = re.subn(pattern, line, text, count=1, flags=re.M)
    if n != 1:
        raise SystemExit(f"{SCENARIO}: no line matching {pattern!r} to override")
    return new


def flight_scenario(args, start, path):
    (x, y, z), yaw = STARTS[start]
    with open(args.scenario, encoding="utf-8") as f:
        text = f.read()
    text = replace_once(text, r"^starts_m = .*$", f"starts_m = [[{x}, {y}, {z}]]")
    text = replace_once(text, r"^start_yaw_deg = .*$", f"start_yaw_deg = [{yaw}]")
    text = replace_once(text, r"^duration_s = .*$", f"duration_s = {args.duration_s}")
    text = replace_once(text, r"^lag_s = .*$", f"lag_s = {args.lag_s}")
    text = replace_once(text, r"^sensor_rate_hz = .*$", f"sensor_rate_hz = {args.sensor_hz}")
    f_px = 382.0 * args.width / 640.0
    hfov = math.degrees(2 * math.atan(args.width / 2 / f_px))
    vfov = math.degrees(2 * math.atan(args.height / 2 / f_px))
    text = replace_once(text, r"^width = .*$", f"width = {args.width}")
    text = replace_once(text, r"^height = .*$", f"height = {args.height}")
    text = replace_once(text, r"^hfov_deg = .*$", f"hfov_deg = {hfov!r}")
    text = replace_once(text, r"^vfov_deg = .*$", f"vfov_deg = {vfov!r}")
    text = replace_once(text, r"^name = .*$", f'name = "{path}-s{start}"')
    extra = args.robot_extra.replace("\\n", "\n")
    if extra:
        text = replace_once(text, r"^radius_m = .*$", "radius_m = 0.3\n" + extra)
    if args.lead_s is not None:
        text += f"\n[robot.planner]\nlead_s = {args.lead_s}\n"
    return text


def hardware_robot_file(args, room, ports):
    m = args.fence_margin_m
    fence_min = [room.interior_min[k] + m for k in range(3)]
    fence_max = [room.interior_max[k] - m for k in range(3)]
    extra = args.robot_extra.replace("\\n", "\n")
    planner = f"\n[robot.planner]\nlead_s = {args.lead_s}\n" if args.lead_s is not None else ""
    return f"""# Written by scripts/hardware_bench/run.py as a new user would from docs/hardware*.md.
id = 0
team_size = 1
out = "out"
record = {"true" if args.record else "false"}

[robot]
sensor_rate_hz = {args.sensor_hz}
radius_m = 0.3
{extra}
{planner}
[robot.link]
team = 7

[ros2]
format = "rmw_zenoh"
startup_timeout_s = 20.0
max_depth_m = 5.0
zenoh = {{ mode = "peer", listen = ["tcp/127.0.0.1:{ports['ros']}"] }}

[ros2.topics]
depth = "/camera/depth/image_rect_raw"
camera_info = "/camera/depth/camera_info"
odometry = "/odom"
plan = "/troupe/plan"
status = "/troupe/status"

[mavlink]
connection = "udpin:127.0.0.1:{ports['mavlink']}"
odometry_source = "{args.odometry}"

[mavlink.geofence]
min_m = {fence_min}
max_m = {fence_max}

[zenoh]
mode = "peer"
listen = ["tcp/127.0.0.1:{ports['team']}"]
"""


# --- the three paths -----------------------------------------------------------------

def fly_hardware(args, room, start, flight_dir):
    ports = {"ros": free_port(), "team": free_port(), "mavlink": free_port(True),
             "state": free_port(True)}
    config = os.path.join(flight_dir, "robot.toml")
    with open(config, "w", encoding="utf-8") as f:
        f.write(hardware_robot_file(args, room, ports))
    (x, y, z), yaw_deg = STARTS[start]
    peers_s = str(args.duration_s + 12.0)
    report = os.path.join(flight_dir, "autopilot.json")
    env = dict(os.environ)
    robot_log = open(os.path.join(flight_dir, "robot.log"), "w", encoding="utf-8")
    robot = subprocess.Popen([os.path.join(args.bin_dir, "troupe-robot"), "--config", config,
                              "--duration-s", str(args.duration_s)],
                             stdout=robot_log, stderr=subprocess.STDOUT, env=env)
    watch = ProcWatch(robot.pid)
    autopilot = subprocess.Popen(
        [venv_python(".venv-pymavlink"), os.path.join(ROOT, "scripts/mavlink/px4_like_autopilot.py"),
         "--connection", f"udpout:127.0.0.1:{ports['mavlink']}", "--report", report,
         "--duration-s", peers_s, "--start-ned", f"{y},{x},{-z}",
         "--start-yaw-ned-deg", str(90.0 - yaw_deg), "--lag-s", str(args.lag_s),
         "--state-to", f"127.0.0.1:{ports['state']}"],
        stdout=subprocess.DEVNULL, stderr=open(os.path.join(flight_dir, "autopilot.log"), "w"))
    camera_cmd = [venv_python(".venv-ros2"), os.path.join(ROOT, "scripts/ros2/box_room_camera.py"),
                  "--connect", f"tcp/127.0.0.1:{ports['ros']}",
                  "--team-connect", f"tcp/127.0.0.1:{ports['team']}",
                  "--state-port", str(ports["state"]), "--duration-s", peers_s,
                  "--scenario", args.scenario, "--rate-hz", str(args.camera_hz),
                  "--width", str(args.width), "--height", str(args.height),
                  "--f", str(382.0 * args.width / 640.0)]
    if args.pause_depth:
        at_s, for_s = args.pause_depth.split(",")
        camera_cmd += ["--pause-depth-at-s", at_s, "--pause-depth-s", for_s]
    camera_out = open(os.path.join(flight_dir, "camera.json"), "w", encoding="utf-8")
    camera = subprocess.Popen(camera_cmd, stdout=camera_out,
                              stderr=open(os.path.join(flight_dir, "camera.log"), "w"))
    robot.wait()
    usage = watch.result()
    # The stand-ins run on past the robot (their reports come at their own end).
    camera.wait()
    autopilot.wait()
    robot_log.close()
    camera_out.close()
    result = {"robot_exit": robot.returncode, **usage}
    summary_path = os.path.join(flight_dir, "out", "summary.json")
    if robot.returncode != 0 or not os.path.exists(summary_path):
        result["error"] = f"troupe-robot exited {robot.returncode}; see robot.log"
        return result
    with open(summary_path, encoding="utf-8") as f:
        summary = json.load(f)
    with open(report, encoding="utf-8") as f:
        auto = json.load(f)
    with open(os.path.join(flight_dir, "camera.json"), encoding="utf-8") as f:
        lines = [l for l in f.read().splitlines() if l.startswith("{")]
    cam = json.loads(lines[-1])
    setpoints = auto["setpoints"]
    sp_times = [s["t"] for s in setpoints]
    t_first = sp_times[0] if sp_times else auto["track"][0][0]
    result.update(surfaces(args, flight_dir, "--autopilot", report, t_from=t_first))
    collision = summary.get("collision") or {}
    result["rounds"] = collision.get("rounds", 0) + collision.get("stale_rounds", 0)
    result["stale_rounds"] = collision.get("stale_rounds", 0)
    result["collision"] = collision
    result["frames"] = summary.get("frames")
    result["keyframes"] = summary.get("keyframes")
    result["plans"] = summary.get("plans")
    result["vehicle"] = summary.get("vehicle")
    # Latency: frame publication → first plan committed after it → first setpoint after.
    plans, frames_used = [], []
    with open(os.path.join(flight_dir, "out", "events.csv"), encoding="utf-8") as f:
        for line in f.read().splitlines()[1:]:
            t, event = line.split(",")
            (plans if event == "plan" else frames_used).append(float(t))
    plans.sort()
    lat = []
    for f_t in cam["frames"]:
        i = bisect.bisect_right(plans, f_t)
        if i == len(plans):
            continue
        j = bisect.bisect_right(sp_times, plans[i])
        if j == len(sp_times):
            continue
        lat.append(sp_times[j] - f_t)
    result["latency_median_s"] = percentile(lat, 0.5)
    result["latency_p95_s"] = percentile(lat, 0.95)
    result["latency_frames"] = len(lat)
    result["camera_frames"] = len(cam["frames"])
    result.update(setpoint_stats(setpoints, t_first, args.duration_s))
    return result


def z_reversals(zs, step_m):
    """Reversals of direction of a sequence of heights, counted over steps of at
    least step_m (smaller moves neither reverse nor move the anchor): dithering."""
    reversals, last_sign, anchor = 0, 0, zs[0] if zs else 0.0
    for z in zs:
        if abs(z - anchor) >= step_m:
            sign = 1 if z > anchor else -1
            if last_sign and sign != last_sign:
                reversals += 1
            last_sign, anchor = sign, z
    return reversals


def setpoint_stats(setpoints, t0, duration_s):
    """What the autopilot received: speed, z reversals, acceleration feed-forward."""
    inside = [s for s in setpoints if s["t"] - t0 <= duration_s]
    speeds = [math.sqrt(s["vx"] ** 2 + s["vy"] ** 2 + s["vz"] ** 2) for s in inside]
    moving = [s for s, v in zip(inside, speeds) if v > 0.3]
    acc = [math.sqrt(s["afx"] ** 2 + s["afy"] ** 2 + s["afz"] ** 2) for s in moving]
    zs = [s["z"] for s in inside]
    steps = [math.dist((a["x"], a["y"], a["z"]), (b["x"], b["y"], b["z"]))
             for a, b in zip(inside, inside[1:])]
    gaps = [b["t"] - a["t"] for a, b in zip(inside, inside[1:])]
    # Acceleration feed-forward steps between setpoints that both carry one (type
    # mask bits 0x1C0 clear); a knot plan's setpoints mark it ignored.
    with_acc = [(a, b) for a, b in zip(inside, inside[1:])
                if not (a["type_mask"] & 0x1C0 or b["type_mask"] & 0x1C0)]
    acc_steps = [math.dist((a["afx"], a["afy"], a["afz"]), (b["afx"], b["afy"], b["afz"]))
                 for a, b in with_acc]
    return {
        "setpoints": len(inside),
        "moving_fraction": len(moving) / len(inside) if inside else None,
        "accel_zero_fraction_moving": (sum(a < 1e-6 for a in acc) / len(acc)) if acc else None,
        "accel_max_mps2": max(acc) if acc else None,
        "z_range_m": (max(zs) - min(zs)) if zs else None,
        "z_reversals": z_reversals(zs, 0.01),  # of the z setpoint, by steps over 1 cm
        "max_setpoint_step_m": max(steps) if steps else None,
        "max_setpoint_gap_s": max(gaps) if gaps else None,
        "max_accel_step_mps2": max(acc_steps) if acc_steps else None,
        "setpoint_gaps_over_60ms": sum(g > 0.06 for g in gaps),
    }


def fly_run(args, start, flight_dir):
    scenario = os.path.join(flight_dir, "scenario.toml")
    with open(scenario, "w", encoding="utf-8") as f:
        f.write(flight_scenario(args, start, "run"))
    log = open(os.path.join(flight_dir, "run.log"), "w", encoding="utf-8")
    t0 = time.time()
    proc = subprocess.Popen([os.path.join(args.bin_dir, "troupe"), "run", scenario,
                             "--out", flight_dir, "--no-progress"],
                            stdout=log, stderr=subprocess.STDOUT)
    watch = ProcWatch(proc.pid)
    _, status, rusage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    usage = watch.result()
    wall = time.time() - t0
    usage.update(cpu_s=rusage.ru_utime + rusage.ru_stime, wall_s=wall,
                 peak_rss_mb=rusage.ru_maxrss / 1024.0)
    usage["cpu_pct_one_core"] = 100.0 * usage["cpu_s"] / wall
    log.close()
    run_dir = os.path.join(flight_dir, f"run-s{start}")
    result = {"robot_exit": proc.returncode, **usage}
    if proc.returncode != 0:
        result["error"] = "troupe run failed; see run.log"
        return result
    with open(os.path.join(run_dir, "summary.json"), encoding="utf-8") as f:
        summary = json.load(f)
    with open(os.path.join(run_dir, "timing.json"), encoding="utf-8") as f:
        timing = json.load(f)
    result.update(surfaces(args, flight_dir, "--mcap", os.path.join(run_dir, "run.mcap")))
    topics = summary["per_robot"][0]["topics"] if "topics" in summary["per_robot"][0] \
        else summary["topics"]
    n = lambda k: topics.get(k, {}).get("messages", 0)  # noqa: E731
    result["rounds"] = n("plan/candidates")
    result["stale_rounds"] = n("plan/candidates") - n("plan/committed")
    result["frames"] = n("sensor/frame")
    result["keyframes"] = n("mapper/keyframe")
    result["plans"] = n("plan/committed")
    result["sim_distance_m"] = summary["per_robot"][0]["distance_m"]
    result["sim_seconds_per_wall_second"] = timing.get("sim_seconds_per_wall_second")
    result["handler_latency"] = timing.get("handler_latency", {}).get("robot0")
    result["latency_median_s"] = result["latency_p95_s"] = None
    return result


def fly_robot(args, start, flight_dir):
    scenario = os.path.join(flight_dir, "scenario.toml")
    with open(scenario, "w", encoding="utf-8") as f:
        f.write(flight_scenario(args, start, "robot"))
    config = os.path.join(flight_dir, "robot.toml")
    with open(config, "w", encoding="utf-8") as f:
        f.write(f"""robot = 0
scenario = "scenario.toml"
duration_s = {args.duration_s}
out = "out"
record = true
[zenoh]
mode = "peer"
listen = ["tcp/127.0.0.1:{free_port()}"]
""")
    log = open(os.path.join(flight_dir, "robot.log"), "w", encoding="utf-8")
    proc = subprocess.Popen([os.path.join(args.bin_dir, "troupe"), "robot", "--config", config],
                            stdout=log, stderr=subprocess.STDOUT)
    watch = ProcWatch(proc.pid)
    proc.wait()
    usage = watch.result()
    log.close()
    result = {"robot_exit": proc.returncode, **usage}
    out = os.path.join(flight_dir, "out")
    if proc.returncode != 0 or not os.path.exists(os.path.join(out, "summary.json")):
        result["error"] = "troupe robot failed; see robot.log"
        return result
    with open(os.path.join(out, "summary.json"), encoding="utf-8") as f:
        summary = json.load(f)
    result.update(surfaces(args, flight_dir, "--mcap", os.path.join(out, "run.mcap")))
    collision = summary.get("collision") or {}
    result["rounds"] = collision.get("rounds", 0) + collision.get("stale_rounds", 0)
    result["stale_rounds"] = collision.get("stale_rounds", 0)
    result["collision"] = collision
    topics = summary["topics"]
    n = lambda k: topics.get(k, {}).get("messages", 0)  # noqa: E731
    result["frames"] = n("sensor/frame")
    result["keyframes"] = n("mapper/keyframe")
    result["plans"] = n("plan/committed")
    result["latency_median_s"] = result["latency_p95_s"] = None
    return result


# --- the table -----------------------------------------------------------------------

def fmt(v, spec):
    return "–" if v is None else format(v, spec)


def table(results):
    head = ("| path | start | lag s | seen @T | distance m | rounds | stale | "
            "frame→setpoint median / p95 s | CPU % core | peak RSS MB | load1 (start/during) |")
    rows = [head, "|" + "---|" * 11]
    for r in results:
        if "error" in r:
            rows.append(f"| {r['path']} | {r['start']} | {r['lag_s']} | {r['error']} |")
            continue
        stale = (f"{r['stale_rounds']} ({100.0 * r['stale_rounds'] / r['rounds']:.0f} %)"
                 if r.get("rounds") else "–")
        rows.append(
            f"| {r['path']} | {r['start']} | {r['lag_s']} | {100 * r['fraction_at']:.1f} % "
            f"| {r['distance_m']:.1f} | {r.get('rounds', '–')} | {stale} "
            f"| {fmt(r.get('latency_median_s'), '.2f')} / {fmt(r.get('latency_p95_s'), '.2f')} "
            f"| {fmt(r.get('cpu_pct_one_core'), '.0f')} | {fmt(r.get('peak_rss_mb'), '.0f')} "
            f"| {r['load1_start']:.1f} / {fmt(r.get('load1_during'), '.1f')} |")
    return "\n".join(rows)


def main():
    args = parse_args()
    room = load_room(args.scenario)
    for name in ("troupe-robot", "troupe"):
        if not os.access(os.path.join(args.bin_dir, name), os.X_OK):
            raise SystemExit(f"{args.bin_dir}/{name} missing: cargo build --release "
                             "-p troupe-robot -p troupe-sims --bins")
    batch = os.path.join(args.out, args.tag)
    os.makedirs(batch, exist_ok=True)
    results_path = os.path.join(batch, "results.json")
    results = []
    if os.path.exists(results_path):
        with open(results_path, encoding="utf-8") as f:
            results = json.load(f)
    for start in args.starts:
        for path in args.paths:
            flight_dir = os.path.join(batch, f"{path}-s{start}")
            shutil.rmtree(flight_dir, ignore_errors=True)
            os.makedirs(flight_dir)
            load_start = wait_for_quiet(args)
            before = uptime()
            print(f"[{time.strftime('%H:%M:%S')}] {path} start {start}: {before}", flush=True)
            fly = {"hardware": lambda: fly_hardware(args, room, start, flight_dir),
                   "run": lambda: fly_run(args, start, flight_dir),
                   "robot": lambda: fly_robot(args, start, flight_dir)}[path]
            r = fly()
            r.update(path=path, start=start, lag_s=args.lag_s, sensor_hz=args.sensor_hz,
                     size=args.size, odometry=args.odometry, lead_s=args.lead_s,
                     robot_extra=args.robot_extra, pause_depth=args.pause_depth, tag=args.tag, load1_start=load_start,
                     uptime_before=before, uptime_after=uptime())
            with open(os.path.join(flight_dir, "result.json"), "w", encoding="utf-8") as f:
                json.dump(r, f, indent=1)
            results = [x for x in results if not (x["path"] == path and x["start"] == start)]
            results.append(r)
            with open(results_path, "w", encoding="utf-8") as f:
                json.dump(results, f, indent=1)
            if "error" in r:
                print(f"  {r['error']}", flush=True)
            else:
                print(f"  seen {100 * r['fraction_at']:.1f} %, {r['distance_m']:.1f} m, "
                      f"rounds {r.get('rounds')} stale {r.get('stale_rounds')}, "
                      f"CPU {fmt(r.get('cpu_pct_one_core'), '.0f')} %; {r['uptime_after']}",
                      flush=True)
    results.sort(key=lambda x: (x["start"], PATHS.index(x["path"])))
    md = (f"# Hardware benchmark `{args.tag}` ({time.strftime('%Y-%m-%d %H:%M')})\n\n"
          f"Seen @T: fraction of the room's surfaces seen at T = {args.duration_s:g} s "
          "(scripts/hardware_bench/surfaces.py).\n\n" + table(results) + "\n")
    with open(os.path.join(batch, "results.md"), "w", encoding="utf-8") as f:
        f.write(md)
    print(md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
