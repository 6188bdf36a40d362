//! Ground-truth metrics of a run, gathered by a [`Tap`] on every publication:
//! explored-volume coverage from the frames, collisions and clearance from the
//! odometry, both checked against the world (never against a robot's map) with
//! [`surface_distance_m`], the true distance to the surface (a world's SDF is only a
//! bound), and per robot the time spent moving without seeing new volume
//! ([`UnproductiveTime`]) and who re-explored what ([`crate::reexploration`]).

use std::collections::VecDeque;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use nalgebra::Point3;
use serde::Serialize;
use troupe_actors::link::{LINK_STATUS, LinkStatus};
use troupe_actors::msgs::{DEPTH_FRAME, ODOMETRY, PLAN};
use troupe_actors::planner::PLANNING_REPORT;
use troupe_algorithms::exploration::MissionStatus;
use troupe_algorithms::frame::{DepthFrame, Odometry};
use troupe_algorithms::plan::Plan;
use troupe_comms::shaping::frame::class_of;
use troupe_comms::wire::Class;

use crate::network::Positions;
use troupe_core::Time;
use troupe_runtime::{LINK_RX, Publication, Tap};

use crate::coverage::CoverageGrid;
use crate::reexploration::{ReExploration, ReExplorationLedger};
use crate::world::{World, surface_distance_m};

/// Collision checks along the path are this far apart, metres.
const PATH_CHECK_STEP_M: f64 = 0.05;

/// Clearances are measured exactly up to this much beyond the body (larger ones are
/// reported as this), metres.
pub const CLEARANCE_REPORTED_M: f64 = 1.0;

/// A robot moving at least this fast can be unproductive, m/s.
pub const UNPRODUCTIVE_SPEED_MPS: f64 = 0.1;

/// The trailing window over which a robot's newly seen volume is summed, seconds.
pub const UNPRODUCTIVE_WINDOW_S: f64 = 2.0;

/// A robot whose frames saw less new volume than this over the last
/// [`UNPRODUCTIVE_WINDOW_S`] is not observing anything new, m³ (eight 0.4 m coverage
/// cells; a robot flying at 1 m/s into an unseen 2 m tunnel sees about 10 m³/s).
pub const UNPRODUCTIVE_MIN_NEW_M3: f64 = 0.5;

/// Time a robot spends moving while its camera sees no new volume — dithering,
/// re-flying seen tunnels — measured on ground-truth coverage.
///
/// Fed once per depth frame of the robot ([`UnproductiveTime::frame`]) with the
/// frame's time, the volume it explored first (cells no robot had seen before, so
/// re-seeing what a peer saw counts as nothing new) and the robot's latest speed.
/// At a frame at time `t` the robot *observes nothing new* when its frames in the
/// trailing window `(t − W, t]` explored less than [`UNPRODUCTIVE_MIN_NEW_M3`]
/// together (`W` = [`UNPRODUCTIVE_WINDOW_S`]). The time since its previous frame is
/// *unproductive* when it observes nothing new and its speed is at least
/// [`UNPRODUCTIVE_SPEED_MPS`]. An *unproductive interval* is the unproductive time
/// accumulated between two frames that do observe something new: stopping (below the
/// speed) adds nothing to it but does not end it, so a robot that turns back and forth
/// in a seen tunnel stays in one interval. Up to `W` seconds after the last new
/// observation do not count (the window still holds it).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct UnproductiveTime {
    /// Frames in the window: time and new volume, m³.
    recent: VecDeque<(Time, f64)>,
    /// Time of the previous frame.
    last_frame: Option<Time>,
    /// Unproductive time in the open interval, nanoseconds.
    current_ns: u64,
    /// Unproductive time over the whole run, nanoseconds.
    total_ns: u64,
    /// Longest interval so far, nanoseconds.
    longest_ns: u64,
    /// The robot's planner last reported no remembered frontier (no report: unknown,
    /// and the time counts).
    no_frontiers: bool,
    /// Unproductive time in the open interval while a frontier was remembered,
    /// nanoseconds.
    current_with_frontiers_ns: u64,
    /// Longest interval so far counting only that time, nanoseconds.
    longest_with_frontiers_ns: u64,
}

/// Seconds of a count of nanoseconds: the times are summed as integers and converted
/// once, so that a total is exact whatever the order of its steps and of the robots
/// it is summed over.
#[must_use]
pub fn ns_to_s(ns: u64) -> f64 {
    Duration::from_nanos(ns).as_secs_f64()
}

