//! The base station (`troupe base --config base.toml`, thesis §8.2.6: the robots'
//! maps go to a base station): a zenoh participant with its own robot id that flies
//! nothing. It runs one "robot" on the real-time executor holding only the
//! [`LinkActor`], so every frame the robots send is reassembled, decoded, validated
//! (team, sender) and deduplicated by the same code a robot uses, and store-and-forward
//! keyframes are acknowledged like a peer does (a robot adds the base to its
//! recipients when the first ack arrives and sends it its stored backlog). A [`Tap`](troupe_actors::runtime::Tap)
//! on the link's publications collects every robot's keyframes (`peer/keyframe`),
//! odometry and plans into [`BaseMaps`].
//!
//! A base file:
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
//! `robot1 hold`, `all hold`, `robot1 resume`, `robot1 velocity 0.5 0 0.1` — which
//! go to the robots as [`BaseCommand`]s on the shared topic [`BASE_COMMAND`]
//! (store-and-forward, highest priority; robots with `[robot.collision]
//! operator_commands = true` apply them, see docs/base-station.md).
//!
//! When the team runs the artifact reporter (`[robot.artifacts] enabled = true`), the
//! base runs a listening [`ArtifactActor`] too: it shares `artifacts/report`, so the
//! robots' store-and-forward reports reach it (and are acknowledged), and its
//! deduplicated list is `artifacts` in `summary.json`.

use std::collections::{BTreeMap, BTreeSet};
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};
use troupe_actors::artifacts::{ARTIFACT_LIST, Artifact, ArtifactActor, ArtifactList};
use troupe_actors::collision::{BASE_COMMAND, BaseCommand};
use troupe_actors::link::{LINK_STATUS, LinkActor, LinkJournal, LinkStatus};
use troupe_actors::mapper::MapModel;
use troupe_actors::mapper::mapfile::{
    GmmMap, MapFileError, MapKeyframe, SurfacePoint, write_atomically, write_ply,
    write_ply_with_source,
};
use troupe_actors::mapper::sogmm::SogmmError;
use troupe_actors::msgs::{PEER_KEYFRAME, PEER_ODOMETRY, PEER_PLAN, PeerKeyframe};
use troupe_actors::runtime::{
    Actor, ActorResult, ActorSpec, ConfigError, Context, ErrorChain, Event, LINK_RX, Publication,
    RealtimeExecutor, RobotId, RobotSpec, TimerId,
};
use troupe_comms::zenoh::{ZenohConfig, ZenohStats, ZenohTransport};
use troupe_robot::toml_file::{SettingsFileError, read_toml};

use troupe_record::{Clock, Compression, RecordOptions, Recorder, RecordingStats, SharedRecorder};

use crate::maps::merged_points;
use crate::recording::RUN_RECORDING;
use crate::scenario::{Scenario, ScenarioError};

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

