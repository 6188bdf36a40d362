//! The recorder: a [`Tap`] that turns every robot's publications into a recording's
//! channels. Channel names (per robot `i`):
//!
//! | channel | schema | from |
//! |---|---|---|
//! | `/tf` | `foxglove.FrameTransform` | `world → robot<i>` at each odometry, `robot<i> → robot<i>/camera` once |
//! | `/robot<i>/pose` | `foxglove.PoseInFrame` | odometry (body pose in `world`) |
//! | `/robot<i>/plan` | `foxglove.SceneUpdate` | committed plans (line strip, replaced) |
//! | `/robot<i>/candidates` | `foxglove.SceneUpdate` | each planning round's candidates, coloured by the collision actor's verdict, reasons in the metadata |
//! | `/robot<i>/keyframes` | `foxglove.SceneUpdate` | own keyframes as 2σ ellipsoids |
//! | `/robot<i>/keyframe_points` | `foxglove.PointCloud` | points drawn from each own keyframe's mixture, `intensity` as it predicts |
//! | `/robot<i>/peer_keyframes` | `foxglove.SceneUpdate` | keyframes received from peers (entity `robot<j>/kf<id>`, peer's colour, when received) |
//! | `/robot<i>/peer_keyframe_points` | `foxglove.PointCloud` | points drawn from each received keyframe's mixture |
//! | `/robot<i>/grid` | `foxglove.PointCloud` | the local grid's occupied cells (centres, `intensity` = occupancy probability), at most once per [`RecordOptions::grid_period_s`] |
//! | `/robot<i>/frontiers` | `foxglove.PointCloud` | the local grid's frontier cells, with each `/robot<i>/grid` message |
//! | `/robot<i>/remembered_frontiers` | `foxglove.PointCloud` | the team frontier memory's frontier cells (planner, guidance on), at most once per [`RecordOptions::grid_period_s`] |
//! | `/robot<i>/route` | `foxglove.SceneUpdate` | with each `remembered_frontiers` message: the route the guidance field leads along, to the frontier it leads to (line strip, replaced; empty when none) |
//! | `/robot<i>/depth` | `foxglove.RawImage` | depth frames (`32FC1`, metres), only with [`RecordOptions::depth_period_s`], at most once per it |
//! | `/robot<i>/peer_plans` | `foxglove.SceneUpdate` | peers' committed plans as received (entity `robot<j>/plan`) |
//! | `/robot<i>/link` | `troupe.LinkStatus` | link counters per class (bytes, queue delay, drops) |
//! | `/robot<i>/peers/robot<j>/pose` | `foxglove.PoseInFrame` | peer odometry as received (only [`Recorder::with_peer_poses`], e.g. the base station) |
//! | `/world` | `foxglove.SceneUpdate` | a triangle mesh of the world's surface, once ([`Recorder::write_world`], simulated runs) |

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard};

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use serde::Serialize;
use troupe_actors::link::LINK_STATUS;
use troupe_actors::msgs::{
    DEPTH_FRAME, GRID_SNAPSHOT, KEYFRAME, ODOMETRY, PEER_KEYFRAME, PEER_ODOMETRY, PEER_PLAN, PLAN,
    PLAN_CANDIDATES, PLAN_DECISION,
};
use troupe_actors::planner::{MISSION_STATUS, REMEMBERED_FRONTIERS, RememberedFrontiers};
use troupe_algorithms::frame::{DepthFrame, Odometry};
use troupe_algorithms::keyframe::Keyframe;
use troupe_algorithms::plan::Plan;
use troupe_algorithms::planner::candidates::{PlanCandidates, PlanDecision};
use troupe_algorithms::team::{PeerKeyframe, PeerPlan};
use troupe_core::ConfigError;
use troupe_core::Time;
use troupe_runtime::{Publication, Tap};

use crate::foxglove::{
    Color, FrameTransform, KeyValuePair, PointCloud, PoseInFrame, RawImage, SceneEntity,
    SceneUpdate, Timestamp,
};
use crate::scene::{
    frontier_cloud, keyframe_cloud, keyframe_entity, mesh_entity, occupied_cloud, path_line,
    robot_color, trajectory_line,
};
use crate::schemas::{self, Schema};
use crate::writer::{Compression, RecordError, Recording};

