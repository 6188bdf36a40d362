//! The planning problem of one round as a generator of scored children (thesis
//! §4.1.3): from any state of a search tree it builds the library's primitive for one
//! action, checks it for kinodynamic feasibility and safety (with its stopping
//! primitive) and scores it. Single-step selection uses the children of the root
//! only; tree search (MCTS) expands deeper states through the same calls.

use nalgebra::Point3;
use rayon::prelude::*;
use troupe_core::TimeSource;

use super::csqmi::view_information;
use super::library;
use super::primitives::{Action, FlatState, Primitive};
pub use super::round::SearchParams;
use super::round::{Candidate, RoundConfig, pose_of};
use crate::camera::PinholeIntrinsics;
use crate::grid::GridSnapshot;

/// A frontier-distance field beyond the window that a guided round measures the
/// frontier reward over (paper V-B over the explored map); the team's
/// [`GuidanceField`](crate::exploration::GuidanceField) is one. A trait so that the
/// planner does not depend on the exploration that plans with it.
pub trait FrontierField: Sync + std::fmt::Debug {
    /// The route distance to the best frontier from a pose at `p` heading `yaw_rad`
    /// (level), metres (∞ off the field).
    fn pose_distance_m(&self, p: &Point3<f64>, yaw_rad: f64) -> f64;
}

/// A round in which no candidate gets this much nearer along its route field is
/// stuck ([`PlanningProblem::route_escape`]), metres.
pub const STUCK_GAIN_M: f64 = 0.05;
/// The least an escape from a stuck round must get nearer along its route field
/// ([`PlanningProblem::route_escape`]), metres.
pub const ESCAPE_GAIN_M: f64 = 0.25;
/// How many times an escape from a stuck round may repeat its first action
/// before its last, best step ([`PlanningProblem::route_escape`]).
pub const ESCAPE_REPEATS: usize = 4;

/// One round's problem: the round's settings, the grid snapshot and the camera, with
/// the library's actions enumerated once.
#[derive(Debug)]
pub struct PlanningProblem<'a> {
    config: &'a RoundConfig,
    snapshot: &'a GridSnapshot,
    camera: &'a PinholeIntrinsics,
    actions: Vec<(Action, Option<f64>)>,
    guidance: Option<&'a dyn FrontierField>,
    /// The round only flies along `guidance` (home): information is not scored.
    homing: bool,
    time_source: TimeSource,
}

impl<'a> PlanningProblem<'a> {
    /// The problem of a round with `config` on `snapshot`, scoring views of `camera`,
    /// under the wall clock ([`Self::under`]).
    #[must_use]
    pub fn new(
        config: &'a RoundConfig,
        snapshot: &'a GridSnapshot,
        camera: &'a PinholeIntrinsics,
    ) -> Self {
        let actions = config
            .library
            .specs()
            .iter()
            .flat_map(|spec| library::actions(spec, &config.library_params))
            .collect();
        PlanningProblem {
            config,
            snapshot,
            camera,
            actions,
            guidance: None,
            homing: false,
            time_source: TimeSource::WallClock,
        }
    }

    /// The same problem planned under `time_source`: under simulated time a search
    /// on it stops after a fixed number of iterations
    /// ([`SearchParams::sim_iterations`]) and never reads the wall clock, so that a
    /// simulated flight depends on its seed alone; under the wall clock it stops on
    /// its wall-clock budget ([`SearchParams::budget_s`]).
    #[must_use]
    pub fn under(mut self, time_source: TimeSource) -> Self {
        self.time_source = time_source;
        self
    }

    /// What moves the time this problem is planned in ([`Self::under`]).
    #[must_use]
    pub fn time_source(&self) -> TimeSource {
        self.time_source
    }

    /// The same problem with the frontier-distance reward V = d(ξ₀) − d(ξτ) measured
    /// over `field` (route distance to the team's remembered frontiers, paper V-B over
    /// the explored map) instead of the window's Euclidean frontier distance, wherever
    /// the field reaches both ends of a primitive. Safety checks do not change.
    #[must_use]
    pub fn guided(mut self, field: &'a dyn FrontierField) -> Self {
        self.guidance = Some(field);
        self
    }

