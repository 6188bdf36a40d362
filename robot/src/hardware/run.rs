//! Starting a hardware robot (every check before the vehicle starts), running it on
//! the real-time executor with the team link over zenoh, and its outputs.

use std::collections::BTreeMap;
use std::future::Future;
use std::path::Path;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use serde::Serialize;
use troupe_actors::collision::{COLLISION_STATUS, CollisionStatus};
use troupe_actors::link::{LINK_STATUS, LinkJournal, LinkStatus};
use troupe_actors::msgs::{DEPTH_FRAME, KEYFRAME, ODOMETRY, PLAN, PinholeIntrinsics};
use troupe_actors::runtime::{
    ActorSpec, Publication, RealtimeExecutor, RobotId, RobotSpec, Time, TopicStats,
};
use troupe_actors::sensor::FrameSource;
use troupe_comms::zenoh::{ZenohStats, ZenohTransport};
use troupe_record::{Clock, RecordOptions, Recorder, RecordingStats, SharedRecorder, period_of_hz};

use super::file::{HardwareError, HardwareRobot};
use crate::mavlink::{AUTOPILOT_STATUS, AutopilotStatus, OdometrySource, mavlink_vehicle};
use crate::ros2::{InputStats, OutputStats, Ros2Inputs, Ros2Outputs, Ros2Publisher, open_session};
use crate::toml_file::SettingsFileError;
use crate::{RobotParts, assemble};

/// How often the camera's first frame is looked for at start.
const CALIBRATION_POLL: Duration = Duration::from_millis(20);

/// What a hardware robot did (`summary.json`).
#[derive(Clone, Debug, Serialize)]
pub struct HardwareSummary {
    /// Robot id.
    pub robot: u32,
    /// Wall seconds it ran.
    pub wall_s: f64,
    /// Depth frames the sensor published.
    pub frames: u64,
    /// Keyframes the mapper published.
    pub keyframes: u64,
    /// Plans committed.
    pub plans: u64,
    /// What the MAVLink vehicle did, from its last status.
    pub vehicle: Option<VehicleSummary>,
    /// The collision actor's last counters (rounds, stops, rejections by reason —
    /// `rejected_geofence` for candidates leaving the fence — and operator holds).
    pub collision: Option<CollisionStatus>,
    /// The team link's last counters.
    pub link: Option<LinkStatus>,
    /// The team link's zenoh counters.
    pub zenoh: ZenohStats,
    /// Packets the executor could not hand to the team link.
    pub transport_errors: u64,
    /// The ROS 2 inputs' counters (received, rejected by reason, frames).
    pub ros2_inputs: InputStats,
    /// The ROS 2 outputs' counters.
    pub ros2_outputs: OutputStats,
    /// Messages and bytes per topic.
    pub topics: BTreeMap<String, TopicStats>,
    /// Per actor: events handled, errors, panics.
    pub actors: Vec<ActorHealth>,
    /// The recording `run.mcap`, when one was written.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub recording: Option<RecordingStats>,
}

/// The MAVLink vehicle's counters at the end of a run.
#[derive(Clone, Debug, Serialize)]
pub struct VehicleSummary {
    /// Setpoints sent (tracking and holding).
    pub setpoints: u64,
    /// Setpoints that held instead of tracking the plan.
    pub holds: u64,
    /// Holds because the plan's reference was outside the geofence.
    pub fence_holds: u64,
    /// Committed plans that left the geofence (none should: the collision actor
    /// checks the same fence before committing).
    pub plans_leaving_fence: u64,
    /// Setpoint ticks with nothing sent (no autopilot heartbeat).
    pub silent: u64,
    /// Whether the autopilot said it was armed.
    pub armed: bool,
    /// Its flight mode.
    pub mode: String,
    /// Messages written to the autopilot (setpoints and heartbeats).
    pub mavlink_sent: u64,
    /// Bytes from the autopilot that did not decode.
    pub mavlink_decode_errors: u64,
}

