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
            library_params: LibraryParams::default(),
            limits: DynamicLimits::default(),
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

/// Largest distance from its start a path may stray and still count as hovering
/// (turning in place), metres: see [`clear_path`].
pub const HOVER_TOLERANCE_M: f64 = 0.05;

/// Whether a path, given as positions in time order (the first is its start), keeps
/// clear of unsafe (occupied or unknown) space in `snapshot` for a required
/// clearance `margin_m` (thesis §4.1.3: a candidate is kept only if it and its
/// stopping trajectory are collision-free).
///
/// From a start with at least `margin_m` clearance, every position must keep it.
/// A start the map has closed in on (new occupied or unknown cells within the
/// margin) would stop the robot for good under that rule, since every candidate
/// starts there (the thesis then sends the stopping trajectory); from such a start
/// a path is clear when no position comes closer to unsafe space than the start
/// *and* the path either hovers (every position within [`HOVER_TOLERANCE_M`] of the
/// start: turning in place) or ends at least one cell farther from unsafe space than
/// it started (or at the margin): it backs away. Keeping the start's clearance alone
/// is not enough — the distance field is measured between cell centres, so a path
/// can keep the same field value while coming up to half a cell diagonal closer to
/// the rock, and round after round a robot inside the margin could creep into it.
/// `false` when the start is in unsafe space itself, or when there is no position.
pub fn clear_path(
    positions: impl IntoIterator<Item = Point3<f64>>,
    snapshot: &GridSnapshot,
    margin_m: f64,
) -> bool {
    let mut positions = positions.into_iter();
    let Some(start) = positions.next() else {
        return false;
    };
    let start_clearance_m = snapshot.clearance_m(&start);
    if start_clearance_m <= 0.0 {
        return false;
    }
    if start_clearance_m >= margin_m {
        return positions.all(|p| snapshot.clearance_m(&p) >= margin_m);
    }
    let mut hovers = true;
    let mut end_clearance_m = start_clearance_m;
    for p in positions {
        end_clearance_m = snapshot.clearance_m(&p);
        if end_clearance_m < start_clearance_m {
            return false;
        }
        hovers &= (p - start).norm() <= HOVER_TOLERANCE_M;
    }
    let backs_away_m = (start_clearance_m + snapshot.resolution_m()).min(margin_m);
    hovers || end_clearance_m >= backs_away_m
}

