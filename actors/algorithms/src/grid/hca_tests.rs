//! Hierarchical Collision Avoidance on the window scenario of thesis §5.2.1: a wall
//! with a 0.9 m × 0.9 m window 10 m ahead; the voxel size must shrink as the robot
//! approaches the window and grow again after it (Fig. 5.2).

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use super::hca::{HcaConfig, KeyframePair, hca_round, regenerate, straight_path_in_collision};
use super::window_scene::{keyframe_at, window_scene};
use super::*;

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
