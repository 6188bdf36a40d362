//! The base station (`troupe base --config base.toml`, thesis §8.2.6: the robots'
//! maps go to a base station): a zenoh participant with its own robot id that flies
//! nothing. It runs one "robot" on the real-time executor holding only the
//! [`LinkActor`], so every frame the robots send is reassembled, decoded, validated
//! (team, sender) and deduplicated by the same code a robot uses, and store-and-forward
//! keyframes are acknowledged like a peer does (a robot adds the base to its
//! recipients when the first ack arrives and sends it its stored backlog). A [`Tap`](troupe_runtime::Tap)
//! on the link's publications collects every robot's keyframes (`peer/keyframe`),
//! odometry and plans into [`BaseMaps`].
//!
//! A base file (its `scenario` is read by the caller's team reader: `troupe base`
//! reads a simulator scenario file, `troupe_sims::scenario::load_team`):
//!
//! ```toml
//! scenario = "../scenarios/default.toml"  # the team (its id, link settings, size)
//! # base_id = 2                          # the base's id on the link; default: the
//! #                                      # team size (must not be a robot's index)
//! # duration_s = 600.0                   # wall seconds; absent: until Ctrl-C
//! # out = "base"                         # relative to this file; default `base/`
//! # ply_points = 200000                  # points sampled into merged_map.ply
//!
//! [zenoh]                                # troupe_comms::zenoh::ZenohConfig
//! listen = ["tcp/0.0.0.0:7450"]
//! connect = ["tcp/10.0.0.2:7447", "tcp/10.0.0.3:7447"]
//! ```
//!
//! Every second it prints one line per robot ([`BaseMaps::status_lines`]). On exit
//! (the duration, SIGINT or SIGTERM) it writes into `out`: `maps/robot<i>.troupe` (each
//! robot's keyframe mixtures), `maps/robot<i>.ply`, `merged_map.troupe` (every
//! keyframe of the team: their support-weighted union is the merged map of Eq. 3.5),
//! `merged_map.ply` (points drawn from it, with a `source` property naming the robot)
//! and `summary.json` ([`BaseSummary`]); while it runs it records every robot's pose,
//! plans and keyframes as received into `out/run.mcap` in wall time (`record = false`
//! turns it off; `docs/recordings.md`).
//!
//! Like a robot process, the base keeps its link journal on disk
//! (`out/state/link.journal`, `docs/link-durability.md`): a robot releases a keyframe
//! once the base acknowledged it, so the base journals it first; after `kill -9`
//! and a restart the journaled keyframes fill the maps again (up to
//! [`BASE_JOURNAL_RECEIVED_BYTES`]), unacknowledged operator commands are resent and
//! no message id is used twice.
//!
//! An operator types commands on the base's standard input, one per line —
//! `robot1 hold`, `all hold`, `robot1 resume`, `robot1 return`, `robot1 velocity 0.5 0 0.1` — which
//! go to the robots as [`BaseCommand`]s on the shared topic
//! [`BASE_COMMAND`](troupe_actors::collision::BASE_COMMAND)
//! (store-and-forward, highest priority; robots with `[robot.collision]
//! operator_commands = true` apply them, see docs/base-station.md).
//!
//! When the team runs the artifact reporter (`[robot.artifacts] enabled = true`), the
//! base runs a listening [`ArtifactActor`] too: it shares `artifacts/report`, so the
//! robots' store-and-forward reports reach it (and are acknowledged), and its
//! deduplicated list is `artifacts` in `summary.json`.

mod maps;
mod operator;

use std::collections::BTreeMap;
use std::future::Future;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};
use troupe_actors::artifacts::{ARTIFACT_LIST, Artifact, ArtifactActor};
use troupe_actors::collision::BaseCommand;
use troupe_actors::link::{LINK_STATUS, LinkActor, LinkStatus};
use troupe_algorithms::mapfile::MapFileError;
use troupe_algorithms::sogmm::SogmmError;
use troupe_comms::scope::SubscriptionConfig;
use troupe_comms::zenoh::{ZenohConfig, ZenohStats};
use troupe_core::ConfigError;
use troupe_record::{Compression, RecordOptions, Recorder, RecordingStats};
use troupe_runtime::{ActorSpec, Publication, RobotSpec};

pub use maps::{BaseMaps, RobotRecord, merged_points};
pub use operator::read_commands;
use operator::{Commander, CountRejections};

use crate::RobotConfig;
use crate::harness::{self, Harness, HarnessError, Member, shutdown_signal};
use crate::toml_file::{SettingsFileError, read_toml};