/// What the recording's times count from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Clock {
    /// Sim time: a run's `Time` as is (nanoseconds from the start of the run).
    Sim,
    /// Wall time: the executor's `Time` (from its start) plus the Unix time of the
    /// start, nanoseconds.
    Wall {
        /// Unix time of the executor's start, nanoseconds.
        unix_start_ns: u64,
    },
}

impl Clock {
    /// Wall time from now (call just before the executor starts).
    #[must_use]
    pub fn wall_from_now() -> Self {
        let unix_start_ns = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX));
        Clock::Wall { unix_start_ns }
    }

    /// The recording time of `time`, nanoseconds.
    #[must_use]
    pub fn nanos(self, time: Time) -> u64 {
        match self {
            Clock::Sim => time.as_nanos(),
            Clock::Wall { unix_start_ns } => unix_start_ns.saturating_add(time.as_nanos()),
        }
    }
}

/// The camera's optical frame in the body frame: the body looks along +x, the
/// optical frame along +z with x right and y down.
fn camera_in_body() -> Isometry3<f64> {
    let rotation =
        UnitQuaternion::from_basis_unchecked(&[-Vector3::y(), -Vector3::z(), Vector3::x()]);
    Isometry3::from_parts(Translation3::identity(), rotation)
}

/// Colour of a candidate the collision actor chose.
const CHOSEN: Color = Color::rgba(0.1, 0.8, 0.2, 1.0);
/// Colour of a candidate rejected for clearance.
const REJECTED_CLEARANCE: Color = Color::rgba(0.9, 0.1, 0.1, 0.8);
/// Colour of a candidate rejected because of a peer.
const REJECTED_PEER: Color = Color::rgba(1.0, 0.6, 0.0, 0.8);
/// Colour of a candidate ranked below the chosen one (never checked).
const UNCHECKED: Color = Color::rgba(0.6, 0.6, 0.6, 0.4);

/// What a recorder writes of the bulky topics, how often, and how it compresses the
/// file. With the defaults the default scenario's recording is about 4.5 MB per
/// robot-minute, under the 20 MB budget (`docs/recordings.md`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RecordOptions {
    /// Least time between two recorded grids (occupied cells and frontiers) of a
    /// robot, and between two of its remembered-frontier sets, seconds; `None`
    /// records none.
    pub grid_period_s: Option<f64>,
    /// Points drawn from each keyframe's mixture, own or received (0: no clouds).
    pub keyframe_points: usize,
    /// Least time between two recorded depth frames of a robot, seconds; `None`
    /// records none (a 160 × 120 frame is about 100 kB in the file).
    pub depth_period_s: Option<f64>,
    /// How the file's chunks are compressed.
    pub compression: Compression,
}

impl Default for RecordOptions {
    fn default() -> Self {
        RecordOptions {
            grid_period_s: Some(1.0),
            keyframe_points: 500,
            depth_period_s: None,
            compression: Compression::default(),
        }
    }
}

/// Most messages per second a `record_*_hz` key may ask for.
pub const MAX_RECORD_HZ: f64 = 30.0;

/// The least time between two recorded messages of a rate in hertz (0: `None`,
/// nothing recorded).
#[must_use]
pub fn period_of_hz(hz: f64) -> Option<f64> {
    (hz > 0.0).then(|| 1.0 / hz)
}

/// Checks a `record_*_hz` key: between 0 and [`MAX_RECORD_HZ`].
pub fn check_rate_hz(key: &str, hz: f64) -> Result<(), ConfigError> {
    if hz.is_finite() && (0.0..=MAX_RECORD_HZ).contains(&hz) {
        Ok(())
    } else {
        Err(ConfigError::new(
            key,
            format!("must be between 0 and {MAX_RECORD_HZ} Hz"),
            hz,
        ))
    }
}

/// Whether a period is set and at least that long passed since `last` (then `last`
/// becomes `now`).
fn due(last: &mut Option<Time>, now: Time, period_s: Option<f64>) -> bool {
    let Some(period_s) = period_s else {
        return false;
    };
    let ready = last.is_none_or(|t| (now.as_secs_f64() - t.as_secs_f64()) >= period_s - 1e-9);
    if ready {
        *last = Some(now);
    }
    ready
}