    /// The same problem flying home along `field` (the route distance to home,
    /// [`GuidanceField::towards`](crate::exploration::GuidanceField::towards)): the
    /// objective is α V alone — views are not scored, so the robot takes the shortest
    /// route rather than the most informative one. Safety checks do not change.
    #[must_use]
    pub fn homing(mut self, field: &'a dyn FrontierField) -> Self {
        self.guidance = Some(field);
        self.homing = true;
        self
    }

    /// Whether the frontier reward comes from a [`FrontierField`].
    #[must_use]
    pub fn is_guided(&self) -> bool {
        self.guidance.is_some()
    }

    /// A way out of a local minimum of the route field ([`Self::guided`] or
    /// [`Self::homing`]): when no candidate gets [`STUCK_GAIN_M`] nearer along it
    /// (the route leads on through a passage no single primitive can enter from
    /// here, one the robot must first descend, climb, turn or sidestep into; the
    /// vertical primitives are slow, 0.3 m/s in Table 4.2), the candidate whose
    /// action, flown up to [`ESCAPE_REPEATS`] times and followed by the best child
    /// of where that leaves the robot, gets the most nearer, if that is at least
    /// [`ESCAPE_GAIN_M`] (ties: the first in library order). `None` otherwise, and
    /// for a problem without a field: the round's own choice stands. Costs up to
    /// [`ESCAPE_REPEATS`] × [`Self::children`] per candidate, only in the rounds
    /// that need it.
    #[must_use]
    pub fn route_escape(&self, candidates: &[Candidate]) -> Option<usize> {
        if self.guidance.is_none() || candidates.iter().any(|c| c.frontier_gain_m >= STUCK_GAIN_M) {
            return None;
        }
        let escape_gain_m = |first: &Candidate| {
            let (mut best_m, mut so_far_m) = (f64::NEG_INFINITY, 0.0);
            let mut step = Some(first.clone());
            for _ in 0..ESCAPE_REPEATS {
                let Some(c) = step.take() else { break };
                so_far_m += c.frontier_gain_m;
                let Some(state) = self.continuation(&c) else {
                    best_m = best_m.max(so_far_m);
                    break;
                };
                let next = self.children(&state);
                let next_m = next.iter().map(|n| n.frontier_gain_m).fold(0.0, f64::max);
                best_m = best_m.max(so_far_m + next_m);
                step = next
                    .into_iter()
                    .find(|n| n.action_index == first.action_index);
            }
            best_m
        };
        candidates
            .iter()
            .enumerate()
            .map(|(i, c)| (i, escape_gain_m(c)))
            .fold(None, |best: Option<(usize, f64)>, (i, gain_m)| match best {
                Some((_, b)) if b >= gain_m => best,
                _ => Some((i, gain_m)),
            })
            .filter(|&(_, gain_m)| gain_m >= ESCAPE_GAIN_M)
            .map(|(i, _)| i)
    }

    /// `candidates` (children of `from`, scored by any problem on the same snapshot)
    /// with their frontier reward and objective scored by this problem; the
    /// information, which does not depend on the frontier field, is kept.
    #[must_use]
    pub fn rescored(&self, from: &FlatState, candidates: Vec<Candidate>) -> Vec<Candidate> {
        candidates
            .into_iter()
            .map(|c| {
                let (frontier_gain_m, reward) = self.objective(from, &c.primitive, c.information);
                Candidate {
                    frontier_gain_m,
                    reward,
                    ..c
                }
            })
            .collect()
    }

    /// The frontier reward V (metres) and the objective I + αV (per second when
    /// [`RoundConfig::reward_per_second`] is set) of `primitive` from `from`.
    fn objective(&self, from: &FlatState, primitive: &Primitive, information: f64) -> (f64, f64) {
        let end_state = primitive.end_state();
        let distance = |s: &FlatState| {
            let p = Point3::from(s.position_m());
            match self.guidance {
                Some(field) => field.pose_distance_m(&p, s.yaw_rad()),
                None => self.snapshot.frontier_distance(&p),
            }
        };
        let (d0, d1) = (distance(from), distance(&end_state));
        let frontier_gain_m = if d0.is_finite() && d1.is_finite() {
            d0 - d1
        } else {
            0.0
        };
        let information = if self.homing { 0.0 } else { information };
        let mut reward = information + self.config.frontier_weight * frontier_gain_m;
        if self.config.reward_per_second {
            reward /= primitive.duration_s();
        }
        (frontier_gain_m, reward)
    }

