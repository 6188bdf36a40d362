//! The committed reference of the planner and teleoperation actors: a primitive
//! until the next planning time, then its stopping primitive (thesis §4.1.3).

use std::time::Duration;

use super::primitives::{Action, DynamicLimits, FlatState, Primitive};
use crate::trajectory::{Knot, Trajectory};
use troupe_core::Time;

/// A primitive from `start` until `switch_s`, then its stopping primitive.
#[derive(Clone, Debug, PartialEq)]
pub struct Committed {
    /// When the primitive starts.
    pub start: Time,
    /// The primitive flown until `switch_s`.
    pub primitive: Primitive,
    /// Seconds after `start` at which the stopping primitive takes over.
    pub switch_s: f64,
    /// The stopping primitive from the primitive's state at `switch_s`.
    pub stopping: Primitive,
}

impl Committed {
    /// Braking from `root` at `now`: the feasible stopping primitive within `limits`
    /// that strays least from `root` ([`DynamicLimits::braking`]), then hovering where
    /// it ends (the fail-safe commitment, thesis §4.1.3); `None` when no stop is
    /// feasible from `root`.
    #[must_use]
    pub fn braking(limits: &DynamicLimits, root: &FlatState, now: Time) -> Option<Committed> {
        let stopping = limits.braking(root)?;
        Some(Committed {
            start: now,
            switch_s: stopping.duration_s(),
            stopping: Primitive::forward_arc(&stopping.end_state(), Action::STOP, 1.0),
            primitive: stopping,
        })
    }

    /// The reference state at `t`.
    pub fn state_at(&self, t: Time) -> FlatState {
        let s = (t - self.start).as_secs_f64();
        if s < self.switch_s {
            self.primitive.state_at(s)
        } else {
            self.stopping.state_at(s - self.switch_s)
        }
    }

    /// Knots every `step_s` (or closer) from `start` to the end of the stopping
    /// primitive, for the vehicle.
    pub fn trajectory(&self, step_s: f64) -> Trajectory {
        let end_s = self.switch_s + self.stopping.duration_s();
        let n = (end_s / step_s.max(1e-3)).ceil().max(1.0) as usize;
        let knots = (0..=n)
            .map(|i| {
                let time = self.start + Duration::from_secs_f64(end_s * i as f64 / n as f64);
                let state = self.state_at(time);
                Knot {
                    time,
                    position_m: state.position_m().into(),
                    yaw_rad: state.yaw_rad(),
                }
            })
            .collect();
        // Knots are finite and in time order by construction.
        Trajectory::new(knots).unwrap_or_default()
    }
}

/// Where a planning round starts (thesis §4.1.3): the committed reference's state at
/// `now`, or, before anything is committed, at rest at the body pose.
#[must_use]
pub fn replanning_root(
    committed: Option<&Committed>,
    now: Time,
    pose: &nalgebra::Isometry3<f64>,
) -> FlatState {
    committed.map_or_else(
        || {
            let (_, _, yaw) = pose.rotation.euler_angles();
            FlatState::at_rest(pose.translation.vector, yaw)
        },
        |c| c.state_at(now),
    )
}
