//! The scripted exploration worlds as a user reaches them: `troupe run` on the shipped
//! T-junction scenario flies the standard team safely, explores beyond the stem, and
//! reports each robot's discovered volume, unproductive time and re-exploration
//! figures consistently.

#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;

const TROUPE: &str = env!("CARGO_BIN_EXE_troupe");

/// Simulated seconds flown: enough to reach the fork (10 m ahead) and look into it.
const DURATION_S: f64 = 30.0;

/// `troupe run SCENARIO` for `duration_s` into `out`: the run's directory (`out/name`)
/// and its `summary.json`.
fn fly(scenario: &Path, duration_s: f64, out: &Path, name: &str) -> (PathBuf, Value) {
    let run = Command::new(TROUPE)
        .arg("run")
        .arg(scenario)
        .args(["--duration-s", &duration_s.to_string(), "--no-progress"])
        .arg("--out")
        .arg(out)
        .env("RUST_LOG", "off")
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let dir = out.join(name);
    let summary =
        serde_json::from_slice(&std::fs::read(dir.join("summary.json")).unwrap()).unwrap();
    (dir, summary)
}

#[test]
fn a_team_explores_the_t_junction_safely_and_accounts_its_unproductive_time() {
    let out = tempfile::tempdir().unwrap();
    let scenario = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/t_junction.toml");
    let (dir, summary) = fly(&scenario, DURATION_S, out.path(), "t_junction");

    assert_eq!(summary["world"]["kind"], "t_junction");
    assert_eq!(summary["collisions"], 0, "collisions with the world");
    assert_eq!(summary["robot_contacts"], 0, "robot bodies overlapped");
    let over_time: Vec<f64> = summary["coverage"]["over_time"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s[1].as_f64().unwrap())
        .collect();
    assert!(over_time.windows(2).all(|w| w[1] >= w[0]), "{over_time:?}");
    // The stem is a third of the tunnels: covering more means looking into the arms.
    let final_fraction = summary["coverage"]["final_fraction"].as_f64().unwrap();
    assert!(final_fraction > 0.45, "coverage {final_fraction}");

    let robots = summary["per_robot"].as_array().unwrap();
    assert_eq!(robots.len(), 2);
    let mut discovered_m3 = 0.0;
    for r in robots {
        assert_eq!(r["unsafe_plans"], 0, "{}", r["name"]);
        let mine = r["discovered_m3"].as_f64().unwrap();
        let total = r["unproductive_s"].as_f64().unwrap();
        let longest = r["longest_unproductive_s"].as_f64().unwrap();
        let with_frontiers = r["longest_unproductive_with_frontiers_s"].as_f64().unwrap();
        assert!(mine > 0.0, "{} saw nothing first", r["name"]);
        assert!(
            (0.0..=total).contains(&longest) && total <= DURATION_S,
            "{}: longest {longest} s of {total} s",
            r["name"]
        );
        assert!(
            (0.0..=longest).contains(&with_frontiers),
            "{}: {with_frontiers} s with frontiers of the longest {longest} s",
            r["name"]
        );
        discovered_m3 += mine;
        // One planning round per period (1 Hz, from the first grid snapshot on)
        // however much the planner hears from its peers: storing their messages costs
        // no modelled planning latency.
        let rounds = r["topics"]["planner/report"]["messages"].as_u64().unwrap();
        assert!(
            (DURATION_S as u64 - 2..=DURATION_S as u64).contains(&rounds),
            "{}: {rounds} planning rounds in {DURATION_S} s",
            r["name"]
        );
    }
    // Every explored cell was seen first by exactly one robot.
    let explored_m3 = summary["coverage"]["explored_volume_m3"].as_f64().unwrap();
    assert!(
        (discovered_m3 - explored_m3).abs() < 1e-6 * explored_m3,
        "{discovered_m3} m³ discovered, {explored_m3} m³ explored"
    );
    // Re-exploration (thesis §8.2.7): per robot, observed = first observed +
    // re-explored; the team's totals are the robots' sums, and its exclusive and
    // shared volumes make the explored volume.
    let figure = |r: &Value, name: &str| r[name].as_f64().unwrap();
    let team = &summary["reexploration"];
    let (mut reexplored_m3, mut exclusive_m3, mut redundant_s) = (0.0, 0.0, 0.0);
    for r in robots {
        let observed = figure(r, "observed_m3");
        let first = figure(r, "first_observed_m3");
        let again = figure(r, "reexplored_m3");
        assert!(
            (observed - first - again).abs() < 1e-6 * observed,
            "{}: {observed} m³ observed, {first} first, {again} again",
            r["name"]
        );
        assert!(figure(r, "redundant_flight_s") <= DURATION_S);
        reexplored_m3 += again;
        exclusive_m3 += figure(r, "exclusive_m3");
        redundant_s += figure(r, "redundant_flight_s");
    }
    for (name, sum) in [
        ("reexplored_m3", reexplored_m3),
        ("exclusive_m3", exclusive_m3),
        ("redundant_flight_s", redundant_s),
    ] {
        assert!((figure(team, name) - sum).abs() <= 1e-9, "team {name}");
    }
    let shared_m3 = figure(team, "shared_m3");
    assert!(
        (exclusive_m3 + shared_m3 - explored_m3).abs() < 1e-6 * explored_m3,
        "{exclusive_m3} m³ exclusive + {shared_m3} m³ shared, {explored_m3} m³ explored"
    );

    // The time series ends on the summary's figures.
    let csv = std::fs::read_to_string(dir.join("timeseries.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let column = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    for (i, r) in robots.iter().enumerate() {
        let last = rows
            .iter()
            .rev()
            .find(|row| row[column("robot")] == i.to_string())
            .unwrap();
        for name in [
            "discovered_m3",
            "unproductive_s",
            "longest_unproductive_s",
            "longest_unproductive_with_frontiers_s",
            "observed_m3",
            "first_observed_m3",
            "reexplored_m3",
            "exclusive_m3",
            "redundant_flight_s",
        ] {
            let cell: f64 = last[column(name)].parse().unwrap();
            // The same sums, added in a different order: equal to rounding.
            let summary = r[name].as_f64().unwrap();
            assert!(
                (cell - summary).abs() <= 1e-9,
                "robot {i} {name}: {cell} vs {summary}"
            );
        }
    }
}

/// A dead end shortened (14 m tunnel, 8 m side tunnel) so that the team explores it
/// all in about a minute.
fn short_dead_end(dir: &Path) -> PathBuf {
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/dead_end.toml");
    let text = std::fs::read_to_string(shipped)
        .unwrap()
        .replace("dead_end_length_m = 24.0", "dead_end_length_m = 14.0")
        .replace("side_length_m = 12.0", "side_length_m = 8.0");
    assert!(text.contains("= 14.0") && text.contains("= 8.0"), "{text}");
    let path = dir.join("short_dead_end.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// Issue 43's mission that ends: once nothing is left to explore, each robot flies home
/// along its memory's route and holds there, and the reports say when and how far. The
/// robots start in a line at the closed end and share their homes: the first back takes
/// the deepest start, so neither holds on the other's way and both are home.
#[test]
fn a_team_that_has_explored_everything_flies_home_and_holds() {
    const FLOWN_S: f64 = 100.0;
    let out = tempfile::tempdir().unwrap();
    let (dir, summary) = fly(&short_dead_end(out.path()), FLOWN_S, out.path(), "dead_end");
    assert_eq!(summary["collisions"], 0);
    assert_eq!(summary["robot_contacts"], 0);
    let coverage = summary["coverage"]["final_fraction"].as_f64().unwrap();
    assert!(coverage > 0.95, "the team went home at coverage {coverage}");

    let csv = std::fs::read_to_string(dir.join("timeseries.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let column = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    let number = |row: &[&str], name: &str| row[column(name)].parse::<f64>().unwrap();

    let robots = summary["per_robot"].as_array().unwrap();
    let starts: Vec<[f64; 3]> = (0..robots.len())
        .map(|i| {
            let first = rows
                .iter()
                .find(|row| row[column("robot")] == i.to_string())
                .unwrap();
            [
                number(first, "x_m"),
                number(first, "y_m"),
                number(first, "z_m"),
            ]
        })
        .collect();
    let distance = |a: &[f64], b: &[f64]| {
        a.iter()
            .zip(b)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    let mut ended = Vec::new();
    let mut home = Vec::new();
    let mut gaps = Vec::new();
    let mut taken = Vec::new();
    for (i, r) in robots.iter().enumerate() {
        assert_eq!(r["unsafe_plans"], 0, "{}", r["name"]);
        let m = &r["mission"];
        assert_eq!(m["phase"], "home", "{}: {m}", r["name"]);
        assert_eq!(m["end"], "explored", "{}: {m}", r["name"]);
        let ended_s = m["ended_s"].as_f64().unwrap();
        let home_s = m["home_s"].as_f64().unwrap();
        let return_s = m["return_s"].as_f64().unwrap();
        assert!(ended_s < home_s && home_s < FLOWN_S, "{}: {m}", r["name"]);
        assert!((home_s - ended_s - return_s).abs() < 1e-6, "{m}");
        assert!(m["return_distance_m"].as_f64().unwrap() > 0.0, "{m}");
        ended.push(ended_s);
        home.push(home_s);
        // Home is where one of the team began, and the robot holds there.
        let own: Vec<&Vec<&str>> = rows
            .iter()
            .filter(|row| row[column("robot")] == i.to_string())
            .collect();
        let home_m: Vec<f64> = m["home_m"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let gap = |p: [f64; 3]| distance(&p, &home_m);
        let start = starts.iter().position(|s| gap(*s) < 0.2);
        assert!(
            start.is_some(),
            "{}: home {home_m:?}, starts {starts:?}",
            r["name"]
        );
        taken.push(start);
        let home_gap_m = m["home_gap_m"].as_f64().unwrap();
        gaps.push(home_gap_m);
        for row in own
            .iter()
            .filter(|row| number(row, "time_s") >= home_s + 2.0)
        {
            let p = [number(row, "x_m"), number(row, "y_m"), number(row, "z_m")];
            assert!(
                (gap(p) - home_gap_m).abs() < 0.8,
                "{} left where it holds: {p:?} at {}, {home_gap_m} m from home",
                r["name"],
                row[0]
            );
            assert_eq!(row[column("phase")], "home");
        }
        // The phases follow each other in order: exploring, returning, home.
        let order = |phase: &str| {
            ["exploring", "returning", "home"]
                .iter()
                .position(|p| *p == phase)
        };
        let phases: Vec<usize> = own
            .iter()
            .map(|row| order(row[column("phase")]).unwrap())
            .collect();
        assert!(
            phases.windows(2).all(|w| w[0] <= w[1]),
            "{}: {phases:?}",
            r["name"]
        );
    }
    // Every robot is home, each at a start of its own.
    assert!(gaps.iter().all(|g| *g <= 1.0), "{gaps:?}");
    taken.sort();
    taken.dedup();
    assert_eq!(taken.len(), robots.len(), "{taken:?}");
    let team = &summary["mission"];
    let latest = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
    assert_eq!(team["complete_s"].as_f64(), Some(latest(&ended)));
    assert_eq!(team["home_s"].as_f64(), Some(latest(&home)));
}
