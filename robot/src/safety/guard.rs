//! The setpoint a vehicle driver may stream now (see [`SetpointGuard`]).

use std::sync::Arc;

use nalgebra::{Point3, Vector3};
use troupe_actors::msgs::Plan;
use troupe_actors::runtime::Time;
use troupe_actors::trajectory::Trajectory;

use super::{Geofence, GeofenceViolation, Watchdog, WatchdogChange};

/// A reference state in the world frame (ENU).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reference {
    /// Position, metres.
    pub position_m: Point3<f64>,
    /// Velocity, m/s.
    pub velocity_mps: Vector3<f64>,
    /// Acceleration, m/s².
    pub acceleration_mps2: Vector3<f64>,
    /// Heading about world z (from east, counter-clockwise), radians.
    pub yaw_rad: f64,
}

/// Samples a trajectory's reference at `t`. The trajectory is linear between knots,
/// so its acceleration is the central difference of the velocity over
/// `[t − window_s, t + window_s]` (a smoothed version of the impulses at the knots).
#[must_use]
pub fn reference_at(trajectory: &Trajectory, t: Time, window_s: f64) -> Option<Reference> {
    let state = trajectory.state_at(t)?;
    let h_s = window_s.max(1e-3);
    let before = Time::from_secs_f64((t.as_secs_f64() - h_s).max(0.0));
    let after = Time::from_secs_f64(t.as_secs_f64() + h_s);
    let v0 = trajectory.state_at(before)?.velocity_mps;
    let v1 = trajectory.state_at(after)?.velocity_mps;
    let span_s = (after.as_secs_f64() - before.as_secs_f64()).max(1e-6);
    Some(Reference {
        position_m: state.position_m,
        velocity_mps: state.velocity_mps,
        acceleration_mps2: (v1 - v0) / span_s,
        yaw_rad: state.yaw_rad,
    })
}

/// What to stream at one tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Setpoint {
    /// Follow this reference.
    Track(Reference),
    /// Hold still: at this position (world frame, inside the fence) and heading when
    /// known; with zero velocity only when no position was ever known.
    Hold {
        /// Where to hold, metres.
        position_m: Option<Point3<f64>>,
        /// Heading to hold, radians (ENU).
        yaw_rad: Option<f64>,
        /// Why.
        reason: HoldReason,
    },
}

/// Why the guard holds instead of tracking the plan.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HoldReason {
    /// No depth frame within the sensor timeout.
    SensorTimeout,
    /// No odometry within the odometry timeout.
    OdometryTimeout,
    /// The heartbeat came back after a loss; waiting for a plan committed since.
    AwaitingPlanAfterLinkLoss,
    /// No plan committed yet.
    NoPlan,
    /// The plan's reference is outside the geofence.
    Geofence,
}

impl HoldReason {
    /// A short name for logs and status.
    #[must_use]
    pub fn as_str(self) -> &'static str {
        match self {
            HoldReason::SensorTimeout => "sensor timeout",
            HoldReason::OdometryTimeout => "odometry timeout",
            HoldReason::AwaitingPlanAfterLinkLoss => "awaiting a new plan after link loss",
            HoldReason::NoPlan => "no plan",
            HoldReason::Geofence => "reference outside the geofence",
        }
    }
}

/// An input the guard watches.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GuardInput {
    /// Depth frames.
    Sensor,
    /// Odometry.
    Odometry,
    /// The autopilot's heartbeat.
    Heartbeat,
}

/// Timeouts and fence of a [`SetpointGuard`] (seconds, world frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GuardConfig {
    /// Longest gap between depth frames.
    pub sensor_timeout_s: f64,
    /// Longest gap between odometry messages.
    pub odometry_timeout_s: f64,
    /// Longest gap between autopilot heartbeats.
    pub heartbeat_timeout_s: f64,
    /// Half-width of the window of the acceleration's central difference.
    pub acceleration_window_s: f64,
    /// The box no setpoint may leave.
    pub geofence: Geofence,
}

