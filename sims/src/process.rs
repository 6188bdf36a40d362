//! One robot per process (`troupe robot --config robot.toml`): the robot of a
//! scenario's team with its own simulated vehicle and camera in the scenario's world
//! (the same world seed gives the same world in every process), or with a recorded
//! sequence as its sensor (`sequence`, see [`crate::replay`]), the standard actors on
//! the real-time executor, and the link over zenoh. What needs the simulator — the
//! world, the simulated camera and vehicle, a recorded sequence — is built here; the
//! rest of the process (journal, team link, executor, signals, duration, recording,
//! `summary.json`) is the robot-process harness, [`troupe_robot::harness`].
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
//! Beyond a handful of robots, a zenoh router (`troupe router`, [`troupe_robot::router`])
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
//!
//! `troupe launch` writes these files for a scenario's team ([`SimulatedTeam`], the
//! simulator's [`TeamFiles`] for [`troupe_robot::launch`]).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Arc, Mutex, PoisonError};

use serde::{Deserialize, Serialize};
use troupe_actors::artifacts::{ARTIFACT_LIST, Artifact};
use troupe_actors::collision::{COLLISION_STATUS, CollisionStatus};
use troupe_actors::link::{LINK_STATUS, LinkStatus};
use troupe_actors::msgs::{PEER_KEYFRAME, PEER_ODOMETRY, PEER_PLAN};
use troupe_actors::planner::PLANNING_REPORT;
use troupe_algorithms::exploration::MissionStatus;
use troupe_comms::zenoh::{ZenohConfig, ZenohStats};
use troupe_core::{ConfigError, RobotId};
use troupe_record::{Compression, RecordOptions, RecordingStats, check_rate_hz, period_of_hz};
use troupe_robot::AssembleError;
use troupe_robot::harness::{
    self, ActorHealth, Harness, HarnessError, Member, shutdown_signal, write_trajectory,
};
use troupe_robot::launch::{TeamFiles, client_session, peer_sessions};
use troupe_robot::registry::Registry;
use troupe_robot::toml_file::{KEYFRAME_POLICY_KEY, SettingsFileError, names_key, read_toml};
use troupe_runtime::{Publication, RobotSpec, TopicStats};

use crate::recording::{record_options, record_world};
use crate::replay::replaying_robot;
use crate::scenario::{Scenario, ScenarioError};
use crate::sequence::{Sequence, SequenceError};
use crate::team::simulated_robot;
use crate::world::Site;
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
    /// Where the robot's parts come from (the simulator's [`crate::parts::registry`]
    /// unless the caller sets its own).
    pub parts: Registry,
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
    /// The harness could not open the link's journal, the team link or the
    /// recording, or could not write the outputs.
    #[error(transparent)]
    Harness(#[from] HarnessError),
}