#[derive(Default)]
struct RobotState {
    camera_written: bool,
    /// The latest round's candidates, until its decision arrives.
    candidates: Option<PlanCandidates>,
    /// When the last grid, remembered frontiers and depth frame were recorded.
    last_grid: Option<Time>,
    last_memory: Option<Time>,
    last_depth: Option<Time>,
}

/// Messages written and bytes, at the end of a recording.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct RecordingStats {
    /// The file.
    pub path: PathBuf,
    /// Its size, bytes.
    pub bytes: u64,
    /// Messages per channel.
    pub messages: BTreeMap<String, u64>,
    /// Publications that could not be recorded (after the first write error the
    /// recorder stops writing and counts what it would have written).
    pub failed: u64,
}

/// Writes a recording from publications (see the module doc for its channels).
pub struct Recorder {
    recording: Recording,
    clock: Clock,
    robots: BTreeMap<u32, RobotState>,
    messages: BTreeMap<String, u64>,
    failed: u64,
    error: Option<RecordError>,
    peer_poses: bool,
    options: RecordOptions,
}

impl Recorder {
    /// Creates the recording at `path` with the default options.
    pub fn create(path: &Path, clock: Clock) -> Result<Self, RecordError> {
        Self::create_with(path, clock, RecordOptions::default())
    }

    /// Creates the recording at `path`, writing the bulky topics and compressing as
    /// `options` say.
    pub fn create_with(
        path: &Path,
        clock: Clock,
        options: RecordOptions,
    ) -> Result<Self, RecordError> {
        Ok(Recorder {
            recording: Recording::create(path, options.compression)?,
            clock,
            robots: BTreeMap::new(),
            messages: BTreeMap::new(),
            failed: 0,
            error: None,
            peer_poses: false,
            options,
        })
    }

    /// Writes the world's surface (`vertices`, three indices per triangle) on `/world`
    /// at time zero, in grey: the rock the 3D view shows around the robots.
    pub fn write_world(&mut self, vertices: &[nalgebra::Point3<f64>], triangles: &[[u32; 3]]) {
        let color = Color::rgba(0.55, 0.5, 0.45, 0.35);
        let entity = mesh_entity("world", vertices, triangles, color, self.stamp(Time::ZERO));
        self.write_scene("/world", Time::ZERO, entity);
    }

    /// Also records peers' odometry as received (`/robot<i>/peers/robot<j>/pose`):
    /// for a base station, whose own body does not move; a team's robots would write
    /// every pose once per receiver.
    #[must_use]
    pub fn with_peer_poses(mut self) -> Self {
        self.peer_poses = true;
        self
    }

    /// The recording's clock.
    #[must_use]
    pub fn clock(&self) -> Clock {
        self.clock
    }

    /// Writes one message (for channels the caller adds, e.g. a simulator's samples).
    /// After a failed write nothing more is written: the failure is counted and the
    /// first error returned by [`Recorder::finish`].
    pub fn write<T: Serialize>(&mut self, topic: &str, schema: &Schema, time: Time, message: &T) {
        if self.error.is_some() {
            self.failed += 1;
            return;
        }
        match self
            .recording
            .write(topic, schema, self.clock.nanos(time), message)
        {
            Ok(()) => *self.messages.entry(topic.to_string()).or_default() += 1,
            Err(e) => {
                tracing::warn!(error = %troupe_core::ErrorChain(&e), "recording stopped");
                self.failed += 1;
                self.error = Some(e);
            }
        }
    }

    /// Attaches a file of the run (JSON, TOML) to the recording.
    pub fn attach(&mut self, name: &str, media_type: &str, time: Time, data: &[u8]) {
        if self.error.is_none()
            && let Err(e) = self
                .recording
                .attach(name, media_type, self.clock.nanos(time), data)
        {
            self.failed += 1;
            self.error = Some(e);
        }
    }

