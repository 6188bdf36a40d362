//! The ROS 2 drivers against a real ROS 2 peer: a Python process serialises real
//! `Image`, `CameraInfo`, `PointCloud2` and `Odometry` messages with rclpy and
//! publishes them with zenoh's Python binding on rmw_zenoh keys (with attachments) or
//! bridge keys over loopback TCP; a robot on the real-time executor turns them into
//! depth frames and odometry, plans from that odometry, and publishes the plan as a
//! `nav_msgs/Path`, which the Python side deserialises with rclpy and reports.
//!
//! Needs the wheels `scripts/ros2/install.sh` puts in `.venv-ros2` (or a Python named by
//! `TROUPE_ROS2_PYTHON`); without them each test prints why and skips.

#![allow(clippy::unwrap_used)]

use std::net::TcpListener;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex};

use nalgebra::{Matrix4, Point3, Vector3, Vector4};
use troupe_actors::msgs::{DEPTH_FRAME, KEYFRAME, ODOMETRY, PLAN};
use troupe_actors::sensor::SensorActor;
use troupe_algorithms::frame::{DepthFrame, Odometry};
use troupe_algorithms::keyframe::Keyframe;
use troupe_algorithms::plan::Plan;
use troupe_algorithms::sogmm::Gmm4;
use troupe_algorithms::trajectory::{Knot, Trajectory};
use troupe_core::Time;
use troupe_robot::ros2::{Ros2Config, Ros2Inputs, Ros2Outputs, Ros2Publisher, open_session};
use troupe_runtime::{
    Actor, ActorResult, ActorSpec, Context, Event, Publication, QueuePolicy, RealtimeExecutor,
    RobotSpec,
};

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("robot/ is inside the workspace")
        .to_path_buf()
}

/// The Python with rclpy, the message packages and zenoh, or why there is none.
fn ros_python() -> Result<PathBuf, String> {
    let python = std::env::var_os("TROUPE_ROS2_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace().join(".venv-ros2/bin/python"));
    if !python.exists() {
        return Err(format!(
            "{} not found (run scripts/ros2/install.sh)",
            python.display()
        ));
    }
    let probe = Command::new(&python)
        .args([
            "-c",
            "import rclpy.serialization, sensor_msgs.msg, nav_msgs.msg, zenoh",
        ])
        .output()
        .map_err(|e| format!("{}: {e}", python.display()))?;
    if !probe.status.success() {
        return Err(format!(
            "{} lacks the ROS 2 wheels: {}",
            python.display(),
            String::from_utf8_lossy(&probe.stderr).trim()
        ));
    }
    Ok(python)
}

/// A free loopback port below the ephemeral range, different per test (`slot`).
fn free_port(slot: u16) -> u16 {
    let base = 20_000 + (std::process::id() % 2_000) as u16 * 4 + slot;
    (0..400u16)
        .map(|k| base + k * 8)
        .find(|p| TcpListener::bind(("127.0.0.1", *p)).is_ok())
        .expect("a free loopback port")
}

/// Plans 1 m straight ahead of every odometry it gets (a stand-in for the planner), and
/// publishes one keyframe (a stand-in for the mapper): one component at (5, 0, 1) with
/// intensity 0.5.
struct AheadPlanner {
    keyframe_sent: bool,
}

impl Actor for AheadPlanner {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&ODOMETRY, QueuePolicy::LATEST);
        Ok(())
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        let Some(odometry) = event.message().and_then(|m| m.get(&ODOMETRY)) else {
            return Ok(());
        };
        let start = Point3::from(odometry.pose.translation.vector);
        let yaw = odometry.pose.rotation.euler_angles().2;
        let ahead = start + odometry.pose.rotation * Vector3::x();
        let knot = |time, position_m| Knot {
            time,
            position_m,
            yaw_rad: yaw,
        };
        let now = ctx.now();
        if !self.keyframe_sent {
            self.keyframe_sent = true;
            let covariance = Matrix4::from_diagonal(&Vector4::new(0.01, 0.04, 0.01, 0.001));
            let gmm = Gmm4::new(
                vec![1.0],
                vec![Vector4::new(5.0, 0.0, 1.0, 0.5)],
                vec![covariance],
            )
            .map_err(|e| troupe_runtime::ActorError::with_source("gmm", e))?;
            ctx.publish(
                &KEYFRAME,
                Keyframe {
                    id: 0,
                    stamp: now,
                    pose: odometry.pose,
                    support_size: 100,
                    gmm,
                },
            );
        }
        let later = Time::from_nanos(now.as_nanos() + 1_000_000_000);
        let trajectory = Trajectory::new(vec![knot(now, start), knot(later, ahead)])
            .map_err(|e| troupe_runtime::ActorError::with_source("plan", e))?;
        ctx.publish(&PLAN, Plan::new(now, trajectory));
        Ok(())
    }
}

#[derive(Default)]
struct Seen {
    frames: Vec<DepthFrame>,
    odometry: Vec<Odometry>,
}

