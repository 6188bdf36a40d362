//! The plug-in that decides where a map-free robot goes next (scripted routes): the
//! explorer actor of `troupe-actors` asks an [`ExplorationBehaviour`] at its
//! replanning rate; implementations live in `troupe-policies` and are chosen by name.

use troupe_core::Time;

use crate::frame::Odometry;
use crate::trajectory::Trajectory;

/// Decides where the robot goes next.
pub trait ExplorationBehaviour: Send + 'static {
    /// A new trajectory to commit, or `None` to keep the current one. Called at the
    /// replanning rate once odometry is known.
    fn replan(&mut self, now: Time, odometry: &Odometry) -> Option<Trajectory>;
}

impl ExplorationBehaviour for Box<dyn ExplorationBehaviour> {
    fn replan(&mut self, now: Time, odometry: &Odometry) -> Option<Trajectory> {
        (**self).replan(now, odometry)
    }
}
