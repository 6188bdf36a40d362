//! The `troupe` binary as a user runs it.

#![allow(clippy::unwrap_used)]

use std::path::Path;
use std::process::Command;

fn troupe(args: &[&str], dir: &Path) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_troupe"))
        .args(args)
        .current_dir(dir)
        .env("RUST_LOG", "off")
        .output()
        .expect("run troupe")
}

fn rejected(scenario: &str, key: &str) {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("bad.toml");
    std::fs::write(&file, scenario).unwrap();
    let out = troupe(&["run", "bad.toml", "--out", "runs"], dir.path());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{scenario}");
    assert!(stderr.contains("bad.toml"), "no file name in: {stderr}");
    assert!(stderr.contains(key), "no key `{key}` in: {stderr}");
    assert_eq!(stderr.lines().count(), 1, "not one line: {stderr}");
    assert!(!dir.path().join("runs").exists(), "something was written");
}

#[test]
fn malformed_scenarios_get_one_clear_error_and_write_nothing() {
    rejected("robots = 2\nspeed = 3\n", "speed");
    rejected("robots = \"two\"\n", "robots");
    rejected("robots = -2\n", "robots");
    rejected("[robot]\nsensor_rate_hz = 0.0\n", "robot.sensor_rate_hz");
    rejected("[camera]\nhfov_deg = true\n", "camera.hfov_deg");
    rejected("robots = [\n", "bad.toml");
}

#[test]
fn a_missing_file_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let out = troupe(&["run", "nope.toml"], dir.path());
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("nope.toml"));
}

#[test]
fn help_explains_the_run_options() {
    let dir = tempfile::tempdir().unwrap();
    let out = troupe(&["run", "--help"], dir.path());
    let help = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success());
    for option in ["--seed", "--duration-s", "--robots", "--out", "SCENARIO"] {
        assert!(help.contains(option), "{option} missing from: {help}");
    }
}

#[test]
fn a_short_run_writes_the_report() {
    let dir = tempfile::tempdir().unwrap();
    let out = troupe(
        &[
            "run",
            "--duration-s",
            "5",
            "--name",
            "short",
            "--out",
            "runs",
        ],
        dir.path(),
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let run = dir.path().join("runs/short");
    for file in ["summary.json", "timing.json", "timeseries.csv"] {
        assert!(run.join(file).is_file(), "{file} missing");
    }
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("coverage"), "{stdout}");
}
