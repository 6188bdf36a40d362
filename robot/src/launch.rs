//! Launching a team as separate robot processes on this machine (`troupe launch
//! SCENARIO.toml` for simulated robots), talking over zenoh on loopback, peer to peer
//! or (with `router`) through one zenoh router ([`crate::router`]) that this process
//! runs; the same robot files work across hosts with other addresses.
//!
//! The launcher is not tied to one kind of robot file: [`TeamFiles`] writes robot
//! `i`'s file with the `[zenoh]` session the launcher chose for it and names the
//! command that runs it (the simulator's `troupe robot --config FILE`,
//! `troupe_sims::process::SimulatedTeam`). Each robot writes its outputs into
//! `robot<i>/` of the launch directory; their `trajectory.csv`
//! ([`crate::harness::write_trajectory`]) gives the closest approach.
//!
//! While the robots run, the launcher samples each process's CPU time and peak
//! resident memory from `/proc` (Linux; elsewhere the usage is absent), and its own,
//! which with a router is the router's (the launcher itself only waits).
//!
//! With `tls` the team is the secure one of `docs/security.md` in one command: the
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
use troupe_comms::zenoh::{
    ZenohAccess, ZenohConfig, ZenohMode, ZenohSigner, ZenohSigning, ZenohTls,
};

use crate::harness::read_trajectory;
use crate::keys::{ROUTER_NAME, write_team_keys};
use crate::router::{Router, RouterError, settings};

/// The robot files of a team, in the format of the processes that run them.
pub trait TeamFiles {
    /// Robots in the team (ids `0..robots`).
    fn robots(&self) -> u32;

    /// Writes robot `robot`'s file into `dir`, with `zenoh` as its session and its
    /// outputs in `dir/robot<robot>/`; returns the file.
    fn write(&self, dir: &Path, robot: u32, zenoh: ZenohConfig) -> std::io::Result<PathBuf>;

    /// The command that runs one robot from its `file`.
    fn command(&self, file: &Path) -> Command;
}

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

/// The directory, in the launch directory, that `tls` writes the keys into.
pub const KEYS_DIR: &str = "keys";

/// The secure form of `zenoh` for the member `name` (`robot<i>`, `router`) of a
/// team of `robots` whose keys `troupe keys` wrote into `keys` (relative to the
/// file the table is written in): `tls/` endpoints, mutual TLS with the member's
/// certificate, access control naming every id (the robots' and the base's)
/// and the router, and, given the team's `signers` (a robot, not the router),
/// frames signed with the member's key.
fn with_team_keys(
    mut zenoh: ZenohConfig,
    keys: &Path,
    name: &str,
    robots: u32,
    router: bool,
    signers: Option<&[ZenohSigner]>,
) -> ZenohConfig {
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
        routers: if router {
            vec![ROUTER_NAME.to_owned()]
        } else {
            Vec::new()
        },
    });
    zenoh.signing = signers.map(|signers| ZenohSigning {
        key_path: keys.join(format!("{name}.key")),
        signers: signers.to_vec(),
    });
    zenoh
}

/// Every robot's session peer to peer: robot `i` listens on `endpoints[i]` (e.g.
/// `tcp/127.0.0.1:7447`) and connects to every other robot's endpoint (zenoh peers do
/// not forward).
#[must_use]
pub fn peer_sessions(endpoints: &[String]) -> Vec<ZenohConfig> {
    (0..endpoints.len())
        .map(|i| ZenohConfig {
            listen: vec![endpoints[i].clone()],
            connect: endpoints
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != i)
                .map(|(_, e)| e.clone())
                .collect(),
            ..ZenohConfig::default()
        })
        .collect()
}

/// A robot's session as a zenoh client that connects only to the router(s)
/// `routers` (e.g. `tcp/10.0.0.1:7447`, started with `troupe router`).
#[must_use]
pub fn client_session(routers: &[String]) -> ZenohConfig {
    ZenohConfig {
        mode: ZenohMode::Client,
        connect: routers.to_vec(),
        ..ZenohConfig::default()
    }
}

/// TCP endpoints on this machine's loopback, one per port.
#[must_use]
pub fn loopback_endpoints(ports: &[u16]) -> Vec<String> {
    ports.iter().map(|p| format!("tcp/127.0.0.1:{p}")).collect()
}