    /// Records one publication, if its topic is one the recorder knows.
    pub fn observe(&mut self, p: &Publication<'_>) {
        let i = p.robot.0;
        if let Some(odometry) = p.get(&ODOMETRY) {
            self.record_odometry(i, p.time, odometry);
        } else if let Some(plan) = p.get(&PLAN) {
            self.record_plan(i, p.time, plan);
        } else if let Some(candidates) = p.get(&PLAN_CANDIDATES) {
            self.robots.entry(i).or_default().candidates = Some(candidates.clone());
        } else if let Some(decision) = p.get(&PLAN_DECISION) {
            let candidates = self.robots.entry(i).or_default().candidates.take();
            if let Some(candidates) = candidates.filter(|c| c.round == decision.round) {
                let entity = self.candidates_entity(i, &candidates, decision);
                self.write_scene(&format!("/robot{i}/candidates"), p.time, entity);
            }
        } else if let Some(keyframe) = p.get(&KEYFRAME) {
            self.record_keyframe(i, p.time, keyframe);
        } else if let Some(peer) = p.get(&PEER_KEYFRAME) {
            self.record_peer_keyframe(i, p.time, peer);
        } else if let Some(peer) = p.get(&PEER_PLAN) {
            self.record_peer_plan(i, p.time, peer);
        } else if let Some(peer) = p.get(&PEER_ODOMETRY) {
            if self.peer_poses {
                let pose = PoseInFrame {
                    timestamp: self.stamp(p.time),
                    frame_id: "world".into(),
                    pose: (&peer.odometry.pose).into(),
                };
                let topic = format!("/robot{i}/peers/robot{}/pose", peer.robot.0);
                self.write(&topic, &schemas::POSE_IN_FRAME, p.time, &pose);
            }
        } else if let Some(snapshot) = p.get(&GRID_SNAPSHOT) {
            if self.due(i, p.time, self.options.grid_period_s, |r| &mut r.last_grid) {
                let stamp = self.stamp(snapshot.stamp);
                let occupied = occupied_cloud(snapshot, stamp);
                self.write_cloud(&format!("/robot{i}/grid"), p.time, &occupied);
                let frontiers = frontier_cloud(snapshot, stamp);
                self.write_cloud(&format!("/robot{i}/frontiers"), p.time, &frontiers);
            }
        } else if let Some(memory) = p.get(&REMEMBERED_FRONTIERS) {
            if self.due(i, p.time, self.options.grid_period_s, |r| {
                &mut r.last_memory
            }) {
                self.record_memory(i, p.time, memory);
            }
        } else if let Some(frame) = p.get(&DEPTH_FRAME) {
            if self.due(i, p.time, self.options.depth_period_s, |r| {
                &mut r.last_depth
            }) {
                self.record_depth(i, p.time, frame);
            }
        } else if let Some(status) = p.get(&LINK_STATUS) {
            let topic = format!("/robot{i}/link");
            self.write(&topic, &schemas::LINK_STATUS, p.time, status);
        } else if let Some(status) = p.get(&MISSION_STATUS.topic()) {
            let topic = format!("/robot{i}/mission");
            self.write(&topic, &schemas::MISSION_STATUS, p.time, status);
        }
    }

    /// Whether robot `i`'s stream kept in `last` is [`due`] at `now` for `period_s`
    /// (and if so, marks it written now).
    fn due(
        &mut self,
        i: u32,
        now: Time,
        period_s: Option<f64>,
        last: fn(&mut RobotState) -> &mut Option<Time>,
    ) -> bool {
        due(last(self.robots.entry(i).or_default()), now, period_s)
    }

    /// `/tf` (the camera's mount once, then the body in the world) and `/robot<i>/pose`.
    fn record_odometry(&mut self, i: u32, time: Time, odometry: &Odometry) {
        let stamp = self.stamp(odometry.stamp);
        let body = format!("robot{i}");
        let state = self.robots.entry(i).or_default();
        if !std::mem::replace(&mut state.camera_written, true) {
            let camera = camera_in_body();
            let mount = FrameTransform {
                timestamp: stamp,
                parent_frame_id: body.clone(),
                child_frame_id: format!("{body}/camera"),
                translation: camera.translation.vector.into(),
                rotation: camera.rotation.into(),
            };
            self.write("/tf", &schemas::FRAME_TRANSFORM, time, &mount);
        }
        let pose = &odometry.pose;
        let transform = FrameTransform {
            timestamp: stamp,
            parent_frame_id: "world".into(),
            child_frame_id: body,
            translation: pose.translation.vector.into(),
            rotation: pose.rotation.into(),
        };
        self.write("/tf", &schemas::FRAME_TRANSFORM, time, &transform);
        let pose = PoseInFrame {
            timestamp: stamp,
            frame_id: "world".into(),
            pose: pose.into(),
        };
        self.write(
            &format!("/robot{i}/pose"),
            &schemas::POSE_IN_FRAME,
            time,
            &pose,
        );
    }

