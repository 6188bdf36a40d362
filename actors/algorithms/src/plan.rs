//! The committed plan: what the vehicle follows and what the planner replans from.

use troupe_core::{Message, Time};

use crate::planner::committed::Committed;
use crate::trajectory::Trajectory;

/// A committed trajectory for the vehicle to follow.
///
/// Every actor that needs the robot's reference reads it from the committed plan: the
/// vehicle follows `trajectory`; a motion-primitive planner replans from `reference`,
/// the exact primitive behind it (state, velocity and acceleration at any time, thesis
/// §4.1.3), which sampled knots would only approximate.
#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    /// When it was committed.
    pub stamp: Time,
    /// The trajectory.
    pub trajectory: Trajectory,
    /// The motion primitive and its stopping primitive that `trajectory` samples, when
    /// a primitive planner made it (`None` for routes and plans received from peers).
    pub reference: Option<Box<Committed>>,
    /// Whether this is the stopping trajectory, committed because no candidate of the
    /// round was safe.
    pub stopping: bool,
}

impl Plan {
    /// A plan of `trajectory` committed at `stamp`, without a primitive reference.
    #[must_use]
    pub fn new(stamp: Time, trajectory: Trajectory) -> Self {
        Plan {
            stamp,
            trajectory,
            reference: None,
            stopping: false,
        }
    }
}

impl Message for Plan {
    fn payload_bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + self.trajectory.payload_bytes()
            + self
                .reference
                .as_ref()
                .map_or(0, |_| std::mem::size_of::<Committed>())
    }
}
