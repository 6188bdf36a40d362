//! One robot per process (`troupe robot --config robot.toml`): the robot of a
//! scenario's team with its own simulated vehicle and camera in the scenario's world
//! (the same world seed gives the same world in every process), or with a recorded
//! sequence as its sensor (`sequence`, see [`crate::replay`]), the standard actors on
//! the real-time executor, and the link over zenoh.
//!
//! A robot file names the scenario and which robot of its team this process is:
//!
//! ```toml
//! robot = 0                                # index in the team: start position, robot id
//! scenario = "../scenarios/default.toml"   # relative to this file
//! duration_s = 60.0                        # wall seconds; absent: until Ctrl-C
//! out = "runs/processes/robot0"            # relative to this file; default: next to it
//! # sequence = "recordings/tunnel"         # replay a recorded sequence (TUM RGB-D
//! #                                        # layout) instead of the simulated camera
//! # record = true                          # out/run.mcap (docs/recordings.md)
//! # record_depth_hz = 0.0                  # depth frames recorded per second
//! # record_compression = "zstd"            # or "lz4", "none"
//!
//! [zenoh]                                  # troupe_comms::zenoh::ZenohConfig
//! mode = "peer"
//! listen = ["tcp/0.0.0.0:7447"]
//! connect = ["tcp/10.0.0.2:7447", "tcp/10.0.0.3:7447"]  # every other robot: zenoh
//!                                                       # peers do not forward
//! ```
//!
//! Beyond a handful of robots, a zenoh router (`troupe router`, [`crate::router`])
//! forwards between them and each robot names only the router:
//!
//! ```toml
//! [zenoh]
//! mode = "client"
//! connect = ["tcp/10.0.0.1:7447"]
//! ```
//!
//! The link keeps its journal in `out/state/link.journal` (`[robot.link]
//! journal_dir`; `docs/link-durability.md`): a process killed and started again
//! resends what its peers had not acknowledged, gets back the peers' messages it
//! had, and never reuses a message id.
//!
//! On exit (the duration, SIGINT or SIGTERM) the process writes `summary.json`
//! ([`ProcessSummary`]) and `trajectory.csv` (`unix_time_s,x_m,y_m,z_m`, the ground
//! truth at every odometry message) into `out`, and while it runs it records what the
//! robot publishes into `out/run.mcap` in wall time (`record = false` turns it off;
//! `docs/recordings.md`).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Instant, SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};
use troupe_actors::artifacts::{ARTIFACT_LIST, Artifact};
use troupe_actors::collision::{COLLISION_STATUS, CollisionStatus};
use troupe_actors::link::{LINK_STATUS, LinkJournal, LinkStatus};
use troupe_actors::msgs::{ODOMETRY, PEER_KEYFRAME, PEER_ODOMETRY, PEER_PLAN};
use troupe_actors::runtime::{
    ConfigError, Publication, RealtimeExecutor, RobotId, RobotIdsError, TopicStats,
};
use troupe_comms::transport::TransportError;
use troupe_comms::zenoh::{ZenohConfig, ZenohMode, ZenohStats, ZenohTransport};
use troupe_robot::AssembleError;
pub use troupe_robot::hardware::shutdown_signal;
use troupe_robot::hardware::{finish_recording, run_for};
use troupe_robot::toml_file::{SettingsFileError, read_toml};

use troupe_record::{
    Clock, Compression, RecordOptions, Recorder, RecordingStats, SharedRecorder, check_rate_hz,
    period_of_hz,
};

use crate::recording::{RUN_RECORDING, record_options, record_world};
use crate::replay::replaying_robot;
use crate::scenario::{Scenario, ScenarioError};
use crate::sequence::{Sequence, SequenceError};
use crate::team::simulated_robot;
use crate::world::mesh::MeshError;

