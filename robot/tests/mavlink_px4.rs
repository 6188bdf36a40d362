//! The MAVLink vehicle against a PX4-like autopilot played by pymavlink
//! (`scripts/mavlink/px4_like_autopilot.py`), over loopback UDP.
//!
//! The vehicle runs on the real-time executor in a small robot: a mission actor
//! commits a plan, a camera actor publishes depth frames (and stops for a while when
//! the scenario says so). The autopilot flies a point mass from the setpoints it
//! receives and reports everything. Needs the venv that `.ci/run` installs
//! (`.venv-pymavlink/`, or `TROUPE_PYMAVLINK_PYTHON`); skips, saying why, without it.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use nalgebra::{Isometry3, Point3, Vector3};
use serde_json::Value;
use troupe_actors::msgs::{DEPTH_FRAME, ODOMETRY, PLAN, VEHICLE_HOLD};
use troupe_algorithms::camera::PinholeIntrinsics;
use troupe_algorithms::frame::{DepthFrame, Odometry};
use troupe_algorithms::plan::Plan;
use troupe_algorithms::trajectory::{Knot, Trajectory};
use troupe_core::Time;
use troupe_robot::frames::{enu_to_ned, yaw_enu_to_ned};
use troupe_robot::mavlink::{
    AUTOPILOT_STATUS, AutopilotStatus, GeofenceConfig, MavlinkConfig, mavlink_vehicle,
};
use troupe_robot::safety::{Geofence, HoldReason};
use troupe_runtime::{
    Actor, ActorResult, ActorSpec, Context, Event, QueuePolicy, RealtimeExecutor, RobotSpec,
    TimerId,
};
use troupe_testkit as kit;

fn unix_now_s() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .expect("clock after 1970")
        .as_secs_f64()
}

fn t(s: f64) -> Time {
    Time::from_secs_f64(s)
}

fn knot(at_s: f64, x: f64, y: f64, z: f64, yaw_rad: f64) -> Knot {
    Knot {
        time: t(at_s),
        position_m: Point3::new(x, y, z),
        yaw_rad,
    }
}

/// Commits one plan at start and again every second (as a planner would). While the
/// vehicle holds (`vehicle/hold`) it commits hovering where it holds, and afterwards
/// the plan's velocity from there (as the collision actor and the planner do).
struct Mission {
    plan: Trajectory,
    hold: Option<(Point3<f64>, f64)>,
    /// Where and when the last hold ended.
    resumed: Option<(Point3<f64>, Time)>,
}

const REPUBLISH: TimerId = TimerId(0);

impl Mission {
    fn new(plan: Trajectory) -> Self {
        Mission {
            plan,
            hold: None,
            resumed: None,
        }
    }
}

impl Actor for Mission {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&VEHICLE_HOLD, QueuePolicy::LATEST);
        ctx.set_timer(REPUBLISH, Duration::from_secs(1));
        self.publish(ctx);
        Ok(())
    }
    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        if let Event::Message(m) = event {
            let Some(hold) = m.get(&VEHICLE_HOLD) else {
                return Ok(());
            };
            match (self.hold, hold.at) {
                (None, Some(_)) => {}
                (Some((at, _)), None) => self.resumed = Some((at, ctx.now())),
                _ => return Ok(()),
            }
            self.hold = hold.at;
        }
        self.publish(ctx);
        Ok(())
    }
}

impl Mission {
    fn publish(&self, ctx: &mut Context<'_>) {
        let stamp = ctx.now();
        let plan = match (self.hold, self.resumed) {
            (Some((at, yaw_rad)), _) => Trajectory::new(vec![Knot {
                time: stamp,
                position_m: at,
                yaw_rad,
            }])
            .expect("a knot"),
            // The plan's velocity from where the vehicle held, from when it resumed.
            (None, Some((at, from))) => {
                let (Some(a), Some(b)) = (
                    self.plan.state_at(from),
                    self.plan.state_at(from + Duration::from_secs(10)),
                ) else {
                    return;
                };
                let shift = at - a.position_m;
                Trajectory::new(vec![
                    Knot {
                        time: from,
                        position_m: at,
                        yaw_rad: a.yaw_rad,
                    },
                    Knot {
                        time: from + Duration::from_secs(10),
                        position_m: b.position_m + shift,
                        yaw_rad: b.yaw_rad,
                    },
                ])
                .expect("two knots")
            }
            (None, None) => self.plan.clone(),
        };
        ctx.publish(&PLAN, Plan::new(stamp, plan));
    }
}