impl From<&AutopilotStatus> for VehicleSummary {
    fn from(s: &AutopilotStatus) -> Self {
        VehicleSummary {
            setpoints: s.guard.tracked + s.guard.held,
            holds: s.guard.held,
            fence_holds: s.guard.fence_holds,
            plans_leaving_fence: s.guard.plans_leaving_fence,
            silent: s.guard.silent,
            armed: s.armed,
            mode: s.mode.clone(),
            mavlink_sent: s.link.sent,
            mavlink_decode_errors: s.link.decode_errors,
        }
    }
}

/// One actor's health.
#[derive(Clone, Debug, Serialize)]
pub struct ActorHealth {
    /// Name.
    pub name: String,
    /// Events handled.
    pub handled: u64,
    /// Hooks that returned an error.
    pub errors: u64,
    /// Panics.
    pub panics: u64,
}

/// What the taps collect during a run.
#[derive(Default)]
struct Collected {
    /// `(unix_time_s, event)` for every depth frame and committed plan.
    events: Vec<(f64, &'static str)>,
    vehicle: Option<VehicleSummary>,
    collision: Option<CollisionStatus>,
    link: Option<LinkStatus>,
}

/// A robot that passed every startup check; nothing has been sent to the vehicle.
struct Started {
    spec: RobotSpec,
    transport: Arc<ZenohTransport>,
    inputs: Ros2Inputs,
    publisher: Ros2Publisher,
    // Kept open for the run: the ROS inputs and outputs live on it.
    _ros_session: zenoh::Session,
}

fn unix_now_s() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

/// The camera's intrinsics: the file's `[camera]`, or those of the first depth frame.
fn camera_intrinsics(
    robot: &HardwareRobot,
    inputs: &Ros2Inputs,
) -> Result<PinholeIntrinsics, HardwareError> {
    if let Some(camera) = robot.file.camera {
        return Ok(camera);
    }
    let timeout_s = robot.file.ros2.startup_timeout_s;
    let start = Instant::now();
    let mut source = inputs.frame_source();
    loop {
        // The error is the trait's; the ROS source never returns one.
        if let Ok(Some(frame)) = source.capture(Time::ZERO, None) {
            return Ok(frame.intrinsics);
        }
        if start.elapsed().as_secs_f64() >= timeout_s {
            return Err(HardwareError::NoCalibration { timeout_s });
        }
        std::thread::sleep(CALIBRATION_POLL);
    }
}

/// Every startup step that can fail, in order: the ROS 2 session and topics, the
/// camera's intrinsics, the robot's actors, the team link. The vehicle's MAVLink
/// connection opens only when the executor starts it, after all of these.
fn start(robot: &HardwareRobot) -> Result<Started, HardwareError> {
    let file = &robot.file;
    let ros_session = open_session(&file.ros2)?;
    let inputs = Ros2Inputs::subscribe(&ros_session, &file.ros2)?;
    tracing::info!(robot = file.id, "waiting for the ROS 2 topics");
    inputs.wait_for_topics()?;
    let camera = camera_intrinsics(robot, &inputs)?;
    let publisher = Ros2Publisher::open(&ros_session, &file.ros2)?;
    let vehicle = mavlink_vehicle(&file.mavlink)
        .map_err(|e| SettingsFileError::config(&robot.path, e.within("mavlink")))?;
    // The link's journal outlives the process (docs/link-durability.md); a new
    // one starts its message ids somewhere new, as a simulated robot process does,
    // so peers do not drop them as repeats.
    let first_id = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as u32);
    let journal_dir = file.robot.link.journal_dir_in(&robot.out);
    let link_journal = LinkJournal::on_disk(&journal_dir, first_id)
        .map_err(|source| HardwareError::Journal { source })?;
    let source_inputs = inputs.clone();
    let parts = RobotParts {
        frame_source: Box::new(move || Box::new(source_inputs.frame_source())),
        vehicle,
        route: Vec::new(),
        depart_at_s: 0.0,
        camera,
        link_journal,
    };
    let mut config = file.robot.clone();
    config.link = config.link.with_team(file.team_size).with_roster_as_peers();
    let mut spec = assemble(&format!("robot{}", file.id), &config, parts)?;
    if file.mavlink.odometry_source == OdometrySource::External {
        let odometry = inputs.clone();
        spec.add(ActorSpec::new("ros2_odometry", move || {
            odometry.odometry_actor()
        }));
    }
    let (out_publisher, out_inputs) = (publisher.clone(), inputs.clone());
    spec.add(ActorSpec::new("ros2_outputs", move || {
        Ros2Outputs::new(out_publisher.clone(), Some(out_inputs.clone()))
    }));
    let transport = ZenohTransport::open(&file.zenoh, file.robot.link.team, vec![file.id])
        .map_err(HardwareError::Session)?
        .with_subscription(file.robot.link.subscribe);
    Ok(Started {
        spec,
        transport: Arc::new(transport),
        inputs,
        publisher,
        _ros_session: ros_session,
    })
}

