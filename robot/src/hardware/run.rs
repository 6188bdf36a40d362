//! Starting a hardware robot (every check before the vehicle starts), running it on
//! the real-time executor with the team link over zenoh, and its outputs.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::future::Future;
use std::path::Path;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use serde::Serialize;
use troupe_actors::collision::{COLLISION_STATUS, CollisionStatus};
use troupe_actors::link::{LINK_STATUS, LinkStatus};
use troupe_actors::msgs::{DEPTH_FRAME, KEYFRAME, PLAN};
use troupe_actors::planner::PLANNING_REPORT;
use troupe_actors::sensor::FrameSource;
use troupe_algorithms::camera::PinholeIntrinsics;
use troupe_algorithms::exploration::MissionStatus;
use troupe_comms::zenoh::ZenohStats;
use troupe_core::Time;
use troupe_record::{RecordOptions, RecordingStats, period_of_hz, schemas};
use troupe_runtime::{ActorSpec, Publication, TopicStats};

use super::file::{HardwareError, HardwareRobot};
use crate::harness::{
    self, ActorHealth, Harness, HarnessError, Member, shutdown_signal, unix_now_s,
};
use crate::mavlink::{AUTOPILOT_STATUS, AutopilotStatus, GaveUp, OdometrySource};
use crate::registry::{HardwareEnvironment, MAVLINK, Placement, Registry};
use crate::ros2::{InputStats, OutputStats, Ros2Inputs, Ros2Outputs, Ros2Publisher, open_session};
use crate::toml_file::SettingsFileError;

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
    /// The robot's mission after its planner's last round (phase, when exploring ended
    /// and why, the return; absent without a planner).
    pub mission: Option<MissionStatus>,
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
    /// Whether the pilot had handed control over (armed, OFFBOARD or GUIDED).
    pub in_control: bool,
    /// Why the vehicle gave up waiting for the autopilot, if it did.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gave_up: Option<String>,
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
            in_control: s.in_control,
            gave_up: s.gave_up.as_ref().map(ToString::to_string),
            mavlink_sent: s.link.sent,
            mavlink_decode_errors: s.link.decode_errors,
        }
    }
}

