//! The setpoint a vehicle driver may stream now (see [`SetpointGuard`]).

use std::sync::Arc;

use nalgebra::{Point3, Vector3};
use troupe_algorithms::plan::Plan;
use troupe_algorithms::planner::committed::Committed;
use troupe_core::Time;

use super::{Geofence, GeofenceViolation, Watchdog, WatchdogChange};

/// A reference state in the world frame (ENU).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reference {
    /// Position, metres.
    pub position_m: Point3<f64>,
    /// Velocity, m/s.
    pub velocity_mps: Vector3<f64>,
    /// Acceleration, m/s² (the feed-forward); `None` when the plan has no primitive
    /// to take it from (a route's knots): then it is not sent as used.
    pub acceleration_mps2: Option<Vector3<f64>>,
    /// Heading about world z (from east, counter-clockwise), radians.
    pub yaw_rad: f64,
}

impl Reference {
    fn of_primitive(committed: &Committed, t: Time) -> Self {
        let state = committed.state_at(t);
        Reference {
            position_m: Point3::from(state.position_m()),
            velocity_mps: state.velocity_mps(),
            acceleration_mps2: Some(state.acceleration_mps2()),
            yaw_rad: state.yaw_rad(),
        }
    }
}

/// Samples a committed plan at `t`. Once its primitive has taken over (thesis §4.1.2:
/// polynomials continuous up to snap, each starting from the state of the one before),
/// from the primitive itself, with its exact velocity and acceleration; before that,
/// from `previous` (the plan committed before it, whose flight leads there); for a plan
/// without a primitive (a route), from its knots — linear between them, so velocity
/// steps at the knots and no acceleration is given.
#[must_use]
pub fn reference_at(plan: &Plan, previous: Option<&Plan>, t: Time) -> Option<Reference> {
    let primitive = |p: &Plan| {
        p.reference
            .as_deref()
            .filter(|c| t >= c.start)
            .map(|c| Reference::of_primitive(c, t))
    };
    primitive(plan)
        .or_else(|| previous.and_then(primitive))
        .or_else(|| {
            let state = plan.trajectory.state_at(t)?;
            Some(Reference {
                position_m: state.position_m,
                velocity_mps: state.velocity_mps,
                acceleration_mps2: None,
                yaw_rad: state.yaw_rad,
            })
        })
}

/// How close to where the vehicle holds a plan's reference must be for tracking to
/// resume, metres (the largest setpoint step a resume may make).
pub const RESUME_TOLERANCE_M: f64 = 0.05;

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
    /// A hold is over (or the autopilot's heartbeat came back after a loss): waiting
    /// for a plan that starts where the vehicle holds.
    AwaitingPlanFromHold,
    /// No plan committed yet.
    NoPlan,
    /// The pilot has not handed control over (the autopilot is not armed and in
    /// OFFBOARD or GUIDED): the hold follows the vehicle wherever the pilot flies it.
    NotInControl,
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
            HoldReason::AwaitingPlanFromHold => "awaiting a plan from where it holds",
            HoldReason::NoPlan => "no plan",
            HoldReason::NotInControl => "waiting for the pilot to hand control over",
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
///   first plan, or when the plan's reference lies outside the fence;
/// - otherwise the plan's **reference** (position, velocity, acceleration, yaw;
///   [`reference_at`]).
///
/// The hold position is latched when the hold begins, so a drifting estimate does not
/// drag the vehicle along. A hold ends only on a plan whose reference is within
/// [`RESUME_TOLERANCE_M`] of it ([`HoldReason::AwaitingPlanFromHold`] until then): the
/// planner kept committing while the vehicle held, from a reference that moved on, and
/// tracking such a plan would jump to where it leads. The driver says where it holds
/// ([`SetpointGuard::hold_point`], published as `troupe_actors::msgs::VEHICLE_HOLD`),
/// and the collision actor then commits hovering there, which resumes in place. After
/// the heartbeat returns from a loss the guard holds where the vehicle is then (the
/// autopilot's failsafe may have moved it) and resumes the same way.
#[derive(Clone, Debug)]
pub struct SetpointGuard {
    config: GuardConfig,
    sensor: Watchdog,
    odometry: Watchdog,
    heartbeat: Watchdog,
    plan: Option<Arc<Plan>>,
    /// The plan committed before `plan` (its flight leads to `plan`'s primitive).
    previous: Option<Arc<Plan>>,
    position_m: Option<Point3<f64>>,
    yaw_rad: Option<f64>,
    /// Whether the pilot has handed control over ([`SetpointGuard::control`]).
    in_control: bool,
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
            previous: None,
            position_m: None,
            yaw_rad: None,
            in_control: false,
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