/// Starts the robot (every check first; see the [module docs](crate::hardware)), runs
/// it until its duration is over or `stop` resolves, then writes `summary.json` and
/// `events.csv` (`unix_time_s,event`: every `frame` the sensor published and every
/// `plan` committed) into its `out` directory.
pub fn run(
    robot: &HardwareRobot,
    stop: impl Future<Output = ()>,
) -> Result<HardwareSummary, HardwareError> {
    let started = start(robot)?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(HardwareError::Runtime)?;
    let (summary, events) = runtime.block_on(fly(robot, started, stop))?;
    write_outputs(&robot.out, &summary, &events)?;
    Ok(summary)
}

/// [`run`] until SIGINT or SIGTERM (or the file's duration).
pub fn run_until_signal(robot: &HardwareRobot) -> Result<HardwareSummary, HardwareError> {
    run(robot, shutdown_signal())
}

async fn fly(
    robot: &HardwareRobot,
    started: Started,
    stop: impl Future<Output = ()>,
) -> Result<(HardwareSummary, Vec<(f64, &'static str)>), HardwareError> {
    let id = robot.file.id;
    let collected: Arc<Mutex<Collected>> = Arc::default();
    let tap = collected.clone();
    let mut executor = RealtimeExecutor::new(vec![started.spec], u64::from(id))
        .with_robot_ids(vec![RobotId(id)])?;
    let transport = started.transport.clone();
    executor.add_tap(move |p: &Publication<'_>| {
        if let Some(o) = p.get(&ODOMETRY) {
            // Where the robot is picks its keyframes' cell and, under a
            // neighbourhood scope, the cells it hears (troupe_comms::scope).
            let v = o.pose.translation.vector;
            transport.set_position(id, [v.x, v.y, v.z]);
            return;
        }
        let mut c = tap.lock().unwrap_or_else(PoisonError::into_inner);
        if p.get(&DEPTH_FRAME).is_some() {
            c.events.push((unix_now_s(), "frame"));
        } else if p.get(&PLAN).is_some() {
            c.events.push((unix_now_s(), "plan"));
        } else if let Some(status) = p.get(&AUTOPILOT_STATUS) {
            c.vehicle = Some(status.into());
        } else if let Some(status) = p.get(&LINK_STATUS) {
            c.link = Some(status.clone());
        } else if let Some(status) = p.get(&COLLISION_STATUS) {
            c.collision = Some(status.clone());
        }
    });
    let recorder = if robot.file.record {
        std::fs::create_dir_all(&robot.out).map_err(|source| HardwareError::Output {
            path: robot.out.clone(),
            source,
        })?;
        let path = robot.out.join("run.mcap");
        let options = RecordOptions {
            depth_period_s: period_of_hz(robot.file.record_depth_hz),
            compression: robot.file.record_compression,
            ..RecordOptions::default()
        };
        let recorder = Recorder::create_with(&path, Clock::wall_from_now(), options)
            .map_err(HardwareError::Recording)?;
        let recorder = SharedRecorder::new(recorder);
        executor.add_tap(recorder.clone());
        Some(recorder)
    } else {
        None
    };
    let started_at = Instant::now();
    let handle = executor
        .spawn_with_transport(started.transport.clone())
        .map_err(HardwareError::Transport)?;
    tracing::info!(robot = id, "running");
    run_for(robot.file.duration_s, stop).await;
    let transport_errors = handle.transport_errors();
    let reports = handle.shutdown().await;
    let zenoh = started.transport.stats();
    if let Err(e) = started.transport.close() {
        tracing::warn!(robot = id, "closing zenoh: {e}");
    }
    let report = reports.into_iter().next().ok_or(HardwareError::NoReport)?;
    let recording = finish_recording(recorder.as_ref(), &format!("robot{id}"));
    let collected = std::mem::take(&mut *collected.lock().unwrap_or_else(PoisonError::into_inner));
    let count = |name: &str| report.topics.get(name).map_or(0, |t| t.messages);
    let summary = HardwareSummary {
        robot: id,
        wall_s: started_at.elapsed().as_secs_f64(),
        frames: count(DEPTH_FRAME.name()),
        keyframes: count(KEYFRAME.name()),
        plans: count(PLAN.name()),
        vehicle: collected.vehicle,
        collision: collected.collision,
        link: collected.link,
        zenoh,
        transport_errors,
        ros2_inputs: started.inputs.stats(),
        ros2_outputs: started.publisher.stats(),
        topics: report.topics.clone(),
        actors: report
            .actors
            .iter()
            .map(|a| ActorHealth {
                name: a.name.clone(),
                handled: a.stats.handled,
                errors: a.stats.errors,
                panics: a.stats.panics,
            })
            .collect(),
        recording,
    };
    Ok((summary, collected.events))
}