/// Publishes small depth frames at 10 Hz, except in `[off_from_s, off_until_s)`.
struct Camera {
    off_from_s: f64,
    off_until_s: f64,
}

const FRAME_TICK: TimerId = TimerId(0);

impl Actor for Camera {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.set_timer(FRAME_TICK, Duration::from_millis(100));
        Ok(())
    }
    fn handle(&mut self, _: &Event, ctx: &mut Context<'_>) -> ActorResult {
        let now_s = ctx.now().as_secs_f64();
        if (self.off_from_s..self.off_until_s).contains(&now_s) {
            return Ok(());
        }
        ctx.publish(
            &DEPTH_FRAME,
            DepthFrame {
                stamp: ctx.now(),
                pose: Isometry3::identity(),
                intrinsics: PinholeIntrinsics {
                    width: 2,
                    height: 2,
                    fx: 1.0,
                    fy: 1.0,
                    cx: 1.0,
                    cy: 1.0,
                    max_depth_m: 5.0,
                },
                depth_m: vec![1.0; 4],
                intensity: vec![0.5; 4],
            },
        );
        Ok(())
    }
}

struct Scenario {
    plan: Trajectory,
    fence: GeofenceConfig,
    /// Depth frames stop in this window (seconds of run time).
    frames_off_s: (f64, f64),
    /// The autopilot stops its heartbeats this long after it is ready.
    heartbeat_stop_after_s: Option<f64>,
    heartbeat_timeout_s: f64,
    sensor_timeout_s: f64,
    run_s: f64,
}

/// What a run produced: the autopilot's report, the run's start (Unix seconds), and
/// what the robot published.
struct Outcome {
    report: Value,
    epoch_s: f64,
    odometry: Vec<Odometry>,
    status: Vec<AutopilotStatus>,
}

impl Outcome {
    fn setpoints(&self) -> &[Value] {
        self.report["setpoints"].as_array().expect("setpoints")
    }
    /// A setpoint's time in seconds of run time.
    fn run_time(&self, sp: &Value) -> f64 {
        num(&sp["t"]) - self.epoch_s
    }
}

fn num(v: &Value) -> f64 {
    v.as_f64().expect("a number")
}

fn position_ned(sp: &Value) -> Vector3<f64> {
    Vector3::new(num(&sp["x"]), num(&sp["y"]), num(&sp["z"]))
}

fn velocity_ned(sp: &Value) -> Vector3<f64> {
    Vector3::new(num(&sp["vx"]), num(&sp["vy"]), num(&sp["vz"]))
}

fn wait_ready(child: &mut Child) -> f64 {
    let stdout = child.stdout.take().expect("piped stdout");
    let mut line = String::new();
    BufReader::new(stdout)
        .read_line(&mut line)
        .expect("autopilot prints a ready line");
    line.trim()
        .strip_prefix("ready ")
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("unexpected first line from the autopilot: {line:?}"))
}