/// A robot file as written (see the module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProcessConfig {
    /// This robot's index in the scenario's team (its id on the link).
    pub robot: u32,
    /// The scenario file, relative to the robot file.
    pub scenario: PathBuf,
    /// Wall seconds to run; absent: until interrupted.
    #[serde(default)]
    pub duration_s: Option<f64>,
    /// Output directory, relative to the robot file; default `robot<i>/` next to it.
    #[serde(default)]
    pub out: Option<PathBuf>,
    /// A recorded sequence directory (TUM RGB-D layout, [`crate::sequence`]),
    /// relative to the robot file: the robot replays it as its sensor instead of
    /// flying the simulated vehicle and camera ([`crate::replay`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sequence: Option<PathBuf>,
    /// The zenoh session.
    #[serde(default)]
    pub zenoh: ZenohConfig,
    /// Write `run.mcap` into `out`: what the robot published, in wall time
    /// (`docs/recordings.md`); `false` turns it off.
    #[serde(default = "record_by_default")]
    pub record: bool,
    /// Depth frames recorded per second (`/robot<i>/depth`, about 100 kB each at
    /// 160 × 120 before compression); absent: the scenario's `[metrics]
    /// record_depth_hz` (0, the default, records none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub record_depth_hz: Option<f64>,
    /// How `run.mcap`'s chunks are compressed: `"zstd"`, `"lz4"` or `"none"`;
    /// absent: the scenario's `[metrics] record_compression` (`"zstd"` by default).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub record_compression: Option<Compression>,
}

fn record_by_default() -> bool {
    true
}

/// A robot file with its paths resolved and its scenario loaded.
#[derive(Clone, Debug)]
pub struct RobotProcess {
    /// The file's settings.
    pub config: ProcessConfig,
    /// The scenario.
    pub scenario: Scenario,
    /// Where the outputs go.
    pub out: PathBuf,
    /// The recorded sequence the robot replays, if the file names one.
    pub sequence: Option<Sequence>,
}

