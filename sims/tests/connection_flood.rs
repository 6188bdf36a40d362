//! Issue 45 item 3 against real `troupe robot` processes: a `troupe launch --tls`
//! team flooded with connections that never become sessions
//! (`sims/tests/connection_flood.py`, Python's `asyncio` and `ssl`) keeps its members
//! together. In a test binary of its own: its four robots and the flood would
//! otherwise share the machine with the other process tests.

use troupe_testkit as common;

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use common::{read_json, root, seconds_of_day, strip_ansi, wait_exit, wait_listening};
use serde_json::Value;

/// A `troupe launch --tls` team `name` of two robots in `dir`, each running
/// `duration_s`, its log (with the link's info lines) in `dir/launch.log`; the
/// ports are robot 0's and robot 1's.
fn launch_tls_team(dir: &Path, name: &str, ports: &[u16], duration_s: f64) -> Child {
    std::fs::write(
        dir.join("team.toml"),
        format!("name = \"{name}\"\nrobots = 2\n"),
    )
    .expect("scenario");
    let log = std::fs::File::create(dir.join("launch.log")).expect("log");
    Command::new(env!("CARGO_BIN_EXE_troupe"))
        .args(["launch", "team.toml", "--tls", "--duration-s"])
        .arg(duration_s.to_string())
        .args(["--base-port", &ports[0].to_string(), "--out", "out"])
        .env(
            "RUST_LOG",
            format!(
                "{},troupe_actors::link=info,zenoh::net::runtime::orchestrator=debug",
                troupe_robot::harness::DEFAULT_LOG_FILTER
            ),
        )
        .current_dir(dir)
        .stdout(Stdio::null())
        .stderr(log)
        .spawn()
        .expect("troupe launch")
}

/// The pid of the `troupe robot` process started by `parent` whose command line
/// names `needle`.
fn child_pid(parent: u32, needle: &str) -> u32 {
    for entry in std::fs::read_dir("/proc").expect("/proc").flatten() {
        let Ok(pid) = entry.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let cmdline = std::fs::read(entry.path().join("cmdline")).unwrap_or_default();
        let stat = std::fs::read_to_string(entry.path().join("stat")).unwrap_or_default();
        // `pid (comm) state ppid …`; the command name may hold spaces.
        let ppid = stat
            .rsplit_once(')')
            .and_then(|(_, rest)| rest.split_whitespace().nth(1)?.parse::<u32>().ok());
        if ppid == Some(parent) && String::from_utf8_lossy(&cmdline).contains(needle) {
            return pid;
        }
    }
    panic!("no child of {parent} runs {needle}");
}

fn signal(pid: u32, signal: &str) {
    let status = Command::new("kill")
        .args([signal, &pid.to_string()])
        .status()
        .expect("kill");
    assert!(status.success(), "kill {signal} {pid}");
}

/// Seconds of the day (UTC) now, as the log's timestamps count them.
fn now_seconds_of_day() -> f64 {
    troupe_robot::harness::unix_now_s().rem_euclid(86_400.0)
}

/// Issue 45 item 3: robot 1 of a `troupe launch --tls` team drops out for 12 s
/// (SIGSTOP) while a stranger floods both robots' ports with 30 connections a
/// second (`connection_flood.py`: junk bytes, TLS handshakes without a
/// certificate, idle sockets); an unattacked twin team beside it drops out the
/// same way. Both rejoin within 5 s of the robot's return (before troupe lowered
/// zenoh's 100 ms pause after a failed TLS handshake, the flooded team never did);
/// the attacked robots count every refused connection, log at most one line per
/// kind of refusal per 10 s, and stay within 1.5× the twin's peak memory.
///
/// The twin is the control: in one CI run (2026-11-29) its robots did not find
/// each other again within the 19 s left, with no flood at all (zenoh's connector
/// lines, at debug in the log, say why next time). A trial whose control does not
/// rejoin says nothing about the flood, so it is flown once more.
#[test]
fn a_tls_team_rejoins_after_a_dropout_under_a_connection_flood() {
    if let Err(control) = flood_trial() {
        eprintln!("the unflooded twin did not rejoin; flying the trial again:\n{control}");
        if let Err(control) = flood_trial() {
            panic!("the unflooded twin did not rejoin in two trials:\n{control}");
        }
    }
}