/// Runs a scenario, or returns `None` (after saying why) without pymavlink.
async fn run(name: &str, scenario: Scenario) -> Option<Outcome> {
    let python = match kit::pymavlink_python() {
        Ok(p) => p,
        Err(reason) => {
            eprintln!("skipping {name}: {reason}");
            return None;
        }
    };
    let port = kit::free_udp_port();
    let report_path = std::env::temp_dir().join(format!(
        "troupe-mavlink-{name}-{}-{port}.json",
        std::process::id()
    ));
    let autopilot_s = scenario.run_s + 1.0;
    let mut command = Command::new(python);
    command
        .arg(kit::root().join("scripts/mavlink/px4_like_autopilot.py"))
        .args(["--connection", &format!("udpout:127.0.0.1:{port}")])
        .args(["--report", &report_path.to_string_lossy()])
        .args(["--duration-s", &autopilot_s.to_string()])
        .args(["--heartbeat-hz", "4"])
        .args(["--start-ned", "0,0,-1"]);
    if let Some(after_s) = scenario.heartbeat_stop_after_s {
        command.args(["--heartbeat-stop-after-s", &after_s.to_string()]);
    }
    let mut child = command
        .stdout(Stdio::piped())
        .spawn()
        .expect("spawn the autopilot");
    let _ready_at = tokio::task::block_in_place(|| wait_ready(&mut child));

    let mut config = MavlinkConfig::new(format!("udpin:127.0.0.1:{port}"), scenario.fence);
    config.heartbeat_timeout_s = scenario.heartbeat_timeout_s;
    config.sensor_timeout_s = scenario.sensor_timeout_s;
    let vehicle = mavlink_vehicle(&config).expect("valid config");
    let plan = scenario.plan.clone();
    let (off_from_s, off_until_s) = scenario.frames_off_s;
    let robot = RobotSpec::new("r0")
        .with(vehicle)
        .with(ActorSpec::new("mission", move || {
            Mission::new(plan.clone())
        }))
        .with(ActorSpec::new("camera", move || Camera {
            off_from_s,
            off_until_s,
        }));
    let odometry = Arc::new(Mutex::new(Vec::new()));
    let status = Arc::new(Mutex::new(Vec::new()));
    let mut executor = RealtimeExecutor::new(vec![robot], 7);
    {
        let (odometry, status) = (odometry.clone(), status.clone());
        executor.add_tap(move |p: &troupe_runtime::Publication<'_>| {
            if let Some(o) = p.get(&ODOMETRY) {
                odometry.lock().expect("tap lock").push(o.clone());
            }
            if let Some(s) = p.get(&AUTOPILOT_STATUS) {
                status.lock().expect("tap lock").push(s.clone());
            }
        });
    }
    let handle = executor.spawn();
    let epoch_s = unix_now_s() - handle.now().as_secs_f64();
    tokio::time::sleep(Duration::from_secs_f64(scenario.run_s)).await;
    let _reports = handle.shutdown().await;
    let exit = tokio::task::block_in_place(|| child.wait()).expect("autopilot exits");
    assert!(exit.success(), "the autopilot failed: {exit}");
    let text = std::fs::read_to_string(&report_path).expect("autopilot report");
    let _ = std::fs::remove_file(&report_path);
    let report: Value = serde_json::from_str(&text).expect("report is JSON");
    let odometry = std::mem::take(&mut *odometry.lock().expect("tap lock"));
    let status = std::mem::take(&mut *status.lock().expect("tap lock"));
    Some(Outcome {
        report,
        epoch_s,
        odometry,
        status,
    })
}

fn wide_fence() -> GeofenceConfig {
    GeofenceConfig {
        min_m: [-10.0, -10.0, 0.0],
        max_m: [10.0, 10.0, 5.0],
    }
}