/// Why a robot process could not start or finish.
#[derive(Debug, thiserror::Error)]
pub enum ProcessError {
    /// The robot file cannot be read, does not have the expected shape, or a value
    /// (in `[zenoh]` too) breaks a rule.
    #[error(transparent)]
    File(#[from] SettingsFileError),
    /// The scenario the robot file names cannot be used.
    #[error("{}: the scenario it names", path.display())]
    Scenario {
        /// The robot file.
        path: PathBuf,
        /// Why the scenario cannot be used.
        source: ScenarioError,
    },
    /// The recorded sequence the robot file names cannot be opened.
    #[error("{}: cannot open its `sequence`", path.display())]
    Sequence {
        /// The robot file.
        path: PathBuf,
        /// Why.
        source: SequenceError,
    },
    /// The scenario's world could not be built.
    #[error("building the world")]
    World(#[source] MeshError),
    /// The robot could not be assembled.
    #[error("assembling robot{id}")]
    Assemble {
        /// The robot's id.
        id: u32,
        /// Why.
        source: AssembleError,
    },
    /// The executor did not accept the robot's id.
    #[error("starting the executor")]
    RobotId(#[source] RobotIdsError),
    /// The team link could not be opened or started.
    #[error("{context}")]
    Transport {
        /// What we were doing.
        context: &'static str,
        /// The transport's error.
        source: TransportError,
    },
    /// The executor ended without a report of the robot.
    #[error("the executor reported no robot")]
    NoReport,
    /// The outputs could not be written.
    #[error("writing {}", path.display())]
    Output {
        /// The directory.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The recording could not be created.
    #[error("creating the recording")]
    Recording(#[source] troupe_record::RecordError),
    /// The tokio runtime could not start.
    #[error("starting the tokio runtime")]
    Runtime(#[source] std::io::Error),
    /// The link's journal could not be opened.
    #[error("opening the link journal")]
    Journal {
        /// Why (names the file).
        source: troupe_comms::journal::JournalError,
    },
}

impl RobotProcess {
    /// Reads and checks a robot file and its scenario.
    pub fn load(path: &Path) -> Result<Self, ProcessError> {
        let mut config: ProcessConfig = read_toml(path).map_err(SettingsFileError::from)?;
        let invalid = |e: ConfigError| ProcessError::from(SettingsFileError::config(path, e));
        let base = path.parent().unwrap_or(Path::new("."));
        let scenario = Scenario::load(&base.join(&config.scenario)).map_err(|source| {
            ProcessError::Scenario {
                path: path.to_path_buf(),
                source,
            }
        })?;
        if config.robot >= scenario.robots {
            return Err(invalid(ConfigError::new(
                "robot",
                format!("must be below the scenario's {} robots", scenario.robots),
                config.robot,
            )));
        }
        if let Some(d) = config.duration_s {
            ConfigError::positive("duration_s", d).map_err(invalid)?;
        }
        if let Some(hz) = config.record_depth_hz {
            check_rate_hz("record_depth_hz", hz).map_err(invalid)?;
        }
        config.zenoh.resolve_paths(base);
        config
            .zenoh
            .validate()
            .map_err(|e| SettingsFileError::zenoh(path, "zenoh", e))?;
        let out = base.join(
            config
                .out
                .clone()
                .unwrap_or_else(|| PathBuf::from(format!("robot{}", config.robot))),
        );
        let sequence = config
            .sequence
            .as_ref()
            .map(|dir| Sequence::open(&base.join(dir)))
            .transpose()
            .map_err(|source| ProcessError::Sequence {
                path: path.to_path_buf(),
                source,
            })?;
        Ok(RobotProcess {
            config,
            scenario,
            out,
            sequence,
        })
    }

    /// What the recording writes: the scenario's `[metrics]` recording keys, the
    /// robot file's `record_depth_hz` and `record_compression` where it sets them.
    #[must_use]
    pub fn record_options(&self) -> RecordOptions {
        let mut options = record_options(&self.scenario.metrics);
        if let Some(hz) = self.config.record_depth_hz {
            options.depth_period_s = period_of_hz(hz);
        }
        if let Some(compression) = self.config.record_compression {
            options.compression = compression;
        }
        options
    }
}

/// What one robot process did (`summary.json`).
#[derive(Clone, Debug, Serialize)]
pub struct ProcessSummary {
    /// Robot id.
    pub robot: u32,
    /// Wall seconds it ran.
    pub wall_s: f64,
    /// Messages and bytes per topic (`peer/*` counts what arrived from the others).
    pub topics: BTreeMap<String, TopicStats>,
    /// Per actor: errors, panics, restarts.
    pub actors: Vec<ProcessActor>,
    /// The link's last counters.
    pub link: Option<LinkStatus>,
    /// The collision actor's last counters (`stopped`: rounds that committed the
    /// stopping trajectory).
    pub collision: Option<CollisionStatus>,
    /// The zenoh session's counters.
    pub zenoh: ZenohStats,
    /// Packets the executor could not hand to the transport.
    pub transport_errors: u64,
    /// Odometry samples in `trajectory.csv`.
    pub trajectory_samples: usize,
    /// What arrived from each peer (by robot id): who this robot heard.
    pub peers: BTreeMap<u32, PeerCounts>,
    /// The recording `run.mcap`, when one was written.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub recording: Option<RecordingStats>,
    /// The team's artifacts as this robot knew them last (with `[robot.artifacts]`;
    /// absent without).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub artifacts: Vec<Artifact>,
}

/// Messages received from one peer.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct PeerCounts {
    /// Odometry messages.
    pub odometry: u64,
    /// Plans.
    pub plans: u64,
    /// Keyframes.
    pub keyframes: u64,
}

/// One actor's health.
#[derive(Clone, Debug, Serialize)]
pub struct ProcessActor {
    /// Name.
    pub name: String,
    /// Events handled.
    pub handled: u64,
    /// Hooks that returned an error.
    pub errors: u64,
    /// Panics.
    pub panics: u64,
}

/// Runs the robot until its duration is over or `stop` resolves, then writes the
/// outputs; must be called inside a multi-threaded tokio runtime.
pub async fn run(
    process: &RobotProcess,
    stop: impl std::future::Future<Output = ()>,
) -> Result<ProcessSummary, ProcessError> {
    // Every team member, the base station included, is a store-and-forward
    // recipient from the start: one that starts late or restarts still gets what
    // was sent before it was heard.
    let mut scenario = process.scenario.clone();
    scenario.robot.link = scenario
        .robot
        .link
        .with_team(scenario.robots)
        .with_roster_as_peers();
    let scenario = &scenario;
    let id = process.config.robot;
    // The link's journal outlives the process (`kill -9` included): what it
    // accepted and what it acknowledged, and its message ids, which a new journal
    // starts somewhere new, so that peers who remember ids of an earlier run (their
    // duplicate filter) do not drop this run's first messages as repeats.
    let first_id = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as u32);
    let journal_dir = scenario.robot.link.journal_dir_in(&process.out);
    let journal = LinkJournal::on_disk(&journal_dir, first_id)
        .map_err(|source| ProcessError::Journal { source })?;
    // A simulated robot keeps its world: the rock surface goes into the recording.
    let (robot, world) = match &process.sequence {
        Some(sequence) => {
            tracing::info!(
                robot = id,
                frames = sequence.len(),
                "replaying {}",
                sequence.dir().display()
            );
            let mut config = scenario.robot.clone();
            config.link = config.link.with_team(scenario.robots);
            let robot = replaying_robot(
                &format!("robot{id}"),
                &config,
                sequence.clone(),
                scenario.vehicle.odometry_rate_hz,
                journal,
            );
            (robot, None)
        }
        None => {
            let world = scenario.world.build().map_err(ProcessError::World)?;
            (
                simulated_robot(scenario, &world, id as usize, journal),
                Some(world),
            )
        }
    };
    let robot = robot.map_err(|source| ProcessError::Assemble { id, source })?;
    let transport = Arc::new(
        ZenohTransport::open(&process.config.zenoh, scenario.robot.link.team, vec![id])
            .map_err(|source| ProcessError::Transport {
                context: "opening the zenoh session",
                source,
            })?
            .with_subscription(scenario.robot.link.subscribe),
    );
    let trajectory: Arc<Mutex<Vec<[f64; 4]>>> = Arc::default();
    let link: Arc<Mutex<Option<LinkStatus>>> = Arc::default();
    let peers: Arc<Mutex<BTreeMap<u32, PeerCounts>>> = Arc::default();
    let artifacts: Arc<Mutex<Vec<Artifact>>> = Arc::default();
    let collision: Arc<Mutex<Option<CollisionStatus>>> = Arc::default();
    let (trajectory_tap, link_tap, peers_tap, artifacts_tap, collision_tap) = (
        trajectory.clone(),
        link.clone(),
        peers.clone(),
        artifacts.clone(),
        collision.clone(),
    );
    let position_tap = transport.clone();
    let mut executor = RealtimeExecutor::new(vec![robot], scenario.seed ^ u64::from(id))
        .with_robot_ids(vec![RobotId(id)])
        .map_err(ProcessError::RobotId)?;
    executor.add_tap(move |p: &Publication<'_>| {
        if let Some(o) = p.get(&ODOMETRY) {
            let t = SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map_or(0.0, |d| d.as_secs_f64());
            let v = o.pose.translation.vector;
            // Where the robot is picks its keyframes' cell and, under a
            // neighbourhood scope, the cells it hears (troupe_comms::scope).
            position_tap.set_position(id, [v.x, v.y, v.z]);
            if let Ok(mut samples) = trajectory_tap.lock() {
                samples.push([t, v.x, v.y, v.z]);
            }
        } else if let Some(status) = p.get(&LINK_STATUS)
            && let Ok(mut last) = link_tap.lock()
        {
            *last = Some(status.clone());
        } else if let Some(status) = p.get(&COLLISION_STATUS)
            && let Ok(mut last) = collision_tap.lock()
        {
            *last = Some(status.clone());
        } else if let Some(list) = p.get(&ARTIFACT_LIST)
            && let Ok(mut last) = artifacts_tap.lock()
        {
            last.clone_from(&list.artifacts);
        } else {
            let count = |robot: RobotId, field: fn(&mut PeerCounts) -> &mut u64| {
                if let Ok(mut peers) = peers_tap.lock() {
                    *field(peers.entry(robot.0).or_default()) += 1;
                }
            };
            if let Some(o) = p.get(&PEER_ODOMETRY) {
                count(o.robot, |c| &mut c.odometry);
            } else if let Some(k) = p.get(&PEER_KEYFRAME) {
                count(k.robot, |c| &mut c.keyframes);
            } else if let Some(plan) = p.get(&PEER_PLAN) {
                count(plan.robot, |c| &mut c.plans);
            }
        }
    });
    let recorder = if process.config.record {
        std::fs::create_dir_all(&process.out).map_err(|source| ProcessError::Output {
            path: process.out.clone(),
            source,
        })?;
        let path = process.out.join(RUN_RECORDING);
        let options = process.record_options();
        let mut recorder = Recorder::create_with(&path, Clock::wall_from_now(), options)
            .map_err(ProcessError::Recording)?;
        if let Some(world) = &world {
            record_world(&mut recorder, world.as_ref());
        }
        let recorder = SharedRecorder::new(recorder);
        executor.add_tap(recorder.clone());
        Some(recorder)
    } else {
        None
    };
    let started = Instant::now();
    let handle = executor
        .spawn_with_transport(transport.clone())
        .map_err(|source| ProcessError::Transport {
            context: "starting the team link",
            source,
        })?;
    tracing::info!(robot = id, "running");
    run_for(process.config.duration_s, stop).await;
    let transport_errors = handle.transport_errors();
    let reports = handle.shutdown().await;
    let zenoh = transport.stats();
    if let Err(e) = transport.close() {
        tracing::warn!(robot = id, "closing zenoh: {e}");
    }
    let report = reports.into_iter().next().ok_or(ProcessError::NoReport)?;
    let recording = finish_recording(recorder.as_ref(), &format!("robot{id}"));
    let trajectory = std::mem::take(
        &mut *trajectory
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner),
    );
    let summary = ProcessSummary {
        robot: id,
        wall_s: started.elapsed().as_secs_f64(),
        topics: report.topics.clone(),
        actors: report
            .actors
            .iter()
            .map(|a| ProcessActor {
                name: a.name.clone(),
                handled: a.stats.handled,
                errors: a.stats.errors,
                panics: a.stats.panics,
            })
            .collect(),
        link: link
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone(),
        collision: collision
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone(),
        zenoh,
        transport_errors,
        trajectory_samples: trajectory.len(),
        peers: std::mem::take(
            &mut *peers
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner),
        ),
        recording,
        artifacts: std::mem::take(
            &mut *artifacts
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner),
        ),
    };
    write_outputs(&process.out, &summary, &trajectory).map_err(|source| ProcessError::Output {
        path: process.out.clone(),
        source,
    })?;
    Ok(summary)
}

