//! An axis-aligned box in the world frame that a robot must stay in: the hardware
//! safety box of issue 17, checked twice — by the collision actor before a plan is
//! committed ([`Geofence::check_from`]) and by a vehicle driver on every setpoint
//! ([`Geofence::contains`], [`Geofence::clamp`]).

use nalgebra::Point3;
use serde::{Deserialize, Serialize};
use troupe_core::{ConfigError, Time};

use crate::trajectory::Trajectory;

const AXES: [&str; 3] = ["x", "y", "z"];

/// A geofence as a robot file writes it (`geofence = { min_m = [x, y, z], max_m =
/// [x, y, z] }`), world frame (ENU), metres.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GeofenceConfig {
    /// Low corner `[x, y, z]`.
    pub min_m: [f64; 3],
    /// High corner `[x, y, z]`.
    pub max_m: [f64; 3],
}

impl GeofenceConfig {
    /// The checked fence; the error's key is empty (the caller names the table).
    pub fn fence(&self) -> Result<Geofence, ConfigError> {
        Geofence::new(Point3::from(self.min_m), Point3::from(self.max_m)).map_err(|e| {
            ConfigError::new(
                "",
                "must have finite corners with min_m below max_m on every axis",
                format!("min_m = {:?}, max_m = {:?} ({e})", self.min_m, self.max_m),
            )
        })
    }
}

/// Why corners do not form a geofence.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum GeofenceError {
    /// A corner coordinate is NaN or infinite.
    #[error("geofence corner {axis} coordinate is not finite")]
    NotFinite {
        /// `"x"`, `"y"` or `"z"`.
        axis: &'static str,
    },
    /// The box is empty along one axis.
    #[error("geofence min {axis} = {min_m} m must be below max {axis} = {max_m} m")]
    Empty {
        /// `"x"`, `"y"` or `"z"`.
        axis: &'static str,
        /// The minimum, metres.
        min_m: f64,
        /// The maximum, metres.
        max_m: f64,
    },
}

/// The first place where a trajectory leaves a [`Geofence`].
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[error("the trajectory is at ({:.2}, {:.2}, {:.2}) m at {time}, outside the geofence", position_m.x, position_m.y, position_m.z)]
pub struct GeofenceViolation {
    /// When it is outside.
    pub time: Time,
    /// Where, metres (world frame).
    pub position_m: Point3<f64>,
}

/// A box `[min_m, max_m]` in the world frame (ENU, metres), boundary included.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Geofence {
    min_m: Point3<f64>,
    max_m: Point3<f64>,
}

impl Geofence {
    /// A fence from its corners; each coordinate of `min_m` must be below `max_m`'s.
    pub fn new(min_m: Point3<f64>, max_m: Point3<f64>) -> Result<Self, GeofenceError> {
        for (i, axis) in AXES.into_iter().enumerate() {
            if !(min_m[i].is_finite() && max_m[i].is_finite()) {
                return Err(GeofenceError::NotFinite { axis });
            }
            if min_m[i] >= max_m[i] {
                return Err(GeofenceError::Empty {
                    axis,
                    min_m: min_m[i],
                    max_m: max_m[i],
                });
            }
        }
        Ok(Geofence { min_m, max_m })
    }

    /// The low corner.
    #[must_use]
    pub fn min_m(&self) -> Point3<f64> {
        self.min_m
    }

    /// The high corner.
    #[must_use]
    pub fn max_m(&self) -> Point3<f64> {
        self.max_m
    }

    /// Whether `p` is inside (boundary included). NaN is never inside.
    #[must_use]
    pub fn contains(&self, p: &Point3<f64>) -> bool {
        (0..3).all(|i| p[i] >= self.min_m[i] && p[i] <= self.max_m[i])
    }

    /// The point of the fence nearest to `p` (`p` itself when inside). A NaN
    /// coordinate is replaced by the box centre's.
    #[must_use]
    pub fn clamp(&self, p: &Point3<f64>) -> Point3<f64> {
        Point3::from(std::array::from_fn::<f64, 3, _>(|i| {
            if p[i].is_nan() {
                0.5 * (self.min_m[i] + self.max_m[i])
            } else {
                p[i].clamp(self.min_m[i], self.max_m[i])
            }
        }))
    }

    /// Checks every knot of a trajectory. Since the box is convex and the trajectory
    /// is linear between knots, the knots being inside means the whole path is.
    pub fn check_trajectory(&self, trajectory: &Trajectory) -> Result<(), GeofenceViolation> {
        let start = trajectory.knots().first().map_or(Time::ZERO, |k| k.time);
        self.check_from(trajectory, start)
    }

