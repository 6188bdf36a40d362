//! Variable resolution and Hierarchical Collision Avoidance (thesis §5.1, Alg. 1).
//!
//! The local map keeps a fixed number of voxels `N_x × N_y × N_z` (default 40 × 20 ×
//! 20, Table 5.1) and adapts the voxel size α between α_min and α_max in steps of Δα:
//! each round starts one step coarser than the last (Alg. 1 line 2) and, while the
//! selected motion is in collision in the map at α, regenerates the map one step finer
//! (lines 8–12), at most three levels per round (line 4). A coarse map reaches far
//! (the box is `α·N` wide) but closes narrow openings; a fine one resolves them but
//! sees little ahead (Fig. 5.2).
//!
//! The map is regenerated from the latest and one past keyframe (§5.1.1):
//! [`KeyframePair`] keeps them, [`hca_round`] runs Alg. 1 over any map builder and
//! collision test, and [`straight_path_in_collision`] is the test the grid actor uses
//! for the motion the robot is about to fly.

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

use troupe_core::ConfigError;

use super::distance::{DistanceField, unsafe_distance};
use super::{CellBox, ComponentStore, KeyframeSource, LocalGrid, LogOddsParams, UpdateRule};
use crate::keyframe::Keyframe;

/// Settings of the variable-resolution map (thesis §5.1, Table 5.1). Off by default.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HcaConfig {
    /// Publish the variable-resolution map instead of the fixed moving window.
    pub enabled: bool,
    /// Voxels along x, y, z (`N_x, N_y, N_z`), fixed while α changes.
    pub voxels: [usize; 3],
    /// Finest voxel size α_min, metres.
    pub alpha_min_m: f64,
    /// Coarsest voxel size α_max, metres.
    pub alpha_max_m: f64,
    /// Step Δα between levels, metres.
    pub alpha_step_m: f64,
    /// Most map levels tried in one round (Alg. 1 line 4: three).
    pub max_levels: u32,
    /// Robot radius `r_robot`, metres.
    pub robot_radius_m: f64,
    /// Extra clearance `r_coll` required from unsafe space, metres.
    pub collision_margin_m: f64,
    /// Length of the straight motion checked ahead of the robot, metres (clipped to
    /// what the map shows ahead: `α·N_x/2 − r_robot − r_coll`).
    pub lookahead_m: f64,
    /// β: the past keyframe is the newest one at least this far from the latest,
    /// metres.
    pub past_keyframe_distance_m: f64,
}

impl Default for HcaConfig {
    fn default() -> Self {
        HcaConfig {
            enabled: false,
            voxels: [40, 20, 20],
            alpha_min_m: 0.1,
            alpha_max_m: 0.5,
            alpha_step_m: 0.01,
            max_levels: 3,
            robot_radius_m: 0.3,
            collision_margin_m: 0.1,
            lookahead_m: 2.0,
            past_keyframe_distance_m: 1.0,
        }
    }
}