    fn record_plan(&mut self, i: u32, time: Time, plan: &Plan) {
        let mut entity =
            SceneEntity::new(self.stamp(plan.stamp), "world", format!("robot{i}/plan"));
        entity
            .lines
            .push(trajectory_line(&plan.trajectory, robot_color(i, 1.0)));
        entity.metadata = vec![
            KeyValuePair::new("robot", i),
            KeyValuePair::new("stopping", plan.stopping),
            KeyValuePair::new("knots", plan.trajectory.knots().len()),
        ];
        self.write_scene(&format!("/robot{i}/plan"), time, entity);
    }

    fn record_keyframe(&mut self, i: u32, time: Time, keyframe: &Keyframe) {
        let entity = keyframe_entity(
            i,
            keyframe,
            Time::from_nanos(self.clock.nanos(keyframe.stamp)),
        );
        let stamp = entity.timestamp;
        self.write_scene(&format!("/robot{i}/keyframes"), time, entity);
        if self.options.keyframe_points > 0 {
            let cloud = keyframe_cloud(i, keyframe, self.options.keyframe_points, stamp);
            self.write_cloud(&format!("/robot{i}/keyframe_points"), time, &cloud);
        }
    }

    fn record_peer_keyframe(&mut self, i: u32, time: Time, peer: &PeerKeyframe) {
        // A peer's stamps count from its own start (in processes): what was
        // received is stamped when it arrived.
        let mut entity = keyframe_entity(
            peer.robot.0,
            &peer.keyframe,
            Time::from_nanos(self.clock.nanos(time)),
        );
        entity.metadata.push(KeyValuePair::new("received_by", i));
        entity.metadata.push(KeyValuePair::new(
            "received_at_s",
            peer.received_at.as_secs_f64(),
        ));
        let stamp = entity.timestamp;
        self.write_scene(&format!("/robot{i}/peer_keyframes"), time, entity);
        if self.options.keyframe_points > 0 {
            let n = self.options.keyframe_points;
            let cloud = keyframe_cloud(peer.robot.0, &peer.keyframe, n, stamp);
            self.write_cloud(&format!("/robot{i}/peer_keyframe_points"), time, &cloud);
        }
    }

    fn record_peer_plan(&mut self, i: u32, time: Time, peer: &PeerPlan) {
        let j = peer.robot.0;
        let mut entity = SceneEntity::new(self.stamp(time), "world", format!("robot{j}/plan"));
        entity
            .lines
            .push(trajectory_line(&peer.plan.trajectory, robot_color(j, 0.6)));
        entity.metadata = vec![
            KeyValuePair::new("robot", j),
            KeyValuePair::new("received_by", i),
            KeyValuePair::new("received_at_s", peer.received_at.as_secs_f64()),
            KeyValuePair::new("priority", peer.priority),
        ];
        self.write_scene(&format!("/robot{i}/peer_plans"), time, entity);
    }

    /// The remembered frontiers as a cloud and the route to the current goal.
    fn record_memory(&mut self, i: u32, time: Time, memory: &RememberedFrontiers) {
        let stamp = self.stamp(memory.stamp);
        let cloud = PointCloud::xyzi(
            stamp,
            "world",
            memory.centres_m.iter().map(|c| (*c, memory.cell_m)),
        );
        self.write_cloud(&format!("/robot{i}/remembered_frontiers"), time, &cloud);
        let mut entity = SceneEntity::new(stamp, "world", format!("robot{i}/route"));
        entity.metadata = vec![
            KeyValuePair::new("robot", i),
            KeyValuePair::new("cells", memory.route_m.len()),
        ];
        if let Some(goal) = memory.route_m.last() {
            entity.metadata.push(KeyValuePair::new(
                "goal",
                format!("{:.1} {:.1} {:.1}", goal.x, goal.y, goal.z),
            ));
        }
        entity.lines.push(path_line(
            memory.route_m.iter().copied(),
            robot_color(i, 0.5),
        ));
        self.write_scene(&format!("/robot{i}/route"), time, entity);
    }