/// Counts of what the guard did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GuardCounters {
    /// Ticks that tracked the plan.
    pub tracked: u64,
    /// Ticks that held.
    pub held: u64,
    /// Ticks whose reference was outside the fence (held instead).
    pub fence_holds: u64,
    /// Ticks with no setpoint (heartbeat missing).
    pub silent: u64,
    /// Plans received that leave the fence somewhere.
    pub plans_leaving_fence: u64,
}

/// The setpoint a vehicle driver may stream now, given its inputs' health, the
/// geofence and the committed plan.
///
/// [`SetpointGuard`] combines three [`Watchdog`]s (depth frames, odometry, the
/// autopilot's heartbeat) with a [`Geofence`]. At every setpoint tick it answers with
/// one of:
///
/// - nothing, while the autopilot's heartbeat is missing (nobody listens; the
///   autopilot's own failsafe is in charge);
/// - a **hold** at the current position (clamped into the fence) with zero velocity —
///   the stopping reference — while a sensor or the odometry is stale, before the
///   first plan, after a heartbeat loss until a fresh plan arrives, or when the plan's
///   reference lies outside the fence;
/// - otherwise the plan's **reference** (position, velocity, acceleration, yaw).
///
/// The hold position is latched when the hold begins, so a drifting estimate does not
/// drag the vehicle along; it is released when tracking resumes.
#[derive(Clone, Debug)]
pub struct SetpointGuard {
    config: GuardConfig,
    sensor: Watchdog,
    odometry: Watchdog,
    heartbeat: Watchdog,
    plan: Option<Arc<Plan>>,
    awaiting_plan: bool,
    position_m: Option<Point3<f64>>,
    yaw_rad: Option<f64>,
    hold: Option<(HoldReason, Option<Point3<f64>>, Option<f64>)>,
    counters: GuardCounters,
}

impl SetpointGuard {
    /// A guard whose watchdogs start at `now`.
    #[must_use]
    pub fn new(config: GuardConfig, now: Time) -> Self {
        SetpointGuard {
            sensor: Watchdog::new(config.sensor_timeout_s, now),
            odometry: Watchdog::new(config.odometry_timeout_s, now),
            heartbeat: Watchdog::new(config.heartbeat_timeout_s, now),
            config,
            plan: None,
            awaiting_plan: false,
            position_m: None,
            yaw_rad: None,
            hold: None,
            counters: GuardCounters::default(),
        }
    }

    /// A depth frame arrived.
    pub fn depth_frame(&mut self, now: Time) -> Option<WatchdogChange> {
        self.sensor.feed(now)
    }

    /// Odometry arrived: the vehicle's position (world frame) and heading.
    pub fn odometry(
        &mut self,
        now: Time,
        position_m: Point3<f64>,
        yaw_rad: f64,
    ) -> Option<WatchdogChange> {
        if position_m.coords.iter().all(|v| v.is_finite()) && yaw_rad.is_finite() {
            self.position_m = Some(position_m);
            self.yaw_rad = Some(yaw_rad);
            self.odometry.feed(now)
        } else {
            None
        }
    }

    /// The autopilot's heartbeat arrived.
    pub fn heartbeat(&mut self, now: Time) -> Option<WatchdogChange> {
        self.heartbeat.feed(now)
    }

    /// A plan was committed. It is followed as far as the fence allows; the error says
    /// where it first leaves the fence (counted).
    pub fn plan(&mut self, plan: Arc<Plan>) -> Result<(), GeofenceViolation> {
        let check = self.config.geofence.check_trajectory(&plan.trajectory);
        if check.is_err() {
            self.counters.plans_leaving_fence += 1;
        }
        self.plan = Some(plan);
        self.awaiting_plan = false;
        check
    }

