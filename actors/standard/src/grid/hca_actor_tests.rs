//! The grid actor on the window flight of thesis §5.2.1: odometry and own keyframes
//! in, snapshots at the resolution Hierarchical Collision Avoidance adapts out.
#![allow(clippy::unwrap_used)]

use std::sync::{Arc, Mutex};
use std::time::Duration;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use troupe_algorithms::grid::hca::HcaConfig;
use troupe_algorithms::grid::window_scene::{keyframe_at, window_scene};
use troupe_algorithms::grid::{GridConfig, UpdateRule};
use troupe_algorithms::sogmm::synthetic::Scene;
use troupe_runtime::{
    Actor, ActorResult, ActorSpec, Context, Event, QueuePolicy, RobotSpec, SimExecutor, Time,
    TimerId,
};

use super::GridActor;
use crate::msgs::{GRID_SNAPSHOT, KEYFRAME, ODOMETRY};
use troupe_algorithms::frame::Odometry;

/// Flies along +x at 1 m/s, publishing odometry and a keyframe every 0.2 s.
struct Flyer {
    step: u32,
    scene: Scene,
}

impl Actor for Flyer {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.set_timer(TimerId(0), Duration::from_millis(200));
        Ok(())
    }
    fn handle(&mut self, _: &Event, ctx: &mut Context<'_>) -> ActorResult {
        let x = f64::from(self.step) * 0.2;
        let pose =
            Isometry3::from_parts(Translation3::new(x, 0.0, 0.0), UnitQuaternion::identity());
        ctx.publish(
            &ODOMETRY,
            Odometry {
                stamp: ctx.now(),
                pose,
                velocity_mps: Vector3::x(),
            },
        );
        ctx.publish(&KEYFRAME, keyframe_at(&self.scene, self.step, pose));
        self.step += 1;
        Ok(())
    }
}

/// Records the resolution of every snapshot with its time.
struct Sink(Arc<Mutex<Vec<(f64, f64)>>>);

impl Actor for Sink {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&GRID_SNAPSHOT, QueuePolicy::fifo(256));
        Ok(())
    }
    fn handle(&mut self, event: &Event, _: &mut Context<'_>) -> ActorResult {
        if let Some(s) = event.message().and_then(|m| m.get(&GRID_SNAPSHOT)) {
            let mut seen = self.0.lock().unwrap();
            seen.push((s.stamp.as_secs_f64(), s.resolution_m()));
        }
        Ok(())
    }
}

#[test]
fn the_grid_actor_adapts_its_resolution_along_the_flight() {
    let config = GridConfig {
        size_m: [12.0, 12.0, 6.0],
        publish_rate_hz: 5.0,
        peer_keyframe_samples: 4000,
        update_rule: UpdateRule::PerScan,
        hca: HcaConfig {
            enabled: true,
            alpha_step_m: 0.05,
            robot_radius_m: 0.25,
            collision_margin_m: 0.05,
            lookahead_m: 1.5,
            ..HcaConfig::default()
        },
        ..GridConfig::default()
    };
    config.validate().unwrap();
    let seen = Arc::new(Mutex::new(Vec::new()));
    let sink = seen.clone();
    let robot = RobotSpec::new("r0")
        .with(ActorSpec::new("flyer", move || Flyer {
            step: 0,
            scene: window_scene(),
        }))
        .with(ActorSpec::new("grid", move || GridActor::new(config)))
        .with(ActorSpec::new("sink", move || Sink(sink.clone())));
    let mut sim = SimExecutor::new(vec![robot], 1);
    sim.run_until(Time::from_secs_f64(16.5));
    let seen = seen.lock().unwrap().clone();
    assert!(seen.len() > 70);
    // At 1 m/s, the time is the distance flown (within a tick).
    let over = |lo: f64, hi: f64| -> Vec<f64> {
        seen.iter()
            .filter(|(t, _)| (lo..hi).contains(t))
            .map(|s| s.1)
            .collect()
    };
    let table = format!("{seen:?}");
    assert!(over(4.5, 7.5).iter().all(|a| *a >= 0.45 - 1e-9), "{table}");
    assert!(over(8.6, 10.4).iter().any(|a| *a <= 0.15 + 1e-9), "{table}");
    assert!(
        over(12.5, 16.5).iter().all(|a| *a >= 0.45 - 1e-9),
        "{table}"
    );
}