/// Smallest distance between the robots of several trajectories at common times
/// (each sample against the other robot's position interpolated at that time), metres;
/// `None` with fewer than two overlapping trajectories.
#[must_use]
pub fn min_distance_between(trajectories: &[Vec<[f64; 4]>]) -> Option<f64> {
    let at = |samples: &[[f64; 4]], t: f64| -> Option<[f64; 3]> {
        let i = samples.partition_point(|s| s[0] <= t);
        if i == 0 || i == samples.len() {
            return None;
        }
        let (a, b) = (samples[i - 1], samples[i]);
        let f = if b[0] > a[0] {
            (t - a[0]) / (b[0] - a[0])
        } else {
            0.0
        };
        Some([0, 1, 2].map(|k| a[k + 1] + f * (b[k + 1] - a[k + 1])))
    };
    let mut best: Option<f64> = None;
    for (i, mine) in trajectories.iter().enumerate() {
        for (j, theirs) in trajectories.iter().enumerate() {
            if i == j {
                continue;
            }
            for s in mine {
                if let Some(q) = at(theirs, s[0]) {
                    let d = ((s[1] - q[0]).powi(2) + (s[2] - q[1]).powi(2) + (s[3] - q[2]).powi(2))
                        .sqrt();
                    best = Some(best.map_or(d, |b: f64| b.min(d)));
                }
            }
        }
    }
    best
}

/// A router this process runs for its robots, and its endpoint.
type RunningRouter = (Router, String);

/// The sessions of the team's robots (see [`LaunchOptions`]; `signers`: the
/// team's keys, with `tls`), and the router this process runs for them.
fn sessions(
    robots: u32,
    dir: &Path,
    options: &LaunchOptions,
    signers: &[ZenohSigner],
) -> Result<(Vec<ZenohConfig>, Option<RunningRouter>), LaunchError> {
    let mut sessions = if options.router {
        let mut router_settings = settings(loopback_endpoints(&[options.base_port]), Vec::new());
        if options.tls {
            router_settings = with_team_keys(
                router_settings,
                &dir.join(KEYS_DIR),
                ROUTER_NAME,
                robots,
                true,
                None,
            );
        }
        let endpoint = router_settings.listen.clone();
        let router = Router::open(&router_settings).map_err(LaunchError::Router)?;
        let sessions = vec![client_session(&endpoint); robots as usize];
        (sessions, Some((router, endpoint[0].clone())))
    } else {
        let ports: Vec<u16> = (0..robots)
            .map(|i| {
                u16::try_from(i)
                    .ok()
                    .and_then(|i| options.base_port.checked_add(i))
                    .ok_or_else(|| LaunchError::Io("ports beyond 65535".into()))
            })
            .collect::<Result<_, _>>()?;
        (peer_sessions(&loopback_endpoints(&ports)), None)
    };
    if options.tls {
        for (i, zenoh) in (0..robots).zip(&mut sessions.0) {
            let secure = with_team_keys(
                std::mem::take(zenoh),
                Path::new(KEYS_DIR),
                &identity_name(i),
                robots,
                options.router,
                Some(signers),
            );
            *zenoh = secure;
        }
    }
    Ok(sessions)
}

/// What the robot processes did, sampled every half second until each exited.
struct Watched {
    exit_codes: Vec<Option<i32>>,
    usage: Vec<Option<ProcessUsage>>,
    wall_s: f64,
}

/// Starts one process per robot file; on a failure, kills those already started.
fn spawn_all(team: &impl TeamFiles, files: &[PathBuf]) -> Result<Vec<Child>, LaunchError> {
    let mut children: Vec<Child> = Vec::new();
    for file in files {
        let mut command = team.command(file);
        match command.spawn() {
            Ok(child) => children.push(child),
            Err(e) => {
                for mut c in children {
                    let _ = c.kill();
                }
                let program = command.get_program().to_string_lossy().into_owned();
                return Err(LaunchError::Io(format!("{program}: {e}")));
            }
        }
    }
    Ok(children)
}

/// Waits for every child, sampling what each uses.
fn watch(mut children: Vec<Child>) -> Result<Watched, LaunchError> {
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
                .map_err(|e| LaunchError::Io(format!("waiting for a robot process: {e}")))?
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
    Ok(Watched {
        exit_codes,
        usage: samples
            .iter()
            .zip(&walls)
            .map(|(s, w)| usage(*s, *w))
            .collect(),
        wall_s: started.elapsed().as_secs_f64(),
    })
}

