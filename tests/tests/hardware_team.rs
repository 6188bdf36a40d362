//! The closed loop of issue 17 with a team: the hardware robot (robot 0, the
//! `troupe-robot` assembly: ROS 2 depth and odometry in over zenoh, MAVLink setpoints
//! out), a simulated peer (robot 1, the `troupe robot` process assembly in its own
//! simulated cave) and the base station (`troupe base`), each with its own zenoh
//! session on loopback, run side by side in this test's process through the same
//! library entry points the binaries call.
//!
//! The other ends are real: `scripts/ros2/box_room_camera.py` (rclpy + the zenoh
//! binding) renders 640×480 depth of a box room at 15 Hz from the pose of
//! `scripts/mavlink/px4_like_autopilot.py` (pymavlink), a point mass flying the
//! robot's setpoints — the Python side of `robot/tests/hardware_loop.rs`.
//!
//! Checks: the hardware robot streams setpoints for ≥ 20 s, none outside its geofence,
//! and no committed plan left the fence (the collision actor's plan check and the
//! vehicle's clamp share the robot file's `[mavlink.geofence]`); the two robots share
//! keyframes both ways; the base's merged map holds keyframes of both. Skips, saying
//! why, without the Python venvs (`.ci/run` installs them).

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::collections::BTreeMap;
use std::time::Duration;

use troupe_robot::base::BaseStation;
use troupe_robot::hardware::HardwareRobot;
use troupe_runtime::TopicStats;
use troupe_sims::process::RobotProcess;
use troupe_testkit as kit;

const FLY_S: f64 = 22.0;
const FENCE_MIN: [f64; 3] = [-2.5, -2.5, 0.5];
const FENCE_MAX: [f64; 3] = [4.5, 2.5, 2.5];

/// A zenoh table listening on `me` and connecting to the `others`.
fn zenoh(me: &str, others: &[&str]) -> String {
    format!("listen = [\"{me}\"]\nconnect = {others:?}\n")
}

