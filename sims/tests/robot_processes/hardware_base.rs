//! Issue 40, item 4: a hardware robot and a base station that joins late, both as
//! the processes a team runs — `troupe-robot` (ROS 2 depth and odometry in over
//! zenoh from `scripts/ros2/box_room_camera.py`, MAVLink setpoints out to
//! `scripts/mavlink/px4_like_autopilot.py`) and `troupe base`, started once the robot
//! has said that its base is absent.
//!
//! Checks: the robot keeps its keyframes for the absent base (store-and-forward,
//! the robot-process default) and says once that the base is not heard; the base,
//! once it connects, gets every keyframe the robot made, those made before it
//! started included, and acknowledges them; its heartbeats keep it a recipient (no
//! "peer silent" line, nothing pending for it at the end). Skips, saying why,
//! without the Python venvs (`.ci/run` installs them) or the `troupe-robot` binary
//! (`cargo test --workspace` builds it).

#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::common;

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The robot's flight (after its topics appeared), wall seconds.
const FLY_S: f64 = 20.0;
/// How long the test waits for the robot to say that its base is absent (its ROS 2
/// topics appear, then its link runs `peer_timeout_s` without the base) before it
/// starts the base anyway, seconds.
const ABSENT_WITHIN_S: f64 = 60.0;

#[test]
fn a_base_that_joins_late_gets_every_keyframe_of_a_hardware_robot() {
    let troupe_robot = Path::new(env!("CARGO_BIN_EXE_troupe")).with_file_name("troupe-robot");
    let (ros_python, mav_python) = match common::hardware_pythons() {
        Ok(pythons) if troupe_robot.exists() => pythons,
        pythons => {
            let built = (!troupe_robot.exists())
                .then(|| format!("{} is not built", troupe_robot.display()));
            let why: Vec<String> = [pythons.err(), built].into_iter().flatten().collect();
            eprintln!("SKIPPED hardware robot + base test: {}", why.join("; "));
            return;
        }
    };
    let dir = tempfile::tempdir().expect("tempdir");
    let dir = dir.path();
    let [ros_port, robot_port, base_port] = common::free_ports_from(26_000, 3)[..] else {
        unreachable!()
    };
    let (mavlink_port, state_port) = (common::free_udp_port(), common::free_udp_port());

    // The team as the base reads it: one robot, the base as id 1.
    std::fs::write(
        dir.join("team.toml"),
        "name = \"hwbase\"\nrobots = 1\n\n[robot.link]\nteam = 5\n",
    )
    .unwrap();
    // A robot file as docs/hardware.md writes it; no keyframe policy named.
    let ros2 = common::box_room_camera_ros2_table(ros_port, 20.0);
    let mavlink =
        common::autopilot_mavlink_tables(mavlink_port, [-2.5, -2.5, 0.5], [4.5, 2.5, 2.5]);
    std::fs::write(
        dir.join("robot0.toml"),
        format!(
            r#"id = 0
team_size = 1
out = "hw0"
record = false
[robot]
sensor_rate_hz = 15.0
[robot.link]
team = 5
{ros2}{mavlink}[zenoh]
listen = ["tcp/127.0.0.1:{robot_port}"]
"#
        ),
    )
    .unwrap();
    std::fs::write(
        dir.join("base.toml"),
        format!(
            "scenario = \"team.toml\"\nout = \"station\"\nply_points = 500\nrecord = false\n\n\
             [zenoh]\nlisten = [\"tcp/127.0.0.1:{base_port}\"]\n\
             connect = [\"tcp/127.0.0.1:{robot_port}\"]\n"
        ),
    )
    .unwrap();

    let peers_s = FLY_S + 30.0;
    let report = dir.join("autopilot.json");
    let autopilot =
        common::spawn_autopilot(&mav_python, mavlink_port, state_port, &report, peers_s);
    let camera = common::spawn_box_room_camera(&ros_python, ros_port, state_port, None, peers_s);
    let started = Instant::now();
    let mut robot = Command::new(&troupe_robot)
        .args(["--config", dir.join("robot0.toml").to_str().unwrap()])
        .args(["--duration-s", &FLY_S.to_string()])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start troupe-robot");
    // The robot's log, line by line as it comes.
    let (lines_tx, lines_rx) = std::sync::mpsc::channel::<String>();
    let stderr = robot.stderr.take().expect("stderr");
    let reader = std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            let _ = lines_tx.send(common::strip_ansi(&line));
        }
    });
    // The base starts once the robot has said that it is absent.
    let mut log = Vec::new();
    while started.elapsed().as_secs_f64() < ABSENT_WITHIN_S {
        if let Ok(line) = lines_rx.recv_timeout(Duration::from_millis(200)) {
            let absent = line.contains("base station not heard");
            log.push(line);
            if absent {
                break;
            }
        }
    }
    let base = Command::new(env!("CARGO_BIN_EXE_troupe"))
        .args(["base", "--config", dir.join("base.toml").to_str().unwrap()])
        .args(["--duration-s", &(FLY_S + 30.0).to_string()])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start troupe base");
    let base_started_s = started.elapsed().as_secs_f64();

    let status = robot.wait().expect("wait");
    reader.join().expect("the log reader");
    log.extend(lines_rx.try_iter());
    let log = log.join("\n");
    assert!(status.success(), "troupe-robot failed: {status}\n{log}");
    // The base hears the last keyframes, then stops as an operator stops it.
    std::thread::sleep(Duration::from_secs(3));
    let stopped = Command::new("kill")
        .args(["-TERM", &base.id().to_string()])
        .status()
        .expect("kill");
    assert!(stopped.success());
    let base_out = common::finish(base, "troupe base");
    let _ = (camera.wait_with_output(), autopilot.wait_with_output());

    let summary = common::read_json(&dir.join("hw0/summary.json"));
    let keyframes = summary["keyframes"].as_u64().unwrap();
    let link = &summary["link"];
    println!(
        "robot: {keyframes} keyframes; base started {base_started_s:.1} s after it; link {}",
        serde_json::json!({
            "silent_peers": link["silent_peers"],
            "peer_timeouts": link["peer_timeouts"],
        })
    );
    let lines = |needle: &str| log.lines().filter(|l| l.contains(needle)).count();
    // The absent base was reported once (it stayed silent past peer_timeout_s
    // before it started), never as a silent peer, and heard from then on.
    assert_eq!(lines("base station not heard"), 1, "{log}");
    let pending = log
        .lines()
        .find(|l| l.contains("base station not heard"))
        .and_then(|l| l.split("pending=").nth(1))
        .and_then(|rest| rest.split_whitespace().next())
        .and_then(|n| n.parse::<u64>().ok());
    assert!(
        pending.is_some_and(|n| n > 0),
        "no keyframe kept for the absent base: {pending:?}"
    );
    assert_eq!(lines("peer silent"), 0, "{log}");
    assert_eq!(link["peer_timeouts"], 1, "{link}");
    assert_eq!(link["silent_peers"], serde_json::json!([]), "{link}");

    // Keyframes made before the base started: the robot's journal kept them for it.
    let base_log = common::strip_ansi(&String::from_utf8_lossy(&base_out.stderr));
    let station = common::read_json(&dir.join("station/summary.json"));
    let got = station["robots"]["0"]["keyframes"].as_u64().unwrap_or(0);
    println!("base: {got} of the robot's {keyframes} keyframes");
    assert!(keyframes >= 4, "the robot made only {keyframes} keyframes");
    assert_eq!(got, keyframes, "the base missed keyframes\n{base_log}");
}