/// Most bytes of received keyframes the base's link journal keeps for a restart
/// (oldest dropped first): the team's map of a long mission (a keyframe is a few
/// tens of kB).
pub const BASE_JOURNAL_RECEIVED_BYTES: usize = 512 * 1024 * 1024;

/// Default points in `merged_map.ply`.
pub const DEFAULT_PLY_POINTS: usize = 200_000;

/// A base file as written (see the module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BaseConfig {
    /// The team's scenario file, relative to the base file.
    pub scenario: PathBuf,
    /// The base's id on the link; default: the team size.
    #[serde(default)]
    pub base_id: Option<u32>,
    /// Wall seconds to run; absent: until interrupted.
    #[serde(default)]
    pub duration_s: Option<f64>,
    /// Output directory, relative to the base file; default `base/` next to it.
    #[serde(default)]
    pub out: Option<PathBuf>,
    /// Points sampled into `merged_map.ply` (shared among the robots by support).
    #[serde(default = "default_ply_points")]
    pub ply_points: usize,
    /// The zenoh session.
    #[serde(default)]
    pub zenoh: ZenohConfig,
    /// Write `run.mcap` into `out`: every robot's pose, plans and keyframes as the base
    /// received them, in wall time (`docs/recordings.md`); `false` turns it off.
    #[serde(default = "record_by_default")]
    pub record: bool,
    /// How `run.mcap`'s chunks are compressed: `"zstd"` (the default), `"lz4"` or
    /// `"none"`.
    #[serde(default)]
    pub record_compression: Compression,
}

fn record_by_default() -> bool {
    true
}

fn default_ply_points() -> usize {
    DEFAULT_PLY_POINTS
}

/// The team a base station serves, as the file its base file names describes it
/// (for `troupe base`, a simulator scenario's `name`, `seed`, `robots` and `[robot]`).
#[derive(Clone, Debug, PartialEq)]
pub struct TeamSettings {
    /// The team's name.
    pub name: String,
    /// Robots in the team (ids `0..robots`).
    pub robots: u32,
    /// The run seed; the base's actors and its merged map's points are seeded by it.
    pub seed: u64,
    /// Every robot's configuration: the base uses its `[robot.link]` and
    /// `[robot.artifacts]`.
    pub robot: RobotConfig,
}

/// A base file with its paths resolved and its team read.
#[derive(Clone, Debug)]
pub struct BaseStation {
    /// The file's settings.
    pub config: BaseConfig,
    /// The team it serves.
    pub team: TeamSettings,
    /// The base's id on the link.
    pub base_id: u32,
    /// Where the outputs go.
    pub out: PathBuf,
}