    /// Checks the watchdogs at `now` and decides what to stream. `changes` receives
    /// every watchdog change (each reported once).
    pub fn tick(
        &mut self,
        now: Time,
        changes: &mut Vec<(GuardInput, WatchdogChange)>,
    ) -> Option<Setpoint> {
        for (input, dog) in [
            (GuardInput::Sensor, &mut self.sensor),
            (GuardInput::Odometry, &mut self.odometry),
            (GuardInput::Heartbeat, &mut self.heartbeat),
        ] {
            if let Some(change) = dog.check(now) {
                changes.push((input, change));
                if (input, change) == (GuardInput::Heartbeat, WatchdogChange::Lost) {
                    // Whatever the plan says once the link is back, it was made for a
                    // vehicle that kept moving; hold until a plan committed since.
                    self.awaiting_plan = true;
                }
            }
        }
        if !self.heartbeat.ever_fed() || self.heartbeat.is_stale() {
            self.counters.silent += 1;
            return None;
        }
        let reason = if self.sensor.is_stale() {
            Some(HoldReason::SensorTimeout)
        } else if self.odometry.is_stale() {
            Some(HoldReason::OdometryTimeout)
        } else if self.awaiting_plan {
            Some(HoldReason::AwaitingPlanAfterLinkLoss)
        } else {
            None
        };
        let reference = match (reason, &self.plan) {
            (Some(reason), _) => Err(reason),
            (None, None) => Err(HoldReason::NoPlan),
            (None, Some(plan)) => {
                match reference_at(&plan.trajectory, now, self.config.acceleration_window_s) {
                    Some(r) if self.config.geofence.contains(&r.position_m) => Ok(r),
                    Some(_) => {
                        self.counters.fence_holds += 1;
                        Err(HoldReason::Geofence)
                    }
                    None => Err(HoldReason::NoPlan),
                }
            }
        };
        match reference {
            Ok(r) => {
                self.hold = None;
                self.counters.tracked += 1;
                Some(Setpoint::Track(r))
            }
            Err(reason) => {
                self.counters.held += 1;
                let fence = self.config.geofence;
                let here = self.position_m.map(|p| fence.clamp(&p));
                let (_, position_m, yaw_rad) =
                    self.hold.get_or_insert((reason, here, self.yaw_rad));
                // Latched where the hold began; filled in if no position was known then.
                if position_m.is_none() {
                    *position_m = here;
                    *yaw_rad = self.yaw_rad;
                }
                let (position_m, yaw_rad) = (*position_m, *yaw_rad);
                self.hold = Some((reason, position_m, yaw_rad));
                Some(Setpoint::Hold {
                    position_m,
                    yaw_rad,
                    reason,
                })
            }
        }
    }

    /// Why it holds now (as of the last tick), if it does.
    #[must_use]
    pub fn hold_reason(&self) -> Option<HoldReason> {
        self.hold.map(|(reason, _, _)| reason)
    }

    /// Whether the heartbeat is missing (never seen, or stale as of the last tick).
    #[must_use]
    pub fn heartbeat_missing(&self) -> bool {
        !self.heartbeat.ever_fed() || self.heartbeat.is_stale()
    }

    /// Seconds since the last heartbeat, if one ever arrived.
    #[must_use]
    pub fn heartbeat_age_s(&self, now: Time) -> Option<f64> {
        self.heartbeat.ever_fed().then(|| self.heartbeat.age_s(now))
    }

