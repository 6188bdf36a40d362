//! Plan payload: a robot's committed trajectory and its priority (thesis §8.2.3).
//!
//! # Compact form
//!
//! The trajectory travels as the time-stamped knots the vehicle follows (time,
//! position, yaw; linear interpolation between knots, hold the last knot after
//! the end) — the same form as the actors' `Trajectory`, so a receiver can check
//! a candidate against it without knowing the sender's primitive library. Knot
//! times are `f32` seconds after `start_ns` (1 µs resolution over a 10 s horizon),
//! positions `f32` metres (60 µm resolution 1 km from the origin).
//!
//! Sizes (all fixed-width): 4 (`plan_id`) + 2 (`priority`) + 8 (`start_ns`) +
//! varint(K) + 20 K bytes for K knots; a 2 s primitive sampled at 10 Hz plus its
//! stopping primitive (about 30 knots) is 615 bytes.

use serde::{Deserialize, Serialize};

use super::ContentError;
use super::check;

/// One knot: 5 `f32`, 20 bytes.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlanKnot {
    /// Seconds after the plan's `start_ns`; ≥ 0 and not decreasing.
    pub t_s: f32,
    /// Position in the sender's world frame, metres.
    pub position_m: [f32; 3],
    /// Heading about world z, radians.
    pub yaw_rad: f32,
}

/// A committed trajectory and the sender's priority for inter-robot avoidance.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    /// Per-sender plan counter; a newer plan replaces an older one.
    #[serde(with = "postcard::fixint::le")]
    pub plan_id: u32,
    /// Priority (assigned before the run, §8.2.3): lower-priority robots avoid
    /// higher-priority ones. Larger value = higher priority.
    #[serde(with = "postcard::fixint::le")]
    pub priority: u16,
    /// Time of the first knot on the sender's clock, nanoseconds.
    #[serde(with = "postcard::fixint::le")]
    pub start_ns: u64,
    /// Knots in time order (at least one).
    pub knots: Vec<PlanKnot>,
}

impl Plan {
    pub(super) fn validate(&self) -> Result<(), ContentError> {
        if self.knots.is_empty() {
            return Err(ContentError::Message("plan has no knots"));
        }
        let mut previous = 0.0f32;
        for (index, k) in self.knots.iter().enumerate() {
            let at = |reason| ContentError::Element { index, reason };
            if !(k.t_s.is_finite() && check::all_finite(&k.position_m) && k.yaw_rad.is_finite()) {
                return Err(at("plan knot contains NaN or infinity"));
            }
            if k.t_s < previous {
                return Err(at(
                    "plan knot time is negative or earlier than the knot before",
                ));
            }
            previous = k.t_s;
        }
        Ok(())
    }
}