fn write_outputs(
    dir: &Path,
    summary: &ProcessSummary,
    trajectory: &[[f64; 4]],
) -> std::io::Result<()> {
    use std::fmt::Write as _;
    std::fs::create_dir_all(dir)?;
    let mut json = serde_json::to_string_pretty(summary).map_err(std::io::Error::other)?;
    json.push('\n');
    std::fs::write(dir.join("summary.json"), json)?;
    let mut csv = String::from("unix_time_s,x_m,y_m,z_m\n");
    for [t, x, y, z] in trajectory {
        let _ = writeln!(csv, "{t:.6},{x},{y},{z}");
    }
    std::fs::write(dir.join("trajectory.csv"), csv)
}

/// Writes one robot file per robot into `dir`: robot `i` listens on `endpoints[i]`
/// (e.g. `tcp/127.0.0.1:7447`) and connects to every other robot's endpoint (zenoh
/// peers do not forward); `scenario` is written as given (use an absolute path, or
/// one relative to `dir`). The same files work across hosts with the hosts'
/// addresses, once they authenticate (`troupe keys`, docs/security.md) or say
/// `insecure = true`: an open listener off loopback is refused. Returns the files.
pub fn write_team(
    dir: &Path,
    scenario: &Path,
    endpoints: &[String],
    duration_s: Option<f64>,
) -> std::io::Result<Vec<PathBuf>> {
    write_robot_files(dir, scenario, endpoints.len(), duration_s, |i| {
        ZenohConfig {
            listen: vec![endpoints[i].clone()],
            connect: endpoints
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != i)
                .map(|(_, e)| e.clone())
                .collect(),
            ..ZenohConfig::default()
        }
    })
}

