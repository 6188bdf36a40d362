//! Issue 24 between processes: two `troupe robot` processes running the artifact
//! reporter and a `troupe base` on loopback over zenoh. The robot that reports first
//! is killed with SIGKILL right after its first reports and started again on its
//! journal; the base starts late, after that crash. No report is lost: the reports
//! the crashed robot made before the crash reach the base, which was not running then
//! (they wait in its journal, `<out>/state/link.journal` and `link.lanes`), and the
//! base's list and the peer's equal the union of the robots' lists.

use crate::common;

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use troupe_robot::launch::{loopback_endpoints, peer_sessions};
use troupe_sims::process::ProcessConfig;

/// Reports within this distance are one artifact (the artifact actor's default
/// merge radius).
const SAME_ARTIFACT_M: f64 = 1.0;

fn troupe() -> Command {
    Command::new(env!("CARGO_BIN_EXE_troupe"))
}

/// Writes `robot<i>.toml` for robot `i` of the scenario `team.toml`, listening on
/// `endpoints[i]` and connecting to the other endpoints.
fn robot_file(dir: &Path, i: usize, endpoints: &[String], duration_s: Option<f64>) -> PathBuf {
    let config = ProcessConfig {
        robot: i as u32,
        scenario: PathBuf::from("team.toml"),
        duration_s,
        out: Some(PathBuf::from(format!("robot{i}"))),
        sequence: None,
        zenoh: peer_sessions(endpoints).swap_remove(i),
        record: false,
        record_depth_hz: None,
        record_compression: None,
    };
    let file = dir.join(format!("robot{i}.toml"));
    std::fs::write(&file, toml::to_string(&config).expect("toml")).expect("robot file");
    file
}

/// Starts `troupe robot`; its "artifact found" log lines are counted in `found`.
fn spawn_robot(file: &Path, found: &Arc<AtomicUsize>) -> Child {
    let mut child = troupe()
        .args(["robot", "--config"])
        .arg(file)
        .env("RUST_LOG", "warn,troupe_actors::artifacts=info")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn troupe robot");
    let stderr = child.stderr.take().expect("stderr");
    let found = found.clone();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            if line.contains("artifact found") {
                found.fetch_add(1, Ordering::SeqCst);
            }
        }
    });
    child
}

