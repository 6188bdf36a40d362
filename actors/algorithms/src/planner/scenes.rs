//! Small synthetic planning scenes (fixed grid snapshots and a camera) shared by the
//! planner's tests, the selection policies' tests and the planner benchmarks.

use nalgebra::{Point3, Vector3};

use super::problem::PlanningProblem;
use super::round::RoundConfig;
use crate::camera::PinholeIntrinsics;
use crate::grid::distance::unsafe_distance;
use crate::grid::{FrontierSet, GridSnapshot};
use crate::grid::{LocalGrid, LogOddsParams};
use troupe_core::Time;

/// The forward depth camera of thesis §4.2.1 (89.57° × 59.24°, z_max = 5 m) at
/// 160 × 120 pixels, as the simulator renders it.
#[must_use]
pub fn forward_camera() -> PinholeIntrinsics {
    let (width, height) = (160u32, 120u32);
    let fx = f64::from(width) / 2.0 / (89.57f64.to_radians() / 2.0).tan();
    let fy = f64::from(height) / 2.0 / (59.24f64.to_radians() / 2.0).tan();
    PinholeIntrinsics {
        width,
        height,
        fx,
        fy,
        cx: f64::from(width) / 2.0,
        cy: f64::from(height) / 2.0,
        max_depth_m: 5.0,
    }
}

/// A planning round in a scene: what a [`PlanningProblem`] borrows, with the
/// [`forward_camera`] and the default [`RoundConfig`].
pub struct SceneRound {
    /// The scene's grid and distance fields.
    pub snapshot: GridSnapshot,
    /// [`forward_camera`].
    pub camera: PinholeIntrinsics,
    /// `RoundConfig::default()`.
    pub config: RoundConfig,
}

impl SceneRound {
    /// A round in `snapshot`.
    #[must_use]
    pub fn new(snapshot: GridSnapshot) -> Self {
        SceneRound {
            snapshot,
            camera: forward_camera(),
            config: RoundConfig::default(),
        }
    }

    /// The planning problem of this round.
    #[must_use]
    pub fn problem(&self) -> PlanningProblem<'_> {
        PlanningProblem::new(&self.config, &self.snapshot, &self.camera)
    }
}

/// A snapshot of `grid` with its distance fields.
#[must_use]
pub fn snapshot_of(grid: LocalGrid) -> GridSnapshot {
    GridSnapshot {
        stamp: Time::ZERO,
        unsafe_distance_m: unsafe_distance(&grid),
        frontiers: FrontierSet::of(&grid),
        grid,
    }
}

/// A room around the origin: a 20 m × 20 m × 6 m grid at 0.2 m in which the
/// cylinder of `radius_m` around the z axis, `half_height_m` above and below z = 0,
/// was seen free (rays
/// ending on a rock wall), except a doorway of half-angle `door_half_angle_rad`
/// around +x whose rays end free at the radius, leaving unknown space (a frontier)
/// behind it.
#[must_use]
pub fn room_with_doorway(
    radius_m: f64,
    half_height_m: f64,
    door_half_angle_rad: f64,
) -> GridSnapshot {
    let mut grid = LocalGrid::centred(
        &Point3::origin(),
        &Vector3::new(20.0, 20.0, 6.0),
        0.2,
        LogOddsParams::default(),
    );
    // Eyes stacked along the z axis see the whole cylinder, not just a fan.
    let eyes = (half_height_m / 0.2).floor() as i32;
    for _ in 0..2 {
        for eye_z in -eyes..=eyes {
            let eye = Point3::new(0.0, 0.0, 0.2 * f64::from(eye_z));
            for az in 0..360 {
                let azimuth = f64::from(az).to_radians();
                let door = azimuth.sin().atan2(azimuth.cos()).abs() < door_half_angle_rad;
                for el in -12..=12 {
                    let end = Point3::new(
                        azimuth.cos() * radius_m,
                        azimuth.sin() * radius_m,
                        half_height_m * f64::from(el) / 12.0,
                    );
                    grid.insert_ray(&eye, &end, !door, None);
                }
            }
        }
    }
    snapshot_of(grid)
}

/// A straight corridor along +x from x = −2 m to x = `length_m`, `half_width_m` wide
/// on each side and `half_height_m` above and below z = 0, seen free with rock
/// walls, open (unknown) beyond its far end; in a 20 m × 20 m × 6 m grid at 0.2 m
/// centred on the origin.
#[must_use]
pub fn corridor(length_m: f64, half_width_m: f64, half_height_m: f64) -> GridSnapshot {
    let mut grid = LocalGrid::centred(
        &Point3::origin(),
        &Vector3::new(20.0, 20.0, 6.0),
        0.2,
        LogOddsParams::default(),
    );
    let step_m = 0.1;
    let steps = ((length_m + 2.0) / step_m).ceil() as usize;
    for _ in 0..4 {
        for i in 0..=steps {
            let x = -2.0 + step_m * i as f64;
            let eye = Point3::new(x, 0.0, 0.0);
            // Side walls and floor/ceiling seen from the corridor's axis.
            for k in 0..=16 {
                let s = -1.0 + 2.0 * f64::from(k) / 16.0;
                for end in [
                    Point3::new(x, half_width_m, s * half_height_m),
                    Point3::new(x, -half_width_m, s * half_height_m),
                    Point3::new(x, s * half_width_m, half_height_m),
                    Point3::new(x, s * half_width_m, -half_height_m),
                ] {
                    grid.insert_ray(&eye, &end, true, None);
                }
            }
        }
    }
    snapshot_of(grid)
}