    /// Whether the pilot has handed control over (the autopilot armed and in
    /// OFFBOARD or GUIDED, `crate::mavlink::in_control`); until then, and whenever the
    /// pilot takes it back, the guard holds where the vehicle is.
    pub fn control(&mut self, in_control: bool) {
        self.in_control = in_control;
    }

    /// A plan was committed. It is followed as far as the fence allows; the error says
    /// where it first leaves the fence (counted).
    pub fn plan(&mut self, plan: Arc<Plan>) -> Result<(), GeofenceViolation> {
        let check = self.config.geofence.check_trajectory(&plan.trajectory);
        if check.is_err() {
            self.counters.plans_leaving_fence += 1;
        }
        self.previous = self.plan.replace(plan);
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
                    // The autopilot's failsafe flies the vehicle meanwhile: once the
                    // heartbeat is back, hold where it is then, until a plan from there.
                    self.hold = Some((HoldReason::AwaitingPlanFromHold, None, None));
                }
            }
        }
        if !self.heartbeat.ever_fed() || self.heartbeat.is_stale() {
            self.counters.silent += 1;
            return None;
        }
        let reason = if !self.in_control {
            Some(HoldReason::NotInControl)
        } else if self.sensor.is_stale() {
            Some(HoldReason::SensorTimeout)
        } else if self.odometry.is_stale() {
            Some(HoldReason::OdometryTimeout)
        } else {
            None
        };
        let reference = match (reason, &self.plan) {
            (Some(reason), _) => Err(reason),
            (None, None) => Err(HoldReason::NoPlan),
            (None, Some(plan)) => match reference_at(plan, self.previous.as_deref(), now) {
                None => Err(HoldReason::NoPlan),
                Some(r) if !self.config.geofence.contains(&r.position_m) => {
                    self.counters.fence_holds += 1;
                    Err(HoldReason::Geofence)
                }
                Some(r) if !self.resumes_on(&r) => Err(HoldReason::AwaitingPlanFromHold),
                Some(r) => Ok(r),
            },
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
                if reason == HoldReason::NotInControl {
                    // The pilot flies: hold wherever the vehicle is, so that the hand-over
                    // holds it in place.
                    self.hold = Some((reason, here, self.yaw_rad));
                }
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

    /// Whether tracking `reference` may begin: not holding, or holding where it starts.
    fn resumes_on(&self, reference: &Reference) -> bool {
        match self.hold {
            None => true,
            Some((_, at, _)) => {
                at.is_some_and(|at| (reference.position_m - at).norm() <= RESUME_TOLERANCE_M)
            }
        }
    }

    /// Where the vehicle stands instead of following the plan, and its heading, as of
    /// the last tick: where it holds (inside the fence), or, while the heartbeat is
    /// missing (nobody listens to setpoints), where it is; `None` while it tracks or
    /// no position is known.
    #[must_use]
    pub fn hold_point(&self) -> Option<(Point3<f64>, f64)> {
        if self.heartbeat_missing() {
            return self.position_m.zip(self.yaw_rad);
        }
        match self.hold {
            Some((_, Some(at), yaw)) => Some((at, yaw.unwrap_or(0.0))),
            _ => None,
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
    use nalgebra::Vector3;
    use troupe_algorithms::planner::primitives::{Action, DynamicLimits, FlatState};
    use troupe_algorithms::trajectory::{Knot, Trajectory};

    fn t(s: f64) -> Time {
        Time::from_secs_f64(s)
    }

    fn guard() -> SetpointGuard {
        fenced_guard(20.0)
    }

    /// A guard whose fence ends `max_x_m` east, the pilot having handed control over.
    fn fenced_guard(max_x_m: f64) -> SetpointGuard {
        let mut g = SetpointGuard::new(
            GuardConfig {
                sensor_timeout_s: 0.5,
                odometry_timeout_s: 0.3,
                heartbeat_timeout_s: 1.0,
                geofence: Geofence::new(
                    Point3::new(-5.0, -5.0, 0.0),
                    Point3::new(max_x_m, 5.0, 3.0),
                )
                .unwrap(),
            },
            t(0.0),
        );
        g.control(true);
        g
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

    /// Whether `sp` holds, awaiting a plan made from the hold, at `x` m.
    fn awaits_plan_at(sp: Option<Setpoint>, x: f64) -> bool {
        matches!(sp, Some(Setpoint::Hold {
            reason: HoldReason::AwaitingPlanFromHold,
            position_m: Some(p),
            ..
        }) if (p.x - x).abs() < 1e-9)
    }

    /// Hovering at `at` from `from` (one knot, held after it).
    fn hover_plan(at: Point3<f64>, from: Time) -> Arc<Plan> {
        let knot = Knot {
            time: from,
            position_m: at,
            yaw_rad: 0.0,
        };
        Arc::new(Plan::new(from, Trajectory::new(vec![knot]).unwrap()))
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
    fn tracks_a_route_plan_with_no_acceleration_to_give() {
        let mut g = guard();
        let mut changes = Vec::new();
        feed_all(&mut g, t(1.0), 1.0);
        assert!(g.plan(eastward_plan()).is_ok());
        let Some(Setpoint::Track(r)) = g.tick(t(1.0), &mut changes) else {
            panic!("expected tracking");
        };
        assert!((r.position_m.x - 1.0).abs() < 1e-9);
        assert!((r.velocity_mps.x - 1.0).abs() < 1e-9);
        assert_eq!(r.acceleration_mps2, None, "knots carry no acceleration");
        assert_eq!(g.counters().tracked, 1);
    }

    /// A planner's plan: `action` from `root` at `start` for one 1 s period, then its
    /// stopping primitive, continuing `before` (the flight that leads to it) from
    /// `decided`.
    fn primitive_plan(
        root: &FlatState,
        action: Action,
        start: Time,
        decided: Time,
        before: Option<&Plan>,
    ) -> Arc<Plan> {
        let limits = DynamicLimits::THESIS;
        let primitive = limits.shortest(root, action).expect("feasible");
        let switch_s = 1.0f64.min(primitive.duration_s());
        let stopping = limits
            .stopping(&primitive.state_at(switch_s))
            .expect("a stop");
        let committed = Committed {
            start,
            primitive,
            switch_s,
            stopping,
        };
        let planned = committed.trajectory(0.1);
        let trajectory = match before {
            Some(p) => p.trajectory.continued_by(decided, &planned),
            None => planned,
        };
        Arc::new(Plan {
            stamp: decided,
            trajectory,
            reference: Some(Box::new(committed)),
            stopping: false,
        })
    }

    /// Issue 40, item 3: the feed-forward is the primitives' own acceleration, so from
    /// one tick to the next it changes by at most the jerk limit times the period,
    /// across plan switches too (the knots' finite differences spiked to 14–23 m/s²).
    #[test]
    fn acceleration_is_the_primitives_own_and_continuous_across_plans() {
        let mut g = guard();
        let mut changes = Vec::new();
        let limits = DynamicLimits::THESIS;
        let forward = Action {
            vx_mps: 1.5,
            ..Action::STOP
        };
        let turn = Action {
            vx_mps: 1.0,
            vz_mps: 0.3,
            yaw_rate_rad_s: 0.4,
            ..Action::STOP
        };
        let rest = FlatState::at_rest(Vector3::new(0.0, 0.0, 1.0), 0.0);
        let first = primitive_plan(&rest, forward, t(0.11), t(0.0), None);
        g.plan(first.clone()).unwrap();
        let period_s = 1.0 / 30.0;
        let mut last: Option<Reference> = None;
        let mut largest_step = 0.0f64;
        let mut second_sent = false;
        for i in 0..90 {
            let now = t(0.2 + period_s * f64::from(i));
            if !second_sent && now >= t(1.0) {
                // The next round, decided at 1.0 s, takes over at 1.11 s.
                let root = first
                    .reference
                    .as_ref()
                    .expect("a primitive")
                    .state_at(t(1.11));
                g.plan(primitive_plan(&root, turn, t(1.11), t(1.0), Some(&first)))
                    .unwrap();
                second_sent = true;
            }
            let x = now.as_secs_f64();
            feed_all(&mut g, now, x);
            let Some(Setpoint::Track(r)) = g.tick(now, &mut changes) else {
                panic!("expected tracking at {now}");
            };
            let a = r
                .acceleration_mps2
                .expect("a primitive gives its acceleration");
            if let Some(before) = last {
                let step = (a - before.acceleration_mps2.expect("given")).norm();
                largest_step = largest_step.max(step);
                assert!(
                    (r.position_m - before.position_m).norm() < 0.1,
                    "position jumped at {now}"
                );
            }
            last = Some(r);
        }
        assert!(
            largest_step <= limits.max_jerk_mps3 * period_s + 1e-6,
            "acceleration stepped {largest_step:.3} m/s² in one tick"
        );
        assert!(largest_step > 0.0, "the plans accelerate");
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
        // Frames return; the plan moved on while the vehicle held (x = 2.1 by now): it
        // is not tracked, which would step the setpoint 0.55 m.
        assert_eq!(g.depth_frame(t(2.1)), Some(WatchdogChange::Restored));
        g.odometry(t(2.1), Point3::new(1.55, 0.0, 1.0), 0.0);
        assert!(matches!(
            g.tick(t(2.1), &mut changes),
            Some(Setpoint::Hold {
                reason: HoldReason::AwaitingPlanFromHold,
                ..
            })
        ));
        let (at, _) = g.hold_point().expect("holding at a known place");
        assert_eq!(at, held_at.expect("held").1);
        // A plan from where it holds (the collision actor's hover there): tracked, in
        // place.
        g.plan(hover_plan(at, t(2.1))).unwrap();
        let Some(Setpoint::Track(r)) = g.tick(t(2.15), &mut changes) else {
            panic!("expected tracking");
        };
        assert!((r.position_m - at).norm() < 1e-9);
        assert_eq!(g.hold_reason(), None);
        assert_eq!(g.hold_point(), None);
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
    fn heartbeat_loss_silences_then_holds_until_a_plan_from_where_it_is() {
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
        // The autopilot's failsafe left the vehicle at x = 1.6.
        g.odometry(t(2.2), Point3::new(1.6, 0.0, 1.0), 0.0);
        assert!(awaits_plan_at(g.tick(t(2.2), &mut changes), 1.6));
        // The plan from before the loss (at x = 2.25 now) does not resume it.
        let sp = g.tick(t(2.25), &mut changes);
        assert!(matches!(sp, Some(Setpoint::Hold { .. })), "{sp:?}");
        g.plan(hover_plan(Point3::new(1.6, 0.0, 1.0), t(2.25)))
            .unwrap();
        let sp = g.tick(t(2.3), &mut changes);
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

    /// Issue 40, item 5: until the pilot hands control over (and whenever it takes it
    /// back) the guard holds wherever the vehicle is — the pilot flies it — and says
    /// so; the hand-over holds the vehicle in place until a plan from there.
    #[test]
    fn holds_where_the_pilot_flies_until_control_is_handed_over() {
        let mut g = guard();
        g.control(false);
        let mut changes = Vec::new();
        g.plan(eastward_plan()).unwrap();
        for i in 0..10 {
            let now = t(0.1 * f64::from(i));
            feed_all(&mut g, now, 3.0 + 0.1 * f64::from(i));
            let Some(Setpoint::Hold {
                position_m, reason, ..
            }) = g.tick(now, &mut changes)
            else {
                panic!("expected a hold");
            };
            assert_eq!(reason, HoldReason::NotInControl);
            assert_eq!(position_m.map(|p| p.x), Some(3.0 + 0.1 * f64::from(i)));
            assert_eq!(g.hold_point().map(|(p, _)| p.x), position_m.map(|p| p.x));
        }
        // Handed over at x = 4: held there (the plan is at x = 1), then a plan from
        // there is tracked.
        g.control(true);
        feed_all(&mut g, t(1.0), 4.0);
        assert!(awaits_plan_at(g.tick(t(1.0), &mut changes), 3.9));
        g.plan(hover_plan(Point3::new(3.9, 0.0, 1.0), t(1.0)))
            .unwrap();
        feed_all(&mut g, t(1.05), 3.9);
        assert!(matches!(
            g.tick(t(1.05), &mut changes),
            Some(Setpoint::Track(_))
        ));
    }

    #[test]
    fn without_a_heartbeat_the_vehicle_stands_where_it_is() {
        let mut g = guard();
        let mut changes = Vec::new();
        g.odometry(t(0.1), Point3::new(2.0, 1.0, 1.5), 0.3);
        assert_eq!(g.tick(t(0.1), &mut changes), None, "nobody listens");
        assert_eq!(g.hold_point(), Some((Point3::new(2.0, 1.0, 1.5), 0.3)));
    }
}
