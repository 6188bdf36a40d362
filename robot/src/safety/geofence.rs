//! An axis-aligned box in the world frame that the vehicle must stay in.

use nalgebra::Point3;
use troupe_actors::trajectory::Trajectory;

const AXES: [&str; 3] = ["x", "y", "z"];

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
#[error("knot {knot} at ({:.2}, {:.2}, {:.2}) m is outside the geofence", position_m.x, position_m.y, position_m.z)]
pub struct GeofenceViolation {
    /// Index of the knot.
    pub knot: usize,
    /// Its position, metres (world frame).
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
        match trajectory
            .knots()
            .iter()
            .enumerate()
            .find(|(_, k)| !self.contains(&k.position_m))
        {
            Some((knot, k)) => Err(GeofenceViolation {
                knot,
                position_m: k.position_m,
            }),
            None => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use troupe_actors::runtime::Time;
    use troupe_actors::trajectory::Knot;

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
        assert_eq!(err.knot, 2);
        assert_eq!(
            err.to_string(),
            "knot 2 at (6.00, 0.00, 1.00) m is outside the geofence"
        );
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