/// Why the base station cannot run.
#[derive(Debug, thiserror::Error)]
pub enum BaseError {
    /// The base file cannot be read, does not have the expected shape, or a value
    /// (in `[zenoh]` too) breaks a rule.
    #[error(transparent)]
    File(#[from] SettingsFileError),
    /// The base file's scenario cannot be used.
    #[error("the base file's scenario")]
    Scenario(#[source] Box<dyn std::error::Error + Send + Sync>),
    /// The harness could not open the link's journal, the team link or the
    /// recording, or could not write `summary.json`.
    #[error(transparent)]
    Harness(#[from] HarnessError),
    /// Sampling the merged map's points failed.
    #[error("sampling the merged map")]
    Sample(#[source] SogmmError),
    /// Writing a map file failed.
    #[error("writing {}", path.display())]
    Map {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: MapFileError,
    },
    /// Writing another output failed.
    #[error("writing {}", path.display())]
    Write {
        /// The file or directory.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
}

impl BaseStation {
    /// Reads and checks a base file, and its team with `read_team` from the file its
    /// `scenario` names (relative to the base file).
    pub fn load<E>(
        path: &Path,
        read_team: impl FnOnce(&Path) -> Result<TeamSettings, E>,
    ) -> Result<Self, BaseError>
    where
        E: std::error::Error + Send + Sync + 'static,
    {
        let mut config: BaseConfig = read_toml(path).map_err(SettingsFileError::from)?;
        let invalid = |e: ConfigError| BaseError::from(SettingsFileError::config(path, e));
        let dir = path.parent().unwrap_or(Path::new("."));
        let team =
            read_team(&dir.join(&config.scenario)).map_err(|e| BaseError::Scenario(e.into()))?;
        let team_base_id = team.robot.link.base_id.unwrap_or(team.robots);
        let base_id = config.base_id.unwrap_or(team_base_id);
        if base_id != team_base_id {
            return Err(invalid(ConfigError::new(
                "base_id",
                format!(
                    "must be the base id the robots accept ({team_base_id}, the scenario's \
                     `[robot.link] base_id` or its team size)"
                ),
                base_id,
            )));
        }
        if base_id < team.robots {
            return Err(invalid(ConfigError::new(
                "base_id",
                format!(
                    "must not be a robot's index (must be at least {})",
                    team.robots
                ),
                base_id,
            )));
        }
        if let Some(d) = config.duration_s {
            ConfigError::positive("duration_s", d).map_err(invalid)?;
        }
        config.zenoh.resolve_paths(dir);
        config
            .zenoh
            .validate()
            .map_err(|e| SettingsFileError::zenoh(path, "zenoh", e))?;
        let out = dir.join(config.out.clone().unwrap_or_else(|| PathBuf::from("base")));
        Ok(BaseStation {
            config,
            team,
            base_id,
            out,
        })
    }
}

/// What the base did (`summary.json`).
#[derive(Clone, Debug, Serialize)]
pub struct BaseSummary {
    /// The base's id on the link.
    pub base_id: u32,
    /// Wall seconds it ran.
    pub wall_s: f64,
    /// Per robot id.
    pub robots: BTreeMap<u32, BaseRobotSummary>,
    /// Keyframes in the merged map.
    pub merged_keyframes: usize,
    /// Points in `merged_map.ply`.
    pub merged_points: usize,
    /// The link's last counters (`rejected_messages`: frames that failed decoding or
    /// validation).
    pub link: Option<LinkStatus>,
    /// Frames and messages the link rejected (a sender outside the roster, bad
    /// bytes, another team, a sender that disagrees with the zenoh key; per reason in
    /// `link.rejections`), and other errors of its handler.
    pub rejected: u64,
    /// The zenoh session's counters.
    pub zenoh: ZenohStats,
    /// The recording `run.mcap`, when one was written.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub recording: Option<RecordingStats>,
    /// The team's artifacts as reported to the base (with `[robot.artifacts]`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub artifacts: Vec<Artifact>,
}

/// One robot as the base saw it.
#[derive(Clone, Debug, Serialize)]
pub struct BaseRobotSummary {
    /// Keyframes kept.
    pub keyframes: usize,
    /// Their occupied components.
    pub components: usize,
    /// Link frames received.
    pub frames: u64,
    /// Their bytes.
    pub bytes: u64,
    /// Odometry messages.
    pub odometry: u64,
    /// Committed plans.
    pub plans: u64,
    /// The robot's mission as it last reported it (absent if it never did).
    pub mission: Option<troupe_algorithms::exploration::MissionStatus>,
    /// Points in `maps/robot<i>.ply`.
    pub ply_points: usize,
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The base's one "robot": the link (its rejections counted), a listening artifact
/// actor when the team reports artifacts, and the operator's commander.
fn base_robot(
    station: &BaseStation,
    rejected: Arc<AtomicU64>,
    commands: std::sync::mpsc::Receiver<BaseCommand>,
) -> Result<RobotSpec, HarnessError> {
    let team = &station.team;
    let link = team
        .robot
        .link
        .clone()
        .with_team(team.robots)
        .with_roster_as_peers();
    // As a robot process, the link's journal is on disk (`out/state/link.journal`):
    // the keyframes it acknowledged (the robots released them) come back into the
    // maps after a crash, the operator's commands not yet acknowledged are resent,
    // and no message id is used twice.
    let journal = harness::open_journal(
        &link.journal_dir_in(&station.out),
        Some(BASE_JOURNAL_RECEIVED_BYTES),
    )?;
    let mut robot = RobotSpec::new("base").with(
        ActorSpec::new("link", move || {
            LinkActor::new(link.clone())?.journaled(journal.clone())
        })
        .wrap(move |inner| {
            Box::new(CountRejections {
                inner,
                rejected: rejected.clone(),
            })
        }),
    );
    let artifacts_config = team.robot.artifacts;
    if artifacts_config.enabled {
        robot.add(ActorSpec::new("artifacts", move || {
            ArtifactActor::listening(artifacts_config)
        }));
    }
    let commands = Arc::new(Mutex::new(commands));
    robot.add(ActorSpec::new("commander", move || Commander {
        commands: commands.clone(),
    }));
    Ok(robot)
}

/// Prints [`BaseMaps::status_lines`] every second, forever.
async fn print_status(maps: &Mutex<BaseMaps>, robots: u32) {
    let mut tick = tokio::time::interval(Duration::from_secs(1));
    tick.tick().await;
    loop {
        tick.tick().await;
        let lines = lock(maps).status_lines(robots, Instant::now());
        // A closed stdout must not stop the base: it still writes the maps.
        let mut stdout = std::io::stdout().lock();
        for line in lines {
            let _ = writeln!(stdout, "{line}");
        }
    }
}

/// Runs the base until its duration is over or `stop` resolves, printing the status
/// lines every second and sending the operator's `commands` to the robots, then
/// writes the outputs; must be called inside a multi-threaded tokio runtime.
pub async fn run(
    station: &BaseStation,
    stop: impl Future<Output = ()>,
    commands: std::sync::mpsc::Receiver<BaseCommand>,
) -> Result<BaseSummary, BaseError> {
    let team = &station.team;
    let rejected = Arc::new(AtomicU64::new(0));
    let robot = base_robot(station, rejected.clone(), commands)?;
    let member = Member {
        name: "base".into(),
        id: station.base_id,
        seed: team.seed ^ u64::from(station.base_id),
        team: team.robot.link.team,
        zenoh: &station.config.zenoh,
        subscription: SubscriptionConfig::default(),
        out: station.out.clone(),
    };
    let mut harness = Harness::open(member, robot)?;
    // The link's own counters come from its status, not the executor's report.
    let link = harness.latest(LINK_STATUS);
    let artifacts = harness.latest(ARTIFACT_LIST);
    let maps: Arc<Mutex<BaseMaps>> = Arc::default();
    let maps_tap = maps.clone();
    harness.add_tap(move |p: &Publication<'_>| lock(&maps_tap).observe(p, Instant::now()));
    if station.config.record {
        let options = RecordOptions {
            compression: station.config.record_compression,
            ..RecordOptions::default()
        };
        harness.record(options, Recorder::with_peer_poses)?;
    }
    let until = async {
        tokio::select! {
            () = stop => {}
            () = print_status(&maps, team.robots) => {}
        }
    };
    let finished = harness.run(station.config.duration_s, until).await?;
    let maps = std::mem::take(&mut *lock(&maps));
    let written = maps.write(&station.out, station.config.ply_points, team.seed)?;
    let link = link.take();
    let summary = BaseSummary {
        base_id: station.base_id,
        wall_s: finished.wall_s,
        robots: maps.summaries(&written),
        merged_keyframes: maps.robots.values().map(|r| r.map.keyframes.len()).sum(),
        merged_points: written.values().sum(),
        // The link counts (and logs, rate-limited) what it rejects itself; other
        // handler errors are counted here.
        rejected: rejected.load(Ordering::Relaxed)
            + link.as_ref().map_or(0, |l| l.rejections.total()),
        link,
        zenoh: finished.zenoh,
        recording: finished.recording,
        artifacts: artifacts.take().map(|a| a.artifacts).unwrap_or_default(),
    };
    harness::write_summary(&station.out, &summary)?;
    Ok(summary)
}

/// Runs the base on a new multi-threaded tokio runtime until its duration is over,
/// Ctrl-C or SIGTERM (`troupe base`), with the operator's commands read from standard
/// input ([`read_commands`]), then writes the outputs.
pub fn run_until_signal(station: &BaseStation) -> Result<BaseSummary, BaseError> {
    let (to, commands) = std::sync::mpsc::channel();
    // Detached: a blocking read of stdin cannot be cancelled; it ends with the
    // process or at the end of the input.
    std::thread::spawn(move || read_commands(std::io::stdin().lock(), std::io::stdout(), &to));
    harness::block_on(run(station, shutdown_signal(), commands))?
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The keys of a scenario file the base uses (`troupe_sims::scenario::load_team`
    /// reads the whole scenario; this crate cannot depend on it).
    #[derive(Deserialize)]
    struct TeamFile {
        name: String,
        seed: u64,
        robots: u32,
        robot: RobotConfig,
    }

    fn read_team(path: &Path) -> Result<TeamSettings, SettingsFileError> {
        let team: TeamFile = read_toml(path)?;
        team.robot
            .validate()
            .map_err(|e| SettingsFileError::config(path, e.within("robot")))?;
        Ok(TeamSettings {
            name: team.name,
            robots: team.robots,
            seed: team.seed,
            robot: team.robot,
        })
    }

    #[test]
    fn the_hardware_base_file_serves_the_example_hardware_team() {
        let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples");
        let base = BaseStation::load(&examples.join("hardware_base.toml"), read_team).unwrap();
        let robot = crate::hardware::HardwareRobot::load(&examples.join("hardware_robot.toml"))
            .unwrap()
            .file;
        assert_eq!(base.team.robots, robot.team_size);
        assert_eq!(base.team.robot.link.team, robot.robot.link.team);
        // The base's id is the one the robots accept: their team size.
        assert_eq!(base.base_id, robot.team_size);
        assert_eq!(base.config.zenoh.connect.len(), robot.team_size as usize);
    }
}