fn write_outputs(
    dir: &Path,
    summary: &HardwareSummary,
    events: &[(f64, &'static str)],
) -> Result<(), HardwareError> {
    use std::fmt::Write as _;
    let err = |path: &Path| {
        let path = path.to_path_buf();
        move |source| HardwareError::Output { path, source }
    };
    std::fs::create_dir_all(dir).map_err(err(dir))?;
    let mut json =
        serde_json::to_string_pretty(summary).map_err(|e| err(dir)(std::io::Error::other(e)))?;
    json.push('\n');
    let path = dir.join("summary.json");
    std::fs::write(&path, json).map_err(err(&path))?;
    let mut csv = String::from("unix_time_s,event\n");
    for (t, event) in events {
        let _ = writeln!(csv, "{t:.6},{event}");
    }
    let path = dir.join("events.csv");
    std::fs::write(&path, csv).map_err(err(&path))
}

/// Finishes a process's `run.mcap` (`None`: recording was off); a failed recording
/// is logged as a warning naming `who` and gives `None`, since the run itself succeeded.
pub fn finish_recording(recorder: Option<&SharedRecorder>, who: &str) -> Option<RecordingStats> {
    match recorder?.finish()? {
        Ok(stats) => Some(stats),
        Err(e) => {
            tracing::warn!(
                "{who}: recording: {}",
                troupe_actors::runtime::ErrorChain(&e)
            );
            None
        }
    }
}

/// Resolves after `duration_s` seconds (never, when `None`) or when `stop` resolves,
/// whichever comes first: how long a robot or base process runs.
pub async fn run_for(duration_s: Option<f64>, stop: impl std::future::Future<Output = ()>) {
    match duration_s {
        Some(d) => {
            tokio::select! {
                () = tokio::time::sleep(Duration::from_secs_f64(d)) => {}
                () = stop => {}
            }
        }
        None => stop.await,
    }
}

/// Resolves on SIGINT (Ctrl-C) or SIGTERM.
pub async fn shutdown_signal() {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{SignalKind, signal};
        if let Ok(mut term) = signal(SignalKind::terminate()) {
            tokio::select! {
                _ = tokio::signal::ctrl_c() => {}
                _ = term.recv() => {}
            }
            return;
        }
    }
    let _ = tokio::signal::ctrl_c().await;
}
