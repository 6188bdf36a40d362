//! `run.mcap` as a user gets it: `troupe run` records by default, the recording
//! changes no flight, `troupe replay` reads it back (summary, plots), and an
//! independent reader — the Python `mcap` and `jsonschema` packages from PyPI, in
//! `.venv-mcap` (installed by `.ci/run`) — checks it against the run's own outputs
//! (`scripts/mcap/check_run.py`: schemas, counts per robot, poses against
//! `timeseries.csv`, ellipsoids against `maps/robot<i>.troupe`). The Python half skips,
//! saying why, without the venv.

#![allow(clippy::unwrap_used)]

use troupe_testkit as common;

use std::path::Path;
use std::process::{Command, Output};

use common::root;

fn troupe(args: &[&str], dir: &Path) -> Output {
    troupe_testkit::run_quiet(env!("CARGO_BIN_EXE_troupe"), args, dir)
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
    assert_eq!(
        report["compression"],
        serde_json::json!(["zstd"]),
        "chunks are zstd by default"
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

/// Channels (and message counts) of a process or base recording, read and
/// checked by `check_run.py FILE.mcap` (schemas; `/world` and depth images where
/// present), and the compressions its chunks name; `None` without the venv.
fn checked_channels(
    file: &Path,
) -> Option<(
    serde_json::Map<String, serde_json::Value>,
    serde_json::Value,
)> {
    let python = root().join(".venv-mcap/bin/python");
    let out = Command::new(&python)
        .arg(root().join("scripts/mcap/check_run.py"))
        .arg(file)
        .output()
        .ok()?;
    if !out.status.success() && String::from_utf8_lossy(&out.stderr).contains("ModuleNotFoundError")
    {
        return None;
    }
    assert!(
        out.status.success(),
        "check_run.py {}: {}{}",
        file.display(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    Some((
        report["channels"].as_object().unwrap().clone(),
        report["compression"].clone(),
    ))
}

/// `troupe launch` (3 robots, 20 s) with a base station connected to them: each robot
/// process's `run.mcap` and the base's open with the independent reader, every message
/// valid under its channel's schema, with the channels a robot publishes (and, for
/// the base, what it receives). The robots record the world's surface once and, as
/// the scenario's `[metrics]` asks, depth frames at 1 Hz in lz4 chunks; the base
/// writes uncompressed chunks (`record_compression = "none"`).
#[test]
fn robot_processes_and_the_base_station_record_what_they_did() {
    let python = root().join(".venv-mcap/bin/python");
    if !Command::new(&python)
        .args(["-c", "import mcap, jsonschema"])
        .output()
        .is_ok_and(|o| o.status.success())
    {
        eprintln!(
            "skipping: {} cannot import mcap, jsonschema (run .ci/run)",
            python.display()
        );
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("team.toml"),
        "name = \"rec\"\nrobots = 3\n\n[metrics]\nrecord_depth_hz = 1.0\nrecord_compression = \"lz4\"\n",
    )
    .unwrap();
    // Four consecutive free ports below the kernel's ephemeral range: `troupe launch`
    // puts robot i on the first + i, the base listens on the last. (Ports the kernel
    // handed out for port 0 were not consecutive, and the ones after them could be
    // taken: once in a full test run, robot 1's was.)
    let ports = common::free_ports_from(5_000, 4);
    let robots: Vec<String> = (0..3)
        .map(|i| format!("\"tcp/127.0.0.1:{}\"", ports[0] + i))
        .collect();
    std::fs::write(
        dir.path().join("base.toml"),
        format!(
            "scenario = \"team.toml\"\nout = \"station\"\nrecord_compression = \"none\"\n\n[zenoh]\nlisten = [\"tcp/127.0.0.1:{}\"]\nconnect = [{}]\n",
            ports[3],
            robots.join(", ")
        ),
    )
    .unwrap();
    // The robots first, so that the base finds them listening when it connects.
    let launch = Command::new(env!("CARGO_BIN_EXE_troupe"))
        .args(["launch", "team.toml", "--duration-s", "20", "--base-port"])
        .arg(ports[0].to_string())
        .args(["--out", "out"])
        .current_dir(dir.path())
        .env("RUST_LOG", "off")
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("troupe launch");
    std::thread::sleep(std::time::Duration::from_secs(3));
    let mut base = Command::new(env!("CARGO_BIN_EXE_troupe"))
        .args(["base", "--config", "base.toml"])
        .current_dir(dir.path())
        .env("RUST_LOG", "off")
        .stdout(std::process::Stdio::null())
        .spawn()
        .expect("troupe base");
    let launched = launch.wait_with_output().unwrap();
    let _ = Command::new("kill")
        .args(["-TERM", &base.id().to_string()])
        .status();
    let base_status = base.wait().unwrap();
    assert!(
        launched.status.success(),
        "troupe launch: {}",
        String::from_utf8_lossy(&launched.stderr)
    );
    assert!(
        base_status.success(),
        "troupe base exited with {base_status}"
    );

    for i in 0..3 {
        let file = dir.path().join(format!("out/rec/robot{i}/run.mcap"));
        let (channels, compression) = checked_channels(&file).expect("the venv was checked above");
        assert_eq!(
            compression,
            serde_json::json!(["lz4"]),
            "{}",
            file.display()
        );
        assert_eq!(
            channels.get("/world"),
            Some(&serde_json::json!(1)),
            "{channels:?}"
        );
        for channel in [
            "pose",
            "plan",
            "candidates",
            "keyframes",
            "keyframe_points",
            "peer_keyframes",
            "peer_keyframe_points",
            "peer_plans",
            "grid",
            "frontiers",
            "remembered_frontiers",
            "route",
            "link",
        ] {
            let topic = format!("/robot{i}/{channel}");
            assert!(
                channels.get(&topic).and_then(serde_json::Value::as_u64) > Some(0),
                "{}: no {topic} in {channels:?}",
                file.display()
            );
        }
        assert!(channels["/tf"].as_u64() > channels[&format!("/robot{i}/pose")].as_u64());
        // 1 Hz over the 20 s run, the first frame when the camera starts.
        let depth = channels[&format!("/robot{i}/depth")].as_u64().unwrap();
        assert!((5..=21).contains(&depth), "robot{i}: {depth} depth frames");
    }
    let station = dir.path().join("station/run.mcap");
    let (channels, compression) = checked_channels(&station).expect("the venv was checked above");
    assert_eq!(compression, serde_json::json!([""]), "uncompressed chunks");
    assert!(!channels.contains_key("/world"), "the base knows no world");
    // The base (robot 3) connects to every robot and records each one it hears.
    let heard = (0..3)
        .filter(|j| {
            channels
                .get(&format!("/robot3/peers/robot{j}/pose"))
                .and_then(serde_json::Value::as_u64)
                > Some(10)
        })
        .count();
    assert_eq!(
        heard, 3,
        "the base recorded the poses of {heard} robots: {channels:?}"
    );
    for channel in ["peer_keyframes", "peer_keyframe_points", "link"] {
        let topic = format!("/robot3/{channel}");
        assert!(
            channels.get(&topic).and_then(serde_json::Value::as_u64) > Some(0),
            "{topic}: {channels:?}"
        );
    }
}
