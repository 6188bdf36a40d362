//! The example's binary flies its scenario: the robot's frames come from this
//! crate's `bursty_camera` and its `battery` actor runs, both chosen by name in
//! `scenario.toml`, neither known to troupe.

#![allow(clippy::unwrap_used)]

use std::path::Path;
use std::process::Command;

const DURATION_S: f64 = 15.0;

#[test]
fn custom_parts_fly_from_the_scenario_file() {
    let scenario = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenario.toml");
    let out = tempfile::tempdir().unwrap();
    let status = Command::new(env!("CARGO_BIN_EXE_custom-parts"))
        .args(["run", "--no-progress", "--no-record", "--duration-s"])
        .arg(DURATION_S.to_string())
        .arg("--out")
        .arg(out.path())
        .arg(&scenario)
        .status()
        .unwrap();
    assert!(status.success(), "{status}");
    let text = std::fs::read_to_string(out.path().join("custom_parts/summary.json")).unwrap();
    let summary: serde_json::Value = serde_json::from_str(&text).unwrap();
    let robot = &summary["per_robot"][0];
    // The battery actor ran and published once a second.
    let battery = robot["actors"]
        .as_array()
        .unwrap()
        .iter()
        .find(|a| a["name"] == "battery")
        .expect("a battery actor");
    assert!(battery["handled"].as_u64().unwrap() > 0, "{battery}");
    assert_eq!(battery["errors"], 0, "{battery}");
    let levels = robot["topics"]["battery/level"]["messages"]
        .as_u64()
        .unwrap();
    assert!(
        (DURATION_S as u64 - 1..=DURATION_S as u64).contains(&levels),
        "{levels}"
    );
    // The frames came from the bursty camera: about 30% of the 5 Hz captures lost
    // (the simulator's camera loses none).
    let captures = 5.0 * DURATION_S;
    let frames = robot["topics"]["sensor/frame"]["messages"]
        .as_u64()
        .unwrap() as f64;
    assert!(
        frames > 0.4 * captures && frames < 0.9 * captures,
        "{frames} frames of {captures} captures"
    );
}

#[test]
fn troupe_without_the_parts_refuses_the_file_naming_them() {
    let scenario = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenario.toml");
    let scenario = troupe_sims::scenario::Scenario::load(&scenario).unwrap();
    let e = troupe_sims::team::Team::new(&scenario)
        .err()
        .expect("refused");
    let text = e.to_string();
    assert!(
        text.contains("robot.sensor") && text.contains("sim_camera"),
        "{text}"
    );
    assert!(
        troupe_sims::team::Team::with_parts(&scenario, &troupe_custom_parts::registry(), |_, _| {})
            .is_ok()
    );
}