impl HcaConfig {
    /// Checks the numbers; the error names the field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.voxels.iter().any(|n| *n < 2 || *n > 512) {
            return Err(ConfigError::new(
                "voxels",
                "must be between 2 and 512 per axis",
                format!("{:?}", self.voxels),
            ));
        }
        if !(self.alpha_min_m.is_finite() && self.alpha_min_m >= 0.01) {
            return Err(ConfigError::new(
                "alpha_min_m",
                "must be ≥ 0.01",
                self.alpha_min_m,
            ));
        }
        if !(self.alpha_max_m.is_finite() && self.alpha_max_m >= self.alpha_min_m) {
            return Err(ConfigError::new(
                "alpha_max_m",
                format!("must be ≥ alpha_min_m ({})", self.alpha_min_m),
                self.alpha_max_m,
            ));
        }
        ConfigError::positive("alpha_step_m", self.alpha_step_m)?;
        if self.level_count() > 10_000 {
            return Err(ConfigError::new(
                "alpha_step_m",
                "must leave at most 10000 levels between alpha_min_m and alpha_max_m",
                self.alpha_step_m,
            ));
        }
        if self.max_levels == 0 {
            return Err(ConfigError::new("max_levels", "must be ≥ 1", 0));
        }
        for (key, value) in [
            ("robot_radius_m", self.robot_radius_m),
            ("collision_margin_m", self.collision_margin_m),
            ("lookahead_m", self.lookahead_m),
            ("past_keyframe_distance_m", self.past_keyframe_distance_m),
        ] {
            ConfigError::non_negative(key, value)?;
        }
        Ok(())
    }

    /// Number of voxel sizes: levels `0..level_count()`, level 0 = α_min.
    #[must_use]
    pub fn level_count(&self) -> u32 {
        let span = ((self.alpha_max_m - self.alpha_min_m) / self.alpha_step_m + 1e-9).floor();
        if span.is_finite() && span >= 0.0 {
            (span.min(f64::from(u32::MAX - 1)) as u32) + 1
        } else {
            1
        }
    }

    /// The coarsest level (α_max, or the last step below it).
    #[must_use]
    pub fn top_level(&self) -> u32 {
        self.level_count() - 1
    }

    /// Voxel size of a level: `α_min + level·Δα`, clamped to `[α_min, α_max]`.
    #[must_use]
    pub fn alpha_m(&self, level: u32) -> f64 {
        (self.alpha_min_m + f64::from(level.min(self.top_level())) * self.alpha_step_m)
            .clamp(self.alpha_min_m, self.alpha_max_m)
    }

    /// The extent of the map at voxel size `alpha_m`, metres.
    #[must_use]
    pub fn size_m(&self, alpha_m: f64) -> Vector3<f64> {
        Vector3::from(self.voxels.map(|n| n as f64 * alpha_m))
    }

    /// Clearance a motion needs from unsafe space, `r_robot + r_coll`, metres.
    #[must_use]
    pub fn required_clearance_m(&self) -> f64 {
        self.robot_radius_m + self.collision_margin_m
    }

    /// Length of the straight motion checked at voxel size `alpha_m`: the lookahead,
    /// at most what the map shows ahead of the robot (`z_eq` of Eq. 5.1 less the
    /// clearance).
    #[must_use]
    pub fn path_length_m(&self, alpha_m: f64) -> f64 {
        let ahead = alpha_m * self.voxels[0] as f64 / 2.0 - self.required_clearance_m();
        self.lookahead_m.min(ahead).max(0.0)
    }
}

/// The result of one planning round of Alg. 1.
#[derive(Clone, Debug)]
pub struct HcaRound {
    /// The level to start the next round from (`α_prev`, Alg. 1 line 17).
    pub level: u32,
    /// The last map generated, and its unsafe-distance field.
    pub grid: LocalGrid,
    /// Distance to unsafe space per cell of `grid`.
    pub unsafe_distance_m: DistanceField,
    /// Maps generated this round (1 to `max_levels`).
    pub levels_tried: u32,
    /// Whether the motion was collision-free in the last map (Alg. 1 line 21); if not,
    /// the previous stopping action should be flown (line 19).
    pub feasible: bool,
}

/// One round of Hierarchical Collision Avoidance (thesis Alg. 1): start one level
/// above `prev_level` (clamped), generate the map with `local_map(α)` and its distance
/// field, and while `in_collision(map, distance)` holds go one level finer, up to
/// `max_levels` maps. The returned level is the one the round ended on: after a
/// failure at the last map it is one finer still (line 11 runs before the loop ends).
pub fn hca_round(
    config: &HcaConfig,
    prev_level: u32,
    mut local_map: impl FnMut(f64) -> LocalGrid,
    mut in_collision: impl FnMut(&LocalGrid, &DistanceField) -> bool,
) -> HcaRound {
    let mut level = prev_level.saturating_add(1).min(config.top_level());
    let mut tried = 0;
    loop {
        let grid = local_map(config.alpha_m(level));
        let distance = unsafe_distance(&grid);
        tried += 1;
        let collides = in_collision(&grid, &distance);
        if collides {
            level = level.saturating_sub(1);
        }
        if !collides || tried >= config.max_levels {
            return HcaRound {
                level,
                grid,
                unsafe_distance_m: distance,
                levels_tried: tried,
                feasible: !collides,
            };
        }
    }
}