impl RobotProcess {
    /// Reads and checks a robot file and its scenario.
    pub fn load(path: &Path) -> Result<Self, ProcessError> {
        let mut config: ProcessConfig = read_toml(path).map_err(SettingsFileError::from)?;
        let invalid = |e: ConfigError| ProcessError::from(SettingsFileError::config(path, e));
        let base = path.parent().unwrap_or(Path::new("."));
        let (mut scenario, text) =
            Scenario::load_with_text(&base.join(&config.scenario)).map_err(|source| {
                ProcessError::Scenario {
                    path: path.to_path_buf(),
                    source,
                }
            })?;
        let policy_named = names_key(&text, KEYFRAME_POLICY_KEY);
        scenario.robot.link = scenario.robot.link.with_process_keyframes(policy_named);
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
        if sequence.is_some() {
            for (key, named) in [
                ("robot.sensor", scenario.robot.sensor.is_some()),
                ("robot.vehicle", scenario.robot.vehicle.is_some()),
            ] {
                if named {
                    return Err(invalid(ConfigError::new(
                        key,
                        "must be absent from the scenario of a robot that replays a \
                         `sequence` (the recording is its sensor and its poses)",
                        "a part",
                    )));
                }
            }
        }
        Ok(RobotProcess {
            config,
            scenario,
            out,
            sequence,
            parts: crate::parts::registry(),
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
    pub actors: Vec<ActorHealth>,
    /// The link's last counters.
    pub link: Option<LinkStatus>,
    /// The collision actor's last counters (`stopped`: rounds that committed the
    /// stopping trajectory).
    pub collision: Option<CollisionStatus>,
    /// The robot's mission after its planner's last round (phase, when exploring ended
    /// and why, the return; absent without a planner).
    pub mission: Option<MissionStatus>,
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

/// The robot of `process` (a scenario with the team as its roster), and its world
/// unless it replays a recorded sequence.
fn build_robot(
    process: &RobotProcess,
    scenario: &Scenario,
) -> Result<(RobotSpec, Option<Arc<dyn Site>>), ProcessError> {
    let id = process.config.robot;
    // The link's journal outlives the process (`kill -9` included): what it
    // accepted and what it acknowledged, and its message ids.
    let journal = harness::open_journal(&scenario.robot.link.journal_dir_in(&process.out), None)?;
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
                id as usize,
                &config,
                sequence.clone(),
                scenario.vehicle.odometry_rate_hz,
                journal,
                &process.parts,
            );
            (robot, None)
        }
        None => {
            // A simulated robot keeps its world: the rock surface goes into the recording.
            let world = scenario.world.build().map_err(ProcessError::World)?;
            (
                simulated_robot(scenario, &world, id as usize, journal, &process.parts),
                Some(world),
            )
        }
    };
    let robot = robot.map_err(|source| ProcessError::Assemble { id, source })?;
    Ok((robot, world))
}

/// Counts what arrives from each peer ([`ProcessSummary::peers`]).
fn count_peers(harness: &mut Harness) -> Arc<Mutex<BTreeMap<u32, PeerCounts>>> {
    let peers: Arc<Mutex<BTreeMap<u32, PeerCounts>>> = Arc::default();
    let tap = peers.clone();
    harness.add_tap(move |p: &Publication<'_>| {
        let count = |robot: RobotId, field: fn(&mut PeerCounts) -> &mut u64| {
            let mut peers = tap.lock().unwrap_or_else(PoisonError::into_inner);
            *field(peers.entry(robot.0).or_default()) += 1;
        };
        if let Some(o) = p.get(&PEER_ODOMETRY) {
            count(o.robot, |c| &mut c.odometry);
        } else if let Some(k) = p.get(&PEER_KEYFRAME) {
            count(k.robot, |c| &mut c.keyframes);
        } else if let Some(plan) = p.get(&PEER_PLAN) {
            count(plan.robot, |c| &mut c.plans);
        }
    });
    peers
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
    let id = process.config.robot;
    let (robot, world) = build_robot(process, &scenario)?;
    let member = Member {
        name: format!("robot{id}"),
        id,
        seed: scenario.seed ^ u64::from(id),
        team: scenario.robot.link.team,
        zenoh: &process.config.zenoh,
        subscription: scenario.robot.link.subscribe,
        out: process.out.clone(),
    };
    let mut harness = Harness::open(member, robot)?;
    harness.track_trajectory();
    let link = harness.latest(LINK_STATUS);
    let collision = harness.latest(COLLISION_STATUS);
    let planning = harness.latest(PLANNING_REPORT);
    let artifacts = harness.latest(ARTIFACT_LIST);
    let peers = count_peers(&mut harness);
    if process.config.record {
        harness.record(process.record_options(), |mut recorder| {
            if let Some(world) = &world {
                record_world(&mut recorder, world.as_ref());
            }
            recorder
        })?;
    }
    let finished = harness.run(process.config.duration_s, stop).await?;
    let summary = ProcessSummary {
        robot: id,
        wall_s: finished.wall_s,
        topics: finished.report.topics.clone(),
        actors: finished.actors(),
        link: link.take(),
        collision: collision.take(),
        mission: planning.take().map(|report| report.mission),
        zenoh: finished.zenoh,
        transport_errors: finished.transport_errors,
        trajectory_samples: finished.trajectory.len(),
        peers: std::mem::take(&mut *peers.lock().unwrap_or_else(PoisonError::into_inner)),
        recording: finished.recording,
        artifacts: artifacts.take().map(|a| a.artifacts).unwrap_or_default(),
    };
    harness::write_summary(&process.out, &summary)?;
    write_trajectory(&process.out, &finished.trajectory)?;
    Ok(summary)
}

/// The simulated robots of a scenario's team as robot files (`troupe launch`): each
/// names `scenario` (write it absolute, or relative to the launch directory), runs
/// `duration_s` and is started as `troupe robot --config FILE` (`troupe`: the path
/// of the `troupe` binary).
#[derive(Clone, Debug)]
pub struct SimulatedTeam {
    /// The scenario file the robot files name.
    pub scenario: PathBuf,
    /// Robots in the team.
    pub robots: u32,
    /// Wall seconds each robot runs; `None`: until interrupted.
    pub duration_s: Option<f64>,
    /// The `troupe` binary.
    pub troupe: PathBuf,
}

impl TeamFiles for SimulatedTeam {
    fn robots(&self) -> u32 {
        self.robots
    }

    fn write(&self, dir: &Path, robot: u32, zenoh: ZenohConfig) -> std::io::Result<PathBuf> {
        write_robot_file(dir, &self.scenario, robot, self.duration_s, zenoh)
    }

    fn command(&self, file: &Path) -> Command {
        let mut command = Command::new(&self.troupe);
        command.arg("robot").arg("--config").arg(file);
        command
    }
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
    std::fs::create_dir_all(dir)?;
    (0..)
        .zip(peer_sessions(endpoints))
        .map(|(i, zenoh)| write_robot_file(dir, scenario, i, duration_s, zenoh))
        .collect()
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
    std::fs::create_dir_all(dir)?;
    (0..robots)
        .map(|i| write_robot_file(dir, scenario, i, duration_s, client_session(routers)))
        .collect()
}

/// Writes `robot<robot>.toml` into `dir` with `zenoh` as its session and its outputs
/// in `robot<robot>/`.
fn write_robot_file(
    dir: &Path,
    scenario: &Path,
    robot: u32,
    duration_s: Option<f64>,
    zenoh: ZenohConfig,
) -> std::io::Result<PathBuf> {
    let config = ProcessConfig {
        robot,
        scenario: scenario.to_path_buf(),
        duration_s,
        out: Some(PathBuf::from(format!("robot{robot}"))),
        sequence: None,
        zenoh,
        record: true,
        record_depth_hz: None,
        record_compression: None,
    };
    let file = dir.join(format!("robot{robot}.toml"));
    let text = toml::to_string(&config).map_err(std::io::Error::other)?;
    std::fs::write(&file, text)?;
    Ok(file)
}

/// Runs the robot on a new multi-threaded tokio runtime until its duration is over,
/// Ctrl-C or SIGTERM (`troupe robot`), then writes the outputs.
pub fn run_until_signal(process: &RobotProcess) -> Result<ProcessSummary, ProcessError> {
    harness::block_on(run(process, shutdown_signal()))?
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
