//! `troupe launch SCENARIO.toml`: the scenario's team as separate `troupe robot`
//! processes on this machine, talking over zenoh on loopback, peer to peer or (with
//! `--router`) through one zenoh router ([`crate::router`]) that this process runs;
//! the same robot files work across hosts with other addresses ([`crate::process`]).
//!
//! While the robots run, the launcher samples each process's CPU time and peak
//! resident memory from `/proc` (Linux; elsewhere the usage is absent), and its own,
//! which with `--router` is the router's (the launcher itself only waits).
//!
//! With `--tls` the team is the secure one of `docs/security.md` in one command: the
//! launcher writes a CA and a certificate per member with `troupe keys`
//! ([`crate::keys`], into `keys/` of the launch directory) and robot files whose
//! `tls/` endpoints use them under mutual TLS, with zenoh's access control
//! (`[zenoh.access]`: robot `i` may publish only as `i`); the router, if any, runs on
//! the router's certificate.

use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::time::{Duration, Instant};

use serde::Serialize;

use troupe_comms::zenoh::security::identity_name;
use troupe_comms::zenoh::{ZenohAccess, ZenohConfig, ZenohTls};

use crate::keys::{ROUTER_NAME, write_team_keys};
use crate::process::{
    ProcessConfig, loopback_endpoints, min_distance_between, read_trajectory, write_client_team,
    write_team,
};
use crate::router::{Router, RouterError, settings};
use crate::scenario::Scenario;

/// How to launch a team.
#[derive(Clone, Debug, PartialEq)]
pub struct LaunchOptions {
    /// Peer to peer: robot `i` listens on `base_port + i`. Through a router: the
    /// router listens on `base_port`.
    pub base_port: u16,
    /// Wall seconds each robot runs; `None`: until interrupted.
    pub duration_s: Option<f64>,
    /// Start one zenoh router and make the robots its clients.
    pub router: bool,
    /// Mutual TLS and access control with credentials written by `troupe keys`
    /// into `dir/keys` (see the module docs).
    pub tls: bool,
}

/// What a launch did (`launch.json`).
#[derive(Clone, Debug, Serialize)]
pub struct LaunchReport {
    /// Robot files, one per process.
    pub robot_files: Vec<PathBuf>,
    /// The router's endpoint, when the robots went through one.
    pub router: Option<String>,
    /// Exit code of each process (`None`: killed by a signal).
    pub exit_codes: Vec<Option<i32>>,
    /// Smallest distance between two robots, from their trajectories aligned in
    /// wall time, metres.
    pub min_inter_robot_distance_m: Option<f64>,
    /// Wall seconds from the first robot's start to the last one's exit.
    pub wall_s: f64,
    /// CPU and memory of each robot process (index = robot), sampled every half
    /// second until it exits; `None` where `/proc` could not tell.
    pub robot_usage: Vec<Option<ProcessUsage>>,
    /// The same for the launching process: the router, with `--router`.
    pub launcher_usage: Option<ProcessUsage>,
}

/// What one process used, from `/proc/<pid>/stat` and `/proc/<pid>/status`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ProcessUsage {
    /// User plus system CPU time, seconds (at the last sample before exit).
    pub cpu_s: f64,
    /// `cpu_s` over the wall seconds it ran, percent of one core.
    pub cpu_percent: f64,
    /// Peak resident memory (`VmHWM`), MiB.
    pub peak_rss_mib: f64,
}

/// Reads the CPU seconds and peak resident MiB of process `pid` (`self` for
/// this one) from `/proc`; `None` where it is not there.
fn read_usage(pid: &str) -> Option<(f64, f64)> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // Fields after the command name (which may hold spaces): state is field 3,
    // utime and stime fields 14 and 15, in clock ticks (USER_HZ, 100 on Linux).
    let after = stat.rsplit_once(')')?.1;
    let fields: Vec<&str> = after.split_whitespace().collect();
    let ticks = fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let kib: f64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))?
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    Some((ticks / 100.0, kib / 1024.0))
}

