//! Teleop from the base station (issue 17): a `troupe robot` process and a `troupe base`
//! process on loopback over zenoh. The operator types `robot0 hold` on the base's
//! standard input: the command crosses the link (shared topic `base/command`), the
//! robot's collision actor commits only stopping trajectories and the robot comes to
//! rest (the base's status lines show its odometry speed); `robot0 resume` and it
//! plans and moves again; `robot0 return` and it ends its exploring and flies home (the
//! status lines show the phase the robot reports over the link).

use crate::common;

use std::io::{BufRead, BufReader, Write};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use troupe_robot::launch::loopback_endpoints;
use troupe_sims::process::write_team;

fn troupe() -> Command {
    Command::new(env!("CARGO_BIN_EXE_troupe"))
}

fn terminate(child: &mut Child, what: &str) {
    let _ = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status();
    let started = Instant::now();
    while child.try_wait().expect("wait").is_none() {
        if started.elapsed() > Duration::from_secs(60) {
            let _ = child.kill();
            panic!("{what} did not stop");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// The speed in a base status line of robot 0, if it is one.
fn speed(line: &str) -> Option<f64> {
    line.strip_prefix("robot0 keyframes=")?
        .split_whitespace()
        .find_map(|w| w.strip_prefix("speed_mps="))?
        .parse()
        .ok()
}

/// The mission phase in a base status line of robot 0, if it is one.
fn phase(line: &str) -> Option<&str> {
    line.strip_prefix("robot0 keyframes=")?
        .split_whitespace()
        .find_map(|w| w.strip_prefix("phase="))
}

#[test]
fn the_base_holds_resumes_and_calls_home_a_robot_over_the_link() {
    let dir = tempfile::tempdir().expect("tempdir");
    std::fs::write(
        dir.path().join("team.toml"),
        "name = \"teleop\"\nrobots = 1\n\n[robot.collision]\noperator_commands = true\n",
    )
    .expect("scenario");
    let endpoints = loopback_endpoints(&common::free_ports_from(1_030, 2));
    let files = write_team(
        dir.path(),
        Path::new("team.toml"),
        &endpoints[..1],
        Some(90.0),
    )
    .expect("robot file");
    std::fs::write(
        dir.path().join("base.toml"),
        format!(
            "scenario = \"team.toml\"\nout = \"station\"\nply_points = 1000\nrecord = false\n\n\
             [zenoh]\nlisten = [\"{}\"]\nconnect = [\"{}\"]\n",
            endpoints[1], endpoints[0]
        ),
    )
    .expect("base file");
    let mut base = troupe()
        .args(["base", "--config"])
        .arg(dir.path().join("base.toml"))
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("spawn troupe base");
    let mut robot = troupe()
        .args(["robot", "--config"])
        .arg(&files[0])
        .stdout(Stdio::null())
        .spawn()
        .expect("spawn troupe robot");
    let (tx, lines) = mpsc::channel::<(Instant, String)>();
    let stdout = base.stdout.take().expect("stdout");
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if tx.send((Instant::now(), line)).is_err() {
                return;
            }
        }
    });
    let mut seen = Vec::new();
    // Reads the base's lines until `until` or a robot-0 speed passes `done`.
    let mut read = |until: Instant, done: &dyn Fn(f64) -> bool| -> bool {
        while let Some(left) = until.checked_duration_since(Instant::now()) {
            match lines.recv_timeout(left) {
                Ok((at, line)) => {
                    let hit = speed(&line).is_some_and(done);
                    seen.push((at, line));
                    if hit {
                        return true;
                    }
                }
                Err(_) => return false,
            }
        }
        false
    };
    let mut stdin = base.stdin.take().expect("stdin");
    let moving = |v: f64| v > 0.05;

    let started = Instant::now();
    let moved = read(started + Duration::from_secs(40), &moving);
    assert!(moved, "robot 0 never moved: {seen:?}");
    writeln!(stdin, "robot0 hold").expect("send hold");
    let held_at = Instant::now();
    read(held_at + Duration::from_secs(8), &|_| false);
    writeln!(stdin, "robot0 resume").expect("send resume");
    let resumed_at = Instant::now();
    let moved_again = read(resumed_at + Duration::from_secs(20), &moving);
    writeln!(stdin, "robot0 return").expect("send return");
    let returned_at = Instant::now();
    read(returned_at + Duration::from_secs(5), &|_| false);
    drop(stdin);
    terminate(&mut robot, "troupe robot");
    terminate(&mut base, "troupe base");

    let text: Vec<&str> = seen.iter().map(|(_, l)| l.as_str()).collect();
    assert!(
        text.iter()
            .any(|l| l.starts_with("command robot0 hold: sent (id ")),
        "{text:?}"
    );
    // From 3 s after the hold (the stop trajectory brakes, then holds) until the
    // resume, every status line shows the robot at rest.
    let held: Vec<f64> = seen
        .iter()
        .filter(|(at, _)| *at > held_at + Duration::from_secs(3) && *at < resumed_at)
        .filter_map(|(_, l)| speed(l))
        .collect();
    assert!(held.len() >= 3, "{text:?}");
    assert!(
        held.iter().all(|&v| v < 0.01),
        "moving while held: {text:?}"
    );
    assert!(moved_again, "robot 0 did not move after resume: {text:?}");
    // Exploring until the command home; then returning (or home already).
    let phases = |from: Instant, to: Instant| -> Vec<&str> {
        seen.iter()
            .filter(|(at, _)| (from..to).contains(at))
            .filter_map(|(_, l)| phase(l))
            .collect()
    };
    let before = phases(held_at, returned_at);
    assert!(
        !before.is_empty() && before.iter().all(|p| *p == "exploring"),
        "{text:?}"
    );
    let after = phases(returned_at + Duration::from_secs(3), Instant::now());
    assert!(
        !after.is_empty() && after.iter().all(|p| ["returning", "home"].contains(p)),
        "{text:?}"
    );
    // The three commands crossed the link and robot 0 acknowledged them.
    let summary: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("station/summary.json")).expect("summary"),
    )
    .expect("json");
    let lane = &summary["link"]["shared"]["base/command"]["sent"];
    assert_eq!(lane["offered_messages"].as_u64(), Some(3), "{summary}");
    assert_eq!(lane["acknowledged_messages"].as_u64(), Some(3), "{summary}");
    let mission = &summary["robots"]["0"]["mission"];
    assert_eq!(mission["end"], "commanded", "{summary}");
}
