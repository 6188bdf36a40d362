//! Three `troupe-robot` processes, one robot each, talking over zenoh on loopback
//! (issue 3 item 4, issue 8 item 7): every robot hears the others' odometry and
//! keyframes, and the robots keep apart.

use std::net::TcpListener;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use troupe_sims::process::{min_distance_between, read_trajectory, write_loopback_team};

/// Free TCP ports on loopback (bound and released; a tiny race is acceptable).
fn free_ports(n: usize) -> Vec<u16> {
    let listeners: Vec<TcpListener> = (0..n)
        .map(|_| TcpListener::bind("127.0.0.1:0").expect("bind"))
        .collect();
    listeners
        .iter()
        .map(|l| l.local_addr().expect("addr").port())
        .collect()
}

#[test]
fn three_robot_processes_share_odometry_and_maps_and_keep_apart() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ports = free_ports(3);
    let duration_s = 20.0;
    std::fs::write(
        dir.path().join("team.toml"),
        "name = \"processes\"\nrobots = 3\n",
    )
    .expect("scenario");
    let files = write_loopback_team(dir.path(), Path::new("team.toml"), &ports, Some(duration_s))
        .expect("robot files");
    let mut children: Vec<_> = files
        .iter()
        .map(|f| {
            Command::new(env!("CARGO_BIN_EXE_troupe-robot"))
                .arg("--config")
                .arg(f)
                .stdout(Stdio::null())
                .spawn()
                .expect("spawn troupe-robot")
        })
        .collect();
    let started = Instant::now();
    for child in &mut children {
        loop {
            if let Some(status) = child.try_wait().expect("wait") {
                assert!(status.success(), "troupe-robot exited with {status}");
                break;
            }
            if started.elapsed() > Duration::from_secs_f64(duration_s + 60.0) {
                let _ = child.kill();
                panic!("troupe-robot did not stop after its duration");
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }
    let mut trajectories = Vec::new();
    for i in 0..3 {
        let out = dir.path().join(format!("robot{i}"));
        let summary: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(out.join("summary.json")).expect("summary.json"),
        )
        .expect("json");
        let messages = |topic: &str| summary["topics"][topic]["messages"].as_u64().unwrap_or(0);
        // Two peers at 10 Hz; allow for start-up and a busy machine.
        assert!(messages("peer/odometry") > 100, "robot{i}: {summary}");
        assert!(messages("peer/keyframe") >= 2, "robot{i}: {summary}");
        assert!(messages("peer/plan") >= 4, "robot{i}: {summary}");
        assert_eq!(summary["link"]["rejected_messages"].as_u64(), Some(0));
        assert_eq!(summary["zenoh"]["rejected_frame"].as_u64(), Some(0));
        for actor in summary["actors"].as_array().expect("actors") {
            assert_eq!(actor["panics"].as_u64(), Some(0), "robot{i}: {actor}");
        }
        trajectories.push(read_trajectory(&out.join("trajectory.csv")).expect("trajectory"));
    }
    let closest = min_distance_between(&trajectories).expect("overlapping trajectories");
    assert!(closest > 0.6, "robots came within {closest} m");
}