    /// The round's settings.
    #[must_use]
    pub fn config(&self) -> &RoundConfig {
        self.config
    }

    /// The grid snapshot planned against.
    #[must_use]
    pub fn snapshot(&self) -> &GridSnapshot {
        self.snapshot
    }

    /// The library's actions (Eq. 4.3), with their fixed duration if any.
    #[must_use]
    pub fn actions(&self) -> &[(Action, Option<f64>)] {
        &self.actions
    }

    /// The child of `from` for action `index` (into [`Self::actions`]): `None` when
    /// the index is out of range, the primitive is infeasible (acceleration and jerk
    /// limits) or it or its stopping primitive comes too close to unsafe space.
    #[must_use]
    pub fn child(&self, from: &FlatState, index: usize) -> Option<Candidate> {
        let &(action, fixed) = self.actions.get(index)?;
        let primitive = self.config.primitive(from, action, fixed)?;
        let stopping = self.config.safe_with_stop(&primitive, self.snapshot)?;
        Some(self.score(from, index, primitive, stopping))
    }

    /// Every feasible, safe child of `from`, scored, in library order. The children
    /// are built on the rayon pool (each on its own, collected in order: the same
    /// result on any number of threads), so a planning round uses the cores that the
    /// other robots of a simulated team leave idle.
    #[must_use]
    pub fn children(&self, from: &FlatState) -> Vec<Candidate> {
        (0..self.actions.len())
            .into_par_iter()
            .filter_map(|i| self.child(from, i))
            .collect()
    }

    /// Where a branch continues after `candidate`: the state at the end of its
    /// primitive, if the part after the planning period (not covered by the
    /// candidate's own check) keeps the clearance too; `None` ends the branch.
    #[must_use]
    pub fn continuation(&self, candidate: &Candidate) -> Option<FlatState> {
        let primitive = &candidate.primitive;
        let switch_s = self.config.planning_period_s.min(primitive.duration_s());
        let margin = self.config.margin_m(self.snapshot.grid.resolution_m());
        let step_s = self.config.check_step_s.max(1e-3);
        let tail_s = primitive.duration_s() - switch_s;
        let n = (tail_s / step_s).ceil() as usize;
        let tail_safe = (1..=n).all(|i| {
            let t = switch_s + tail_s * i as f64 / n as f64;
            let p = Point3::from(primitive.state_at(t).position_m());
            self.snapshot.clearance_m(&p) >= margin
        });
        tail_safe.then(|| primitive.end_state())
    }

    /// Scores a safe, feasible primitive from `from`: the information reward (at
    /// the end pose, or summed along the primitive, see
    /// [`RoundConfig::information_samples`]) plus α times the frontier-distance
    /// reward V = d(ξ₀) − d(ξτ) (paper Eq. 8, thesis §4.1.3; over the window, or over
    /// the [`FrontierField`] of a [`Self::guided`] problem).
    fn score(
        &self,
        from: &FlatState,
        index: usize,
        primitive: Primitive,
        stopping: Primitive,
    ) -> Candidate {
        let config = self.config;
        let end = primitive.end_state();
        let samples = config.information_samples.max(1);
        // Hovering in place shows the sensor the view it has been seeing all along:
        // what CSQMI still promises there (cells it cannot resolve, e.g. behind pixels
        // with no return) will not be gained by staying, and would otherwise keep a
        // robot hovering forever whenever it beats every move.
        let information = if self.homing || stays_put(from, &end) {
            0.0
        } else {
            (1..=samples)
                .map(|k| {
                    let t = primitive.duration_s() * k as f64 / samples as f64;
                    view_information(
                        &self.snapshot.grid,
                        &pose_of(&primitive.state_at(t)),
                        self.camera,
                        &config.view,
                    )
                })
                .sum::<f64>()
                / samples as f64
        };
        let (frontier_gain_m, reward) = self.objective(from, &primitive, information);
        Candidate {
            action_index: index,
            primitive,
            stopping,
            information,
            frontier_gain_m,
            reward,
        }
    }
}

