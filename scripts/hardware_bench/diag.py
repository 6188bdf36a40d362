#!/usr/bin/env python3
"""Where a robot's planning rounds go, from its debug log.

Reads the stderr of `troupe-robot` or `troupe robot` run with
RUST_LOG=troupe_actors=debug (run.py keeps it as robot.log in each flight directory)
and prints one JSON object:

- rounds: the planner's "planning round" lines — the round's time (its handler's
  start, executor time), how long after that the line was written (the round's
  compute time up to its choice: the log line's wall clock minus the executor's start,
  taken as the "running" line's wall clock — or, without one (troupe robot logs it
  under troupe_sims), the fastest round's, which makes them lower bounds — minus the
  round's time), candidates,
  reward, action, position;
- compute_s: median / p95 / max of that compute time;
- stale: the collision actor's "round would not continue the committed flight" lines
  (its time is the decision's), each with the delay from the latest round before it;
- rejections by reason ("candidate rejected"), stops ("every candidate rejected");
- z: the planned positions' heights: range and direction reversals (dithering).

  scripts/hardware_bench/diag.py runs/hardware_bench/debug/hardware-s0/robot.log
"""
import json
import re
import statistics
import sys
from datetime import datetime

from run import z_reversals  # run.py, beside this file

ANSI = re.compile(r"\x1b\[[0-9;]*m")
TS = re.compile(r"^(\d{4}-\d\d-\d\dT[\d:.]+)Z")


def wall(line):
    m = TS.match(line)
    if not m:
        return None
    return datetime.fromisoformat(m.group(1)).timestamp()


def field(line, name):
    m = re.search(rf"\b{name}=(\[[^\]]*\]|Some\([^)]*\)|\S+)", line)
    return m.group(1) if m else None


def seconds(text):
    """Executor time as troupe prints it (e.g. `12.345s`, `1m2.5s`, or a number)."""
    if text is None:
        return None
    text = text.strip('"')
    m = re.fullmatch(r"(?:(\d+)m)?([\d.]+)(ms|s)?", text)
    if not m:
        return None
    value = float(m.group(2)) * (0.001 if m.group(3) == "ms" else 1.0)
    return value + 60.0 * float(m.group(1) or 0)


def numbers(text):
    return [float(v) for v in re.findall(r"-?\d+(?:\.\d+)?(?:e-?\d+)?", text or "")]


def pct(values, q):
    v = sorted(values)
    return v[round((len(v) - 1) * q)] if v else None


def main():
    if len(sys.argv) != 2 or sys.argv[1] in ("-h", "--help"):
        print(__doc__)
        return 0 if len(sys.argv) == 2 else 2
    with open(sys.argv[1], encoding="utf-8", errors="replace") as f:
        lines = [ANSI.sub("", l) for l in f]
    start_wall = None
    rounds, stale, rejections, stops = [], [], {}, 0
    for line in lines:
        w = wall(line)
        if start_wall is None and " running" in line and "INFO" in line:
            start_wall = w
        if "planning round" in line:
            t = seconds(field(line, "time"))
            pos = numbers(field(line, "position"))
            rounds.append({"time_s": t, "wall": w,
                           "candidates": int(field(line, "candidates") or 0),
                           "reward": field(line, "reward"), "action": field(line, "action"),
                           "guided": field(line, "guided"), "position": pos})
        elif "would not continue the committed flight" in line:
            stale.append({"time_s": seconds(field(line, "time")),
                          "round": int(field(line, "round") or 0)})
        elif "candidate rejected" in line:
            reason = field(line, "reason") or "?"
            rejections[reason] = rejections.get(reason, 0) + 1
        elif "every candidate rejected" in line:
            stops += 1
    timed = [r for r in rounds if r["wall"] is not None and r["time_s"] is not None]
    anchor_kind = "running line"
    if start_wall is None and timed:
        # No "running" line (troupe robot logs it under troupe_sims): take the fastest
        # round as taking no time, so these compute times are lower bounds.
        start_wall = min(r["wall"] - r["time_s"] for r in timed)
        anchor_kind = "fastest round"
    for r in timed:
        if start_wall is not None:
            r["compute_s"] = r["wall"] - start_wall - r["time_s"]
    compute = [r["compute_s"] for r in rounds if "compute_s" in r]
    # Anchor the offset on the fastest round (the "running" line comes a little after
    # the executor's start): report both.
    floor = min(compute) if compute else 0.0
    for s in stale:
        before = [r["time_s"] for r in rounds if r["time_s"] is not None
                  and r["time_s"] <= s["time_s"]]
        s["delay_s"] = s["time_s"] - max(before) if before else None
    zs = [r["position"][2] for r in rounds if len(r["position"]) == 3]
    delays = [s["delay_s"] for s in stale if s["delay_s"] is not None]
    out = {
        "rounds": len(rounds),
        "compute_anchor": anchor_kind,
        "compute_s": {"median": pct(compute, 0.5), "p95": pct(compute, 0.95),
                      "max": max(compute) if compute else None, "min": floor},
        "stale": len(stale),
        "stale_delay_s": {"median": pct(delays, 0.5), "max": max(delays) if delays else None},
        "rejections": rejections,
        "stops": stops,
        "no_candidates": sum(r["candidates"] == 0 for r in rounds),
        "z_range_m": (max(zs) - min(zs)) if zs else None,
        "z_reversals_5cm": z_reversals(zs, 0.05),
        "actions": {},
        "round_list": rounds,
        "stale_list": stale,
    }
    for r in rounds:
        kind = (r["action"] or "None").split("(")[0].split("{")[0].strip()
        out["actions"][kind] = out["actions"].get(kind, 0) + 1
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