impl UnproductiveTime {
    /// Accounts for a frame at `time` that explored `new_m3` first, with the robot
    /// moving at `speed_mps`. Frames must come in time order; a frame earlier than the
    /// previous one adds no time, a non-finite or negative volume counts as nothing
    /// new, and a non-finite speed as standing still.
    pub fn frame(&mut self, time: Time, new_m3: f64, speed_mps: f64) {
        let new_m3 = if new_m3.is_finite() {
            new_m3.max(0.0)
        } else {
            0.0
        };
        let window = Duration::from_secs_f64(UNPRODUCTIVE_WINDOW_S);
        self.recent
            .retain(|(t, _)| *t <= time && time.saturating_since(*t) < window);
        self.recent.push_back((time, new_m3));
        // A handful of frames (the window times the sensor rate): summed afresh, in
        // time order.
        let recent_m3: f64 = self.recent.iter().map(|(_, v)| v).sum();
        let step_ns = self.last_frame.map_or(0, |last| {
            u64::try_from(time.saturating_since(last).as_nanos()).unwrap_or(u64::MAX)
        });
        self.last_frame = Some(time);
        if recent_m3 >= UNPRODUCTIVE_MIN_NEW_M3 {
            self.current_ns = 0;
            self.current_with_frontiers_ns = 0;
        } else if speed_mps >= UNPRODUCTIVE_SPEED_MPS {
            self.current_ns = self.current_ns.saturating_add(step_ns);
            self.total_ns = self.total_ns.saturating_add(step_ns);
            self.longest_ns = self.longest_ns.max(self.current_ns);
            if !self.no_frontiers {
                self.current_with_frontiers_ns =
                    self.current_with_frontiers_ns.saturating_add(step_ns);
                self.longest_with_frontiers_ns = self
                    .longest_with_frontiers_ns
                    .max(self.current_with_frontiers_ns);
            }
        }
    }

    /// Records whether the robot's planner remembers a frontier to go to (from its
    /// latest planning report), for the frames that follow.
    pub fn remembers_frontiers(&mut self, remembers: bool) {
        self.no_frontiers = !remembers;
    }

    /// Unproductive time so far, nanoseconds.
    #[must_use]
    pub fn total_ns(&self) -> u64 {
        self.total_ns
    }

    /// Unproductive time so far, seconds.
    #[must_use]
    pub fn total_s(&self) -> f64 {
        ns_to_s(self.total_ns)
    }

    /// The longest unproductive interval so far, seconds (the open one included).
    #[must_use]
    pub fn longest_s(&self) -> f64 {
        ns_to_s(self.longest_ns)
    }

    /// The longest unproductive interval so far counting only the time while the robot
    /// remembered a frontier, seconds (the open one included).
    #[must_use]
    pub fn longest_with_frontiers_s(&self) -> f64 {
        ns_to_s(self.longest_with_frontiers_ns)
    }
}

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
    /// Of [`Self::received_bytes`], the frames of the keyframe class: the map data
    /// (GMM keyframes or occupancy-grid change sets) that reached this robot, thesis
    /// Fig. 8.9 (a)–(f).
    pub received_bytes_keyframe: u64,
    /// Volume this robot's frames saw before any other frame of the team, m³ (the
    /// robots' shares of the explored volume).
    pub discovered_m3: f64,
    /// The coverage cells behind [`Self::discovered_m3`].
    #[serde(skip)]
    pub discovered_cells: u64,
    /// Time spent moving without seeing new volume, seconds (see [`UnproductiveTime`]).
    pub unproductive_s: f64,
    /// The longest unproductive interval, seconds (see [`UnproductiveTime`]).
    pub longest_unproductive_s: f64,
    /// The longest unproductive interval counting only the time while the robot
    /// remembered a frontier to go to, seconds (see [`UnproductiveTime`]).
    pub longest_unproductive_with_frontiers_s: f64,
    /// The tracker behind the three unproductive figures.
    #[serde(skip)]
    pub unproductive: UnproductiveTime,
    /// Observed, first-observed, re-explored and exclusive volume and redundant flight
    /// time (thesis §8.2.7's mechanism; see [`crate::reexploration`]).
    #[serde(flatten)]
    pub reexploration: ReExploration,
    /// The robot's mission after its planner's last round: phase, when exploring ended
    /// and why, when it was home, the return's time and distance (absent without a
    /// planner).
    pub mission: Option<MissionStatus>,
}

