//! Ground-truth metrics of a run, gathered by a [`Tap`] on every publication:
//! explored-volume coverage from the frames, collisions and clearance from the
//! odometry, both checked against the world (never against a robot's map) with
//! [`surface_distance_m`], the true distance to the surface (a world's SDF is only a
//! bound).

use std::sync::{Arc, Mutex, MutexGuard};

use nalgebra::Point3;
use serde::Serialize;
use troupe_actors::link::{LINK_STATUS, LinkStatus};
use troupe_actors::msgs::{DEPTH_FRAME, ODOMETRY, PLAN};

use crate::network::Positions;
use troupe_actors::runtime::{LINK_RX, Publication, Tap};

use crate::coverage::CoverageGrid;
use crate::world::{World, surface_distance_m};

/// Collision checks along the path are this far apart, metres.
const PATH_CHECK_STEP_M: f64 = 0.05;

/// Clearances are measured exactly up to this much beyond the body (larger ones are
/// reported as this), metres.
pub const CLEARANCE_REPORTED_M: f64 = 1.0;

/// Ground truth about one robot (the serialised fields are what `summary.json` reports).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct RobotTruth {
    /// Last known position.
    #[serde(skip)]
    pub position: Option<Point3<f64>>,
    /// Last known yaw, radians.
    #[serde(skip)]
    pub yaw_rad: f64,
    /// Last known speed, m/s.
    #[serde(skip)]
    pub speed_mps: f64,
    /// Path length flown, metres.
    pub distance_m: f64,
    /// Times the body entered the rock (a collision episode counts once).
    pub collisions: u64,
    /// Whether the body is in collision now.
    #[serde(skip)]
    pub in_collision: bool,
    /// Smallest distance between the body surface and the world, metres.
    pub min_clearance_m: f64,
    /// Highest speed, m/s.
    pub max_speed_mps: f64,
    /// Frames rendered.
    pub frames: u64,
    /// Frames with no valid pixel.
    pub empty_frames: u64,
    /// Committed plans received.
    pub plans: u64,
    /// Committed plans with a knot closer to the rock than the body radius (ground
    /// truth): a plan the robot should never have committed.
    pub unsafe_plans: u64,
    /// The link's latest counters.
    pub link: Option<LinkStatus>,
    /// Bytes the network delivered to this robot (all classes, fragments and acks
    /// included).
    pub received_bytes: u64,
}

/// Everything the monitor knows.
pub struct Truth {
    /// Explored cells.
    pub coverage: CoverageGrid,
    /// Per robot.
    pub robots: Vec<RobotTruth>,
    /// Smallest distance between two robot centres seen at an odometry update, metres.
    pub min_inter_robot_distance_m: f64,
    /// Episodes of two robot bodies overlapping (centres closer than two radii).
    pub robot_contacts: u64,
    /// Pairs (row-major, `i * n + j`) whose bodies overlap now.
    in_contact: Vec<bool>,
}

/// The tap; clone the handle from [`GroundTruthMonitor::truth`] before giving the
/// monitor to an executor.
pub struct GroundTruthMonitor {
    world: Arc<dyn World>,
    pixel_stride: usize,
    radius_m: f64,
    truth: Arc<Mutex<Truth>>,
    positions: Positions,
}

impl GroundTruthMonitor {
    /// A monitor for `robots` robots of body radius `radius_m`.
    #[must_use]
    pub fn new(
        world: Arc<dyn World>,
        coverage_cell_m: f64,
        pixel_stride: usize,
        robots: usize,
        radius_m: f64,
    ) -> Self {
        let coverage = CoverageGrid::new(world.as_ref(), coverage_cell_m);
        let count = robots;
        let robots = vec![
            RobotTruth {
                min_clearance_m: f64::INFINITY,
                ..RobotTruth::default()
            };
            robots
        ];
        GroundTruthMonitor {
            world,
            pixel_stride,
            radius_m,
            positions: Arc::new(Mutex::new(vec![[0.0; 3]; count])),
            truth: Arc::new(Mutex::new(Truth {
                coverage,
                robots,
                min_inter_robot_distance_m: f64::INFINITY,
                robot_contacts: 0,
                in_contact: vec![false; count * count],
            })),
        }
    }

    /// Robot positions as last seen, for the network's range model.
    #[must_use]
    pub fn positions(&self) -> Positions {
        self.positions.clone()
    }