    /// What it did so far.
    #[must_use]
    pub fn counters(&self) -> GuardCounters {
        self.counters
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use troupe_actors::trajectory::Knot;

    fn t(s: f64) -> Time {
        Time::from_secs_f64(s)
    }

    fn guard() -> SetpointGuard {
        fenced_guard(20.0)
    }

    /// A guard whose fence ends `max_x_m` east.
    fn fenced_guard(max_x_m: f64) -> SetpointGuard {
        SetpointGuard::new(
            GuardConfig {
                sensor_timeout_s: 0.5,
                odometry_timeout_s: 0.3,
                heartbeat_timeout_s: 1.0,
                acceleration_window_s: 0.05,
                geofence: Geofence::new(
                    Point3::new(-5.0, -5.0, 0.0),
                    Point3::new(max_x_m, 5.0, 3.0),
                )
                .unwrap(),
            },
            t(0.0),
        )
    }

    /// East at 1 m/s from x = 0 at t = 0 to x = 10 at t = 10, 1 m up, facing east.
    fn eastward_plan() -> Arc<Plan> {
        let knot = |s: f64| Knot {
            time: t(s),
            position_m: Point3::new(s, 0.0, 1.0),
            yaw_rad: 0.0,
        };
        Arc::new(Plan::new(
            t(0.0),
            Trajectory::new(vec![knot(0.0), knot(10.0)]).unwrap(),
        ))
    }

    /// Feeds every input at `now` with the vehicle at `x` m east.
    fn feed_all(g: &mut SetpointGuard, now: Time, x: f64) {
        g.depth_frame(now);
        g.odometry(now, Point3::new(x, 0.0, 1.0), 0.0);
        g.heartbeat(now);
    }

    #[test]
    fn silent_without_heartbeat_and_holds_without_plan() {
        let mut g = guard();
        let mut changes = Vec::new();
        assert_eq!(g.tick(t(0.1), &mut changes), None, "no heartbeat yet");
        feed_all(&mut g, t(0.2), 0.0);
        let sp = g.tick(t(0.2), &mut changes);
        assert!(matches!(
            sp,
            Some(Setpoint::Hold {
                reason: HoldReason::NoPlan,
                position_m: Some(_),
                ..
            })
        ));
        assert!(changes.is_empty());
    }

    #[test]
    fn tracks_the_plan_with_velocity_and_acceleration() {
        let mut g = guard();
        let mut changes = Vec::new();
        feed_all(&mut g, t(1.0), 1.0);
        assert!(g.plan(eastward_plan()).is_ok());
        let Some(Setpoint::Track(r)) = g.tick(t(1.0), &mut changes) else {
            panic!("expected tracking");
        };
        assert!((r.position_m.x - 1.0).abs() < 1e-9);
        assert!((r.velocity_mps.x - 1.0).abs() < 1e-9);
        assert!(r.acceleration_mps2.norm() < 1e-9, "constant velocity");
        assert_eq!(g.counters().tracked, 1);
    }

    #[test]
    fn acceleration_is_the_smoothed_change_of_velocity() {
        // At rest until t = 1, then 2 m/s east.
        let knot = |s: f64, x: f64| Knot {
            time: t(s),
            position_m: Point3::new(x, 0.0, 0.0),
            yaw_rad: 0.0,
        };
        let traj = Trajectory::new(vec![knot(0.0, 0.0), knot(1.0, 0.0), knot(3.0, 4.0)]).unwrap();
        let r = reference_at(&traj, t(1.0), 0.1).unwrap();
        // Velocity steps 0 → 2 m/s across the 0.2 s window.
        assert!(
            (r.acceleration_mps2.x - 10.0).abs() < 1e-6,
            "{}",
            r.acceleration_mps2
        );
        let r = reference_at(&traj, t(2.0), 0.1).unwrap();
        assert!(r.acceleration_mps2.norm() < 1e-9);
    }

    #[test]
    fn sensor_timeout_holds_once_latched_and_resumes() {
        let mut g = guard();
        let mut changes = Vec::new();
        g.plan(eastward_plan()).unwrap();
        feed_all(&mut g, t(1.0), 1.0);
        assert!(matches!(
            g.tick(t(1.0), &mut changes),
            Some(Setpoint::Track(_))
        ));
        // Frames stop after t = 1.0; odometry and heartbeat go on.
        let mut held_at = None;
        for i in 1..=20 {
            let now = t(1.0 + 0.05 * f64::from(i));
            g.odometry(now, Point3::new(now.as_secs_f64(), 0.0, 1.0), 0.0);
            g.heartbeat(now);
            if let Some(Setpoint::Hold {
                position_m, reason, ..
            }) = g.tick(now, &mut changes)
            {
                assert_eq!(reason, HoldReason::SensorTimeout);
                let p = position_m.unwrap();
                // Latched where the hold began, not chasing the odometry.
                let first = *held_at.get_or_insert((now, p));
                assert_eq!(p, first.1);
            }
        }
        let (since, _) = held_at.expect("held");
        assert!(since.as_secs_f64() > 1.5 && since.as_secs_f64() <= 1.55 + 1e-9);
        assert_eq!(changes, vec![(GuardInput::Sensor, WatchdogChange::Lost)]);
        // Frames return: tracking resumes and the recovery is not a "change" of check.
        assert_eq!(g.depth_frame(t(2.1)), Some(WatchdogChange::Restored));
        g.odometry(t(2.1), Point3::new(2.1, 0.0, 1.0), 0.0);
        assert!(matches!(
            g.tick(t(2.1), &mut changes),
            Some(Setpoint::Track(_))
        ));
        assert_eq!(g.hold_reason(), None);
    }

    #[test]
    fn odometry_timeout_holds() {
        let mut g = guard();
        let mut changes = Vec::new();
        g.plan(eastward_plan()).unwrap();
        feed_all(&mut g, t(1.0), 1.0);
        g.depth_frame(t(1.35));
        g.heartbeat(t(1.35));
        let sp = g.tick(t(1.35), &mut changes);
        assert!(matches!(
            sp,
            Some(Setpoint::Hold {
                reason: HoldReason::OdometryTimeout,
                ..
            })
        ));
        assert_eq!(changes, vec![(GuardInput::Odometry, WatchdogChange::Lost)]);
    }

    #[test]
    fn heartbeat_loss_silences_then_holds_until_a_new_plan() {
        let mut g = guard();
        let mut changes = Vec::new();
        g.plan(eastward_plan()).unwrap();
        feed_all(&mut g, t(1.0), 1.0);
        assert!(g.tick(t(1.0), &mut changes).is_some());
        g.depth_frame(t(2.05));
        g.odometry(t(2.05), Point3::new(2.0, 0.0, 1.0), 0.0);
        assert_eq!(g.tick(t(2.05), &mut changes), None);
        assert!(g.heartbeat_missing());
        assert_eq!(changes, vec![(GuardInput::Heartbeat, WatchdogChange::Lost)]);
        assert_eq!(g.heartbeat(t(2.2)), Some(WatchdogChange::Restored));
        g.depth_frame(t(2.2));
        g.odometry(t(2.2), Point3::new(2.0, 0.0, 1.0), 0.0);
        assert!(matches!(
            g.tick(t(2.2), &mut changes),
            Some(Setpoint::Hold {
                reason: HoldReason::AwaitingPlanAfterLinkLoss,
                ..
            })
        ));
        g.plan(eastward_plan()).unwrap();
        let sp = g.tick(t(2.25), &mut changes);
        assert!(matches!(sp, Some(Setpoint::Track(_))), "{sp:?}");
        assert_eq!(g.counters().silent, 1);
    }

    #[test]
    fn never_streams_outside_the_fence() {
        let mut g = fenced_guard(5.0);
        let mut changes = Vec::new();
        // The plan leaves the fence (x max 5) at t = 5.
        assert_eq!(g.plan(eastward_plan()).unwrap_err().time, t(10.0));
        assert_eq!(g.counters().plans_leaving_fence, 1);
        let fence = g.config.geofence;
        let mut fence_holds = 0;
        for i in 0..100 {
            let now = t(0.1 * f64::from(i));
            // The vehicle drifts past the fence too: the hold pulls it back inside.
            feed_all(&mut g, now, now.as_secs_f64().min(5.5));
            match g.tick(now, &mut changes) {
                Some(Setpoint::Track(r)) => assert!(fence.contains(&r.position_m)),
                Some(Setpoint::Hold {
                    position_m, reason, ..
                }) => {
                    assert_eq!(reason, HoldReason::Geofence);
                    assert!(fence.contains(&position_m.unwrap()));
                    fence_holds += 1;
                }
                None => panic!("heartbeat is fresh"),
            }
        }
        assert!(fence_holds > 40);
        assert_eq!(g.counters().fence_holds, fence_holds);
    }

    #[test]
    fn holds_with_zero_velocity_when_no_position_is_known() {
        let mut g = guard();
        let mut changes = Vec::new();
        g.heartbeat(t(0.1));
        g.depth_frame(t(0.1));
        g.plan(eastward_plan()).unwrap();
        // No odometry ever: stale after 0.3 s.
        let sp = g.tick(t(0.4), &mut changes);
        assert_eq!(
            sp,
            Some(Setpoint::Hold {
                position_m: None,
                yaw_rad: None,
                reason: HoldReason::OdometryTimeout
            })
        );
        // NaN odometry is ignored.
        assert_eq!(
            g.odometry(t(0.5), Point3::new(f64::NAN, 0.0, 0.0), 0.0),
            None
        );
    }
}