    /// Checks the part of a trajectory from `from` to its end — the span the
    /// collision actor's distance-field check samples — exactly: the state at `from`
    /// and every later knot (linear between knots, so nothing between them can leave
    /// the convex box). After its last knot a trajectory holds still.
    pub fn check_from(&self, trajectory: &Trajectory, from: Time) -> Result<(), GeofenceViolation> {
        let start = trajectory.state_at(from).map(|s| (from, s.position_m));
        let later = trajectory
            .knots()
            .iter()
            .filter(|k| k.time > from)
            .map(|k| (k.time, k.position_m));
        match start
            .into_iter()
            .chain(later)
            .find(|(_, p)| !self.contains(p))
        {
            Some((time, position_m)) => Err(GeofenceViolation { time, position_m }),
            None => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trajectory::Knot;

    fn fence() -> Geofence {
        Geofence::new(Point3::new(-1.0, -2.0, 0.0), Point3::new(4.0, 2.0, 3.0)).unwrap()
    }

    fn line(to: Point3<f64>) -> Trajectory {
        let knot = |t: f64, p: Point3<f64>| Knot {
            time: Time::from_secs_f64(t),
            position_m: p,
            yaw_rad: 0.0,
        };
        Trajectory::new(vec![
            knot(0.0, Point3::new(0.0, 0.0, 1.0)),
            knot(1.0, Point3::new(1.0, 0.0, 1.0)),
            knot(2.0, to),
        ])
        .unwrap()
    }

    #[test]
    fn contains_and_clamps() {
        let f = fence();
        assert!(f.contains(&Point3::new(0.0, 0.0, 1.0)));
        assert!(
            f.contains(&Point3::new(4.0, 2.0, 3.0)),
            "boundary is inside"
        );
        assert!(!f.contains(&Point3::new(4.01, 0.0, 1.0)));
        assert!(!f.contains(&Point3::new(0.0, 0.0, -0.1)));
        assert!(!f.contains(&Point3::new(f64::NAN, 0.0, 1.0)));
        assert_eq!(
            f.clamp(&Point3::new(9.0, -5.0, 1.0)),
            Point3::new(4.0, -2.0, 1.0)
        );
        assert_eq!(
            f.clamp(&Point3::new(1.0, 1.0, 1.0)),
            Point3::new(1.0, 1.0, 1.0)
        );
        let c = f.clamp(&Point3::new(f64::NAN, 0.0, 9.0));
        assert_eq!(c, Point3::new(1.5, 0.0, 3.0));
        assert!(f.contains(&c));
    }

    #[test]
    fn checks_whole_trajectories() {
        let f = fence();
        assert_eq!(
            f.check_trajectory(&line(Point3::new(3.0, 1.0, 2.0))),
            Ok(())
        );
        let err = f
            .check_trajectory(&line(Point3::new(6.0, 0.0, 1.0)))
            .unwrap_err();
        assert_eq!(err.time, Time::from_secs_f64(2.0));
        assert_eq!(err.position_m, Point3::new(6.0, 0.0, 1.0));
        assert!(err.to_string().contains("(6.00, 0.00, 1.00) m"), "{err}");
    }

    #[test]
    fn checks_from_a_time_on() {
        let f = fence();
        // Starts outside (x = -3), comes in by t = 1, leaves at the end (x = 6).
        let knot = |t: f64, x: f64| Knot {
            time: Time::from_secs_f64(t),
            position_m: Point3::new(x, 0.0, 1.0),
            yaw_rad: 0.0,
        };
        let t = Trajectory::new(vec![knot(0.0, -3.0), knot(1.0, 0.0), knot(3.0, 3.0)]).unwrap();
        // The past does not count: from t = 0.75 (x = -0.75) on it stays inside.
        assert_eq!(f.check_from(&t, Time::from_secs_f64(0.75)), Ok(()));
        // From t = 0.5 the state itself (x = -1.5) is outside.
        let err = f.check_from(&t, Time::from_secs_f64(0.5)).unwrap_err();
        assert_eq!(err.time, Time::from_secs_f64(0.5));
        assert!((err.position_m.x + 1.5).abs() < 1e-9);
        // After its last knot a trajectory holds: checking from later looks at the end.
        assert_eq!(f.check_from(&t, Time::from_secs_f64(9.0)), Ok(()));
        let out = Trajectory::new(vec![knot(0.0, 0.0), knot(1.0, 4.5)]).unwrap();
        assert_eq!(
            f.check_from(&out, Time::from_secs_f64(0.2))
                .unwrap_err()
                .time,
            Time::from_secs_f64(1.0)
        );
        assert!(f.check_from(&out, Time::from_secs_f64(5.0)).is_err());
    }

    #[test]
    fn config_gives_a_fence_or_names_the_rule() {
        let c = GeofenceConfig {
            min_m: [-1.0, -2.0, 0.0],
            max_m: [4.0, 2.0, 3.0],
        };
        assert_eq!(c.fence(), Ok(fence()));
        let bad = GeofenceConfig {
            max_m: [4.0, 2.0, f64::NAN],
            ..c
        };
        let e = bad.fence().unwrap_err().within("geofence");
        assert_eq!(e.key, "geofence");
        assert!(e.value.contains("not finite"), "{e}");
    }

    #[test]
    fn rejects_bad_corners() {
        assert_eq!(
            Geofence::new(Point3::new(0.0, 0.0, 0.0), Point3::new(1.0, 0.0, 1.0)),
            Err(GeofenceError::Empty {
                axis: "y",
                min_m: 0.0,
                max_m: 0.0
            })
        );
        assert_eq!(
            Geofence::new(Point3::new(0.0, 0.0, f64::NAN), Point3::new(1.0, 1.0, 1.0)),
            Err(GeofenceError::NotFinite { axis: "z" })
        );
    }
}