    /// Shared handle on the metrics.
    #[must_use]
    pub fn truth(&self) -> Arc<Mutex<Truth>> {
        self.truth.clone()
    }
}

/// Locks the truth (a poisoned lock still holds consistent counters).
pub fn lock_truth(truth: &Mutex<Truth>) -> MutexGuard<'_, Truth> {
    truth
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl Tap for GroundTruthMonitor {
    fn on_publish(&mut self, p: &Publication<'_>) {
        let r = p.robot.0 as usize;
        if let Some(frame) = p.get(&DEPTH_FRAME) {
            let mut truth = lock_truth(&self.truth);
            let Some(robot) = truth.robots.get_mut(r) else {
                return;
            };
            robot.frames += 1;
            if frame.valid_pixels() == 0 {
                robot.empty_frames += 1;
            }
            truth.coverage.observe(frame, self.pixel_stride);
        } else if let Some(packet) = p.get(&LINK_RX) {
            if let Some(robot) = lock_truth(&self.truth).robots.get_mut(r) {
                robot.received_bytes += packet.bytes.len() as u64;
            }
        } else if let Some(status) = p.get(&LINK_STATUS) {
            if let Some(robot) = lock_truth(&self.truth).robots.get_mut(r) {
                robot.link = Some(status.clone());
            }
        } else if let Some(plan) = p.get(&PLAN) {
            let closest = plan
                .trajectory
                .knots()
                .iter()
                .map(|k| {
                    let d = surface_distance_m(self.world.as_ref(), &k.position_m, self.radius_m);
                    (d, k.position_m)
                })
                .min_by(|a, b| a.0.total_cmp(&b.0));
            let unsafe_plan = closest.is_some_and(|(d, _)| d < self.radius_m);
            let mut truth = lock_truth(&self.truth);
            let Some(robot) = truth.robots.get_mut(r) else {
                return;
            };
            robot.plans += 1;
            if unsafe_plan {
                robot.unsafe_plans += 1;
                if let Some((distance_m, at)) = closest {
                    tracing::warn!(robot = r, time = %p.time, clearance_m = distance_m - self.radius_m,
                        x = at.x, y = at.y, z = at.z, "committed plan enters the rock (ground truth)");
                }
            }
        } else if let Some(odometry) = p.get(&ODOMETRY) {
            let position = Point3::from(odometry.pose.translation.vector);
            if let Some(slot) = self
                .positions
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .get_mut(r)
            {
                *slot = position.coords.into();
            }
            let (_, _, yaw) = odometry.pose.rotation.euler_angles();
            let mut truth = lock_truth(&self.truth);
            let Some(robot) = truth.robots.get_mut(r) else {
                return;
            };
            let previous = robot.position.unwrap_or(position);
            let step = (position - previous).norm();
            let checks = (step / PATH_CHECK_STEP_M).ceil().max(1.0) as usize;
            let mut colliding = robot.in_collision;
            for i in 1..=checks {
                let q = previous + (position - previous) * (i as f64 / checks as f64);
                let clearance = surface_distance_m(
                    self.world.as_ref(),
                    &q,
                    self.radius_m + CLEARANCE_REPORTED_M,
                ) - self.radius_m;
                robot.min_clearance_m = robot.min_clearance_m.min(clearance);
                if clearance < 0.0 {
                    if !colliding {
                        robot.collisions += 1;
                        tracing::warn!(robot = r, x = q.x, y = q.y, z = q.z, time = %p.time, "collision with the world");
                    }
                    colliding = true;
                } else {
                    colliding = false;
                }
            }
            robot.in_collision = colliding;
            robot.distance_m += step;
            robot.position = Some(position);
            robot.yaw_rad = yaw;
            robot.speed_mps = odometry.velocity_mps.norm();
            robot.max_speed_mps = robot.max_speed_mps.max(robot.speed_mps);
            let n = truth.robots.len();
            for j in (0..n).filter(|j| *j != r) {
                let Some(other) = truth.robots[j].position else {
                    continue;
                };
                let distance = (other - position).norm();
                truth.min_inter_robot_distance_m = truth.min_inter_robot_distance_m.min(distance);
                let (a, b) = (r.min(j), r.max(j));
                let touching = distance < 2.0 * self.radius_m;
                if touching && !truth.in_contact[a * n + b] {
                    truth.robot_contacts += 1;
                    tracing::warn!(robots = ?(a, b), distance, time = %p.time, "robot bodies overlap");
                }
                truth.in_contact[a * n + b] = touching;
            }
        }
    }
}