/// Whether the straight motion from `start` along `direction` for `length_m` comes
/// closer than `clearance_m` to unsafe space (occupied or unknown) in `grid`, whose
/// unsafe-distance field is `distance`. Points are checked every half cell; a point
/// outside the map is in collision (unknown). The clearance of a point is its cell's
/// distance less half a cell (the distance field runs between cell centres).
#[must_use]
pub fn straight_path_in_collision(
    grid: &LocalGrid,
    distance: &DistanceField,
    start: &Point3<f64>,
    direction: &Vector3<f64>,
    length_m: f64,
    clearance_m: f64,
) -> bool {
    let norm = direction.norm();
    if !(norm.is_finite() && norm > 0.0 && length_m.is_finite()) {
        return true;
    }
    let dir = direction / norm;
    let half_cell = grid.resolution_m() / 2.0;
    let steps = (length_m.max(0.0) / half_cell).ceil() as usize;
    (0..=steps).any(|i| {
        let p = start + dir * (length_m * i as f64 / steps.max(1) as f64);
        grid.cell_of(&p).is_none_or(|c| {
            distance
                .get(grid.index(c))
                .is_none_or(|d| d - half_cell < clearance_m)
        })
    })
}

/// The latest keyframe and a past one at least β away (thesis §5.1.1), from which the
/// variable-resolution map is regenerated.
#[derive(Clone, Debug, Default)]
pub struct KeyframePair {
    recent: Vec<Keyframe>,
}

/// Most recent keyframes kept to pick the past one from.
const RECENT_KEYFRAMES: usize = 32;

impl KeyframePair {
    /// Records a new latest keyframe (non-finite poses are ignored).
    pub fn push(&mut self, keyframe: &Keyframe) {
        if !keyframe
            .pose
            .translation
            .vector
            .iter()
            .all(|v| v.is_finite())
        {
            return;
        }
        if self.recent.len() >= RECENT_KEYFRAMES {
            self.recent.remove(0);
        }
        self.recent.push(keyframe.clone());
    }

    /// The latest keyframe.
    #[must_use]
    pub fn latest(&self) -> Option<&Keyframe> {
        self.recent.last()
    }

    /// The newest keyframe whose sensor position is at least `beta_m` from the
    /// latest's.
    #[must_use]
    pub fn past(&self, beta_m: f64) -> Option<&Keyframe> {
        let latest = self.latest()?.pose.translation.vector;
        self.recent
            .iter()
            .rev()
            .skip(1)
            .find(|k| (k.pose.translation.vector - latest).norm() >= beta_m)
    }
}

impl KeyframePair {
    /// A store holding the past keyframe (if any) and the latest, in that order, to
    /// regenerate maps from (`max_samples` points per keyframe at most), updating by
    /// `rule`.
    #[must_use]
    pub fn store(&self, beta_m: f64, max_samples: usize, rule: UpdateRule) -> ComponentStore {
        let mut store = ComponentStore::new(max_samples, 2, 4.0).with_rule(rule);
        for keyframe in self.past(beta_m).into_iter().chain(self.latest()) {
            store.insert(KeyframeSource::Own, keyframe);
        }
        store
    }
}

/// The local map of Alg. 1 line 8: `N_x × N_y × N_z` voxels of `alpha_m` centred on
/// `centre`, ray-traced from every keyframe in `store`.
#[must_use]
pub fn regenerate(
    config: &HcaConfig,
    logodds: LogOddsParams,
    centre: &Point3<f64>,
    alpha_m: f64,
    store: &mut ComponentStore,
) -> LocalGrid {
    let mut grid = LocalGrid::centred(centre, &config.size_m(alpha_m), alpha_m, logodds);
    let whole = CellBox {
        min: [0; 3],
        max: grid.dims(),
    };
    store.rebuild(&mut grid, &[whole]);
    grid
}