    /// The depth image, if its size matches its intrinsics (else counted as failed).
    fn record_depth(&mut self, i: u32, time: Time, frame: &DepthFrame) {
        let k = &frame.intrinsics;
        if frame.depth_m.len() != k.width as usize * k.height as usize {
            self.failed += 1;
            return;
        }
        let image = RawImage::float32(
            self.stamp(frame.stamp),
            &format!("robot{i}/camera"),
            k.width,
            k.height,
            &frame.depth_m,
        );
        self.write(
            &format!("/robot{i}/depth"),
            &schemas::RAW_IMAGE,
            time,
            &image,
        );
    }

    fn stamp(&self, time: Time) -> Timestamp {
        Timestamp::from_nanos(self.clock.nanos(time))
    }

    fn write_cloud(&mut self, topic: &str, time: Time, cloud: &PointCloud) {
        self.write(topic, &schemas::POINT_CLOUD, time, cloud);
    }

    fn write_scene(&mut self, topic: &str, time: Time, entity: SceneEntity) {
        let update = SceneUpdate {
            deletions: Vec::new(),
            entities: vec![entity],
        };
        self.write(topic, &schemas::SCENE_UPDATE, time, &update);
    }

    /// One planning round: every candidate's line in the colour of its verdict, the
    /// stopping trajectory when nothing was chosen, the reasons in the metadata.
    fn candidates_entity(
        &self,
        i: u32,
        round: &PlanCandidates,
        decision: &PlanDecision,
    ) -> SceneEntity {
        let mut entity = SceneEntity::new(
            self.stamp(round.stamp),
            "world",
            format!("robot{i}/candidates"),
        );
        entity
            .metadata
            .push(KeyValuePair::new("round", round.round));
        let chosen = match decision.chosen {
            Some(k) => k.to_string(),
            None if decision.stale => "stale: the committed flight kept".to_string(),
            None => "stop".to_string(),
        };
        entity.metadata.push(KeyValuePair::new("chosen", chosen));
        for (k, candidate) in round.candidates.iter().enumerate() {
            let rejection = decision
                .rejected
                .iter()
                .find(|(r, _)| *r == k)
                .map(|(_, why)| *why);
            let (color, verdict) = match (rejection, decision.chosen) {
                (Some(why), _) if why.is_peer() => (REJECTED_PEER, format!("rejected: {why}")),
                (Some(why), _) => (REJECTED_CLEARANCE, format!("rejected: {why}")),
                (None, Some(c)) if c == k => (CHOSEN, "chosen".to_string()),
                _ => (UNCHECKED, "not checked".to_string()),
            };
            entity
                .lines
                .push(trajectory_line(&candidate.trajectory, color));
            entity.metadata.push(KeyValuePair::new(
                &format!("candidate {k}"),
                format!("{verdict}, reward {:.3}", candidate.reward),
            ));
        }
        if decision.chosen.is_none() && !decision.stale {
            entity.lines.push(trajectory_line(&round.stop, CHOSEN));
        }
        entity
    }

    /// Writes the summary and index and closes the file; fails with the first write
    /// error if any write failed.
    pub fn finish(self) -> Result<RecordingStats, RecordError> {
        if let Some(e) = self.error {
            return Err(e);
        }
        let path = self.recording.finish()?;
        let bytes = std::fs::metadata(&path).map_or(0, |m| m.len());
        Ok(RecordingStats {
            path,
            bytes,
            messages: self.messages,
            failed: self.failed,
        })
    }
}

/// A recorder shared between the executor's tap and its owner, who finishes it
/// after the run.
#[derive(Clone)]
pub struct SharedRecorder(Arc<Mutex<Option<Recorder>>>);

impl SharedRecorder {
    /// Shares `recorder`.
    #[must_use]
    pub fn new(recorder: Recorder) -> Self {
        SharedRecorder(Arc::new(Mutex::new(Some(recorder))))
    }