/// A base file with its paths resolved and its scenario loaded.
#[derive(Clone, Debug)]
pub struct BaseStation {
    /// The file's settings.
    pub config: BaseConfig,
    /// The team's scenario.
    pub scenario: Scenario,
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
    Scenario(#[source] ScenarioError),
    /// The base could not be started.
    #[error("{context}")]
    Start {
        /// What was being started.
        context: &'static str,
        /// Why it failed.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
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
    /// Reads and checks a base file and its scenario.
    pub fn load(path: &Path) -> Result<Self, BaseError> {
        let mut config: BaseConfig = read_toml(path).map_err(SettingsFileError::from)?;
        let invalid = |e: ConfigError| BaseError::from(SettingsFileError::config(path, e));
        let dir = path.parent().unwrap_or(Path::new("."));
        let scenario = Scenario::load(&dir.join(&config.scenario)).map_err(BaseError::Scenario)?;
        let team_base_id = scenario.robot.link.base_id.unwrap_or(scenario.robots);
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
        if base_id < scenario.robots {
            return Err(invalid(ConfigError::new(
                "base_id",
                format!(
                    "must not be a robot's index (must be at least {})",
                    scenario.robots
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
            scenario,
            base_id,
            out,
        })
    }
}

/// What the base holds of one robot.
#[derive(Clone, Debug)]
pub struct RobotRecord {
    /// The robot's keyframes, in arrival order.
    pub map: GmmMap,
    /// (keyframe id, stamp ns) of every keyframe kept: a repeat is not kept twice.
    seen: BTreeSet<(u32, u64)>,
    /// Link frames received from it.
    pub frames: u64,
    /// Bytes of those frames.
    pub bytes: u64,
    /// Odometry messages received.
    pub odometry: u64,
    /// When the last odometry message arrived.
    pub last_odometry: Option<Instant>,
    /// Committed plans received.
    pub plans: u64,
    /// Speed of the last odometry, m/s.
    pub speed_mps: Option<f64>,
}

impl Default for RobotRecord {
    fn default() -> Self {
        RobotRecord {
            map: GmmMap {
                model: MapModel::Sogmm,
                keyframes: Vec::new(),
            },
            seen: BTreeSet::new(),
            frames: 0,
            bytes: 0,
            odometry: 0,
            last_odometry: None,
            plans: 0,
            speed_mps: None,
        }
    }
}

/// Every robot's keyframes, odometry and plans as the base received them, by robot id.
#[derive(Clone, Debug, Default)]
pub struct BaseMaps {
    /// Per robot id.
    pub robots: BTreeMap<u32, RobotRecord>,
}

impl BaseMaps {
    /// Keeps a robot's keyframe (already validated by the link); returns whether it
    /// was new.
    pub fn add_keyframe(&mut self, peer: &PeerKeyframe) -> bool {
        let k = &peer.keyframe;
        let record = self.robots.entry(peer.robot.0).or_default();
        if !record.seen.insert((k.id, k.stamp.as_nanos())) {
            return false;
        }
        record.map.keyframes.push(MapKeyframe {
            stamp_s: k.stamp.as_secs_f64(),
            pose: k.pose,
            support: u64::from(k.support_size),
            occupied: k.gmm.clone(),
            free: None,
            free_support: 0,
        });
        true
    }

    /// Records an observed publication of the base's link (the [`Tap`] body).
    ///
    /// [`Tap`]: troupe_actors::runtime::Tap
    pub fn observe(&mut self, p: &Publication<'_>, now: Instant) {
        if let Some(rx) = p.get(&LINK_RX) {
            let record = self.robots.entry(rx.from.0).or_default();
            record.frames += 1;
            record.bytes += rx.bytes.len() as u64;
        } else if let Some(k) = p.get(&PEER_KEYFRAME) {
            self.add_keyframe(k);
        } else if let Some(o) = p.get(&PEER_ODOMETRY) {
            let record = self.robots.entry(o.robot.0).or_default();
            record.odometry += 1;
            record.last_odometry = Some(now);
            record.speed_mps = Some(o.odometry.velocity_mps.norm());
        } else if let Some(plan) = p.get(&PEER_PLAN) {
            self.robots.entry(plan.robot.0).or_default().plans += 1;
        }
    }

    /// One status line per robot (every robot of `team` first, then any other sender
    /// heard), e.g. `robot0 keyframes=12 components=3456 bytes=812345
    /// odometry_age_s=0.08 plans=9 speed_mps=0.42` (`none` before the first odometry).
    #[must_use]
    pub fn status_lines(&self, team: u32, now: Instant) -> Vec<String> {
        let ids: BTreeSet<u32> = (0..team).chain(self.robots.keys().copied()).collect();
        let empty = RobotRecord::default();
        ids.into_iter()
            .map(|id| {
                let r = self.robots.get(&id).unwrap_or(&empty);
                let age = r.last_odometry.map_or("none".into(), |t| {
                    format!("{:.2}", now.saturating_duration_since(t).as_secs_f64())
                });
                let speed = r.speed_mps.map_or("none".into(), |v| format!("{v:.2}"));
                format!(
                    "robot{id} keyframes={} components={} bytes={} odometry_age_s={age} plans={} \
                     speed_mps={speed}",
                    r.map.keyframes.len(),
                    r.map.occupied_components(),
                    r.bytes,
                    r.plans
                )
            })
            .collect()
    }

    /// Every robot's keyframes in one map: its surface is the support-weighted merge of
    /// all of them (Eq. 3.5, [`GmmMap::merged_occupied`]).
    #[must_use]
    pub fn merged(&self) -> GmmMap {
        GmmMap {
            model: MapModel::Sogmm,
            keyframes: self
                .robots
                .values()
                .flat_map(|r| r.map.keyframes.iter().cloned())
                .collect(),
        }
    }

    /// Writes the maps into `dir` (see the module docs): `total_points` are drawn
    /// for `merged_map.ply` in proportion to each robot's support, and each robot's
    /// PLY holds its share. Robots without keyframes get no files. Returns the
    /// points written per robot.
    pub fn write(
        &self,
        dir: &Path,
        total_points: usize,
        seed: u64,
    ) -> Result<BTreeMap<u32, usize>, BaseError> {
        let write_error = |path: &Path| {
            let path = path.to_path_buf();
            move |source| BaseError::Write { path, source }
        };
        let map_error = |path: &Path| {
            let path = path.to_path_buf();
            move |source| BaseError::Map { path, source }
        };
        let maps_dir = dir.join("maps");
        std::fs::create_dir_all(&maps_dir).map_err(write_error(&maps_dir))?;
        let mapped: Vec<(u32, &GmmMap)> = self
            .robots
            .iter()
            .filter(|(_, r)| !r.map.keyframes.is_empty())
            .map(|(id, r)| (*id, &r.map))
            .collect();
        let maps: Vec<GmmMap> = mapped.iter().map(|(_, m)| (*m).clone()).collect();
        let (points, source) =
            merged_points(&maps, total_points, seed).map_err(BaseError::Sample)?;
        let mut written = BTreeMap::new();
        for (index, (id, map)) in mapped.iter().enumerate() {
            let path = maps_dir.join(format!("robot{id}.troupe"));
            map.save(&path).map_err(map_error(&path))?;
            let own: Vec<SurfacePoint> = points
                .iter()
                .zip(&source)
                .filter(|(_, s)| usize::from(**s) == index)
                .map(|(p, _)| *p)
                .collect();
            let path = maps_dir.join(format!("robot{id}.ply"));
            let mut ply = Vec::with_capacity(256 + 19 * own.len());
            write_ply(&mut ply, &own).map_err(write_error(&path))?;
            write_atomically(&path, &ply).map_err(map_error(&path))?;
            written.insert(*id, own.len());
        }
        let path = dir.join("merged_map.troupe");
        self.merged().save(&path).map_err(map_error(&path))?;
        // Tag each point with the robot's id (ids above 254 share the tag 255).
        let tags: Vec<u8> = source
            .iter()
            .map(|s| {
                mapped
                    .get(usize::from(*s))
                    .and_then(|(id, _)| u8::try_from(*id).ok())
                    .unwrap_or(u8::MAX)
            })
            .collect();
        let path = dir.join("merged_map.ply");
        let mut ply = Vec::with_capacity(256 + 20 * points.len());
        write_ply_with_source(&mut ply, &points, Some(&tags)).map_err(write_error(&path))?;
        write_atomically(&path, &ply).map_err(map_error(&path))?;
        Ok(written)
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
    /// Points in `maps/robot<i>.ply`.
    pub ply_points: usize,
}

/// The base's link: what its handler rejects (each a bad frame or message from the
/// network) is counted and logged at the 1st, 2nd, 4th, … rejection instead of once
/// per frame, so a flood of hostile bytes cannot flood the log.
struct CountRejections {
    inner: Box<dyn Actor>,
    rejected: Arc<AtomicU64>,
}

impl Actor for CountRejections {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        self.inner.start(ctx)
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        if let Err(e) = self.inner.handle(event, ctx) {
            let n = self.rejected.fetch_add(1, Ordering::Relaxed) + 1;
            if n.is_power_of_two() {
                tracing::warn!("base link: {n} rejected so far; latest: {}", ErrorChain(&e));
            }
        }
        Ok(())
    }

    fn stop(&mut self, ctx: &mut Context<'_>) {
        self.inner.stop(ctx);
    }
}

/// Shares [`BASE_COMMAND`] with the team and publishes the operator's commands on it
/// as they arrive from the standard-input reader ([`read_commands`]).
struct Commander {
    commands: Arc<Mutex<std::sync::mpsc::Receiver<BaseCommand>>>,
}

const POLL_COMMANDS: TimerId = TimerId(0);

impl Actor for Commander {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        BASE_COMMAND.share(ctx);
        ctx.set_timer(POLL_COMMANDS, Duration::from_millis(50));
        Ok(())
    }

    fn handle(&mut self, _event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        let commands: Vec<BaseCommand> = lock(&self.commands).try_iter().collect();
        for command in commands {
            ctx.publish(&BASE_COMMAND.topic(), command);
        }
        Ok(())
    }
}

/// Reads operator lines from `input` until it ends, answering each on `out`
/// (`command robot1 hold: sent (id …)`, or why the line is not a command) and
/// sending the commands to `to`. Ids start at the wall clock in microseconds and grow
/// by at least one per command, so a restarted base's commands are newer.
pub fn read_commands(
    input: impl std::io::BufRead,
    mut out: impl std::io::Write,
    to: &std::sync::mpsc::Sender<BaseCommand>,
) {
    let mut last_id = 0u64;
    for line in input.lines() {
        let Ok(line) = line else { return };
        let now_us = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_micros()).unwrap_or(u64::MAX));
        let id = now_us.max(last_id + 1);
        let answer = match BaseCommand::parse(&line, id) {
            Ok(None) => continue,
            Ok(Some(command)) => {
                last_id = id;
                if to.send(command).is_err() {
                    return;
                }
                format!("command {}: sent (id {id})", line.trim())
            }
            Err(e) => format!("command {}: not sent: {e}", line.trim()),
        };
        let _ = writeln!(out, "{answer}");
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Runs the base until its duration is over or `stop` resolves, printing the status
/// lines every second and sending the operator's `commands` to the robots, then
/// writes the outputs; must be called inside a multi-threaded tokio runtime.
pub async fn run(
    station: &BaseStation,
    stop: impl std::future::Future<Output = ()>,
    commands: std::sync::mpsc::Receiver<BaseCommand>,
) -> Result<BaseSummary, BaseError> {
    let scenario = &station.scenario;
    let id = station.base_id;
    let link = scenario
        .robot
        .link
        .clone()
        .with_team(scenario.robots)
        .with_roster_as_peers();
    // As a robot process, the link's journal is on disk (`out/state/link.journal`):
    // the keyframes it acknowledged (the robots released them) come back into the
    // maps after a crash, the operator's commands not yet acknowledged are resent,
    // and no message id is used twice; a new journal's ids start from the clock.
    let first_id = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as u32);
    let journal = LinkJournal::on_disk_keeping(
        &link.journal_dir_in(&station.out),
        first_id,
        BASE_JOURNAL_RECEIVED_BYTES,
    )
    .map_err(|e| BaseError::Start {
        context: "opening the link journal",
        source: Box::new(e),
    })?;
    let rejected = Arc::new(AtomicU64::new(0));
    let counter = rejected.clone();
    let mut robot = RobotSpec::new("base").with(
        ActorSpec::new("link", move || {
            LinkActor::new(link.clone())?.journaled(journal.clone())
        })
        .wrap(move |inner| {
            Box::new(CountRejections {
                inner,
                rejected: counter.clone(),
            })
        }),
    );
    let artifacts_config = scenario.robot.artifacts;
    if artifacts_config.enabled {
        robot.add(ActorSpec::new("artifacts", move || {
            ArtifactActor::listening(artifacts_config)
        }));
    }
    let commands = Arc::new(Mutex::new(commands));
    robot.add(ActorSpec::new("commander", move || Commander {
        commands: commands.clone(),
    }));
    let maps: Arc<Mutex<BaseMaps>> = Arc::default();
    let status: Arc<Mutex<Option<LinkStatus>>> = Arc::default();
    let artifacts: Arc<Mutex<ArtifactList>> = Arc::default();
    let mut executor = RealtimeExecutor::new(vec![robot], scenario.seed ^ u64::from(id))
        .with_robot_ids(vec![RobotId(id)])
        .map_err(|e| BaseError::Start {
            context: "the base's robot id",
            source: Box::new(e),
        })?;
    let (maps_tap, status_tap, artifacts_tap) = (maps.clone(), status.clone(), artifacts.clone());
    executor.add_tap(move |p: &Publication<'_>| {
        if let Some(s) = p.get(&LINK_STATUS) {
            *lock(&status_tap) = Some(s.clone());
        } else if let Some(list) = p.get(&ARTIFACT_LIST) {
            *lock(&artifacts_tap) = list.clone();
        } else {
            lock(&maps_tap).observe(p, Instant::now());
        }
    });
    let recorder = if station.config.record {
        let path = station.out.join(RUN_RECORDING);
        let recorder = std::fs::create_dir_all(&station.out)
            .map_err(|source| BaseError::Write {
                path: station.out.clone(),
                source,
            })
            .and_then(|()| {
                let options = RecordOptions {
                    compression: station.config.record_compression,
                    ..RecordOptions::default()
                };
                Recorder::create_with(&path, Clock::wall_from_now(), options).map_err(|e| {
                    BaseError::Start {
                        context: "creating the recording",
                        source: Box::new(e),
                    }
                })
            })?;
        let recorder = SharedRecorder::new(recorder.with_peer_poses());
        executor.add_tap(recorder.clone());
        Some(recorder)
    } else {
        None
    };
    let transport = Arc::new(
        ZenohTransport::open(&station.config.zenoh, scenario.robot.link.team, vec![id]).map_err(
            |e| BaseError::Start {
                context: "opening zenoh",
                source: Box::new(e),
            },
        )?,
    );
    let started = Instant::now();
    let handle = executor
        .spawn_with_transport(transport.clone())
        .map_err(|e| BaseError::Start {
            context: "starting the transport",
            source: Box::new(e),
        })?;
    tracing::info!(base = id, "running");
    let print_status = async {
        let mut tick = tokio::time::interval(Duration::from_secs(1));
        tick.tick().await;
        loop {
            tick.tick().await;
            let lines = lock(&maps).status_lines(scenario.robots, Instant::now());
            // A closed stdout must not stop the base: it still writes the maps.
            let mut stdout = std::io::stdout().lock();
            for line in lines {
                let _ = writeln!(stdout, "{line}");
            }
        }
    };
    let until = troupe_robot::hardware::run_for(station.config.duration_s, stop);
    tokio::select! {
        () = until => {}
        () = print_status => {}
    }
    // The link's own counters come from its status (the tap), not the report.
    let _reports = handle.shutdown().await;
    let zenoh = transport.stats();
    if let Err(e) = transport.close() {
        tracing::warn!(base = id, "closing zenoh: {e}");
    }
    let recording = match recorder.as_ref().and_then(SharedRecorder::finish) {
        Some(Ok(stats)) => Some(stats),
        Some(Err(e)) => {
            tracing::warn!(base = id, "recording: {}", ErrorChain(&e));
            None
        }
        None => None,
    };
    let maps = std::mem::take(&mut *lock(&maps));
    let written = maps.write(&station.out, station.config.ply_points, scenario.seed)?;
    let link = lock(&status).clone();
    let summary = BaseSummary {
        base_id: id,
        wall_s: started.elapsed().as_secs_f64(),
        robots: maps
            .robots
            .iter()
            .map(|(robot, r)| {
                let summary = BaseRobotSummary {
                    keyframes: r.map.keyframes.len(),
                    components: r.map.occupied_components(),
                    frames: r.frames,
                    bytes: r.bytes,
                    odometry: r.odometry,
                    plans: r.plans,
                    ply_points: written.get(robot).copied().unwrap_or(0),
                };
                (*robot, summary)
            })
            .collect(),
        merged_keyframes: maps.robots.values().map(|r| r.map.keyframes.len()).sum(),
        merged_points: written.values().sum(),
        // The link counts (and logs, rate-limited) what it rejects itself; other
        // handler errors are counted here.
        rejected: rejected.load(Ordering::Relaxed)
            + link.as_ref().map_or(0, |l| l.rejections.total()),
        link,
        zenoh,
        recording,
        artifacts: lock(&artifacts).artifacts.clone(),
    };
    let path = station.out.join("summary.json");
    let mut json = serde_json::to_string_pretty(&summary).map_err(|e| BaseError::Write {
        path: path.clone(),
        source: e.into(),
    })?;
    json.push('\n');
    std::fs::write(&path, json).map_err(|source| BaseError::Write { path, source })?;
    Ok(summary)
}

/// Runs the base on a new multi-threaded tokio runtime until its duration is over,
/// Ctrl-C or SIGTERM (`troupe base`), with the operator's commands read from standard
/// input ([`read_commands`]), then writes the outputs.
pub fn run_until_signal(station: &BaseStation) -> Result<BaseSummary, BaseError> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| BaseError::Start {
            context: "starting the tokio runtime",
            source: Box::new(e),
        })?;
    let (to, commands) = std::sync::mpsc::channel();
    // Detached: a blocking read of stdin cannot be cancelled; it ends with the
    // process or at the end of the input.
    std::thread::spawn(move || read_commands(std::io::stdin().lock(), std::io::stdout(), &to));
    runtime.block_on(run(station, crate::process::shutdown_signal(), commands))
}

