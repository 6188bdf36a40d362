//! Hierarchical Collision Avoidance on the window scenario of thesis §5.2.1: a wall
//! with a 0.9 m × 0.9 m window 10 m ahead; the voxel size must shrink as the robot
//! approaches the window and grow again after it (Fig. 5.2).

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Matrix4, Point3, Translation3, UnitQuaternion, Vector3, Vector4};

use super::hca::{HcaConfig, KeyframePair, hca_round, regenerate, straight_path_in_collision};
use super::*;
use crate::mapper::sogmm::gmm::Gmm4;
use crate::mapper::sogmm::points::pixel_to_body;
use crate::mapper::sogmm::synthetic::{Rect, Scene, Texture};
use crate::msgs::{Keyframe, PinholeIntrinsics};
use crate::runtime::Time;

const WALL_X_M: f64 = 10.0;
const HALF_WINDOW_M: f64 = 0.45;

fn plane_x(x: f64, y: [f64; 2], z: [f64; 2]) -> Rect {
    Rect {
        origin: Point3::new(x, y[0], z[0]),
        u: Vector3::new(0.0, y[1] - y[0], 0.0),
        v: Vector3::new(0.0, 0.0, z[1] - z[0]),
        texture: Texture::Uniform(0.5),
    }
}

/// The wall at x = 10 m (10 m × 6 m) around a 0.9 m × 0.9 m window centred on the
/// flight line, and a back wall at x = 20 m that the robot sees through the window.
fn window_scene() -> Scene {
    let (w, h, a) = (5.0, 3.0, HALF_WINDOW_M);
    Scene {
        rects: vec![
            plane_x(WALL_X_M, [-w, -a], [-h, h]),
            plane_x(WALL_X_M, [a, w], [-h, h]),
            plane_x(WALL_X_M, [-a, a], [-h, -a]),
            plane_x(WALL_X_M, [-a, a], [a, h]),
            plane_x(20.0, [-8.0, 8.0], [-5.0, 5.0]),
        ],
    }
}

/// A wide camera (about 103° horizontal), 12 m range.
fn camera() -> PinholeIntrinsics {
    PinholeIntrinsics {
        width: 160,
        height: 120,
        fx: 64.0,
        fy: 64.0,
        cx: 80.0,
        cy: 60.0,
        max_depth_m: 12.0,
    }
}

/// A keyframe GMM built from the surface points the camera sees at `pose`: one
/// component per 0.225 m bin (the window edges fall on bin edges) of points (its sample mean and covariance).
pub(super) fn keyframe_at(scene: &Scene, id: u32, pose: Isometry3<f64>) -> Keyframe {
    let k = camera();
    let (depth, _) = scene.render(&k, &pose);
    let mut bins: BTreeMap<[i64; 3], Vec<Vector3<f64>>> = BTreeMap::new();
    for row in 0..k.height {
        for col in 0..k.width {
            let d = f64::from(depth[(row * k.width + col) as usize]);
            if d > 0.0 {
                let p = pose * pixel_to_body(&k, col, row, d);
                let key = [0, 1, 2].map(|i| (p[i] / 0.225).floor() as i64);
                bins.entry(key).or_default().push(p.coords);
            }
        }
    }
    let (mut weights, mut means, mut covariances) = (Vec::new(), Vec::new(), Vec::new());
    let mut support = 0;
    for points in bins.values().filter(|p| p.len() >= 3) {
        let n = points.len() as f64;
        let mean = points.iter().sum::<Vector3<f64>>() / n;
        let mut cov = Matrix4::identity() * 0.01;
        let spatial = points
            .iter()
            .map(|p| (p - mean) * (p - mean).transpose())
            .sum::<nalgebra::Matrix3<f64>>()
            / n
            + nalgebra::Matrix3::identity() * 1e-5;
        cov.fixed_view_mut::<3, 3>(0, 0).copy_from(&spatial);
        weights.push(n);
        means.push(Vector4::new(mean.x, mean.y, mean.z, 0.5));
        covariances.push(cov);
        support += points.len();
    }
    let total: f64 = weights.iter().sum();
    weights.iter_mut().for_each(|w| *w /= total);
    Keyframe {
        id,
        stamp: Time::ZERO,
        pose,
        support_size: support as u32,
        gmm: Gmm4::new(weights, means, covariances).unwrap(),
    }
}

