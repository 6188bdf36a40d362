//! `run.mcap` as a user gets it: `troupe run` records by default, the recording
//! changes no flight, `troupe replay` reads it back (summary, plots), and an
//! independent reader — the Python `mcap` and `jsonschema` packages from PyPI, in
//! `.venv-mcap` (installed by `.ci/run`) — checks it against the run's own outputs
//! (`scripts/mcap/check_run.py`: schemas, counts per robot, poses against
//! `timeseries.csv`, ellipsoids against `maps/robot<i>.troupe`). The Python half skips,
//! saying why, without the venv.

#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

fn troupe(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_troupe"))
        .args(args)
        .current_dir(dir)
        .env("RUST_LOG", "off")
        .output()
        .expect("run troupe")
}

fn ok(out: Output) -> String {
    assert!(
        out.status.success(),
        "troupe failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

/// Seconds of the recorded run: long enough for keyframes to reach the other robot.
const DURATION: &str = "20";

#[test]
fn a_run_is_recorded_without_changing_it_and_reads_back() {
    let dir = tempfile::tempdir().unwrap();
    let run = |out: &str, extra: &[&str]| {
        let mut args = vec![
            "run",
            "--duration-s",
            DURATION,
            "--out",
            out,
            "--no-progress",
        ];
        args.extend_from_slice(extra);
        ok(troupe(&args, dir.path()))
    };
    let printed = run("recorded", &[]);
    assert!(printed.contains("MB per robot-minute"), "{printed}");
    run("plain", &["--no-record"]);
    let recorded = dir.path().join("recorded/default");
    let plain = dir.path().join("plain/default");
    assert_eq!(
        std::fs::read(recorded.join("summary.json")).unwrap(),
        std::fs::read(plain.join("summary.json")).unwrap(),
        "recording changed the run"
    );
    assert!(!plain.join("run.mcap").exists());
    let leftovers: Vec<String> = std::fs::read_dir(dir.path().join("recorded"))
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    assert_eq!(leftovers, ["default"], "partial files left behind");

    // `troupe replay`: the summary, and the plots drawn again from the recording.
    let recording = recorded.join("run.mcap");
    let json = ok(troupe(
        &["replay", recording.to_str().unwrap(), "--json"],
        dir.path(),
    ));
    let summary: serde_json::Value = serde_json::from_str(&json).unwrap();
    let channels = summary["channels"].as_object().unwrap();
    for robot in 0..2 {
        for (channel, schema) in [
            ("pose", "foxglove.PoseInFrame"),
            ("plan", "foxglove.SceneUpdate"),
            ("candidates", "foxglove.SceneUpdate"),
            ("keyframes", "foxglove.SceneUpdate"),
            ("peer_keyframes", "foxglove.SceneUpdate"),
            ("link", "troupe.LinkStatus"),
            ("sample", "troupe.Sample"),
        ] {
            let c = &channels[&format!("/robot{robot}/{channel}")];
            assert_eq!(c["schema"], schema, "/robot{robot}/{channel}");
            assert!(
                c["messages"].as_u64().unwrap() > 0,
                "/robot{robot}/{channel}"
            );
        }
    }
    let span = summary["span_s"].as_array().unwrap();
    assert_eq!(span[1].as_f64().unwrap(), 20.0);
    assert_eq!(
        summary["attachments"],
        serde_json::json!(["summary.json", "scenario.toml"])
    );
    let plots = dir.path().join("replot");
    ok(troupe(
        &[
            "replay",
            recording.to_str().unwrap(),
            "--plots",
            plots.to_str().unwrap(),
        ],
        dir.path(),
    ));
    for stem in [
        "coverage",
        "link_bytes",
        "speed",
        "nearest_robot",
        "trajectories",
    ] {
        assert_eq!(
            std::fs::read(plots.join(format!("{stem}.svg"))).unwrap(),
            std::fs::read(recorded.join(format!("{stem}.svg"))).unwrap(),
            "{stem}.svg from the recording differs from the run's"
        );
    }

    // The independent reader.
    let python = root().join(".venv-mcap/bin/python");
    let has_mcap = Command::new(&python)
        .args(["-c", "import mcap, jsonschema"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !has_mcap {
        eprintln!(
            "skipping the Python check: {} cannot import mcap, jsonschema (run .ci/run)",
            python.display()
        );
        return;
    }
    let out = Command::new(&python)
        .arg(root().join("scripts/mcap/check_run.py"))
        .arg(&recorded)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "check_run.py: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(report["poses_compared"].as_u64().unwrap() >= 40, "{report}");
    assert!(
        report["ellipsoids_compared"].as_u64().unwrap() > 0,
        "{report}"
    );
}

#[test]
fn replay_rejects_what_is_not_a_recording_with_one_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let garbage = dir.path().join("garbage.mcap");
    std::fs::write(&garbage, b"\x89MCAP0\r\n this is not a recording").unwrap();
    for file in ["garbage.mcap", "missing.mcap"] {
        let out = troupe(&["replay", file], dir.path());
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{file}");
        assert!(stderr.contains(file), "{stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
}