/// Positions of `primitive` on `[0, until_s]`, at most `step_s` apart (both ends included).
fn samples(primitive: &Primitive, until_s: f64, step_s: f64) -> impl Iterator<Item = Point3<f64>> {
    let n = (until_s / step_s.max(1e-3)).ceil().max(1.0) as usize;
    (0..=n).map(move |i| {
        Point3::from(
            primitive
                .state_at(until_s * i as f64 / n as f64)
                .position_m(),
        )
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

    /// Checks a primitive (up to the planning period) followed by its stopping
    /// primitive against the snapshot, as one path ([`clear_path`] with
    /// [`Self::margin_m`]); returns the stopping primitive when the path is clear.
    #[must_use]
    pub fn safe_with_stop(
        &self,
        primitive: &Primitive,
        snapshot: &GridSnapshot,
    ) -> Option<Primitive> {
        let switch = self.planning_period_s.min(primitive.duration_s());
        let stopping = self.limits.stopping(&primitive.state_at(switch))?;
        let path = samples(primitive, switch, self.check_step_s)
            .chain(samples(&stopping, stopping.duration_s(), self.check_step_s).skip(1));
        clear_path(path, snapshot, self.margin_m(snapshot.grid.resolution_m())).then_some(stopping)
    }
}

/// Settings of the anytime tree search (thesis §4.1.3).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SearchParams {
    /// Wall-clock budget of one search under the wall clock, seconds (anytime: the
    /// best branch found when it runs out is returned). A search always finishes its
    /// current iteration. Not used under simulated time ([`Self::sim_iterations`]).
    pub budget_s: f64,
    /// Optional cap on iterations under the wall clock; with a cap and a budget that is
    /// never reached the search is deterministic for a given random stream. Not used
    /// under simulated time ([`Self::sim_iterations`]).
    pub max_iterations: Option<usize>,
    /// Iterations of one search under simulated time
    /// ([`TimeSource::Simulated`](troupe_core::TimeSource::Simulated)), where it never
    /// reads the wall clock: a fixed amount of work, so that a simulated flight depends
    /// on its seed alone and not on the machine or its load (the wall clock budget
    /// could end the same search after a different number of iterations run to run).
    /// The default, [`SearchParams::DEFAULT_SIM_ITERATIONS`], is what the search did
    /// within its wall-clock defaults on the default scenario.
    pub sim_iterations: usize,
    /// Deepest branch, in primitives (1 = single-step).
    pub max_depth: usize,
    /// UCT exploration constant c (scaled by the largest root reward magnitude).
    pub exploration: f64,
    /// Discount γ of rewards deeper in a branch (return = Σ γ^k r_k).
    pub discount: f64,
}

impl SearchParams {
    /// The default of [`Self::sim_iterations`]: the median number of iterations a
    /// search completed within the wall-clock defaults (0.5 s budget, cap 400) on the
    /// default scenario with `selection = "mcts"`, 120 s, seeds 1–3: 400, the cap. Of
    /// its 714 searches 695 reached the cap, 6 were cut short by the wall clock after
    /// 335–391 iterations and 13 had no candidate (2026-11-28, dev build, the 2-core
    /// machine at load 4–6). Simulated flights are those the search flew whenever the
    /// wall clock did not cut it short.
    pub const DEFAULT_SIM_ITERATIONS: usize = 400;
}

impl Default for SearchParams {
    fn default() -> Self {
        SearchParams {
            budget_s: 0.5,
            max_iterations: Some(400),
            sim_iterations: SearchParams::DEFAULT_SIM_ITERATIONS,
            max_depth: 3,
            exploration: std::f64::consts::FRAC_1_SQRT_2,
            discount: 0.9,
        }
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::Point3;

    use super::clear_path;
    use crate::planner::scenes::corridor;

    fn line(from: [f64; 3], to: [f64; 3], n: usize) -> Vec<Point3<f64>> {
        let (a, b) = (Point3::from(from), Point3::from(to));
        (0..=n)
            .map(|i| a + (b - a) * (i as f64 / n as f64))
            .collect()
    }

    #[test]
    fn outside_the_margin_every_position_keeps_it() {
        let snapshot = corridor(8.0, 1.5, 1.5);
        let margin_m = 0.8;
        assert!(snapshot.clearance_m(&Point3::origin()) >= margin_m);
        assert!(clear_path(
            line([0.0; 3], [4.0, 0.0, 0.0], 40),
            &snapshot,
            margin_m
        ));
        assert!(!clear_path(
            line([0.0; 3], [0.0, 1.4, 0.0], 40),
            &snapshot,
            margin_m
        ));
        assert!(!clear_path(Vec::new(), &snapshot, margin_m));
    }

    #[test]
    fn inside_the_margin_a_path_hovers_or_backs_away_but_never_creeps_along() {
        let snapshot = corridor(8.0, 1.5, 1.5);
        let margin_m = 1.2;
        // Near the +y wall, inside the margin.
        let start = [1.0, 0.9, 0.0];
        let c0 = snapshot.clearance_m(&Point3::from(start));
        assert!(c0 > 0.0 && c0 < margin_m, "{c0}");
        // Along the wall the field value stays the same: the old rule (never closer
        // than the start) let a robot creep on like this round after round.
        let along = line(start, [3.0, 0.9, 0.0], 20);
        assert!(along.iter().all(|p| snapshot.clearance_m(p) >= c0));
        assert!(!clear_path(along, &snapshot, margin_m));
        // Turning in place is as safe as hovering.
        assert!(clear_path(vec![start.into(); 5], &snapshot, margin_m));
        // Backing away to the corridor's axis is clear.
        assert!(clear_path(
            line(start, [1.0, 0.0, 0.0], 20),
            &snapshot,
            margin_m
        ));
        // Coming closer is not.
        assert!(!clear_path(
            line(start, [1.0, 1.2, 0.0], 20),
            &snapshot,
            margin_m
        ));
    }

    #[test]
    fn nothing_leaves_unsafe_space() {
        let snapshot = corridor(8.0, 1.5, 1.5);
        // Beyond the far end: unknown.
        let start = [9.5, 0.0, 0.0];
        assert!(snapshot.clearance_m(&Point3::from(start)) <= 0.0);
        assert!(!clear_path(line(start, [0.0; 3], 40), &snapshot, 0.5));
    }
}