#[test]
fn the_voxel_size_shrinks_at_the_window_and_grows_after_it() {
    let config = HcaConfig {
        enabled: true,
        alpha_min_m: 0.1,
        alpha_max_m: 0.5,
        alpha_step_m: 0.05,
        robot_radius_m: 0.25,
        collision_margin_m: 0.05,
        lookahead_m: 1.5,
        ..HcaConfig::default()
    };
    config.validate().unwrap();
    let scene = window_scene();
    let mut pair = KeyframePair::default();
    let mut level = config.top_level();
    let mut trace = Vec::new();
    for step in 0..=80u32 {
        let x = f64::from(step) * 0.2;
        let position = Point3::new(x, 0.0, 0.0);
        let pose = Isometry3::from_parts(
            Translation3::from(position.coords),
            UnitQuaternion::identity(),
        );
        pair.push(&keyframe_at(&scene, step, pose));
        let mut store = pair.store(config.past_keyframe_distance_m, 4000, UpdateRule::PerScan);
        let round = hca_round(
            &config,
            level,
            |alpha| {
                regenerate(
                    &config,
                    LogOddsParams::default(),
                    &position,
                    alpha,
                    &mut store,
                )
            },
            |grid, distance| {
                let length = config.path_length_m(grid.resolution_m());
                straight_path_in_collision(
                    grid,
                    distance,
                    &position,
                    &Vector3::x(),
                    length,
                    config.required_clearance_m(),
                )
            },
        );
        assert!(round.levels_tried >= 1 && round.levels_tried <= config.max_levels);
        assert_eq!(round.grid.dims(), config.voxels, "fixed voxel counts");
        level = round.level;
        trace.push((x, round.grid.resolution_m(), round.feasible));
    }
    let alpha_over = |lo: f64, hi: f64| -> Vec<f64> {
        trace
            .iter()
            .filter(|(x, _, _)| (lo..hi).contains(x))
            .map(|t| t.1)
            .collect()
    };
    let min = |v: Vec<f64>| v.into_iter().fold(f64::INFINITY, f64::min);
    let max = |v: Vec<f64>| v.into_iter().fold(0.0, f64::max);
    // The first metres are fine-grained too: without a past keyframe the camera's
    // frustum leaves unknown cells beside the robot (§5.1.1 keeps one for that).
    let far = alpha_over(4.5, 7.5);
    let near = alpha_over(8.8, 10.1);
    let after = alpha_over(12.0, 16.1);
    let table: Vec<String> = trace
        .iter()
        .map(|(x, a, f)| format!("{x:.1}:{a:.2}{}", if *f { "" } else { "!" }))
        .collect();
    let table = table.join(" ");
    assert!(max(far.clone()) > max(near.clone()));
    assert!(
        min(far.clone()) >= config.alpha_max_m - config.alpha_step_m - 1e-9,
        "far from the window the map stays coarse: {table}"
    );
    assert!(
        max(near.clone()) <= config.alpha_min_m + config.alpha_step_m + 1e-9,
        "at the window the map is fine: {table}"
    );
    assert!(
        min(after) >= config.alpha_max_m - config.alpha_step_m - 1e-9,
        "after the window the map coarsens again: {table}"
    );
}

mod actor {
    //! The same flight through the grid actor: odometry and own keyframes in,
    //! snapshots at the adapted resolution out.

    use std::sync::{Arc, Mutex};
    use std::time::Duration;

    use super::*;
    use crate::grid::{GridActor, GridConfig};
    use crate::msgs::{GRID_SNAPSHOT, KEYFRAME, ODOMETRY, Odometry};
    use crate::runtime::{
        Actor, ActorResult, ActorSpec, Context, Event, QueuePolicy, RobotSpec, SimExecutor, TimerId,
    };

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
}