/// Runs the robot against the Python peer; returns what the robot published and the
/// peer's report.
fn run(format: &str, topics: &str, extra: &str, slot: u16) -> Option<(Seen, serde_json::Value)> {
    let python = match ros_python() {
        Ok(p) => p,
        Err(why) => {
            println!("skipped: {why}");
            return None;
        }
    };
    let port = free_port(slot);
    let config: Ros2Config = toml::from_str(&format!(
        r#"
        format = "{format}"
        startup_timeout_s = 30.0
        {extra}
        extrinsics = {{ translation_m = [0.1, 0.0, -0.05] }}
        zenoh = {{ listen = ["tcp/127.0.0.1:{port}"] }}
        [topics]
        odometry = "/odom"
        plan = "/troupe/plan"
        map = "/troupe/map"
        status = "/troupe/status"
        {topics}
        "#
    ))
    .unwrap();
    let session = open_session(&config).unwrap();
    let inputs = Ros2Inputs::subscribe(&session, &config).unwrap();
    let publisher = Ros2Publisher::open(&session, &config).unwrap();
    let peer = Command::new(&python)
        .arg(workspace().join("scripts/ros2/ros_peer.py"))
        .args(["--format", format, "--timeout", "60"])
        .args(["--connect", &format!("tcp/127.0.0.1:{port}")])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    inputs.wait_for_topics().unwrap();

    let seen = Arc::new(Mutex::new(Seen::default()));
    let mut robot = RobotSpec::new("r0");
    let (odometry_inputs, frame_inputs, status_inputs) =
        (inputs.clone(), inputs.clone(), inputs.clone());
    robot
        .add(ActorSpec::new("odometry", move || {
            odometry_inputs.odometry_actor()
        }))
        .add(ActorSpec::new("sensor", move || {
            SensorActor::new(frame_inputs.frame_source(), 20.0)
        }))
        .add(ActorSpec::new("planner", || AheadPlanner {
            keyframe_sent: false,
        }))
        .add(ActorSpec::new("ros2", move || {
            Ros2Outputs::new(publisher.clone(), Some(status_inputs.clone()))
        }));
    let mut executor = RealtimeExecutor::new(vec![robot], 1);
    let tap_seen = seen.clone();
    executor.add_tap(move |p: &Publication<'_>| {
        let mut seen = tap_seen.lock().unwrap();
        if let Some(frame) = p.get(&DEPTH_FRAME) {
            seen.frames.push(frame.clone());
        }
        if let Some(odometry) = p.get(&ODOMETRY) {
            seen.odometry.push(odometry.clone());
        }
    });
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let handle = runtime.block_on(async { executor.spawn() });
    let output = peer.wait_with_output().unwrap();
    runtime.block_on(handle.shutdown());
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "peer failed: {stdout}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let report: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    let stats = inputs.stats();
    assert!(
        stats.rejected.is_empty() || stats.rejected.keys().all(|k| k == "frame/no_odometry"),
        "{stats:?}"
    );
    let seen = Arc::try_unwrap(seen).ok().unwrap().into_inner().unwrap();
    Some((seen, report))
}