/// Only heartbeats and position targets ever go to the autopilot: no arming, no mode
/// change, no command of any kind.
fn assert_only_heartbeats_and_setpoints(outcome: &Outcome) {
    let types = outcome.report["received_types"]
        .as_object()
        .expect("received types");
    for kind in types.keys() {
        assert!(
            kind == "HEARTBEAT" || kind == "SET_POSITION_TARGET_LOCAL_NED",
            "the vehicle sent {kind}"
        );
    }
    assert!(types.contains_key("HEARTBEAT"), "our own heartbeat");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn streams_the_plan_in_ned_at_rate_and_publishes_odometry() {
    // Hover at 1 m, then climb and fly north-east while turning to face north.
    let plan = Trajectory::new(vec![
        knot(0.0, 0.0, 0.0, 1.0, 0.0),
        knot(1.5, 0.0, 0.0, 1.0, 0.0),
        knot(4.5, 3.0, 1.5, 2.5, std::f64::consts::FRAC_PI_2),
    ])
    .unwrap();
    let scenario = Scenario {
        plan: plan.clone(),
        fence: wide_fence(),
        frames_off_s: (f64::INFINITY, f64::INFINITY),
        heartbeat_stop_after_s: None,
        heartbeat_timeout_s: 1.0,
        sensor_timeout_s: 1.0,
        run_s: 6.5,
    };
    let Some(outcome) = run("track", scenario).await else {
        return;
    };
    assert_only_heartbeats_and_setpoints(&outcome);
    let setpoints = outcome.setpoints();
    // Rate: the setpoints of [1, 6] s of run time, at ≥ 20 Hz (configured 30 Hz).
    let window: Vec<&Value> = setpoints
        .iter()
        .filter(|sp| (1.0..6.0).contains(&outcome.run_time(sp)))
        .collect();
    let rate_hz = window.len() as f64 / 5.0;
    assert!(rate_hz >= 20.0, "setpoint rate {rate_hz:.1} Hz");
    let mut gaps: Vec<f64> = window
        .windows(2)
        .map(|w| num(&w[1]["t"]) - num(&w[0]["t"]))
        .collect();
    gaps.sort_by(f64::total_cmp);
    assert!(
        gaps[gaps.len() / 2] < 0.05,
        "median gap {} s",
        gaps[gaps.len() / 2]
    );
    println!(
        "setpoint rate {rate_hz:.1} Hz, median gap {:.4} s",
        gaps[gaps.len() / 2]
    );

    // Addressing and type: to the autopilot that sent the heartbeats, in LOCAL_NED,
    // position + velocity + acceleration + yaw.
    for sp in &window {
        assert_eq!(sp["frame"], 1, "MAV_FRAME_LOCAL_NED");
        assert_eq!(
            (&sp["target_system"], &sp["target_component"]),
            (&1.into(), &1.into())
        );
        assert_eq!(
            (&sp["src_system"], &sp["src_component"]),
            (&1.into(), &191.into())
        );
        // A plan of knots (no primitive) has no acceleration to give: ignored too.
        assert_eq!(
            sp["type_mask"],
            0x800 | 0x1c0,
            "yaw rate and acceleration ignored"
        );
    }
    // Each setpoint is the plan's ENU reference at its time, converted to NED.
    let mut compared = 0;
    for sp in &window {
        let at_s = outcome.run_time(sp);
        let reference = plan.state_at(t(at_s)).unwrap();
        let expected = enu_to_ned(&reference.position_m.coords);
        // Allow for the clock offset between the two processes (1.8 m/s at most).
        assert!(
            (position_ned(sp) - expected).norm() < 0.1,
            "at {at_s:.3} s: setpoint {} vs plan {}",
            position_ned(sp),
            expected
        );
        let velocity = enu_to_ned(&reference.velocity_mps);
        if (2.0..4.0).contains(&at_s) {
            assert!((velocity_ned(sp) - velocity).norm() < 1e-3);
            compared += 1;
        }
    }
    assert!(compared > 30);
    // The point mass arrived where the plan ends, in NED: 1.5 m north, 3 m east, 2.5 m up.
    let end = &outcome.report["final_position_ned"];
    let end = Vector3::new(num(&end[0]), num(&end[1]), num(&end[2]));
    assert!(
        (end - Vector3::new(1.5, 3.0, -2.5)).norm() < 0.1,
        "autopilot ended at {end}"
    );
    let yaw = num(&outcome.report["final_yaw_ned"]);
    assert!(
        (yaw - yaw_enu_to_ned(std::f64::consts::FRAC_PI_2)).abs() < 1e-3,
        "facing north, yaw {yaw}"
    );
    // The robot's odometry is the autopilot's state in ENU / FLU.
    let last = outcome.odometry.last().expect("odometry published");
    let p = last.pose.translation.vector;
    assert!(
        (p - Vector3::new(3.0, 1.5, 2.5)).norm() < 0.1,
        "odometry at {p}"
    );
    let forward = last.pose.rotation * Vector3::x();
    assert!(
        (forward - Vector3::y()).norm() < 1e-3,
        "odometry facing {forward}"
    );
    assert!(
        outcome.odometry.len() > 100,
        "{} odometry messages",
        outcome.odometry.len()
    );
    // The status reports the autopilot as PX4 reports itself.
    let status = outcome.status.last().expect("status published");
    assert!(status.armed && status.mode == "OFFBOARD", "{status:?}");
    assert_eq!(status.autopilot, Some((1, 1)));
    assert!(!status.heartbeat_lost);
    assert!(status.heartbeat_age_s.is_some_and(|a| a < 1.0));
    assert_eq!(status.link.decode_errors, 0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_sensor_timeout_holds_then_resumes() {
    // East at 0.5 m/s for the whole run; frames stop in [2, 3.5) s.
    let plan = Trajectory::new(vec![
        knot(0.0, 0.0, 0.0, 1.0, 0.0),
        knot(20.0, 10.0, 0.0, 1.0, 0.0),
    ])
    .unwrap();
    let (off_from_s, off_until_s, timeout_s) = (2.0, 3.5, 0.5);
    let scenario = Scenario {
        plan,
        fence: GeofenceConfig {
            min_m: [-10.0, -10.0, 0.0],
            max_m: [20.0, 10.0, 5.0],
        },
        frames_off_s: (off_from_s, off_until_s),
        heartbeat_stop_after_s: None,
        heartbeat_timeout_s: 1.0,
        sensor_timeout_s: timeout_s,
        run_s: 5.0,
    };
    let Some(outcome) = run("sensor", scenario).await else {
        return;
    };
    assert_only_heartbeats_and_setpoints(&outcome);
    let is_hold = |sp: &Value| velocity_ned(sp).norm() == 0.0;
    let setpoints = outcome.setpoints();
    // Tracking (moving east = NED +y) while frames flow.
    for sp in setpoints
        .iter()
        .filter(|sp| (0.5..1.9).contains(&outcome.run_time(sp)))
    {
        assert!(
            !is_hold(sp),
            "held at {:.3} s with frames flowing",
            outcome.run_time(sp)
        );
        assert!((num(&sp["vy"]) - 0.5).abs() < 1e-4);
    }
    // The first hold comes within the timeout (+ 0.2 s) of the frames stopping, and
    // not before the last frame (≤ 0.1 s before the stop) is older than the timeout.
    let first_hold = setpoints
        .iter()
        .find(|sp| outcome.run_time(sp) > off_from_s - 0.1 && is_hold(sp))
        .expect("a hold setpoint after the frames stopped");
    let hold_s = outcome.run_time(first_hold);
    println!("frames stopped at {off_from_s} s, hold from {hold_s:.3} s");
    assert!(
        hold_s <= off_from_s + timeout_s + 0.2,
        "hold only at {hold_s:.3} s"
    );
    assert!(
        hold_s >= off_from_s - 0.1 + timeout_s - 0.05,
        "hold already at {hold_s:.3} s"
    );
    // The hold stays at one position until the frames return.
    let held: Vec<&Value> = setpoints
        .iter()
        .filter(|sp| (hold_s..off_until_s).contains(&outcome.run_time(sp)))
        .collect();
    assert!(held.len() > 10);
    for sp in &held {
        assert!(
            is_hold(sp),
            "moving at {:.3} s without frames",
            outcome.run_time(sp)
        );
        assert_eq!(position_ned(sp), position_ned(first_hold));
    }
    // Tracking resumes once frames return, from where the vehicle held: no setpoint
    // steps more than 5 cm (the plan had moved on 0.75 m meanwhile).
    let resumed = setpoints
        .iter()
        .find(|sp| outcome.run_time(sp) > off_until_s && !is_hold(sp))
        .expect("tracking resumed");
    assert!(outcome.run_time(resumed) < off_until_s + 0.3);
    let largest_step_m = setpoints
        .windows(2)
        .filter(|w| outcome.run_time(&w[1]) > hold_s)
        .map(|w| (position_ned(&w[1]) - position_ned(&w[0])).norm())
        .fold(0.0, f64::max);
    println!("largest setpoint step after the hold began: {largest_step_m:.4} m");
    assert!(
        largest_step_m <= 0.05,
        "a setpoint stepped {largest_step_m:.3} m"
    );
    assert!(
        outcome
            .status
            .iter()
            .any(|s| s.hold == Some(HoldReason::SensorTimeout))
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn holds_inside_the_geofence_and_goes_silent_without_heartbeat() {
    // East at 1 m/s from 1 s on, through the fence's east wall at x = 2 m (t = 3 s).
    let plan = Trajectory::new(vec![
        knot(0.0, 0.0, 0.0, 1.0, 0.0),
        knot(1.0, 0.0, 0.0, 1.0, 0.0),
        knot(7.0, 6.0, 0.0, 1.0, 0.0),
    ])
    .unwrap();
    let fence = GeofenceConfig {
        min_m: [-2.0, -2.0, 0.0],
        max_m: [2.0, 2.0, 3.0],
    };
    let heartbeat_timeout_s = 1.0;
    let scenario = Scenario {
        plan,
        fence,
        frames_off_s: (f64::INFINITY, f64::INFINITY),
        heartbeat_stop_after_s: Some(4.5),
        heartbeat_timeout_s,
        sensor_timeout_s: 1.0,
        run_s: 6.5,
    };
    let Some(outcome) = run("fence", scenario).await else {
        return;
    };
    assert_only_heartbeats_and_setpoints(&outcome);
    let geofence = Geofence::new(Point3::from(fence.min_m), Point3::from(fence.max_m)).unwrap();
    let setpoints = outcome.setpoints();
    assert!(setpoints.len() > 60);
    let mut at_wall = 0;
    for sp in setpoints {
        // Back to ENU: (north, east, down) → (east, north, up); f32 on the wire.
        let p = position_ned(sp);
        let enu = Point3::new(p.y, p.x, -p.z);
        let inside = (0..3)
            .all(|i| enu[i] >= geofence.min_m()[i] - 1e-5 && enu[i] <= geofence.max_m()[i] + 1e-5);
        assert!(inside, "setpoint outside the fence: {enu}");
        if velocity_ned(sp).norm() == 0.0 && outcome.run_time(sp) > 3.0 {
            at_wall += 1;
            assert!(enu.x > 1.8, "held at {enu}, short of the wall");
        }
    }
    assert!(at_wall > 10, "{at_wall} hold setpoints at the fence");
    // Nothing after the heartbeats stop (beyond the timeout and one tick of slack).
    let last_heartbeat = num(&outcome.report["last_heartbeat_sent"]);
    let deadline = last_heartbeat + heartbeat_timeout_s + 0.2;
    let late: Vec<f64> = setpoints
        .iter()
        .map(|sp| num(&sp["t"]))
        .filter(|at| *at > deadline)
        .collect();
    assert!(
        late.is_empty(),
        "{} setpoints after the heartbeat stopped",
        late.len()
    );
    assert!(
        setpoints.iter().any(|sp| num(&sp["t"]) > last_heartbeat),
        "setpoints went on until the timeout"
    );
    let last = outcome.status.last().expect("status");
    assert!(last.heartbeat_lost, "{last:?}");
    assert!(
        last.guard.fence_holds > 10 && last.guard.plans_leaving_fence > 0,
        "{last:?}"
    );
    assert!(
        outcome
            .status
            .iter()
            .any(|s| s.hold == Some(HoldReason::Geofence))
    );
}
