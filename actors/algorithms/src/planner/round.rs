//! One planning round as plain code: generate the library's primitives from a state,
//! keep the feasible and safe ones, score them (thesis §4.1.3, paper V-B).

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use super::csqmi::ViewRewardParams;
use super::library::{self, LibraryParams, LibrarySpec};
use super::primitives::{Action, DynamicLimits, FlatState, Primitive};
use crate::grid::GridSnapshot;

/// A feasible, safe candidate and its reward.
#[derive(Clone, Debug)]
pub struct Candidate {
    /// Index of its action in the library ([`PlanningProblem::actions`](super::problem::PlanningProblem::actions)).
    pub action_index: usize,
    /// The primitive.
    pub primitive: Primitive,
    /// The stopping primitive from its state one planning period in.
    pub stopping: Primitive,
    /// CSQMI of the view at the end pose (or the mean over poses along the
    /// primitive, [`RoundConfig::information_samples`]), nats.
    pub information: f64,
    /// Frontier-distance reward V = d(ξ₀) − d(ξτ), metres (0 when there is no frontier).
    pub frontier_gain_m: f64,
    /// Objective I + αV (divided by the duration τ when
    /// [`RoundConfig::reward_per_second`] is set).
    pub reward: f64,
}

/// Which library to plan with.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LibraryChoice {
    /// Thesis Table 4.2b (40 primitives).
    Minimal,
    /// Thesis Table 4.2a (186 primitives).
    Large,
    /// Paper Table I (65 primitives).
    Paper,
}

impl LibraryChoice {
    /// The library's specs.
    #[must_use]
    pub fn specs(self) -> Vec<LibrarySpec> {
        match self {
            LibraryChoice::Minimal => library::minimal(),
            LibraryChoice::Large => library::large(),
            LibraryChoice::Paper => library::paper(),
        }
    }
}

/// Settings of a planning round.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RoundConfig {
    /// Library.
    pub library: LibraryChoice,
    /// Library bounds.
    pub library_params: LibraryParams,
    /// Dynamic limits and duration search.
    pub limits: DynamicLimits,
    /// Weight α of the frontier reward (paper Eq. 8).
    pub frontier_weight: f64,
    /// CSQMI beam settings.
    pub view: ViewRewardParams,
    /// Required clearance of the robot centre from unsafe space, metres (r_coll).
    pub collision_radius_m: f64,
    /// Time between collision checks along a primitive, seconds.
    pub check_step_s: f64,
    /// Planning period Δt_p: the primitive runs this long before its stopping
    /// primitive takes over, seconds.
    pub planning_period_s: f64,
    /// Views scored per primitive: 1 scores the end pose only (thesis §4.1.3);
    /// n > 1 averages the views at τ/n, 2τ/n, …, τ.
    pub information_samples: usize,
    /// Score a primitive by its objective per second of duration (a rate, so short
    /// and long primitives compare fairly) instead of the objective itself.
    pub reward_per_second: bool,
    /// Anytime tree search settings (used by search policies such as MCTS).
    pub search: SearchParams,
}

impl Default for RoundConfig {
    fn default() -> Self {
        RoundConfig {
            library: LibraryChoice::Minimal,
            library_params: LibraryParams {
                max_speed_mps: 1.5,
                perpendicular_speed_mps: 1.0,
                ..LibraryParams::default()
            },
            limits: DynamicLimits {
                max_accel_mps2: 3.0,
                max_jerk_mps3: 10.0,
                ..DynamicLimits::default()
            },
            frontier_weight: 5.0,
            view: ViewRewardParams::default(),
            collision_radius_m: 0.4,
            check_step_s: 0.1,
            planning_period_s: 1.0,
            information_samples: 1,
            reward_per_second: false,
            search: SearchParams::default(),
        }
    }
}

/// The body pose of a flat state (level, heading ψ).
#[must_use]
pub fn pose_of(state: &FlatState) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::from(state.position_m()),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), state.yaw_rad()),
    )
}

/// The clearance every sample of a trajectory starting `start_clearance_m` from
/// unsafe space must keep, for a required `margin_m`: the margin itself, or — when the
/// start is already inside the margin — the start's own clearance, so that a robot the
/// map has closed in on (new occupied or unknown cells within the margin) may turn in
/// place or back away but never come closer than where it hovers; a trajectory that
/// keeps this is no less safe than hovering. The thesis sends the stopping trajectory
/// whenever nothing keeps the margin (§4.1.3); from inside the margin that would stop
/// the robot for good, since every candidate starts there. `None` when the start is in
/// unsafe space itself (clearance 0): nothing may leave.
#[must_use]
pub fn required_clearance_m(margin_m: f64, start_clearance_m: f64) -> Option<f64> {
    if start_clearance_m >= margin_m {
        Some(margin_m)
    } else if start_clearance_m > 0.0 {
        Some(start_clearance_m)
    } else {
        None
    }
}

