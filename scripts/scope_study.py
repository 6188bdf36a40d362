#!/usr/bin/env python3
"""Received bytes per robot against team size, with and without the neighbourhood
subscription (issue 22; docs/scale.md).

Flies the warehouse team of `sims/scenarios/scope_warehouse.toml` in sim time with
`troupe run`, for each team size and each scope, in a warehouse whose width grows
with the team (one aisle per robot, so robot density stays the same), and prints
one markdown table row per flight: the bytes per second the simulated network
delivered to each robot (the `received_bytes` column of `timeseries.csv`, all
classes, fragments and acks) over a window once every robot has left its start.

    cargo build -p troupe-sims --bin troupe
    python3 scripts/scope_study.py [--troupe target/debug/troupe] [--sizes 2 4 8 16]
        [--window-s 40] [--out runs/scope_study]

Runs one flight at a time (each is single-threaded); a 16-robot flight is the
slowest. Prints the table and writes `rows.json` into OUT.
"""

import argparse
import json
import pathlib
import statistics
import subprocess
import sys
import time

REPO = pathlib.Path(__file__).resolve().parent.parent
BASE = REPO / "sims" / "scenarios" / "scope_warehouse.toml"
AISLE_PITCH_M = 4.7  # shelf depth 1.2 m + aisle 3.5 m (the scenario's)


def scenario(base: str, robots: int, scope: str) -> str:
    """The base scenario for `robots` robots (one aisle each) and `scope`."""
    width_m = max(AISLE_PITCH_M * robots, 9.4)
    rows = robots - 1 if robots > 1 else 1
    return (
        base.replace("robots = 2\n", f"robots = {robots}\n", 1)
        .replace("size_m = [80.0, 9.4, 8.0]", f"size_m = [80.0, {width_m:.1f}, 8.0]", 1)
        .replace("shelf_rows = 1\n", f"shelf_rows = {rows}\n", 1)
        .replace('scope = "neighbourhood"', f'scope = "{scope}"', 1)
    )


DEPARTURE_INTERVAL_S = 4.0  # troupe_sims::world::DEPARTURE_INTERVAL_S


def window_rates(timeseries: pathlib.Path, start_s: float, end_s: float) -> list:
    """Bytes per second each robot received between `start_s` and `end_s`, from the
    cumulative `received_bytes` column of `timeseries.csv`."""
    lines = timeseries.read_text().splitlines()
    columns = lines[0].split(",")
    t_col, robot_col = columns.index("time_s"), columns.index("robot")
    rx_col = columns.index("received_bytes")
    at = {}  # robot -> [(t, bytes)]
    for line in lines[1:]:
        f = line.split(",")
        at.setdefault(int(f[robot_col]), []).append((float(f[t_col]), int(f[rx_col])))
    rates = []
    for robot in sorted(at):
        def value(t):
            return max((b for (s, b) in at[robot] if s <= t), default=0)
        rates.append((value(end_s) - value(start_s)) / (end_s - start_s))
    return rates


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--troupe", default=str(REPO / "target" / "debug" / "troupe"))
    parser.add_argument("--sizes", type=int, nargs="+", default=[2, 4, 8, 16])
    parser.add_argument("--scopes", nargs="+", default=["all", "neighbourhood"])
    parser.add_argument("--window-s", type=float, default=40.0,
                        help="measured once the last robot has left (departures are "
                             "staggered by 4 s)")
    parser.add_argument("--out", default="runs/scope_study")
    args = parser.parse_args()
    out = pathlib.Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    base = BASE.read_text()
    for needle in ("robots = 2\n", "size_m = [80.0, 9.4, 8.0]", "shelf_rows = 1\n",
                   'scope = "neighbourhood"'):
        if needle not in base:
            sys.exit(f"{BASE}: expected `{needle.strip()}` in the base scenario")
    rows = []
    print(f"received bytes per robot, over {args.window_s:.0f} sim s once every robot flies")
    print("| robots | scope | median (kB/s) | max (kB/s) | sim s | wall s | sim s / wall s |")
    print("|---|---|---|---|---|---|---|")
    for robots in args.sizes:
        for scope in args.scopes:
            name = f"scope_{robots}_{scope}"
            path = out / f"{name}.toml"
            path.write_text(scenario(base, robots, scope))
            start_s = DEPARTURE_INTERVAL_S * (robots - 1) + 5.0
            duration_s = start_s + args.window_s + 1.0
            started = time.monotonic()
            run = subprocess.run(
                [args.troupe, "run", str(path), "--out", str(out), "--name", name,
                 "--duration-s", str(duration_s), "--no-progress", "--no-record"],
                capture_output=True, text=True)
            wall_s = time.monotonic() - started
            if run.returncode != 0:
                sys.exit(f"{name}: troupe run failed:\n{run.stderr}")
            rates = window_rates(out / name / "timeseries.csv", start_s,
                                 start_s + args.window_s)
            row = {
                "robots": robots,
                "scope": scope,
                "received_Bps_per_robot": rates,
                "median_kBps": statistics.median(rates) / 1e3,
                "max_kBps": max(rates) / 1e3,
                "sim_s": duration_s,
                "wall_s": wall_s,
            }
            rows.append(row)
            print(f"| {robots} | {scope} | {row['median_kBps']:.2f} | {row['max_kBps']:.2f} "
                  f"| {duration_s:.0f} | {wall_s:.0f} | {duration_s / wall_s:.2f} |",
                  flush=True)
    (out / "rows.json").write_text(json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
