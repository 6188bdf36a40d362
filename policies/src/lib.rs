//! troupe-policies: pluggable decisions, chosen by name in a robot's configuration.
//!
//! - [`route::WaypointRoute`] — a scripted exploration behaviour that needs no map:
//!   it follows waypoints handed to it (for instance a cave's tunnel centre lines).
//!
//! - [`selection::Greedy`] (single-step best action, paper Alg. 1) and
//!   [`selection::RandomFeasible`] (the baseline) choose among the planner's
//!   candidates; [`selection::Mcts`] searches sequences of primitives (anytime
//!   MCTS with UCT, thesis §4.1.3).
//!
//! - [`priority::PriorityAvoidance`] — priority-based inter-robot avoidance (thesis
//!   §8.2.3) for the collision actor: cylinders sampled along both plans, stale peers
//!   as stopping envelopes.
//!
//! [`behaviour_by_name`] and [`selection_by_name`] are how the robot assembly turns
//! config strings into policies:
//!
//! ```
//! use nalgebra::{Isometry3, Point3, Vector3};
//! use troupe_algorithms::frame::Odometry;
//! use troupe_core::Time;
//! use troupe_policies::{BehaviourInputs, SELECTIONS, behaviour_by_name, selection_by_name};
//!
//! // A route behaviour: from the origin to 4 m ahead.
//! let inputs = BehaviourInputs {
//!     route: vec![Point3::origin(), Point3::new(4.0, 0.0, 0.0)],
//!     speed_mps: 1.0,
//!     yaw_rate_rad_s: 0.5,
//!     depart_at_s: 0.0,
//! };
//! let mut route = behaviour_by_name("waypoint_route", &inputs).unwrap()();
//! let here = Odometry { stamp: Time::ZERO, pose: Isometry3::identity(), velocity_mps: Vector3::zeros() };
//! let plan = route.replan(Time::ZERO, &here).expect("a route to follow");
//! assert!(plan.knots().len() >= 2);
//!
//! // Every action selection the planner can be configured with.
//! for name in SELECTIONS {
//!     assert!(selection_by_name(name).is_ok());
//! }
//! assert!(selection_by_name("psychic").is_err());
//! ```
#![deny(missing_docs)]

pub mod priority;
pub mod route;
pub mod selection;

use nalgebra::Point3;
use troupe_algorithms::exploration::ExplorationBehaviour;
use troupe_algorithms::planner::selection::ActionSelection;
use troupe_core::Time;

/// Inputs a behaviour may need besides its own parameters.
#[derive(Clone, Debug, Default)]
pub struct BehaviourInputs {
    /// Waypoints in the world frame (required by `waypoint_route`).
    pub route: Vec<Point3<f64>>,
    /// Cruise speed, m/s.
    pub speed_mps: f64,
    /// Turn rate for turning in place, rad/s.
    pub yaw_rate_rad_s: f64,
    /// Earliest departure, seconds of run time (staggered launches keep robots that
    /// share a first tunnel apart).
    pub depart_at_s: f64,
}

/// Names accepted by [`behaviour_by_name`].
pub const BEHAVIOURS: &[&str] = &["waypoint_route"];

/// Why a behaviour could not be built.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum PolicyError {
    /// Unknown name.
    #[error("unknown exploration behaviour `{0}` (known: {known})", known = BEHAVIOURS.join(", "))]
    UnknownBehaviour(String),
    /// Unknown selection policy.
    #[error("unknown action selection `{0}` (known: {known})", known = SELECTIONS.join(", "))]
    UnknownSelection(String),
    /// Missing or bad input.
    #[error("behaviour `{behaviour}`: {reason}")]
    BadInput {
        /// Behaviour name.
        behaviour: &'static str,
        /// What is wrong.
        reason: String,
    },
}

/// Builds fresh instances of a validated behaviour (one per actor start or restart).
pub type BehaviourFactory = Box<dyn Fn() -> Box<dyn ExplorationBehaviour> + Send>;

/// Checks the inputs of the named behaviour and returns a factory for it.
pub fn behaviour_by_name(
    name: &str,
    inputs: &BehaviourInputs,
) -> Result<BehaviourFactory, PolicyError> {
    match name {
        "waypoint_route" => {
            let prototype = route::WaypointRoute::new(
                inputs.route.clone(),
                inputs.speed_mps,
                inputs.yaw_rate_rad_s,
            )?
            .departing_at(Time::from_secs_f64(inputs.depart_at_s));
            Ok(Box::new(move || Box::new(prototype.clone())))
        }
        other => Err(PolicyError::UnknownBehaviour(other.to_string())),
    }
}

/// Names accepted by [`selection_by_name`].
pub const SELECTIONS: &[&str] = &["greedy", "random", "mcts"];

/// Builds fresh instances of an action-selection policy (one per planner start).
pub type SelectionFactory = Box<dyn Fn() -> Box<dyn ActionSelection> + Send>;

/// A factory for the named action-selection policy.
pub fn selection_by_name(name: &str) -> Result<SelectionFactory, PolicyError> {
    match name {
        "greedy" => Ok(Box::new(|| Box::new(selection::Greedy))),
        "random" => Ok(Box::new(|| Box::new(selection::RandomFeasible))),
        "mcts" => Ok(Box::new(|| Box::new(selection::Mcts::default()))),
        other => Err(PolicyError::UnknownSelection(other.to_string())),
    }
}