    fn lock(&self) -> MutexGuard<'_, Option<Recorder>> {
        self.0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Runs `f` on the recorder unless it was finished.
    pub fn with<R>(&self, f: impl FnOnce(&mut Recorder) -> R) -> Option<R> {
        self.lock().as_mut().map(f)
    }

    /// Finishes the recording (`None` when it was already finished).
    pub fn finish(&self) -> Option<Result<RecordingStats, RecordError>> {
        self.lock().take().map(Recorder::finish)
    }
}

impl Tap for SharedRecorder {
    fn on_publish(&mut self, p: &Publication<'_>) {
        self.with(|r| r.observe(p));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_period_lets_through_at_most_one_message_per_period() {
        let mut last = None;
        let at = |s: f64| Time::from_secs_f64(s);
        let passed: Vec<f64> = [0.0, 0.4, 0.99, 1.0, 1.5, 2.2, 2.9, 3.2]
            .into_iter()
            .filter(|&t| due(&mut last, at(t), Some(1.0)))
            .collect();
        assert_eq!(passed, [0.0, 1.0, 2.2, 3.2]);
        let mut never = None;
        assert!(!due(&mut never, at(5.0), None));
        assert_eq!(never, None);
    }

    #[test]
    fn rates_become_periods_and_out_of_range_rates_name_their_key() {
        assert_eq!(period_of_hz(0.0), None);
        assert_eq!(period_of_hz(4.0), Some(0.25));
        assert!(check_rate_hz("record_depth_hz", 0.0).is_ok());
        assert!(check_rate_hz("record_depth_hz", MAX_RECORD_HZ).is_ok());
        for bad in [-1.0, 31.0, f64::NAN, f64::INFINITY] {
            let e = check_rate_hz("record_depth_hz", bad).unwrap_err();
            assert_eq!(e.key, "record_depth_hz");
        }
    }

    /// Every compression writes chunks that name it, and the messages read back.
    #[test]
    fn each_compression_names_its_chunks_and_reads_back() {
        let dir = tempfile::tempdir().unwrap();
        for (compression, name) in [
            (Compression::Zstd, "zstd"),
            (Compression::Lz4, "lz4"),
            (Compression::None, ""),
        ] {
            let path = dir.path().join(format!("{compression:?}.mcap"));
            let options = RecordOptions {
                compression,
                ..RecordOptions::default()
            };
            let mut recorder = Recorder::create_with(&path, Clock::Sim, options).unwrap();
            for k in 0..200_u32 {
                let sample =
                    serde_json::json!({ "time_s": k, "fraction": 0.5, "explored_m3": 1.0 });
                recorder.write(
                    "/c",
                    &schemas::COVERAGE,
                    Time::from_secs_f64(f64::from(k)),
                    &sample,
                );
            }
            let stats = recorder.finish().unwrap();
            assert_eq!(stats.messages["/c"], 200);
            let bytes = std::fs::read(&path).unwrap();
            let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
            assert!(!summary.chunk_indexes.is_empty());
            for chunk in &summary.chunk_indexes {
                assert_eq!(chunk.compression, name, "{compression:?}");
            }
            let read: Vec<serde_json::Value> = mcap::MessageStream::new(&bytes)
                .unwrap()
                .map(|m| serde_json::from_slice(&m.unwrap().data).unwrap())
                .collect();
            assert_eq!(read.len(), 200);
            assert_eq!(read[199]["time_s"], 199);
        }
    }

    #[test]
    fn compression_keys_parse_from_their_names() {
        #[derive(serde::Deserialize)]
        struct Key {
            c: Compression,
        }
        let parse = |text: &str| serde_json::from_str::<Key>(text).map(|k| k.c);
        assert_eq!(parse(r#"{"c":"zstd"}"#).unwrap(), Compression::Zstd);
        assert_eq!(parse(r#"{"c":"lz4"}"#).unwrap(), Compression::Lz4);
        assert_eq!(parse(r#"{"c":"none"}"#).unwrap(), Compression::None);
        assert!(parse(r#"{"c":"gzip"}"#).is_err());
    }
}
