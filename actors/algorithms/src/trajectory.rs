//! Time-parameterised trajectories as sampled (time, position, yaw) knots with
//! linear interpolation — the common form a plan takes on its way to the vehicle.

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use troupe_core::Time;

/// One knot of a trajectory.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Knot {
    /// Time of the knot.
    pub time: Time,
    /// Position in the world frame, metres.
    pub position_m: Point3<f64>,
    /// Heading about world z, radians.
    pub yaw_rad: f64,
}

/// A trajectory: knots in increasing time order. Before the first knot the robot is
/// at the first; after the last, it holds the last (hover).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Trajectory {
    knots: Vec<Knot>,
}

/// Why knots do not form a trajectory.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum TrajectoryError {
    /// No knots.
    #[error("a trajectory needs at least one knot")]
    Empty,
    /// Times must not decrease.
    #[error("knot {0} is earlier than the knot before it")]
    TimeNotMonotone(usize),
    /// NaN or infinite coordinates.
    #[error("knot {0} has a non-finite position or yaw")]
    NotFinite(usize),
}

/// State of the trajectory at one time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrajectoryState {
    /// Position, metres.
    pub position_m: Point3<f64>,
    /// Velocity, m/s.
    pub velocity_mps: Vector3<f64>,
    /// Heading, radians.
    pub yaw_rad: f64,
}

impl TrajectoryState {
    /// The body pose (level: no roll or pitch).
    #[must_use]
    pub fn pose(&self) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::from(self.position_m.coords),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), self.yaw_rad),
        )
    }
}

impl Trajectory {
    /// Checks and wraps knots.
    pub fn new(knots: Vec<Knot>) -> Result<Self, TrajectoryError> {
        if knots.is_empty() {
            return Err(TrajectoryError::Empty);
        }
        for (i, k) in knots.iter().enumerate() {
            if !(k.position_m.coords.iter().all(|v| v.is_finite()) && k.yaw_rad.is_finite()) {
                return Err(TrajectoryError::NotFinite(i));
            }
            if i > 0 && k.time < knots[i - 1].time {
                return Err(TrajectoryError::TimeNotMonotone(i));
            }
        }
        Ok(Trajectory { knots })
    }

    /// The knots.
    #[must_use]
    pub fn knots(&self) -> &[Knot] {
        &self.knots
    }

    /// `next`, continuing this trajectory from `from` until `next` begins: this one's
    /// state at `from` and its knots up to `next`'s first, then `next` (a plan that
    /// takes over from a future reference point, thesis §4.1.3, with the flight that
    /// leads there). When `next` begins at or before `from`, `next` alone.
    #[must_use]
    pub fn continued_by(&self, from: Time, next: &Trajectory) -> Trajectory {
        let Some(start) = next.knots.first().map(|k| k.time) else {
            return self.clone();
        };
        let Some(here) = self.state_at(from).filter(|_| from < start) else {
            return next.clone();
        };
        let mut knots = Vec::with_capacity(self.knots.len() + next.knots.len() + 1);
        knots.push(Knot {
            time: from,
            position_m: here.position_m,
            yaw_rad: here.yaw_rad,
        });
        knots.extend(
            self.knots
                .iter()
                .filter(|k| k.time > from && k.time < start)
                .copied(),
        );
        knots.extend_from_slice(&next.knots);
        Trajectory { knots }
    }

    /// Time of the last knot.
    #[must_use]
    pub fn end_time(&self) -> Time {
        self.knots.last().map_or(Time::ZERO, |k| k.time)
    }

    /// Heap bytes (for message accounting).
    #[must_use]
    pub fn payload_bytes(&self) -> usize {
        self.knots.len() * std::mem::size_of::<Knot>()
    }

    /// Position, velocity and yaw at time `t` (yaw interpolated along the shorter arc).
    #[must_use]
    pub fn state_at(&self, t: Time) -> Option<TrajectoryState> {
        let first = self.knots.first()?;
        let last = self.knots.last()?;
        let hold = |k: &Knot| TrajectoryState {
            position_m: k.position_m,
            velocity_mps: Vector3::zeros(),
            yaw_rad: k.yaw_rad,
        };
        if t <= first.time {
            return Some(hold(first));
        }
        if t >= last.time {
            return Some(hold(last));
        }
        // First knot strictly after t.
        let i = self.knots.partition_point(|k| k.time <= t);
        let (a, b) = (&self.knots[i - 1], &self.knots[i]);
        let span_s = (b.time - a.time).as_secs_f64();
        let s = (t - a.time).as_secs_f64() / span_s;
        let delta = b.position_m - a.position_m;
        let dyaw = wrap_angle(b.yaw_rad - a.yaw_rad);
        Some(TrajectoryState {
            position_m: a.position_m + delta * s,
            velocity_mps: delta / span_s,
            yaw_rad: wrap_angle(a.yaw_rad + dyaw * s),
        })
    }
}