/// Odometry at (1, 2, 3) yawed 90°, 1 m/s forward; camera 0.1 m ahead and 0.05 m below.
fn check_outputs(seen: &Seen, everything: &serde_json::Value) {
    let odometry = seen.odometry.last().expect("odometry published");
    assert!((odometry.pose.translation.vector - Vector3::new(1.0, 2.0, 3.0)).norm() < 1e-12);
    assert!((odometry.velocity_mps - Vector3::new(0.0, 1.0, 0.0)).norm() < 1e-9);
    let frame = seen.frames.last().expect("a depth frame");
    let camera = frame.pose.translation.vector;
    assert!(
        (camera - Vector3::new(1.0, 2.1, 2.95)).norm() < 1e-9,
        "{camera}"
    );
    assert!((frame.pose.rotation * Vector3::x() - Vector3::y()).norm() < 1e-9);

    let report = &everything["path"];
    assert_eq!(report["frame_id"], "odom");
    let poses = report["poses"].as_array().unwrap();
    assert_eq!(poses.len(), 2);
    let pose = |i: usize| -> Vec<f64> {
        poses[i]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect()
    };
    let h = std::f64::consts::FRAC_1_SQRT_2;
    for (got, want) in pose(0).iter().zip([1.0, 2.0, 3.0, h, h]) {
        assert!((got - want).abs() < 1e-9, "{:?}", pose(0));
    }
    for (got, want) in pose(1).iter().zip([1.0, 3.0, 3.0, h, h]) {
        assert!((got - want).abs() < 1e-9, "{:?}", pose(1));
    }

    // The keyframe map: 2000 points (the default) around the component, its intensity.
    let map = &everything["map"];
    assert_eq!(map["frame_id"], "odom");
    assert_eq!(map["width"], 2000);
    assert_eq!(
        map["fields"],
        serde_json::json!([["x", 0, 7], ["y", 4, 7], ["z", 8, 7], ["intensity", 12, 7]])
    );
    let mean: Vec<f64> = map["mean"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    for (got, want) in mean.iter().zip([5.0, 0.0, 1.0, 0.5]) {
        assert!((got - want).abs() < 0.02, "{mean:?}");
    }

    // The status: this robot, with the input counters.
    let status = &everything["status"];
    assert_eq!(status["robot"], "r0");
    assert!(
        status["inputs"]["received"]["odometry"].as_u64().unwrap() > 0,
        "{status}"
    );
    assert_eq!(status["outputs"]["dropped_full"], 0, "{status}");
}

#[test]
fn rmw_zenoh_depth_intensity_and_odometry_round_trip_through_rclpy() {
    let topics = r#"
        depth = "/camera/depth/image_rect_raw"
        camera_info = "/camera/depth/camera_info"
        intensity = "/camera/infra1/image_rect_raw"
    "#;
    let Some((seen, report)) = run("rmw_zenoh", topics, "", 0) else {
        return;
    };
    check_outputs(&seen, &report);
    let frame = seen.frames.last().unwrap();
    let k = frame.intrinsics;
    assert_eq!(
        (k.width, k.height, k.fx, k.fy, k.cx, k.cy),
        (8, 6, 4.0, 4.0, 4.0, 3.0)
    );
    for r in 0..6 {
        for c in 0..8 {
            let i = r * 8 + c;
            let (depth, intensity) = if (r, c) == (0, 0) {
                (0.0, 0.0)
            } else {
                (
                    (1000 + 100 * r + 10 * c) as f32 / 1000.0,
                    (10 * c + r) as f32 / 255.0,
                )
            };
            assert!((frame.depth_m[i] - depth).abs() < 1e-6, "depth at {r},{c}");
            assert!(
                (frame.intensity[i] - intensity).abs() < 1e-6,
                "intensity at {r},{c}"
            );
        }
    }
    // The path came on an rmw_zenoh key with rmw_zenoh's attachment.
    let report = &report["path"];
    assert!(
        report["key"]
            .as_str()
            .unwrap()
            .starts_with("0/troupe/plan/nav_msgs::msg::dds_::Path_/RIHS01_1957a5bb"),
        "{report}"
    );
    let attachment: Vec<u64> = report["attachment"]
        .as_array()
        .expect("an attachment")
        .iter()
        .map(|v| v.as_u64().unwrap())
        .collect();
    assert_eq!(attachment.len(), 33);
    assert_eq!(attachment[16], 16);
    assert!(attachment[0] >= 1);
}

#[test]
fn bridge_point_cloud_and_odometry_round_trip_through_rclpy() {
    let topics = r#"points = "/camera/depth/points""#;
    let intrinsics = "points_intrinsics = { width = 8, height = 6, fx = 4.0, fy = 4.0, \
                      cx = 4.0, cy = 3.0, max_depth_m = 5.0 }";
    let Some((seen, report)) = run("bridge", topics, intrinsics, 1) else {
        return;
    };
    check_outputs(&seen, &report);
    assert_eq!(report["path"]["key"], "troupe/plan");
    assert_eq!(report["map"]["key"], "troupe/map");
    assert!(report["path"]["attachment"].is_null());
    // (0, 0, 2) → pixel (4, 3); (1, 0.5, 4) → u 5, v 3.5 → (5, 3); (−0.5, −0.25, 1) →
    // u 2, v 2 → (2, 2).
    let frame = seen.frames.last().unwrap();
    let mut expected = vec![0.0f32; 48];
    expected[3 * 8 + 4] = 2.0;
    expected[3 * 8 + 5] = 4.0;
    expected[2 * 8 + 2] = 1.0;
    assert_eq!(frame.depth_m, expected);
}

#[test]
fn a_silent_topic_is_one_clear_error_after_the_startup_timeout() {
    let port = free_port(2);
    let config: Ros2Config = toml::from_str(&format!(
        r#"
        format = "rmw_zenoh"
        startup_timeout_s = 0.3
        zenoh = {{ listen = ["tcp/127.0.0.1:{port}"] }}
        [topics]
        depth = "/camera/depth/image_rect_raw"
        camera_info = "/camera/depth/camera_info"
        odometry = "/odom"
        "#
    ))
    .unwrap();
    let session = open_session(&config).unwrap();
    let inputs = Ros2Inputs::subscribe(&session, &config).unwrap();
    let err = inputs.wait_for_topics().unwrap_err().to_string();
    assert_eq!(
        err,
        "ROS 2 topic `/camera/depth/image_rect_raw` (zenoh key \
         `0/camera/depth/image_rect_raw/sensor_msgs::msg::dds_::Image_/*`) sent nothing \
         within 0.3 s: check the topic name, `format`, `domain_id`, `bridge_namespace` and \
         the zenoh endpoints"
    );
}
