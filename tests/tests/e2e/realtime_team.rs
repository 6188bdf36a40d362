//! The standard robot's actors, unchanged, under the real-time executor.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use nalgebra::{Isometry3, Point3};
use troupe_actors::link::LinkJournal;
use troupe_actors::msgs::{DEPTH_FRAME, PEER_ODOMETRY};
use troupe_actors::vehicle::VehicleActor;
use troupe_robot::{RobotConfig, RobotParts, assemble};
use troupe_runtime::{ActorSpec, Publication, RealtimeExecutor};
use troupe_sims::camera::CameraParams;
use troupe_sims::sim_sensor::SimCameraSource;
use troupe_sims::vehicle::{SimVehicle, VehicleConfig, new_body};
use troupe_sims::world::{CaveParams, CaveWorld, World};

#[test]
fn standard_robots_run_on_the_wall_clock() {
    let world = Arc::new(CaveWorld::generate(&CaveParams::default(), 7));
    let config = RobotConfig {
        sensor_rate_hz: 20.0,
        replan_rate_hz: 10.0,
        ..RobotConfig::default()
    };
    let team = (0..2)
        .map(|i| {
            let start = world.start_position(i, 2);
            let body = new_body(Isometry3::translation(start.x, start.y, start.z));
            let camera_world: Arc<dyn World> = world.clone();
            let parts = RobotParts {
                frame_source: Box::new(move || {
                    Box::new(SimCameraSource::new(
                        camera_world.clone(),
                        CameraParams::default(),
                        i as u64,
                    ))
                }),
                vehicle: ActorSpec::new("vehicle", move || {
                    VehicleActor::new(SimVehicle::new(body.clone(), VehicleConfig::default()))
                }),
                route: world.centreline_route(i, 2),
                depart_at_s: 0.0,
                camera: CameraParams::default().intrinsics(),
                link_journal: LinkJournal::default(),
            };
            assemble(&format!("robot{i}"), &config, parts).unwrap()
        })
        .collect();
    // Frames, peer odometry messages, and each peer's positions as others saw them.
    let seen = Arc::new(Mutex::new((
        0usize,
        0usize,
        vec![Vec::<Point3<f64>>::new(); 2],
    )));
    let s = seen.clone();
    let mut executor = RealtimeExecutor::new(team, 1);
    executor.add_tap(move |p: &Publication<'_>| {
        let mut seen = s.lock().unwrap();
        if let Some(frame) = p.get(&DEPTH_FRAME) {
            seen.0 += 1;
            assert!(frame.valid_pixels() > 0);
        }
        if let Some(peer) = p.get(&PEER_ODOMETRY) {
            seen.1 += 1;
            seen.2[peer.robot.0 as usize].push(Point3::from(peer.odometry.pose.translation.vector));
        }
    });
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    // A robot moved (the planner committed plans through the collision actor, the
    // vehicle followed); whether both do soon is the planner's choice.
    let moved = |positions: &[Vec<Point3<f64>>]| {
        positions
            .iter()
            .filter(|p| p.len() >= 2 && (p[p.len() - 1] - p[0]).norm() > 0.3)
            .count()
    };
    // Wall-clock time on a busy machine varies: run until the checks hold (about
    // 3 s when the machine is idle), at most a minute.
    let done = |(frames, peers, positions): &(usize, usize, Vec<Vec<Point3<f64>>>)| {
        *frames >= 10 && *peers >= 10 && moved(positions) >= 1
    };
    let reports = runtime.block_on(async {
        let handle = executor.spawn();
        let started = std::time::Instant::now();
        while !done(&seen.lock().unwrap()) && started.elapsed() < Duration::from_secs(60) {
            tokio::time::sleep(Duration::from_millis(200)).await;
        }
        handle.shutdown().await
    });
    let (frames, peer_messages, peer_positions) = seen.lock().unwrap().clone();
    assert!(frames >= 10, "only {frames} frames");
    assert!(
        peer_messages >= 10,
        "only {peer_messages} peer odometry messages"
    );
    assert!(
        moved(&peer_positions) >= 1,
        "no robot moved: {peer_positions:?}"
    );
    for robot in &reports {
        assert!(
            robot
                .actors
                .iter()
                .all(|a| a.stats.panics == 0 && a.stats.errors == 0)
        );
        assert!(robot.topics["plan/committed"].messages >= 1);
        assert!(robot.actors.iter().any(|a| a.name == "planner"));
        assert!(robot.topics["grid/snapshot"].messages >= 1);
    }
}