/// Everything the monitor knows.
pub struct Truth {
    /// Explored cells.
    pub coverage: CoverageGrid,
    /// Who observed which cell of `coverage` when.
    pub reexploration: ReExplorationLedger,
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
        let reexploration =
            ReExplorationLedger::new(coverage.grid().cell_count(), coverage.grid().cell_m, count);
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
                reexploration,
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
            self.on_depth_frame(r, p.time, frame);
        } else if let Some(packet) = p.get(&LINK_RX) {
            if let Some(robot) = lock_truth(&self.truth).robots.get_mut(r) {
                robot.received_bytes += packet.bytes.len() as u64;
                if class_of(&packet.bytes) == Ok(Class::Keyframe) {
                    robot.received_bytes_keyframe += packet.bytes.len() as u64;
                }
            }
        } else if let Some(report) = p.get(&PLANNING_REPORT) {
            if let Some(robot) = lock_truth(&self.truth).robots.get_mut(r) {
                if let Some(frontiers) = report.frontiers {
                    robot.unproductive.remembers_frontiers(frontiers > 0);
                }
                robot.mission = Some(report.mission);
            }
        } else if let Some(status) = p.get(&LINK_STATUS) {
            if let Some(robot) = lock_truth(&self.truth).robots.get_mut(r) {
                robot.link = Some(status.clone());
            }
        } else if let Some(plan) = p.get(&PLAN) {
            self.on_plan(r, p.time, plan);
        } else if let Some(odometry) = p.get(&ODOMETRY) {
            self.on_odometry(r, p.time, odometry);
        }
    }
}

impl GroundTruthMonitor {
    /// Coverage, re-exploration and unproductive time from what robot `r`'s frame saw.
    fn on_depth_frame(&mut self, r: usize, time: Time, frame: &DepthFrame) {
        let mut truth = lock_truth(&self.truth);
        let Some(robot) = truth.robots.get_mut(r) else {
            return;
        };
        robot.frames += 1;
        if frame.valid_pixels() == 0 {
            robot.empty_frames += 1;
        }
        // Counted in cells and converted once: no float sum to drift.
        let before = truth.coverage.explored_cells();
        let Truth {
            coverage,
            reexploration,
            robots,
            ..
        } = &mut *truth;
        let mut account = reexploration.frame(r, time);
        coverage.observe_visiting(frame, self.pixel_stride, |cell| {
            if let Some(a) = account.as_mut() {
                a.saw(cell);
            }
        });
        if let Some(a) = account {
            a.finish(robots[r].speed_mps);
        }
        robots[r].reexploration = reexploration.robot(r);
        let new_cells = (truth.coverage.explored_cells() - before) as u64;
        let cell_m3 = truth.coverage.cell_volume_m3();
        let new_m3 = new_cells as f64 * cell_m3;
        let robot = &mut truth.robots[r];
        robot.discovered_cells += new_cells;
        robot.discovered_m3 = robot.discovered_cells as f64 * cell_m3;
        robot.unproductive.frame(time, new_m3, robot.speed_mps);
        robot.unproductive_s = robot.unproductive.total_s();
        robot.longest_unproductive_s = robot.unproductive.longest_s();
        robot.longest_unproductive_with_frontiers_s = robot.unproductive.longest_with_frontiers_s();
    }

