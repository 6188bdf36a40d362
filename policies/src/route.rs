//! A scripted route: fly through given waypoints at a constant speed.
//!
//! It needs no map and makes no decisions; it exists so that a team can be run end
//! to end before the information-driven planner (thesis §4) is in place, and as a
//! baseline. Safety comes from the route: the scenario must hand it waypoints with
//! clearance (the cave's centre lines have at least 1 m).

use nalgebra::{Point3, Vector3};
use troupe_algorithms::exploration::ExplorationBehaviour;
use troupe_algorithms::frame::Odometry;
use troupe_algorithms::trajectory::{Knot, Trajectory, wrap_angle};
use troupe_core::Time;

use crate::PolicyError;

/// Heading changes larger than this are turned in place before moving on.
const TURN_IN_PLACE_RAD: f64 = 0.5;

/// See the [module docs](self).
#[derive(Clone, Debug)]
pub struct WaypointRoute {
    waypoints: Vec<Point3<f64>>,
    speed_mps: f64,
    yaw_rate_rad_s: f64,
    depart_at: Time,
    committed: bool,
}

impl WaypointRoute {
    /// A route through `waypoints` at `speed_mps`, turning in place at `yaw_rate_rad_s`.
    pub fn new(
        waypoints: Vec<Point3<f64>>,
        speed_mps: f64,
        yaw_rate_rad_s: f64,
    ) -> Result<Self, PolicyError> {
        let bad = |reason: String| PolicyError::BadInput {
            behaviour: "waypoint_route",
            reason,
        };
        if waypoints.is_empty() {
            return Err(bad("needs at least one waypoint".into()));
        }
        if waypoints
            .iter()
            .any(|p| !p.coords.iter().all(|v| v.is_finite()))
        {
            return Err(bad("waypoints must be finite".into()));
        }
        if !(speed_mps.is_finite() && speed_mps > 0.0) {
            return Err(bad(format!("speed must be > 0 m/s, got {speed_mps}")));
        }
        if !(yaw_rate_rad_s.is_finite() && yaw_rate_rad_s > 0.0) {
            return Err(bad(format!(
                "yaw rate must be > 0 rad/s, got {yaw_rate_rad_s}"
            )));
        }
        Ok(WaypointRoute {
            waypoints,
            speed_mps,
            yaw_rate_rad_s,
            depart_at: Time::ZERO,
            committed: false,
        })
    }

    /// Holds position until `depart_at` (run time), then flies the route.
    #[must_use]
    pub fn departing_at(mut self, depart_at: Time) -> Self {
        self.depart_at = depart_at;
        self
    }

    /// The whole route as a trajectory starting at `start` from `position` with `yaw`.
    #[must_use]
    pub fn trajectory_from(&self, start: Time, position: Point3<f64>, yaw_rad: f64) -> Trajectory {
        let mut knots = vec![Knot {
            time: start,
            position_m: position,
            yaw_rad,
        }];
        let mut t = start.as_secs_f64();
        let mut here = position;
        let mut heading = yaw_rad;
        for &next in &self.waypoints {
            let step: Vector3<f64> = next - here;
            let length = step.norm();
            if length < 1e-6 {
                continue;
            }
            let horizontal = step.xy().norm();
            let new_heading = if horizontal > 1e-6 {
                step.y.atan2(step.x)
            } else {
                heading
            };
            let turn = wrap_angle(new_heading - heading).abs();
            if turn > TURN_IN_PLACE_RAD {
                t += turn / self.yaw_rate_rad_s;
                knots.push(Knot {
                    time: Time::from_secs_f64(t),
                    position_m: here,
                    yaw_rad: new_heading,
                });
            }
            t += length / self.speed_mps;
            knots.push(Knot {
                time: Time::from_secs_f64(t),
                position_m: next,
                yaw_rad: new_heading,
            });
            here = next;
            heading = new_heading;
        }
        // Knots are built in increasing time from finite inputs.
        Trajectory::new(knots).unwrap_or_default()
    }
}