/// Wraps an angle to (−π, π].
#[must_use]
pub fn wrap_angle(a: f64) -> f64 {
    let two_pi = std::f64::consts::TAU;
    let mut r = a.rem_euclid(two_pi);
    if r > std::f64::consts::PI {
        r -= two_pi;
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    fn knot(t: f64, x: f64, yaw: f64) -> Knot {
        Knot {
            time: Time::from_secs_f64(t),
            position_m: Point3::new(x, 0.0, 1.0),
            yaw_rad: yaw,
        }
    }

    #[test]
    fn interpolates_holds_and_wraps_yaw() {
        let traj = Trajectory::new(vec![knot(1.0, 0.0, 3.0), knot(3.0, 4.0, -3.0)]).unwrap();
        let mid = traj.state_at(Time::from_secs_f64(2.0)).unwrap();
        assert!((mid.position_m.x - 2.0).abs() < 1e-12);
        assert!((mid.velocity_mps.x - 2.0).abs() < 1e-12);
        // 3.0 → −3.0 is 0.283 rad through π, not 6 rad the long way.
        assert!(mid.yaw_rad.abs() > 3.0);
        let before = traj.state_at(Time::ZERO).unwrap();
        assert_eq!(before.position_m.x, 0.0);
        assert_eq!(before.velocity_mps, Vector3::zeros());
        let after = traj.state_at(Time::from_secs_f64(10.0)).unwrap();
        assert_eq!(after.position_m.x, 4.0);
    }

    #[test]
    fn a_later_plan_continues_the_flight_that_leads_to_it() {
        let old = Trajectory::new(
            (0..=10)
                .map(|i| knot(f64::from(i) * 0.2, f64::from(i) * 0.2, 0.0))
                .collect(),
        )
        .unwrap();
        let next = Trajectory::new(vec![knot(1.2, 1.2, 0.0), knot(2.2, 1.2, 0.0)]).unwrap();
        let joined = old.continued_by(Time::from_secs_f64(0.5), &next);
        let times_ms: Vec<u64> = joined
            .knots()
            .iter()
            .map(|k| k.time.as_nanos() / 1_000_000)
            .collect();
        assert_eq!(times_ms, vec![500, 600, 800, 1000, 1200, 2200]);
        // Continuous: the old flight until the new plan begins, then the new plan.
        for t in [0.5, 0.7, 1.1, 1.2, 1.7, 3.0] {
            let t = Time::from_secs_f64(t);
            let expected = if t < Time::from_secs_f64(1.2) {
                &old
            } else {
                &next
            };
            let (a, b) = (joined.state_at(t).unwrap(), expected.state_at(t).unwrap());
            assert!((a.position_m - b.position_m).norm() < 1e-9, "{t}");
        }
        // A plan that begins at or before `from` replaces the old one outright.
        assert_eq!(old.continued_by(Time::from_secs_f64(1.2), &next), next);
        assert_eq!(old.continued_by(Time::from_secs_f64(1.5), &next), next);
    }

    #[test]
    fn rejects_bad_knots() {
        assert_eq!(Trajectory::new(vec![]), Err(TrajectoryError::Empty));
        assert_eq!(
            Trajectory::new(vec![knot(2.0, 0.0, 0.0), knot(1.0, 1.0, 0.0)]),
            Err(TrajectoryError::TimeNotMonotone(1))
        );
        assert_eq!(
            Trajectory::new(vec![knot(0.0, f64::NAN, 0.0)]),
            Err(TrajectoryError::NotFinite(0))
        );
    }

    #[test]
    fn wrap_angle_range() {
        for a in [-10.0, -3.2, 0.0, 3.2, 10.0, std::f64::consts::PI] {
            let w = wrap_angle(a);
            assert!(w > -std::f64::consts::PI - 1e-12 && w <= std::f64::consts::PI + 1e-12);
            assert!(
                ((a - w) / std::f64::consts::TAU).fract().abs() < 1e-9
                    || ((a - w) / std::f64::consts::TAU).fract().abs() > 1.0 - 1e-9
            );
        }
    }
}