/// Whether every sample of `primitive` on `[0, until_s]` keeps `margin_m` from unsafe space.
pub(super) fn safe(
    primitive: &Primitive,
    until_s: f64,
    snapshot: &GridSnapshot,
    margin_m: f64,
    step_s: f64,
) -> bool {
    let n = (until_s / step_s.max(1e-3)).ceil().max(1.0) as usize;
    (0..=n).all(|i| {
        let p = Point3::from(
            primitive
                .state_at(until_s * i as f64 / n as f64)
                .position_m(),
        );
        snapshot.clearance_m(&p) >= margin_m
    })
}

impl RoundConfig {
    /// Clearance a sample point needs in the distance field: r_coll plus the
    /// discretisation slack (the field measures between cell centres).
    #[must_use]
    pub fn margin_m(&self, resolution_m: f64) -> f64 {
        self.collision_radius_m + resolution_m * (3f64.sqrt() + 1.0) / 2.0
    }

    /// The primitive for an action: fixed duration, or the shortest feasible one.
    #[must_use]
    pub fn primitive(
        &self,
        from: &FlatState,
        action: Action,
        fixed_duration_s: Option<f64>,
    ) -> Option<Primitive> {
        match fixed_duration_s {
            Some(tau) => {
                let p = Primitive::forward_arc(from, action, tau);
                self.limits.admits(&p).then_some(p)
            }
            None => self.limits.shortest(from, action),
        }
    }

    /// Checks a primitive and its stopping primitive against the snapshot; returns
    /// the stopping primitive when both are safe.
    ///
    /// Both must keep [`Self::margin_m`] from unsafe space, or — when the primitive
    /// starts inside that margin — never come closer to unsafe space than its start
    /// ([`required_clearance_m`]).
    #[must_use]
    pub fn safe_with_stop(
        &self,
        primitive: &Primitive,
        snapshot: &GridSnapshot,
    ) -> Option<Primitive> {
        let start = Point3::from(primitive.state_at(0.0).position_m());
        let margin = required_clearance_m(
            self.margin_m(snapshot.grid.resolution_m()),
            snapshot.clearance_m(&start),
        )?;
        let switch = self.planning_period_s.min(primitive.duration_s());
        if !safe(primitive, switch, snapshot, margin, self.check_step_s) {
            return None;
        }
        let stopping = self.limits.stopping(&primitive.state_at(switch))?;
        safe(
            &stopping,
            stopping.duration_s(),
            snapshot,
            margin,
            self.check_step_s,
        )
        .then_some(stopping)
    }
}

/// Settings of the anytime tree search (thesis §4.1.3).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SearchParams {
    /// Wall-clock budget of one search, seconds (anytime: the best branch found when
    /// it runs out is returned). A search always finishes its current iteration.
    pub budget_s: f64,
    /// Optional cap on iterations; with a cap and a budget that is never reached the
    /// search is deterministic for a given random stream (tests, reproducible runs).
    pub max_iterations: Option<usize>,
    /// Deepest branch, in primitives (1 = single-step).
    pub max_depth: usize,
    /// UCT exploration constant c (scaled by the largest root reward magnitude).
    pub exploration: f64,
    /// Discount γ of rewards deeper in a branch (return = Σ γ^k r_k).
    pub discount: f64,
}

impl Default for SearchParams {
    fn default() -> Self {
        SearchParams {
            budget_s: 0.5,
            max_iterations: Some(400),
            max_depth: 3,
            exploration: std::f64::consts::FRAC_1_SQRT_2,
            discount: 0.9,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::required_clearance_m;

    #[test]
    fn required_clearance_is_the_margin_or_the_start_inside_it() {
        assert_eq!(required_clearance_m(0.6, 1.2), Some(0.6));
        assert_eq!(required_clearance_m(0.6, 0.6), Some(0.6));
        assert_eq!(required_clearance_m(0.6, 0.4), Some(0.4));
        assert_eq!(required_clearance_m(0.6, 0.0), None);
    }
}