fn wait(child: &mut Child, within: Duration, what: &str) {
    let started = Instant::now();
    loop {
        if let Some(status) = child.try_wait().expect("wait") {
            assert!(status.success(), "{what} exited with {status}");
            return;
        }
        if started.elapsed() > within {
            let _ = child.kill();
            panic!("{what} did not stop");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

fn terminate(child: &mut Child, what: &str) {
    let pid = child.id().to_string();
    let sent = Command::new("kill")
        .args(["-TERM", &pid])
        .status()
        .expect("kill");
    assert!(sent.success());
    wait(child, Duration::from_secs(60), what);
}

fn summary(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("summary.json")).expect("json")
}

/// The artifacts of a summary: (position, first reporter).
fn artifacts(summary: &serde_json::Value) -> Vec<([f64; 3], u64)> {
    summary["artifacts"]
        .as_array()
        .map(|list| {
            list.iter()
                .map(|a| {
                    let p = &a["position_m"];
                    let c = |k: usize| p[k].as_f64().expect("coordinate");
                    (
                        [c(0), c(1), c(2)],
                        a["first_reporter"].as_u64().expect("reporter"),
                    )
                })
                .collect()
        })
        .unwrap_or_default()
}

fn near(a: &[f64; 3], b: &[f64; 3]) -> bool {
    let d2: f64 = a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum();
    d2.sqrt() <= SAME_ARTIFACT_M
}

/// Whether two lists name the same artifacts (one to one, within the merge radius).
fn same_artifacts(a: &[([f64; 3], u64)], b: &[([f64; 3], u64)]) -> bool {
    a.len() == b.len()
        && a.iter().all(|(p, _)| b.iter().any(|(q, _)| near(p, q)))
        && b.iter().all(|(q, _)| a.iter().any(|(p, _)| near(p, q)))
}

#[test]
fn reports_reach_the_peer_and_a_late_base_through_a_robot_crash() {
    let dir = tempfile::tempdir().expect("tempdir");
    // Many artifacts, so that a robot finds one soon after it leaves the start.
    std::fs::write(
        dir.path().join("team.toml"),
        "name = \"artifacts\"\nrobots = 2\n\n[camera]\nrender_stride = 1\n\n[world.artifacts]\ncount = 40\nmin_spacing_m = 2.0\n\n\
         [robot.artifacts]\nenabled = true\n\n[robot.link.shared.\"artifacts/report\"]\n\
         class = \"plan\"\npolicy = \"store_and_forward\"\n",
    )
    .expect("scenario");
    let endpoints = loopback_endpoints(&common::free_ports_from(23_000, 3));
    // The robots dial each other; the base, when it comes, dials them.
    let robots = &endpoints[..2];
    let found = [0, 1].map(|_| Arc::new(AtomicUsize::new(0)));
    let mut children =
        [0, 1].map(|i| spawn_robot(&robot_file(dir.path(), i, robots, None), &found[i]));

    // The robot that reports first (the one that left the start first; which one
    // that is depends on timing) is the one that crashes; its peer acknowledges
    // within a second or so.
    let started = Instant::now();
    let crashed = loop {
        if let Some(i) = (0..2).find(|&i| found[i].load(Ordering::SeqCst) > 0) {
            break i;
        }
        assert!(
            started.elapsed() < Duration::from_secs(90),
            "neither robot found an artifact in 90 s"
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    let peer = 1 - crashed;
    eprintln!(
        "robot {crashed} found an artifact first, after {:.1?}",
        started.elapsed()
    );
    std::thread::sleep(Duration::from_secs(3));
    children[crashed].kill().expect("SIGKILL");
    let _ = children[crashed].wait();
    let before_crash = found[crashed].load(Ordering::SeqCst);

    // The crashed robot again on its journal (20 s), and the base, which missed
    // everything so far.
    let restarted = Arc::new(AtomicUsize::new(0));
    children[crashed] = spawn_robot(
        &robot_file(dir.path(), crashed, robots, Some(20.0)),
        &restarted,
    );
    std::fs::write(
        dir.path().join("base.toml"),
        format!(
            "scenario = \"team.toml\"\nout = \"station\"\nply_points = 1000\n\n[zenoh]\n\
             listen = [\"{}\"]\nconnect = [\"{}\", \"{}\"]\n",
            endpoints[2], endpoints[0], endpoints[1]
        ),
    )
    .expect("base file");
    let mut base = troupe()
        .args(["base", "--config"])
        .arg(dir.path().join("base.toml"))
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .spawn()
        .expect("spawn troupe base");
    wait(
        &mut children[crashed],
        Duration::from_secs(80),
        "restarted robot",
    );
    // The peer and the base get the restarted robot's last reports, then stop.
    std::thread::sleep(Duration::from_secs(2));
    terminate(&mut children[peer], "peer robot");
    terminate(&mut base, "base");

    let summaries = [0, 1].map(|i| summary(&dir.path().join(format!("robot{i}/summary.json"))));
    let station = summary(&dir.path().join("station/summary.json"));
    let lists = [0, 1].map(|i| artifacts(&summaries[i]));
    let at_base = artifacts(&station);
    let mut union: Vec<([f64; 3], u64)> = Vec::new();
    for a in lists.iter().flatten() {
        if !union.iter().any(|(p, _)| near(p, &a.0)) {
            union.push(*a);
        }
    }
    let context = format!(
        "robot {crashed} found {before_crash} before the crash, {} after; robot {peer} found {}\n\
         robot0 {:?}\nrobot1 {:?}\nbase {at_base:?}",
        restarted.load(Ordering::SeqCst),
        found[peer].load(Ordering::SeqCst),
        lists[0],
        lists[1],
    );
    // What the crashed robot reported before the crash reached its peer ...
    let early: Vec<_> = lists[peer]
        .iter()
        .filter(|(_, by)| *by == crashed as u64)
        .collect();
    assert!(!early.is_empty(), "{context}");
    // ... and the base, which started after the crash: from the crashed robot's journal.
    for (p, _) in &early {
        assert!(at_base.iter().any(|(q, _)| near(p, q)), "{context}");
    }
    assert!(same_artifacts(&at_base, &union), "base: {context}");
    assert!(same_artifacts(&lists[peer], &union), "peer: {context}");
    // The restarted robot knows what its peer reported (its journal replays what it
    // had received) and what it finds again; its own reports from before the crash it
    // knows only if it sees them again, so its list is a part of the union.
    assert!(
        lists[crashed]
            .iter()
            .all(|(p, _)| union.iter().any(|(q, _)| near(p, q))),
        "restarted robot: {context}"
    );
    for s in &summaries {
        for actor in s["actors"].as_array().expect("actors") {
            assert_eq!(actor["panics"].as_u64(), Some(0), "{actor}");
        }
        let shared = &s["link"]["shared"]["artifacts/report"];
        assert_eq!(shared["undecodable"].as_u64(), Some(0), "{shared}");
        assert_eq!(shared["unknown_name"].as_u64(), Some(0), "{shared}");
    }
}