/// Writes `team`'s robot files into `dir` (see [`LaunchOptions`]), starts the router
/// if asked, starts one process per robot, waits for all of them, and writes
/// `dir/launch.json`.
pub fn launch(
    team: &impl TeamFiles,
    dir: &Path,
    options: &LaunchOptions,
) -> Result<LaunchReport, LaunchError> {
    let io = |what: &str, e: std::io::Error| LaunchError::Io(format!("{what}: {e}"));
    let robots = team.robots();
    let signers = if options.tls {
        write_team_keys(&dir.join(KEYS_DIR), robots, options.router)
            .map_err(LaunchError::Keys)?
            .signers
    } else {
        Vec::new()
    };
    let (sessions, router) = sessions(robots, dir, options, &signers)?;
    std::fs::create_dir_all(dir).map_err(|e| io(&dir.display().to_string(), e))?;
    let files = (0..robots)
        .zip(sessions)
        .map(|(i, zenoh)| team.write(dir, i, zenoh))
        .collect::<std::io::Result<Vec<PathBuf>>>()
        .map_err(|e| io(&dir.display().to_string(), e))?;
    let watched = watch(spawn_all(team, &files)?)?;
    let launcher_usage = usage(read_usage("self"), watched.wall_s);
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
        exit_codes: watched.exit_codes,
        min_inter_robot_distance_m: min_distance_between(&trajectories),
        wall_s: watched.wall_s,
        robot_usage: watched.usage,
        launcher_usage,
    };
    let mut json = serde_json::to_string_pretty(&report)
        .map_err(|e| LaunchError::Io(format!("launch.json: {e}")))?;
    json.push('\n');
    std::fs::write(dir.join("launch.json"), json).map_err(|e| io("launch.json", e))?;
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn peers_connect_to_every_other_robot_and_clients_only_to_the_router() {
        let endpoints = loopback_endpoints(&[7447, 7448, 7449]);
        assert_eq!(endpoints[1], "tcp/127.0.0.1:7448");
        let peers = peer_sessions(&endpoints);
        assert_eq!(peers.len(), 3);
        assert_eq!(peers[1].listen, [endpoints[1].clone()]);
        assert_eq!(
            peers[1].connect,
            [endpoints[0].clone(), endpoints[2].clone()]
        );
        assert_eq!(peers[1].mode, ZenohMode::default());
        let client = client_session(&endpoints[..1]);
        assert_eq!(client.mode, ZenohMode::Client);
        assert!(client.listen.is_empty());
        assert_eq!(client.connect, [endpoints[0].clone()]);
    }

    #[test]
    fn secure_sessions_use_tls_endpoints_and_the_member_keys() {
        let zenoh = with_team_keys(
            peer_sessions(&loopback_endpoints(&[9000, 9001])).remove(0),
            Path::new(KEYS_DIR),
            "robot0",
            2,
            false,
            Some(&[]),
        );
        assert_eq!(zenoh.listen, ["tls/127.0.0.1:9000"]);
        assert_eq!(zenoh.connect, ["tls/127.0.0.1:9001"]);
        let tls = zenoh.tls.expect("tls");
        assert_eq!(tls.cert_path, Path::new("keys/robot0.pem"));
        assert!(tls.mutual);
        let access = zenoh.access.expect("access");
        assert_eq!(access.ids, [0, 1, 2]);
        assert!(access.routers.is_empty(), "no router, no router identity");
        let signing = zenoh.signing.expect("signing");
        assert_eq!(signing.key_path, Path::new("keys/robot0.key"));
    }

    #[test]
    fn the_closest_approach_interpolates_between_samples() {
        // `a` passes under `b`, which hovers at (1, 3, 0) from t = 0 to t = 2 s.
        let a = vec![
            [0.0, 0.0, 0.0, 0.0],
            [1.0, 1.0, 0.0, 0.0],
            [2.0, 2.0, 0.0, 0.0],
        ];
        let b = vec![[0.0, 1.0, 3.0, 0.0], [2.0, 1.0, 3.0, 0.0]];
        let d = min_distance_between(&[a.clone(), b]).expect("overlap");
        assert!((d - 3.0).abs() < 1e-12, "{d}");
        assert_eq!(min_distance_between(&[a]), None);
    }
}