/// A robot that passed every startup check; nothing has been sent to the vehicle.
struct Started {
    harness: Harness,
    inputs: Ros2Inputs,
    publisher: Ros2Publisher,
    // Kept open for the run: the ROS inputs and outputs live on it.
    _ros_session: zenoh::Session,
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

/// Every startup step that can fail, in order: the part names, the ROS 2 session and
/// topics, the camera's intrinsics, the robot's actors (its parts from `registry`),
/// the team link. The vehicle's MAVLink connection opens only when the executor
/// starts it, after all of these.
fn start(robot: &HardwareRobot, registry: &Registry) -> Result<Started, HardwareError> {
    let file = &robot.file;
    let invalid = |e: crate::ConfigError| SettingsFileError::config(&robot.path, e);
    registry
        .check(&file.robot)
        .map_err(|e| invalid(e.within("robot")))?;
    let ros_session = open_session(&file.ros2)?;
    let inputs = Ros2Inputs::subscribe(&ros_session, &file.ros2)?;
    tracing::info!(robot = file.id, "waiting for the ROS 2 topics");
    inputs.wait_for_topics()?;
    let camera = camera_intrinsics(robot, &inputs)?;
    let publisher = Ros2Publisher::open(&ros_session, &file.ros2)?;
    if registry.choices(&file.robot).1.kind == MAVLINK {
        file.mavlink
            .validate()
            .map_err(|e| invalid(e.within("mavlink")))?;
    }
    // The link's journal outlives the process (docs/link-durability.md).
    let link_journal = harness::open_journal(&file.robot.link.journal_dir_in(&robot.out), None)?;
    let environment = HardwareEnvironment {
        inputs: inputs.clone(),
        camera,
        mavlink: file.mavlink.clone(),
    };
    let mut config = file.robot.clone();
    config.link = config.link.with_team(file.team_size).with_roster_as_peers();
    let name = format!("robot{}", file.id);
    let mut spec = registry.assemble(
        &config,
        Placement {
            name: &name,
            index: file.id as usize,
            environment: &environment,
            route: Vec::new(),
            depart_at_s: 0.0,
            link_journal,
        },
    )?;
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
    let member = Member {
        name: format!("robot{}", file.id),
        id: file.id,
        seed: u64::from(file.id),
        team: file.robot.link.team,
        zenoh: &file.zenoh,
        subscription: file.robot.link.subscribe,
        out: robot.out.clone(),
    };
    Ok(Started {
        harness: Harness::open(member, spec)?,
        inputs,
        publisher,
        _ros_session: ros_session,
    })
}

/// Starts the robot (every check first; see the [module docs](crate::hardware)), runs
/// it until its duration is over, `stop` resolves or the vehicle gives up waiting for
/// the autopilot, then writes `summary.json` and `events.csv` (`unix_time_s,event`:
/// every `frame` the sensor published and every `plan` committed) into its `out`
/// directory. A vehicle that gave up is an error ([`HardwareError::Vehicle`]), after
/// the outputs are written.
pub fn run(
    robot: &HardwareRobot,
    stop: impl Future<Output = ()>,
) -> Result<HardwareSummary, HardwareError> {
    run_with(robot, &Registry::hardware(), stop)
}

/// [`run`] with the robot's parts from `registry` (a user's drivers and actors beside
/// troupe's: [`Registry::hardware`] extended).
pub fn run_with(
    robot: &HardwareRobot,
    registry: &Registry,
    stop: impl Future<Output = ()>,
) -> Result<HardwareSummary, HardwareError> {
    let started = start(robot, registry)?;
    let (summary, events, gave_up) = harness::block_on(fly(robot, started, stop))??;
    harness::write_summary(&robot.out, &summary)?;
    write_events(&robot.out, &events)?;
    match gave_up {
        Some(source) => Err(HardwareError::Vehicle {
            source,
            setpoints: summary.vehicle.as_ref().map_or(0, |v| v.setpoints),
        }),
        None => Ok(summary),
    }
}

/// [`run`] until SIGINT or SIGTERM (or the file's duration).
pub fn run_until_signal(robot: &HardwareRobot) -> Result<HardwareSummary, HardwareError> {
    run(robot, shutdown_signal())
}

/// The run between the startup checks and the outputs: the harness's taps, its
/// recording, the flight, and the summary from what the taps saw.
async fn fly(
    robot: &HardwareRobot,
    started: Started,
    stop: impl Future<Output = ()>,
) -> Result<(HardwareSummary, Vec<(f64, &'static str)>, Option<GaveUp>), HardwareError> {
    let Started {
        mut harness,
        inputs,
        publisher,
        _ros_session,
    } = started;
    let events: Arc<Mutex<Vec<(f64, &'static str)>>> = Arc::default();
    let tap = events.clone();
    harness.add_tap(move |p: &Publication<'_>| {
        let event = if p.get(&DEPTH_FRAME).is_some() {
            "frame"
        } else if p.get(&PLAN).is_some() {
            "plan"
        } else {
            return;
        };
        tap.lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push((unix_now_s(), event));
    });
    let vehicle = harness.latest(AUTOPILOT_STATUS);
    // The vehicle gave up waiting for the autopilot: the run ends.
    let gave_up = Arc::new(tokio::sync::Notify::new());
    let notify = gave_up.clone();
    harness.add_tap(move |p: &Publication<'_>| {
        if p.get(&AUTOPILOT_STATUS)
            .is_some_and(|s| s.gave_up.is_some())
        {
            notify.notify_one();
        }
    });
    let stop = async move {
        tokio::select! {
            () = stop => {}
            () = gave_up.notified() => {}
        }
    };
    let link = harness.latest(LINK_STATUS);
    let collision = harness.latest(COLLISION_STATUS);
    let planning = harness.latest(PLANNING_REPORT);
    if robot.file.record {
        let options = RecordOptions {
            depth_period_s: period_of_hz(robot.file.record_depth_hz),
            compression: robot.file.record_compression,
            ..RecordOptions::default()
        };
        harness.record(options, |recorder| recorder)?;
        if let Some(recorder) = harness.recorder() {
            let channel = format!("/robot{}/vehicle", robot.file.id);
            harness.add_tap(move |p: &Publication<'_>| {
                if let Some(status) = p.get(&AUTOPILOT_STATUS) {
                    recorder.with(|r| {
                        r.write(&channel, &schemas::VEHICLE_STATUS, p.time, &status.state());
                    });
                }
            });
        }
    }
    let finished = harness.run(robot.file.duration_s, stop).await?;
    let vehicle = vehicle.take();
    let gave_up = vehicle.as_ref().and_then(|s| s.gave_up.clone());
    let summary = HardwareSummary {
        robot: robot.file.id,
        wall_s: finished.wall_s,
        frames: finished.messages(DEPTH_FRAME.name()),
        keyframes: finished.messages(KEYFRAME.name()),
        plans: finished.messages(PLAN.name()),
        vehicle: vehicle.as_ref().map(VehicleSummary::from),
        collision: collision.take(),
        mission: planning.take().map(|report| report.mission),
        link: link.take(),
        zenoh: finished.zenoh.clone(),
        transport_errors: finished.transport_errors,
        ros2_inputs: inputs.stats(),
        ros2_outputs: publisher.stats(),
        topics: finished.report.topics.clone(),
        actors: finished.actors(),
        recording: finished.recording,
    };
    let events = std::mem::take(&mut *events.lock().unwrap_or_else(PoisonError::into_inner));
    Ok((summary, events, gave_up))
}

/// Writes `events.csv` (`unix_time_s,event`) into `dir`.
fn write_events(dir: &Path, events: &[(f64, &'static str)]) -> Result<(), HarnessError> {
    let mut csv = String::from("unix_time_s,event\n");
    for (t, event) in events {
        let _ = writeln!(csv, "{t:.6},{event}");
    }
    let path = dir.join("events.csv");
    std::fs::write(&path, csv).map_err(|source| HarnessError::Output { path, source })
}