/// Whether a primitive from `from` (at rest) ends where it started: same position
/// within a millimetre and same heading within a milliradian.
fn stays_put(from: &FlatState, end: &FlatState) -> bool {
    from.velocity_mps().norm() < 1e-6
        && (end.position_m() - from.position_m()).norm() < 1e-3
        && (end.yaw_rad() - from.yaw_rad()).abs() < 1e-3
}

impl RoundConfig {
    /// Every feasible, safe candidate from `from`, scored (the children of the
    /// root in [`PlanningProblem`]).
    #[must_use]
    pub fn candidates(
        &self,
        from: &FlatState,
        snapshot: &GridSnapshot,
        camera: &PinholeIntrinsics,
    ) -> Vec<Candidate> {
        PlanningProblem::new(self, snapshot, camera).children(from)
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;

    use super::*;
    use crate::planner::scenes::{self, SceneRound};

    #[test]
    fn children_are_safe_scored_and_continue_only_through_clear_space() {
        let round = SceneRound::new(scenes::room_with_doorway(3.5, 1.5, 0.5));
        let problem = round.problem();
        let (snapshot, camera, config) = (&round.snapshot, &round.camera, &round.config);
        let root = FlatState::at_rest(Vector3::zeros(), 0.0);
        let children = problem.children(&root);
        assert!(children.len() > 5 && children.len() <= problem.actions().len());
        let margin = config.margin_m(snapshot.grid.resolution_m());
        let per_second = RoundConfig {
            reward_per_second: true,
            ..*config
        };
        let rated = PlanningProblem::new(&per_second, snapshot, camera);
        let mut continued = 0;
        for child in &children {
            // The end-pose information of thesis §4.1.3, plus α V.
            let end = child.primitive.end_state();
            let info = if stays_put(&root, &end) {
                0.0
            } else {
                view_information(&snapshot.grid, &pose_of(&end), camera, &config.view)
            };
            assert!((child.information - info).abs() < 1e-12);
            assert!(
                (child.reward - (info + config.frontier_weight * child.frontier_gain_m)).abs()
                    < 1e-12
            );
            let again = rated.child(&root, child.action_index).expect("same child");
            assert!((again.reward * child.primitive.duration_s() - child.reward).abs() < 1e-9);
            // A continuation exists only if the whole primitive keeps the margin.
            if let Some(next) = problem.continuation(child) {
                continued += 1;
                assert_eq!(next, end);
                for i in 0..=100 {
                    let t = child.primitive.duration_s() * f64::from(i) / 100.0;
                    let p = Point3::from(child.primitive.state_at(t).position_m());
                    assert!(snapshot.clearance_m(&p) >= margin - 0.05, "{p}");
                }
            }
        }
        assert!(continued > 0);
        // Out-of-range actions have no child.
        assert!(problem.child(&root, problem.actions().len()).is_none());
    }

    #[test]
    fn hovering_in_place_promises_no_information() {
        let round = SceneRound::new(scenes::room_with_doorway(3.5, 1.5, 0.5));
        let problem = round.problem();
        let (snapshot, camera, config) = (&round.snapshot, &round.camera, &round.config);
        // Facing the doorway: the view from here still holds unknown cells.
        let root = FlatState::at_rest(Vector3::zeros(), 0.0);
        let here = view_information(&snapshot.grid, &pose_of(&root), camera, &config.view);
        assert!(here > 1.0, "{here}");
        let children = problem.children(&root);
        let hover: Vec<_> = children
            .iter()
            .filter(|c| c.primitive.action() == crate::planner::primitives::Action::STOP)
            .collect();
        assert_eq!(
            hover.len(),
            1,
            "the minimal library hovers once (vertical, v_z = 0)"
        );
        assert_eq!(hover[0].information, 0.0);
        assert!(children.iter().any(|c| c.information > 1.0));
    }

    /// The route from 1.5 m ahead of a pose to a home 28 m down a corridor along +x.
    #[derive(Debug)]
    struct HomeDownTheCorridor;

    impl FrontierField for HomeDownTheCorridor {
        fn pose_distance_m(&self, p: &Point3<f64>, yaw_rad: f64) -> f64 {
            let ahead = p + Vector3::new(yaw_rad.cos(), yaw_rad.sin(), 0.0) * 1.5;
            (Point3::new(30.0, 0.0, 0.0) - ahead).norm()
        }
    }

    #[test]
    fn a_robot_facing_left_of_its_route_can_turn_right_towards_it_in_place() {
        // Facing 1.2 rad to the left of the corridor and its route home: turning left
        // in place leads away; with the yaw row both ways, turning right gets nearer.
        let snapshot = scenes::corridor(8.0, 1.5, 1.0);
        let camera = scenes::forward_camera();
        let root = FlatState::at_rest(Vector3::new(2.0, 0.0, 0.0), 1.2);
        let turns = |yaw_both_ways| {
            let defaults = RoundConfig::default();
            let config = RoundConfig {
                library_params: library::LibraryParams {
                    yaw_both_ways,
                    ..defaults.library_params
                },
                ..defaults
            };
            let problem =
                PlanningProblem::new(&config, &snapshot, &camera).homing(&HomeDownTheCorridor);
            problem
                .children(&root)
                .into_iter()
                .filter(|c| {
                    let a = c.primitive.action();
                    a.vx_mps == 0.0 && a.vy_mps == 0.0 && a.vz_mps == 0.0 && a.yaw_rate_rad_s != 0.0
                })
                .map(|c| (c.primitive.action().yaw_rate_rad_s, c.frontier_gain_m))
                .collect::<Vec<_>>()
        };
        let one_way = turns(false);
        assert_eq!(one_way.len(), 1);
        assert!(one_way[0].0 > 0.0 && one_way[0].1 < 0.0, "{one_way:?}");
        let both_ways = turns(true);
        assert_eq!(both_ways.len(), 2);
        assert!(
            both_ways
                .iter()
                .any(|&(w, gain_m)| w < 0.0 && gain_m > 0.25),
            "{both_ways:?}"
        );
    }

    #[test]
    fn inside_the_margin_children_never_come_closer_and_some_back_away() {
        // A corridor 3 m wide and 2 m high; the robot hovers 0.55 m from its left wall,
        // inside the 0.67 m margin (as when new cells close in on a hovering robot).
        let round = SceneRound::new(scenes::corridor(8.0, 1.5, 1.0));
        let problem = round.problem();
        let (snapshot, config) = (&round.snapshot, &round.config);
        let margin = config.margin_m(snapshot.grid.resolution_m());
        let root = FlatState::at_rest(Vector3::new(2.0, 0.95, 0.0), 0.0);
        let start = snapshot.clearance_m(&Point3::from(root.position_m()));
        assert!(start > 0.0 && start < margin, "start clearance {start}");
        let children = problem.children(&root);
        assert!(
            !children.is_empty(),
            "a robot inside the margin must not stall"
        );
        let mut backed_away = false;
        for child in &children {
            let switch_s = config.planning_period_s.min(child.primitive.duration_s());
            let samples =
                (0..=50).map(|i| child.primitive.state_at(switch_s * f64::from(i) / 50.0));
            let stops = (0..=50).map(|i| {
                child
                    .stopping
                    .state_at(child.stopping.duration_s() * f64::from(i) / 50.0)
            });
            for state in samples.chain(stops) {
                let c = snapshot.clearance_m(&Point3::from(state.position_m()));
                assert!(c >= start - 1e-9, "{child:?} comes closer: {c} < {start}");
            }
            let end = child.stopping.end_state();
            backed_away |= snapshot.clearance_m(&Point3::from(end.position_m())) >= margin;
        }
        assert!(backed_away, "some child must get back out of the margin");
        // In unsafe space itself nothing may leave.
        let buried = FlatState::at_rest(Vector3::new(2.0, 1.6, 0.0), 0.0);
        assert_eq!(
            snapshot.clearance_m(&Point3::from(buried.position_m())),
            0.0
        );
        assert!(problem.children(&buried).is_empty());
    }
}