fn usage(sample: Option<(f64, f64)>, wall_s: f64) -> Option<ProcessUsage> {
    sample.map(|(cpu_s, peak_rss_mib)| ProcessUsage {
        cpu_s,
        cpu_percent: if wall_s > 0.0 {
            100.0 * cpu_s / wall_s
        } else {
            0.0
        },
        peak_rss_mib,
    })
}

/// Why a launch failed.
#[derive(Debug, thiserror::Error)]
pub enum LaunchError {
    /// The scenario could not be read.
    #[error(transparent)]
    Scenario(#[from] crate::scenario::ScenarioError),
    /// Files could not be written or read, or a process not started.
    #[error("{0}")]
    Io(String),
    /// The router did not start.
    #[error("starting the router")]
    Router(#[source] RouterError),
    /// The team's credentials could not be written.
    #[error("writing the team's keys")]
    Keys(#[source] crate::keys::KeysError),
}

/// The directory, in the launch directory, that `--tls` writes the keys into.
pub const KEYS_DIR: &str = "keys";

/// The secure form of `zenoh` for the member `name` (`robot<i>`, `router`) of a
/// team of `robots` whose keys `troupe keys` wrote into `keys` (relative to the
/// file the table is written in): `tls/` endpoints, mutual TLS with the member's
/// certificate, and access control naming every id (the robots' and the base's)
/// and the router.
fn with_team_keys(mut zenoh: ZenohConfig, keys: &Path, name: &str, robots: u32) -> ZenohConfig {
    let tls = |endpoints: &mut Vec<String>| {
        for e in endpoints {
            if let Some(rest) = e.strip_prefix("tcp/") {
                *e = format!("tls/{rest}");
            }
        }
    };
    tls(&mut zenoh.listen);
    tls(&mut zenoh.connect);
    zenoh.tls = Some(ZenohTls {
        root_ca_path: keys.join("ca.pem"),
        cert_path: keys.join(format!("{name}.pem")),
        key_path: keys.join(format!("{name}.key")),
        mutual: true,
    });
    zenoh.access = Some(ZenohAccess {
        ids: (0..=robots).collect(),
        routers: vec![ROUTER_NAME.to_owned()],
    });
    zenoh
}

/// Rewrites each robot file's `[zenoh]` table in its secure form
/// ([`with_team_keys`], keys in `KEYS_DIR` next to the files).
fn secure_robot_files(files: &[PathBuf], robots: u32) -> Result<(), LaunchError> {
    let io = |file: &Path, e: String| LaunchError::Io(format!("{}: {e}", file.display()));
    for file in files {
        let text = std::fs::read_to_string(file).map_err(|e| io(file, e.to_string()))?;
        let mut config: ProcessConfig =
            toml::from_str(&text).map_err(|e| io(file, e.to_string()))?;
        let name = identity_name(config.robot);
        config.zenoh = with_team_keys(config.zenoh, Path::new(KEYS_DIR), &name, robots);
        let text = toml::to_string(&config).map_err(|e| io(file, e.to_string()))?;
        std::fs::write(file, text).map_err(|e| io(file, e.to_string()))?;
    }
    Ok(())
}

/// Writes robot files for `scenario_path`'s team into `dir` (see [`LaunchOptions`]),
/// starts the router if asked, starts one `troupe robot` (`troupe_exe`) per robot,
/// waits for all of them, and writes `dir/launch.json`.
pub fn launch(
    scenario_path: &Path,
    dir: &Path,
    options: &LaunchOptions,
    troupe_exe: &Path,
) -> Result<LaunchReport, LaunchError> {
    let io = |what: &str, e: std::io::Error| LaunchError::Io(format!("{what}: {e}"));
    let scenario = Scenario::load(scenario_path)?;
    let scenario_abs = std::fs::canonicalize(scenario_path)
        .map_err(|e| io(&scenario_path.display().to_string(), e))?;
    if options.tls {
        write_team_keys(&dir.join(KEYS_DIR), scenario.robots).map_err(LaunchError::Keys)?;
    }
    let (files, router) = if options.router {
        let mut router_settings = settings(loopback_endpoints(&[options.base_port]), Vec::new());
        if options.tls {
            router_settings = with_team_keys(
                router_settings,
                &dir.join(KEYS_DIR),
                ROUTER_NAME,
                scenario.robots,
            );
        }
        let endpoint = router_settings.listen.clone();
        let router = Router::open(&router_settings).map_err(LaunchError::Router)?;
        let files = write_client_team(
            dir,
            &scenario_abs,
            scenario.robots,
            &endpoint,
            options.duration_s,
        )
        .map_err(|e| io(&dir.display().to_string(), e))?;
        (files, Some((router, endpoint[0].clone())))
    } else {
        let ports: Vec<u16> = (0..scenario.robots)
            .map(|i| {
                u16::try_from(i)
                    .ok()
                    .and_then(|i| options.base_port.checked_add(i))
                    .ok_or_else(|| LaunchError::Io("ports beyond 65535".into()))
            })
            .collect::<Result<_, _>>()?;
        let files = write_team(
            dir,
            &scenario_abs,
            &loopback_endpoints(&ports),
            options.duration_s,
        )
        .map_err(|e| io(&dir.display().to_string(), e))?;
        (files, None)
    };
    if options.tls {
        secure_robot_files(&files, scenario.robots)?;
    }
    let mut children: Vec<Child> = Vec::new();
    for file in &files {
        match Command::new(troupe_exe)
            .arg("robot")
            .arg("--config")
            .arg(file)
            .spawn()
        {
            Ok(child) => children.push(child),
            Err(e) => {
                for mut c in children {
                    let _ = c.kill();
                }
                return Err(io(&troupe_exe.display().to_string(), e));
            }
        }
    }
    // Ctrl-C in the terminal reaches the whole process group: each robot writes its
    // outputs and exits, and this waits for them, sampling what they use.
    let started = Instant::now();
    let mut exit_codes = vec![None; children.len()];
    let mut running: Vec<bool> = vec![true; children.len()];
    let mut samples: Vec<Option<(f64, f64)>> = vec![None; children.len()];
    let mut walls = vec![0.0; children.len()];
    while running.iter().any(|r| *r) {
        for (i, child) in children.iter_mut().enumerate() {
            if !running[i] {
                continue;
            }
            if let Some(status) = child
                .try_wait()
                .map_err(|e| io("waiting for troupe robot", e))?
            {
                exit_codes[i] = status.code();
                running[i] = false;
                walls[i] = started.elapsed().as_secs_f64();
            } else if let Some(s) = read_usage(&child.id().to_string()) {
                samples[i] = Some(s);
            }
        }
        std::thread::sleep(Duration::from_millis(500));
    }
    let wall_s = started.elapsed().as_secs_f64();
    let launcher_usage = usage(read_usage("self"), wall_s);
    let router = router.map(|(router, endpoint)| {
        if let Err(e) = router.close() {
            tracing::warn!("{e}");
        }
        endpoint
    });
    let trajectories: Vec<_> = (0..files.len())
        .filter_map(|i| read_trajectory(&dir.join(format!("robot{i}/trajectory.csv"))).ok())
        .collect();
    let report = LaunchReport {
        robot_files: files,
        router,
        exit_codes,
        min_inter_robot_distance_m: min_distance_between(&trajectories),
        wall_s,
        robot_usage: samples
            .iter()
            .zip(&walls)
            .map(|(s, w)| usage(*s, *w))
            .collect(),
        launcher_usage,
    };
    let mut json = serde_json::to_string_pretty(&report)
        .map_err(|e| LaunchError::Io(format!("launch.json: {e}")))?;
    json.push('\n');
    std::fs::write(dir.join("launch.json"), json).map_err(|e| io("launch.json", e))?;
    Ok(report)
}