/// Writes one robot file per robot (`robots` of them) into `dir`, each a zenoh
/// client that connects only to the router(s) `routers` (e.g. `tcp/10.0.0.1:7447`,
/// started with `troupe router`); otherwise as [`write_team`]. Returns the files.
pub fn write_client_team(
    dir: &Path,
    scenario: &Path,
    robots: u32,
    routers: &[String],
    duration_s: Option<f64>,
) -> std::io::Result<Vec<PathBuf>> {
    write_robot_files(dir, scenario, robots as usize, duration_s, |_| {
        ZenohConfig {
            mode: ZenohMode::Client,
            connect: routers.to_vec(),
            ..ZenohConfig::default()
        }
    })
}

/// Writes `robot<i>.toml` for `i` below `robots`, with `zenoh(i)` as its session.
fn write_robot_files(
    dir: &Path,
    scenario: &Path,
    robots: usize,
    duration_s: Option<f64>,
    zenoh: impl Fn(usize) -> ZenohConfig,
) -> std::io::Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir)?;
    (0..robots)
        .map(|i| {
            let config = ProcessConfig {
                robot: u32::try_from(i).map_err(std::io::Error::other)?,
                scenario: scenario.to_path_buf(),
                duration_s,
                out: Some(PathBuf::from(format!("robot{i}"))),
                sequence: None,
                zenoh: zenoh(i),
                record: true,
                record_depth_hz: None,
                record_compression: None,
            };
            let file = dir.join(format!("robot{i}.toml"));
            let text = toml::to_string(&config).map_err(std::io::Error::other)?;
            std::fs::write(&file, text)?;
            Ok(file)
        })
        .collect()
}