    /// Counts robot `r`'s committed plan, and whether it enters the rock.
    fn on_plan(&mut self, r: usize, time: Time, plan: &Plan) {
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
                tracing::warn!(robot = r, time = %time, clearance_m = distance_m - self.radius_m,
                    x = at.x, y = at.y, z = at.z, "committed plan enters the rock (ground truth)");
            }
        }
    }

    /// Robot `r`'s path checked against the rock (collisions, clearance) and its
    /// distance to the other robots (contacts).
    fn on_odometry(&mut self, r: usize, time: Time, odometry: &Odometry) {
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
                    tracing::warn!(robot = r, x = q.x, y = q.y, z = q.z, time = %time, "collision with the world");
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
                tracing::warn!(robots = ?(a, b), distance, time = %time, "robot bodies overlap");
            }
            truth.in_contact[a * n + b] = touching;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Feeds frames at 4 Hz (exact binary times) from `from_s` to `to_s` (exclusive),
    /// each seeing `new_m3` while moving at `speed_mps`.
    fn fly(u: &mut UnproductiveTime, from_s: f64, to_s: f64, new_m3: f64, speed_mps: f64) {
        let mut t = from_s;
        while t < to_s {
            u.frame(Time::from_secs_f64(t), new_m3, speed_mps);
            t += 0.25;
        }
    }

    #[test]
    fn moving_without_new_volume_counts_once_the_window_is_empty() {
        let mut u = UnproductiveTime::default();
        // 10 s seeing new volume, then 20 s flying through seen space.
        fly(&mut u, 0.0, 10.0, 1.0, 1.0);
        assert_eq!(u.total_s(), 0.0);
        fly(&mut u, 10.0, 30.0, 0.0, 1.0);
        // The last new frame (9.75 s) leaves the window at 11.75 s, which counts the
        // step from 11.5 s; the last frame is at 29.75 s.
        assert_eq!(u.total_s(), 29.75 - 11.5);
        assert_eq!(u.longest_s(), u.total_s());
    }

    #[test]
    fn stopping_adds_nothing_and_new_volume_ends_the_interval() {
        let mut u = UnproductiveTime::default();
        fly(&mut u, 0.0, 10.0, 0.0, 1.0); // 9.75 s moving, nothing new
        fly(&mut u, 10.0, 20.0, 0.0, 0.0); // hovering: no time, same interval
        fly(&mut u, 20.0, 25.0, 0.0, 1.0); // 5 s more
        assert_eq!(u.longest_s(), 14.75);
        fly(&mut u, 25.0, 26.0, 1.0, 1.0); // sees something: the interval ends
        fly(&mut u, 26.0, 31.0, 0.0, 1.0); // counts from 27.5 s to 30.75 s
        assert_eq!(u.longest_s(), 14.75, "the earlier interval was longer");
        assert_eq!(u.total_s(), 14.75 + 3.25);
    }

    #[test]
    fn a_trickle_below_the_threshold_is_nothing_new() {
        let mut u = UnproductiveTime::default();
        // 0.05 m³ a frame is 0.4 m³ per 2 s window: below the threshold.
        fly(&mut u, 0.0, 10.0, 0.05, 1.0);
        assert_eq!(u.total_s(), 9.75);
        let mut v = UnproductiveTime::default();
        // 0.08 m³ a frame is 0.64 m³ per window: productive from the 7th frame on
        // (1.5 s); the steps of frames 2 to 6 counted.
        fly(&mut v, 0.0, 10.0, 0.08, 1.0);
        assert_eq!(v.total_s(), 1.25);
    }

    #[test]
    fn time_without_a_remembered_frontier_pauses_the_interval_with_frontiers() {
        let mut u = UnproductiveTime::default();
        fly(&mut u, 0.0, 10.0, 0.0, 1.0); // 9.75 s with a frontier (no report: counts)
        u.remembers_frontiers(false);
        fly(&mut u, 10.0, 30.0, 0.0, 1.0); // 20 s with nothing left to go to
        u.remembers_frontiers(true);
        fly(&mut u, 30.0, 35.0, 0.0, 1.0); // 5 s more: the same interval
        assert_eq!(u.longest_s(), 34.75);
        assert_eq!(u.longest_with_frontiers_s(), 14.75);
        fly(&mut u, 35.0, 36.0, 1.0, 1.0); // sees something: both intervals end
        fly(&mut u, 36.0, 41.0, 0.0, 1.0);
        assert_eq!(u.longest_with_frontiers_s(), 14.75);
        assert_eq!(
            u.total_s(),
            34.75 + 3.25,
            "the total counts every unproductive step"
        );
    }

    #[test]
    fn bad_inputs_add_no_time() {
        let mut u = UnproductiveTime::default();
        let at = Time::from_secs_f64;
        u.frame(at(1.0), f64::NAN, 1.0);
        u.frame(at(0.5), 0.0, 1.0); // out of order
        u.frame(at(2.0), -3.0, f64::NAN);
        u.frame(at(3.0), f64::INFINITY, 1.0);
        assert_eq!(u.total_s(), 1.0, "only 2 s → 3 s, moving with nothing new");
    }

    #[test]
    fn unproductive_time_is_summed_in_whole_nanoseconds() {
        // 117 steps of 0.2 s: as floats, 23.400000000000006 s or so, depending on the
        // order of the additions; as nanoseconds, exactly 23.4 s in every order.
        let mut u = UnproductiveTime::default();
        for k in 0..=117u64 {
            u.frame(Time::from_nanos(k * 200_000_000), 0.0, 1.0);
        }
        assert_eq!(u.total_ns(), 23_400_000_000);
        assert_eq!(u.total_s(), 23.4);
        assert_eq!(u.longest_s(), 23.4);
    }
}