#[test]
fn hardware_robot_a_simulated_peer_and_the_base_share_one_map() {
    let Some((ros_python, mav_python)) =
        kit::or_skip(kit::hardware_pythons(), "hardware team test")
    else {
        return;
    };
    let dir = tempfile::tempdir().expect("tempdir");
    let dir = dir.path();
    let ros_port = kit::free_tcp_port();
    let team: Vec<String> = (0..3)
        .map(|_| format!("tcp/127.0.0.1:{}", kit::free_tcp_port()))
        .collect();
    let (hw, sim, base) = (team[0].as_str(), team[1].as_str(), team[2].as_str());
    let (mavlink_port, state_port) = (kit::free_udp_port(), kit::free_udp_port());

    // The team: robot 0 on hardware, robot 1 simulated, the base as id 2.
    std::fs::write(
        dir.join("team.toml"),
        "name = \"hwteam\"\nrobots = 2\n\n[robot.link]\nteam = 3\npeers = [0, 1]\n",
    )
    .unwrap();
    // The camera's topics in, then the robot's plans out in the same `[ros2.topics]`.
    let ros2 = kit::box_room_camera_ros2_table(ros_port, 20.0);
    let mavlink = kit::autopilot_mavlink_tables(mavlink_port, FENCE_MIN, FENCE_MAX);
    std::fs::write(
        dir.join("robot0.toml"),
        format!(
            r#"id = 0
team_size = 2
out = "hw0"
record = false
[robot]
sensor_rate_hz = 15.0
[robot.link]
team = 3
peers = [1]
{ros2}plan = "/troupe/plan"
{mavlink}[zenoh]
{}"#,
            zenoh(hw, &[sim, base])
        ),
    )
    .unwrap();
    std::fs::write(
        dir.join("robot1.toml"),
        format!(
            "robot = 1\nscenario = \"team.toml\"\nout = \"sim1\"\nrecord = false\n\n[zenoh]\n{}",
            zenoh(sim, &[hw, base])
        ),
    )
    .unwrap();
    std::fs::write(
        dir.join("base.toml"),
        format!(
            "scenario = \"team.toml\"\nout = \"station\"\nply_points = 2000\nrecord = false\n\n\
             [zenoh]\n{}",
            zenoh(base, &[hw, sim])
        ),
    )
    .unwrap();
    let hardware = HardwareRobot::load(&dir.join("robot0.toml")).expect("robot0.toml");
    let peer = RobotProcess::load(&dir.join("robot1.toml")).expect("robot1.toml");
    let station = BaseStation::load(&dir.join("base.toml"), troupe_sims::scenario::load_team)
        .expect("base.toml");

    // The Python ends run past the robot's flight (it starts once their topics appear).
    let peers_s = FLY_S + 15.0;
    let report = dir.join("autopilot.json");
    let autopilot = kit::spawn_autopilot(&mav_python, mavlink_port, state_port, &report, peers_s);
    let camera = kit::spawn_box_room_camera(&ros_python, ros_port, state_port, None, peers_s);

    // The base and the simulated peer run until the hardware robot is done.
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let stopped = |mut rx: tokio::sync::watch::Receiver<bool>| async move {
        let _ = rx.wait_for(|s| *s).await;
    };
    let (base_rx, peer_rx) = (stop_rx.clone(), stop_rx);
    let base_thread = std::thread::spawn(move || {
        let runtime = tokio::runtime::Runtime::new().expect("runtime");
        let (_commands, from_operator) = std::sync::mpsc::channel();
        runtime.block_on(troupe_robot::base::run(
            &station,
            stopped(base_rx),
            from_operator,
        ))
    });
    let peer_thread = std::thread::spawn(move || {
        let runtime = tokio::runtime::Runtime::new().expect("runtime");
        runtime.block_on(troupe_sims::process::run(&peer, stopped(peer_rx)))
    });
    let flown = troupe_robot::hardware::run(&hardware, async {
        tokio::time::sleep(Duration::from_secs_f64(FLY_S)).await;
    });
    // The base hears the last keyframes before it stops.
    std::thread::sleep(Duration::from_secs(3));
    stop_tx.send(true).unwrap();
    let peer_summary = peer_thread.join().unwrap().expect("the simulated peer");
    let base_summary = base_thread.join().unwrap().expect("the base");
    let hw_summary = flown.expect("the hardware robot");
    kit::finish(camera, "the camera");
    kit::finish(autopilot, "the autopilot");

    // The hardware robot mapped and planned, and no committed plan left the fence.
    println!(
        "hardware: frames {} keyframes {} plans {} vehicle {:?} collision {:?}",
        hw_summary.frames,
        hw_summary.keyframes,
        hw_summary.plans,
        hw_summary.vehicle,
        hw_summary.collision
    );
    assert!(hw_summary.keyframes > 0 && hw_summary.plans > 0);
    let vehicle = hw_summary.vehicle.as_ref().expect("vehicle status");
    assert_eq!(vehicle.plans_leaving_fence, 0, "{vehicle:?}");
    assert_eq!(vehicle.fence_holds, 0, "{vehicle:?}");
    assert!(hw_summary.collision.is_some(), "no collision actor status");

    // It flew ≥ 20 s: setpoints over that span, none outside the fence.
    let autopilot = kit::read_json(&report);
    let setpoints = autopilot["setpoints"].as_array().unwrap();
    let times: Vec<f64> = setpoints.iter().map(|s| s["t"].as_f64().unwrap()).collect();
    let span_s = times.last().unwrap_or(&0.0) - times.first().unwrap_or(&0.0);
    println!("{} setpoints over {span_s:.1} s", times.len());
    assert!(span_s >= 20.0, "setpoints over only {span_s:.1} s");
    kit::assert_setpoints_inside_fence(&autopilot, FENCE_MIN, FENCE_MAX);

    // The robots shared keyframes both ways.
    let received = |topics: &BTreeMap<String, TopicStats>| {
        topics.get("peer/keyframe").map_or(0, |t| t.messages)
    };
    let (hw_got, sim_got) = (received(&hw_summary.topics), received(&peer_summary.topics));
    println!("keyframes received: hardware robot {hw_got}, simulated peer {sim_got}");
    assert!(
        hw_got > 0,
        "the hardware robot got no keyframe from its peer"
    );
    assert!(
        sim_got > 0,
        "the simulated peer got no keyframe from the hardware robot"
    );

    // The base's merged map holds both robots' keyframes.
    let robots = &base_summary.robots;
    println!(
        "base: {:?}",
        robots
            .iter()
            .map(|(id, r)| (id, r.keyframes))
            .collect::<Vec<_>>()
    );
    for id in [0, 1] {
        assert!(
            robots.get(&id).is_some_and(|r| r.keyframes > 0),
            "the base has no keyframe of robot {id}"
        );
    }
    let merged =
        troupe_algorithms::mapfile::GmmMap::load(&dir.join("station").join("merged_map.troupe"))
            .expect("merged map");
    assert_eq!(
        merged.keyframes.len(),
        robots.values().map(|r| r.keyframes).sum::<usize>()
    );
}
