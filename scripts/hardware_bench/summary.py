#!/usr/bin/env python3
"""One table over every batch of run.py under runs/hardware_bench/ (or the directory
given): tag, path, start, the flight's settings that differ from the baseline, surfaces
seen, distance, stale rounds, planning-round compute time (from robot.log when the
flight ran with RUST_LOG=troupe_actors=debug, diag.py), latency, CPU, load.

  scripts/hardware_bench/summary.py [runs/hardware_bench] [--json]
"""
import json
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))


def fmt(v, spec, scale=1.0):
    return "–" if v is None else format(v * scale, spec)


def compute_of(flight_dir):
    log = os.path.join(flight_dir, "robot.log")
    if not os.path.exists(log):
        return None
    with open(log, encoding="utf-8", errors="replace") as f:
        if "planning round" not in f.read():
            return None
    out = subprocess.run([sys.executable, os.path.join(HERE, "diag.py"), log],
                         capture_output=True, text=True, check=True).stdout
    return json.loads(out)


def main():
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    root = args[0] if args else os.path.join(HERE, "..", "..", "runs", "hardware_bench")
    rows = []
    for tag in sorted(os.listdir(root)):
        path = os.path.join(root, tag, "results.json")
        if not os.path.exists(path):
            continue
        with open(path, encoding="utf-8") as f:
            for r in json.load(f):
                d = compute_of(os.path.join(root, tag, f"{r['path']}-s{r['start']}"))
                if d:
                    r["round_compute_median_s"] = d["compute_s"]["median"]
                    r["round_compute_p95_s"] = d["compute_s"]["p95"]
                rows.append(r)
    if "--json" in sys.argv:
        print(json.dumps(rows, indent=1))
        return 0
    print("| tag | path | start | settings | seen @90 s | distance m | stale / rounds | "
          "round compute median / p95 s | frame→setpoint median / p95 s | CPU % | RSS MB | "
          "load1 during |")
    print("|" + "---|" * 12)
    for r in sorted(rows, key=lambda r: (r["tag"], r["start"], r["path"])):
        if "error" in r:
            print(f"| {r['tag']} | {r['path']} | {r['start']} | | {r['error']} |")
            continue
        settings = [f"lag {r['lag_s']}"]
        if r.get("sensor_hz") != 15.0:
            settings.append(f"{r['sensor_hz']:g} Hz")
        if r.get("size") != "640x480":
            settings.append(r["size"])
        if r.get("odometry") != "external":
            settings.append(f"{r['odometry']} odometry")
        if r.get("lead_s") is not None:
            settings.append(f"lead_s {r['lead_s']}")
        if r.get("pause_depth") or r["tag"] == "outage":
            settings.append(f"depth paused {r.get('pause_depth') or '30,10'} s")
        if r.get("robot_extra"):
            settings.append(r["robot_extra"])
        print(f"| {r['tag']} | {r['path']} | {r['start']} | {', '.join(settings)} "
              f"| {100 * r['fraction_at']:.1f} % | {r['distance_m']:.0f} "
              f"| {r['stale_rounds']} / {r['rounds']} "
              f"| {fmt(r.get('round_compute_median_s'), '.2f')} / "
              f"{fmt(r.get('round_compute_p95_s'), '.2f')} "
              f"| {fmt(r.get('latency_median_s'), '.2f')} / {fmt(r.get('latency_p95_s'), '.2f')} "
              f"| {fmt(r.get('cpu_pct_one_core'), '.0f')} | {fmt(r.get('peak_rss_mb'), '.0f')} "
              f"| {fmt(r.get('load1_during'), '.1f')} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