impl ExplorationBehaviour for WaypointRoute {
    /// Commits the route once, at the first call at or after the departure time. A
    /// fresh instance (after a restart) resumes on the route segment nearest to the
    /// robot, heading for that segment's end: the robot is on the segment, so the end
    /// is reachable in a straight line along it.
    fn replan(&mut self, now: Time, odometry: &Odometry) -> Option<Trajectory> {
        if self.committed || now < self.depart_at {
            return None;
        }
        self.committed = true;
        let position = Point3::from(odometry.pose.translation.vector);
        let (_, _, yaw) = odometry.pose.rotation.euler_angles();
        let resume = self
            .waypoints
            .windows(2)
            .enumerate()
            .min_by(|(_, a), (_, b)| {
                segment_distance(&position, &a[0], &a[1])
                    .total_cmp(&segment_distance(&position, &b[0], &b[1]))
            })
            .map_or(0, |(k, _)| k + 1);
        Some(
            self.remaining_from(resume)
                .trajectory_from(now, position, yaw),
        )
    }
}

/// Distance from `p` to the segment `a`–`b`.
fn segment_distance(p: &Point3<f64>, a: &Point3<f64>, b: &Point3<f64>) -> f64 {
    let ab = b - a;
    let length2 = ab.norm_squared();
    let s = if length2 > 0.0 {
        ((p - a).dot(&ab) / length2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p - (a + ab * s)).norm()
}

impl WaypointRoute {
    fn remaining_from(&self, index: usize) -> WaypointRoute {
        WaypointRoute {
            waypoints: self.waypoints[index..].to_vec(),
            ..self.clone()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_speed_and_turns_in_place() {
        let route = WaypointRoute::new(
            vec![Point3::new(2.0, 0.0, 1.0), Point3::new(2.0, 3.0, 1.0)],
            1.0,
            1.0,
        )
        .unwrap();
        let traj = route.trajectory_from(Time::from_secs_f64(1.0), Point3::new(0.0, 0.0, 1.0), 0.0);
        let knots = traj.knots();
        // start, arrive at (2,0), turn 90° in place, arrive at (2,3).
        assert_eq!(knots.len(), 4);
        assert!((knots[1].time.as_secs_f64() - 3.0).abs() < 1e-9);
        assert!((knots[2].time.as_secs_f64() - (3.0 + std::f64::consts::FRAC_PI_2)).abs() < 1e-9);
        assert!((traj.end_time().as_secs_f64() - (6.0 + std::f64::consts::FRAC_PI_2)).abs() < 1e-9);
        for i in 0..100 {
            let s = traj
                .state_at(Time::from_secs_f64(1.0 + i as f64 * 0.07))
                .unwrap();
            assert!(s.velocity_mps.norm() <= 1.0 + 1e-9);
        }
    }

    #[test]
    fn a_fresh_instance_resumes_from_the_nearest_waypoint() {
        let waypoints: Vec<_> = (0..10)
            .map(|i| Point3::new(f64::from(i), 0.0, 1.0))
            .collect();
        let mut route = WaypointRoute::new(waypoints, 1.0, 1.0).unwrap();
        let odometry = |x: f64| Odometry {
            stamp: Time::ZERO,
            pose: nalgebra::Isometry3::translation(x, 0.0, 1.0),
            velocity_mps: Vector3::zeros(),
        };
        let first = route.replan(Time::ZERO, &odometry(0.0)).unwrap();
        assert_eq!(first.knots().len(), 10);
        assert!(
            route
                .replan(Time::from_secs_f64(1.0), &odometry(1.0))
                .is_none()
        );
        let mut restarted = WaypointRoute::new(route.waypoints.clone(), 1.0, 1.0).unwrap();
        let resumed = restarted
            .replan(Time::from_secs_f64(5.0), &odometry(6.2))
            .unwrap();
        // Starts where the robot is, on segment 6–7, and goes on to 7, 8, 9 (no
        // backtracking to the start of the route).
        assert_eq!(resumed.knots()[1].position_m.x, 7.0);
        assert_eq!(resumed.knots().len(), 4);
        let late = WaypointRoute::new(vec![Point3::new(1.0, 0.0, 1.0)], 1.0, 1.0).unwrap();
        let mut late = late.departing_at(Time::from_secs_f64(4.0));
        assert!(
            late.replan(Time::from_secs_f64(3.0), &odometry(0.0))
                .is_none()
        );
        assert!(
            late.replan(Time::from_secs_f64(4.0), &odometry(0.0))
                .is_some()
        );
    }

    #[test]
    fn rejects_bad_inputs() {
        assert!(WaypointRoute::new(vec![], 1.0, 1.0).is_err());
        assert!(WaypointRoute::new(vec![Point3::origin()], 0.0, 1.0).is_err());
        assert!(WaypointRoute::new(vec![Point3::new(f64::NAN, 0.0, 0.0)], 1.0, 1.0).is_err());
        assert!(crate::behaviour_by_name("teleport", &Default::default()).is_err());
    }
}