/// TCP endpoints on this machine's loopback, one per port.
#[must_use]
pub fn loopback_endpoints(ports: &[u16]) -> Vec<String> {
    ports.iter().map(|p| format!("tcp/127.0.0.1:{p}")).collect()
}

/// Reads a `trajectory.csv` written by [`run`].
pub fn read_trajectory(path: &Path) -> std::io::Result<Vec<[f64; 4]>> {
    let text = std::fs::read_to_string(path)?;
    text.lines()
        .skip(1)
        .map(|line| {
            let v: Vec<f64> = line
                .split(',')
                .map(str::parse)
                .collect::<Result<_, _>>()
                .map_err(std::io::Error::other)?;
            match v.as_slice() {
                [t, x, y, z] => Ok([*t, *x, *y, *z]),
                _ => Err(std::io::Error::other(format!("bad line `{line}`"))),
            }
        })
        .collect()
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

/// Runs the robot on a new multi-threaded tokio runtime until its duration is over,
/// Ctrl-C or SIGTERM (`troupe robot`), then writes the outputs.
pub fn run_until_signal(process: &RobotProcess) -> Result<ProcessSummary, ProcessError> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(ProcessError::Runtime)?;
    runtime.block_on(run(process, shutdown_signal()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A robot file next to a scenario that asks for depth frames and lz4.
    fn load(robot_file: &str) -> Result<RobotProcess, ProcessError> {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(
            dir.path().join("team.toml"),
            "robots = 2\n[metrics]\nrecord_depth_hz = 2.0\nrecord_compression = \"lz4\"\n",
        )
        .unwrap();
        let path = dir.path().join("robot0.toml");
        std::fs::write(
            &path,
            format!("robot = 0\nscenario = \"team.toml\"\n{robot_file}"),
        )
        .unwrap();
        RobotProcess::load(&path)
    }

    #[test]
    fn recording_keys_come_from_the_scenario_unless_the_robot_file_sets_them() {
        let options = load("").unwrap().record_options();
        assert_eq!(options.depth_period_s, Some(0.5));
        assert_eq!(options.compression, Compression::Lz4);
        assert_eq!(options.grid_period_s, Some(1.0));
        let options = load("record_depth_hz = 0.0\nrecord_compression = \"none\"\n")
            .unwrap()
            .record_options();
        assert_eq!(options.depth_period_s, None);
        assert_eq!(options.compression, Compression::None);
        for (bad, expected) in [
            (
                "record_depth_hz = 31.0\n",
                "`record_depth_hz` must be between 0 and 30 Hz",
            ),
            ("record_compression = \"gz\"\n", "unknown variant `gz`"),
        ] {
            let e = load(bad).unwrap_err();
            let chain = troupe_core::ErrorChain(&e).to_string();
            assert!(chain.contains(expected), "{chain}");
        }
    }
}
