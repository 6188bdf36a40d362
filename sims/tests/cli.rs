//! The `troupe` binary as a user runs it.

#![allow(clippy::unwrap_used)]

use std::path::Path;
use std::process::Command;

fn troupe(args: &[&str], dir: &Path) -> std::process::Output {
    troupe_testkit::run_quiet(env!("CARGO_BIN_EXE_troupe"), args, dir)
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
    rejected("[camera]\nrender_stride = 0\n", "camera.render_stride");
    rejected(
        "[camera]\nrender_stride = 2\n[robot.grid]\npixel_stride = 1\n",
        "robot.grid.pixel_stride",
    );
    rejected(
        "[robot.artifacts]\nenabled = true\n",
        "camera.render_stride",
    );
    rejected(
        "[metrics]\nog_change_set_resolutions_m = [0.1, 0.0]\n",
        "metrics.og_change_set_resolutions_m[1]",
    );
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

#[test]
fn a_sweep_writes_one_row_per_run_aggregates_and_plots() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("base.toml"),
        "robots = 1\n[world]\nkind = \"window\"\n[robot]\nradius_m = 0.2\n",
    )
    .unwrap();
    std::fs::write(
        dir.path().join("study.toml"),
        r#"name = "tiny"
scenario = "base.toml"
seeds = [1, 2]
duration_s = 3.0
[[axes]]
key = "robot.speed_mps"
values = [0.5, 1.0]
"#,
    )
    .unwrap();
    let out = troupe(
        &["sweep", "study.toml", "--jobs", "2", "--out", "runs"],
        dir.path(),
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let root = dir.path().join("runs/tiny");
    let results = std::fs::read_to_string(root.join("results.csv")).unwrap();
    let lines: Vec<&str> = results.lines().collect();
    assert_eq!(lines.len(), 5, "{results}");
    assert!(lines[0].starts_with("run,seed,robot.speed_mps,final_coverage"));
    // Runs come back in study order whatever order they finished in.
    assert!(lines[1].starts_with("tiny-0.5-s1,1,0.5,"), "{}", lines[1]);
    assert!(lines[4].starts_with("tiny-1.0-s2,2,1.0,"), "{}", lines[4]);
    let aggregate = std::fs::read_to_string(root.join("aggregate.csv")).unwrap();
    assert_eq!(aggregate.lines().count(), 3, "{aggregate}");
    for file in [
        "coverage.svg",
        "coverage.png",
        "runs/tiny-0.5-s1/summary.json",
    ] {
        assert!(root.join(file).exists(), "{file} missing");
    }
    // An interrupted sweep resumes: finished runs are reused, the missing one flies
    // again and (deterministic, same seed) gives the same row but for its wall time.
    std::fs::remove_dir_all(root.join("runs/tiny-1.0-s1")).unwrap();
    let out = troupe(
        &[
            "sweep",
            "study.toml",
            "--jobs",
            "2",
            "--out",
            "runs",
            "--resume",
        ],
        dir.path(),
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(stderr.contains("3 of 4 runs reused"), "{stderr}");
    assert!(stderr.contains("[4/4] tiny-1.0-s1"), "{stderr}");
    let resumed = std::fs::read_to_string(root.join("results.csv")).unwrap();
    let without_wall_s = |csv: &str| -> Vec<String> {
        csv.lines()
            .map(|l| l.rsplit_once(',').map_or(l, |(rest, _)| rest).to_owned())
            .collect()
    };
    assert_eq!(without_wall_s(&resumed), without_wall_s(&results));
    assert_eq!(
        resumed.lines().nth(1),
        lines.get(1).copied(),
        "reused row unchanged"
    );
    // A bad study is one clear error and writes nothing.
    std::fs::write(dir.path().join("bad.toml"), "name = \"x\"\nseeds = []\n").unwrap();
    let out = troupe(&["sweep", "bad.toml", "--out", "bad_runs"], dir.path());
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("seeds"));
    assert!(!dir.path().join("bad_runs").exists());
}

/// Backend `"gpu"` on a machine without a usable Vulkan driver (the loader pointed at
/// none): the run stops at once with one error naming the key, instead of flying
/// robots whose cameras fail every frame.
#[test]
fn a_gpu_camera_without_a_gpu_stops_the_run_with_one_error() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("gpu.toml"),
        "duration_s = 5.0\n[camera]\nbackend = \"gpu\"\n",
    )
    .unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_troupe"))
        .args(["run", "gpu.toml", "--out", "runs", "--no-progress"])
        .current_dir(dir.path())
        .env("RUST_LOG", "off")
        .env("VK_DRIVER_FILES", dir.path().join("none.json"))
        .env("VK_ICD_FILENAMES", dir.path().join("none.json"))
        .output()
        .expect("run troupe");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(stderr.contains("camera.backend"), "{stderr}");
    assert!(stderr.contains("Vulkan adapter"), "{stderr}");
    let written = std::fs::read_dir(dir.path().join("runs"))
        .into_iter()
        .flatten()
        .flatten()
        .any(|run| run.path().join("summary.json").exists());
    assert!(!written, "a run was reported");
}