/// One trial of the test above; `Err` (with the twin's log) when the control team
/// did not rejoin, panics when anything else fails.
fn flood_trial() -> Result<(), String> {
    let duration_s = 40.0;
    let ports = common::free_ports_from(11_000, 4);
    let teams: Vec<(tempfile::TempDir, &str, Vec<u16>)> = ["flooded", "twin"]
        .into_iter()
        .zip(ports.chunks(2))
        .map(|(name, ports)| (tempfile::tempdir().expect("tempdir"), name, ports.to_vec()))
        .collect();
    let mut launches: Vec<Child> = teams
        .iter()
        .map(|(dir, name, ports)| launch_tls_team(dir.path(), name, ports, duration_s))
        .collect();
    let all_ports: Vec<u16> = teams.iter().flat_map(|t| t.2.clone()).collect();
    wait_listening(&all_ports, Duration::from_secs(30));
    std::thread::sleep(Duration::from_secs(4));
    let (flooded_dir, _, flooded_ports) = &teams[0];
    let flood = Command::new("python3")
        .arg(root().join("sims/tests/connection_flood.py"))
        .args(flooded_ports.iter().map(u16::to_string))
        .args(["--rate", "30", "--seconds", "26", "--idle-s", "12", "--ca"])
        .arg(flooded_dir.path().join("out/flooded/keys/ca.pem"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("python3 connection_flood.py");
    std::thread::sleep(Duration::from_secs(3));
    let dropped: Vec<u32> = teams
        .iter()
        .zip(&launches)
        .map(|((_, name, _), launch)| child_pid(launch.id(), &format!("{name}/robot1.toml")))
        .collect();
    for pid in &dropped {
        signal(*pid, "-STOP");
    }
    std::thread::sleep(Duration::from_secs(12));
    for pid in &dropped {
        signal(*pid, "-CONT");
    }
    let back_at = now_seconds_of_day();
    let flood = flood.wait_with_output().expect("flood");
    let flood_report = String::from_utf8_lossy(&flood.stdout).into_owned()
        + &String::from_utf8_lossy(&flood.stderr);
    assert!(flood.status.success(), "{flood_report}");
    let mut logs = Vec::new();
    for ((dir, name, _), launch) in teams.iter().zip(&mut launches) {
        let status = wait_exit(launch, "troupe launch", Duration::from_secs(120));
        let log = strip_ansi(&std::fs::read_to_string(dir.path().join("launch.log")).expect("log"));
        assert!(status.success(), "{name}: {log}");
        logs.push(log);
    }
    // Robot 0 hears robot 1 again once a new session carries its messages.
    let rejoined_at = |log: &str| {
        log.lines()
            .filter(|l| l.contains("peer heard again") && l.contains("robot=\"robot0\""))
            .filter_map(|l| seconds_of_day(l.split_whitespace().next()?))
            .find(|t| *t > back_at - 0.5)
    };
    let rejoined: Vec<Option<f64>> = logs.iter().map(|log| rejoined_at(log)).collect();
    if rejoined[1].is_none() {
        return Err(logs[1].clone());
    }
    let mut peak_rss_mib = Vec::new();
    for (((dir, name, _), log), rejoined) in teams.iter().zip(&logs).zip(rejoined) {
        let Some(rejoined) = rejoined else {
            panic!("{name}: robot 0 never heard robot 1 again ({flood_report}):\n{log}");
        };
        let rejoin_s = rejoined - back_at;
        eprintln!("{name}: rejoined {rejoin_s:.2} s after the dropout");
        assert!(
            rejoin_s <= 5.0,
            "{name}: rejoined after {rejoin_s:.1} s:\n{log}"
        );
        let launched = dir.path().join("out").join(name);
        let report = read_json(&launched.join("launch.json"));
        peak_rss_mib.push(
            report["robot_usage"]
                .as_array()
                .expect("robot_usage")
                .iter()
                .filter_map(|u| u["peak_rss_mib"].as_f64())
                .fold(0.0, f64::max),
        );
        let refused: Vec<u64> = (0..2)
            .map(|i| {
                let s = read_json(&launched.join(format!("robot{i}/summary.json")));
                s["zenoh"]["refused_connections"]
                    .as_object()
                    .expect("refused_connections")
                    .values()
                    .filter_map(Value::as_u64)
                    .sum()
            })
            .collect();
        let summary_lines: Vec<&str> = log
            .lines()
            .filter(|l| l.contains("zenoh refused"))
            .collect();
        if *name == "twin" {
            // Peers that connect to each other at once close the spare connection
            // mid-handshake; a robot back from a dropout finds stale ones.
            assert!(refused.iter().all(|n| *n <= 4), "{refused:?}\n{log}");
            assert!(summary_lines.is_empty(), "{log}");
            continue;
        }
        // About 260 connections per port; a robot refuses those it saw (some the
        // stopped robot's kernel turned away).
        assert!(
            refused.iter().all(|n| *n > 100),
            "{refused:?} {flood_report}"
        );
        assert!(
            !log.contains("zenoh_link_tls::unicast"),
            "zenoh's own line per refused connection:\n{log}"
        );
        // Per kind, from two robots: at most one line per robot per 10 s.
        let mut times: std::collections::BTreeMap<&str, Vec<f64>> = Default::default();
        for line in &summary_lines {
            let kind = line
                .split_whitespace()
                .find(|w| w.starts_with("kind="))
                .unwrap_or_default();
            let at = seconds_of_day(line.split_whitespace().next().expect("time")).expect("time");
            times.entry(kind).or_default().push(at);
        }
        assert!(!times.is_empty(), "{log}");
        for (kind, at) in &times {
            for three in at.windows(3) {
                assert!(
                    three[2] - three[0] > 9.5,
                    "`{kind}` lines {three:?}:\n{log}"
                );
            }
        }
    }
    eprintln!(
        "peak RSS MiB: flooded {:.0}, twin {:.0}",
        peak_rss_mib[0], peak_rss_mib[1]
    );
    assert!(
        peak_rss_mib[0] <= 1.5 * peak_rss_mib[1],
        "peak RSS {peak_rss_mib:?} MiB"
    );
    Ok(())
}
