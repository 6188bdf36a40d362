//! Each view enters the grid once: with the robot's own depth frames traced, its own
//! keyframe of the same view is kept for rebuilding the boxes the moving window
//! uncovers, not traced again on arrival (it used to count the view twice).
#![allow(clippy::unwrap_used)]

use std::sync::{Arc, Mutex};
use std::time::Duration;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use troupe_algorithms::grid::window_scene::{camera, keyframe_at, window_scene};
use troupe_algorithms::grid::{GridConfig, UpdateRule};
use troupe_runtime::{
    Actor, ActorResult, ActorSpec, Context, Event, QueuePolicy, RobotSpec, SimExecutor, Time,
    TimerId,
};

use super::GridActor;
use crate::msgs::{DEPTH_FRAME, GRID_SNAPSHOT, KEYFRAME, ODOMETRY};
use troupe_algorithms::frame::{DepthFrame, Odometry};

/// At 5 m before the window wall: odometry at once, then the depth frame, then (if
/// `keyframe`) the keyframe fitted to the same view.
struct View {
    keyframe: bool,
    step: u32,
}

impl Actor for View {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.set_timer(TimerId(0), Duration::from_millis(100));
        Ok(())
    }
    fn handle(&mut self, _: &Event, ctx: &mut Context<'_>) -> ActorResult {
        let pose =
            Isometry3::from_parts(Translation3::new(5.0, 0.0, 0.0), UnitQuaternion::identity());
        let scene = window_scene();
        match self.step {
            0 => ctx.publish(
                &ODOMETRY,
                Odometry {
                    stamp: ctx.now(),
                    pose,
                    velocity_mps: Vector3::zeros(),
                },
            ),
            1 => {
                let k = camera();
                let (depth_m, intensity) = scene.render(&k, &pose);
                ctx.publish(
                    &DEPTH_FRAME,
                    DepthFrame {
                        stamp: ctx.now(),
                        pose,
                        intrinsics: k,
                        depth_m,
                        intensity,
                    },
                );
            }
            2 if self.keyframe => ctx.publish(&KEYFRAME, keyframe_at(&scene, 0, pose)),
            _ => {}
        }
        self.step += 1;
        Ok(())
    }
}

/// Keeps the cell values of the last snapshot.
struct Last(Arc<Mutex<Vec<f32>>>);

impl Actor for Last {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&GRID_SNAPSHOT, QueuePolicy::LATEST);
        Ok(())
    }
    fn handle(&mut self, event: &Event, _: &mut Context<'_>) -> ActorResult {
        if let Some(s) = event.message().and_then(|m| m.get(&GRID_SNAPSHOT)) {
            *self.0.lock().unwrap() = s.grid.values().to_vec();
        }
        Ok(())
    }
}

fn grid_after(trace_depth_frames: bool, keyframe: bool) -> Vec<f32> {
    let config = GridConfig {
        size_m: [12.0, 12.0, 6.0],
        publish_rate_hz: 2.0,
        update_rule: UpdateRule::PerScan,
        trace_depth_frames,
        ..GridConfig::default()
    };
    let last = Arc::new(Mutex::new(Vec::new()));
    let sink = last.clone();
    let robot = RobotSpec::new("r0")
        .with(ActorSpec::new("view", move || View { keyframe, step: 0 }))
        .with(ActorSpec::new("grid", move || GridActor::new(config)))
        .with(ActorSpec::new("last", move || Last(sink.clone())));
    let mut sim = SimExecutor::new(vec![robot], 1);
    sim.run_until(Time::from_secs_f64(2.0));
    let values = last.lock().unwrap().clone();
    assert!(!values.is_empty(), "the grid published a snapshot");
    values
}

#[test]
fn an_own_keyframe_does_not_count_a_traced_view_twice() {
    // Frames traced: the keyframe of the same view changes no cell.
    let frame_only = grid_after(true, false);
    assert!(
        frame_only.iter().any(|v| *v > 0.0),
        "the frame marked surfaces"
    );
    assert_eq!(frame_only, grid_after(true, true));
    // Frames not traced: the keyframe is the only evidence and enters the grid.
    let nothing = grid_after(false, false);
    let from_keyframe = grid_after(false, true);
    assert!(from_keyframe.iter().zip(&nothing).any(|(a, b)| a != b));
}
