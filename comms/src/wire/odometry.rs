//! Odometry payload: a robot's pose and velocity in its own world frame.

use serde::{Deserialize, Serialize};

use super::ContentError;

/// Pose and velocity, sent at 10 Hz for inter-robot avoidance (thesis §8.2.3).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Odometry {
    /// Position in the sender's world frame, metres.
    pub position_m: [f64; 3],
    /// Orientation as a unit quaternion (x, y, z, w).
    pub orientation_xyzw: [f64; 4],
    /// Linear velocity in the world frame, m/s.
    pub velocity_mps: [f64; 3],
}

impl Odometry {
    pub(super) fn validate(&self) -> Result<(), ContentError> {
        let finite = self
            .position_m
            .iter()
            .chain(&self.orientation_xyzw)
            .chain(&self.velocity_mps)
            .all(|v| v.is_finite());
        if !finite {
            return Err(ContentError::Message("odometry contains NaN or infinity"));
        }
        let norm2: f64 = self.orientation_xyzw.iter().map(|v| v * v).sum();
        if (norm2 - 1.0).abs() > 1e-6 {
            return Err(ContentError::Message(
                "odometry orientation is not a unit quaternion",
            ));
        }
        Ok(())
    }
}