#[cfg(test)]
mod tests {
    use super::*;
    use troupe_actors::collision::OperatorCommand;

    #[test]
    fn reads_operator_lines_into_commands_with_growing_ids() {
        let input = "robot1 hold\n\nrobot1 fly\nall resume\nrobot0 vel 0.5 0 0.1\n";
        let (to, from) = std::sync::mpsc::channel();
        let mut out = Vec::new();
        read_commands(input.as_bytes(), &mut out, &to);
        let sent: Vec<BaseCommand> = from.try_iter().collect();
        let targets: Vec<_> = sent.iter().map(|c| (c.robot, c.command)).collect();
        assert_eq!(
            targets,
            [
                (Some(1), OperatorCommand::Hold),
                (None, OperatorCommand::Resume),
                (
                    Some(0),
                    OperatorCommand::Velocity {
                        vx_mps: 0.5,
                        vz_mps: 0.0,
                        yaw_rate_rad_s: 0.1
                    }
                ),
            ]
        );
        assert!(sent.windows(2).all(|w| w[0].id < w[1].id));
        let out = String::from_utf8(out).unwrap();
        let lines: Vec<&str> = out.lines().collect();
        assert_eq!(lines.len(), 4, "{out}");
        assert!(lines[0].starts_with("command robot1 hold: sent (id "));
        assert!(
            lines[1].starts_with("command robot1 fly: not sent: `fly` is not a command"),
            "{out}"
        );
    }
}
