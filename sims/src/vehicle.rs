//! The simulated vehicle: follows the committed plan, optionally with a tracking
//! error, and reports odometry.
//!
//! By default it is wherever the plan says (plus the tracking error). With
//! `lag_s > 0` it is instead a point mass flown like a multirotor's position
//! controller flies a setpoint stream, the model of
//! `scripts/mavlink/px4_like_autopilot.py --lag-s`: the commanded acceleration is
//! the reference's acceleration plus a critically damped PD loop on position and
//! velocity ([`LAG_KP`], [`LAG_KD`], clamped to [`LAG_MAX_ACCEL_MPS2`] per axis), and
//! the achieved acceleration follows it with a first-order lag of time constant
//! `lag_s`, integrated in [`LAG_STEP_S`] steps; the heading follows the reference's.
//!
//! The body's state lives outside the actor (in a [`SimBody`] shared with the
//! factory), so that a restarted vehicle actor continues from where the physical
//! robot is — a crash of the control software does not teleport the robot. After a
//! restart it keeps following the last plan it had.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use nalgebra::{Isometry3, Translation3, Vector3};
use rand::Rng;
use serde::{Deserialize, Serialize};
use troupe_actors::vehicle::Vehicle;
use troupe_algorithms::frame::Odometry;
use troupe_algorithms::plan::Plan;
use troupe_core::ConfigError;
use troupe_core::Time;
use troupe_runtime::{ActorError, ActorResult, Context};

/// Settings of the simulated vehicle (the `[vehicle]` table of a scenario).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VehicleConfig {
    /// Odometry rate, Hz.
    pub odometry_rate_hz: f64,
    /// Standard deviation of the tracking error per axis, metres (0: perfect tracking).
    /// The error is a first-order Gauss–Markov process, so it drifts smoothly.
    pub tracking_error_std_m: f64,
    /// Correlation time of the tracking error, seconds.
    pub tracking_error_tau_s: f64,
    /// Time constant of the first-order lag between commanded and achieved
    /// acceleration, seconds (see the [module docs](self)); 0, the default, puts the
    /// vehicle on its reference. Not written when 0, so that records of earlier runs
    /// still compare equal.
    #[serde(skip_serializing_if = "is_zero")]
    pub lag_s: f64,
}

// serde's skip_serializing_if passes a reference.
#[allow(clippy::trivially_copy_pass_by_ref)]
fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

/// Position gain of the lagging vehicle's controller, 1/s² (as the autopilot stand-in's).
pub const LAG_KP: f64 = 4.0;
/// Velocity gain of the lagging vehicle's controller, 1/s.
pub const LAG_KD: f64 = 4.0;
/// Largest commanded acceleration per axis of the lagging vehicle, m/s².
pub const LAG_MAX_ACCEL_MPS2: f64 = 15.0;
/// Integration step of the lagging vehicle, seconds.
pub const LAG_STEP_S: f64 = 0.005;
/// Half-width of the central difference that gives the reference's acceleration, s.
const LAG_ACCEL_HALF_S: f64 = 0.05;

impl Default for VehicleConfig {
    fn default() -> Self {
        VehicleConfig {
            odometry_rate_hz: 10.0,
            tracking_error_std_m: 0.05,
            tracking_error_tau_s: 2.0,
            lag_s: 0.0,
        }
    }
}

impl VehicleConfig {
    /// Checks the numbers; the error names the field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        ConfigError::positive("odometry_rate_hz", self.odometry_rate_hz)?;
        if !(self.tracking_error_std_m.is_finite()
            && (0.0..=0.5).contains(&self.tracking_error_std_m))
        {
            return Err(ConfigError::new(
                "tracking_error_std_m",
                "must be in [0, 0.5] m",
                self.tracking_error_std_m,
            ));
        }
        ConfigError::positive("tracking_error_tau_s", self.tracking_error_tau_s)?;
        if !(self.lag_s.is_finite() && (0.0..=2.0).contains(&self.lag_s)) {
            return Err(ConfigError::new("lag_s", "must be in [0, 2] s", self.lag_s));
        }
        Ok(())
    }
}

/// The physical state of one simulated robot.
#[derive(Debug)]
pub struct BodyState {
    /// Current pose.
    pub pose: Isometry3<f64>,
    /// Current velocity, m/s.
    pub velocity_mps: Vector3<f64>,
    /// The plan being followed.
    pub plan: Option<Arc<Plan>>,
    /// Current tracking error (added to the planned position), metres.
    pub tracking_error_m: Vector3<f64>,
    /// When the tracking error was last advanced.
    pub error_time: Time,
    /// Achieved acceleration of a lagging vehicle (`lag_s > 0`), m/s².
    pub acceleration_mps2: Vector3<f64>,
    /// Up to when a lagging vehicle's motion has been integrated (`None`: not yet).
    pub dynamics_time: Option<Time>,
}

/// Shared handle on a body.
pub type SimBody = Arc<Mutex<BodyState>>;

/// A new body at rest.
#[must_use]
pub fn new_body(pose: Isometry3<f64>) -> SimBody {
    Arc::new(Mutex::new(BodyState {
        pose,
        velocity_mps: Vector3::zeros(),
        plan: None,
        tracking_error_m: Vector3::zeros(),
        error_time: Time::ZERO,
        acceleration_mps2: Vector3::zeros(),
        dynamics_time: None,
    }))
}

/// The simulated vehicle driver (a [`Vehicle`], in the robot's `vehicle` actor); see
/// the [module docs](self).
pub struct SimVehicle {
    body: SimBody,
    config: VehicleConfig,
}

/// A standard normal sample (Box–Muller).
fn standard_normal(rng: &mut impl Rng) -> f64 {
    let u1: f64 = rng.random_range(f64::MIN_POSITIVE..1.0);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

impl SimVehicle {
    /// A vehicle moving `body`.
    #[must_use]
    pub fn new(body: SimBody, config: VehicleConfig) -> Self {
        SimVehicle { body, config }
    }

    fn body(&self) -> Result<std::sync::MutexGuard<'_, BodyState>, ActorError> {
        self.body
            .lock()
            .map_err(|_| ActorError::msg("vehicle body lock poisoned"))
    }

    /// Moves the body to now and says where it is.
    fn advance(&self, ctx: &mut Context<'_>) -> Result<Odometry, ActorError> {
        let now = ctx.now();
        let mut body = self.body()?;
        if self.config.tracking_error_std_m > 0.0 && now > body.error_time {
            let dt = (now - body.error_time).as_secs_f64();
            let decay = (-dt / self.config.tracking_error_tau_s).exp();
            let spread = self.config.tracking_error_std_m * (1.0 - decay * decay).sqrt();
            let rng = ctx.rng();
            let kick = Vector3::new(
                standard_normal(rng),
                standard_normal(rng),
                standard_normal(rng),
            );
            body.tracking_error_m = body.tracking_error_m * decay + kick * spread;
            body.error_time = now;
        }
        if self.config.lag_s > 0.0 {
            fly_lagging(&mut body, now, self.config.lag_s);
        } else if let Some(state) = body.plan.as_ref().and_then(|p| p.trajectory.state_at(now)) {
            let mut pose = state.pose();
            pose.translation = Translation3::from(pose.translation.vector + body.tracking_error_m);
            body.pose = pose;
            body.velocity_mps = state.velocity_mps;
        }
        Ok(Odometry {
            stamp: now,
            pose: body.pose,
            velocity_mps: body.velocity_mps,
        })
    }
}

/// Advances a lagging vehicle (see the [module docs](self)) to `now`.
fn fly_lagging(body: &mut BodyState, now: Time, lag_s: f64) {
    let (Some(plan), Some(mut t)) = (body.plan.clone(), body.dynamics_time) else {
        // Nothing to fly yet: the body rests where it is.
        body.dynamics_time = Some(now);
        return;
    };
    let trajectory = &plan.trajectory;
    let velocity_at = |s: f64| {
        trajectory
            .state_at(Time::from_secs_f64(s.max(0.0)))
            .map_or_else(Vector3::zeros, |r| r.velocity_mps)
    };
    let end = now.as_secs_f64();
    let mut s = t.as_secs_f64();
    let mut position = body.pose.translation.vector;
    while s < end {
        let dt = LAG_STEP_S.min(end - s);
        let Some(reference) = trajectory.state_at(t) else {
            break;
        };
        let feed_forward = (velocity_at(s + LAG_ACCEL_HALF_S) - velocity_at(s - LAG_ACCEL_HALF_S))
            / (2.0 * LAG_ACCEL_HALF_S);
        let target = reference.position_m.coords + body.tracking_error_m;
        let command = (feed_forward
            + (target - position) * LAG_KP
            + (reference.velocity_mps - body.velocity_mps) * LAG_KD)
            .map(|a| a.clamp(-LAG_MAX_ACCEL_MPS2, LAG_MAX_ACCEL_MPS2));
        body.acceleration_mps2 += (command - body.acceleration_mps2) * (1.0 - (-dt / lag_s).exp());
        let a = body.acceleration_mps2;
        position += body.velocity_mps * dt + a * (0.5 * dt * dt);
        body.velocity_mps += a * dt;
        s += dt;
        t = Time::from_secs_f64(s);
    }
    let yaw = trajectory
        .state_at(now)
        .map_or_else(|| body.pose.rotation.euler_angles().2, |r| r.yaw_rad);
    body.pose = Isometry3::from_parts(
        Translation3::from(position),
        nalgebra::UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw),
    );
    body.dynamics_time = Some(now);
}

impl Vehicle for SimVehicle {
    fn period(&self) -> Duration {
        Duration::from_secs_f64(1.0 / self.config.odometry_rate_hz.max(1e-3))
    }

    fn start(&mut self, ctx: &mut Context<'_>) -> Result<Option<Odometry>, ActorError> {
        self.advance(ctx).map(Some)
    }

    fn follow(&mut self, plan: Arc<Plan>, _ctx: &mut Context<'_>) -> ActorResult {
        self.body()?.plan = Some(plan);
        Ok(())
    }

    fn step(&mut self, ctx: &mut Context<'_>) -> Result<Option<Odometry>, ActorError> {
        self.advance(ctx).map(Some)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use nalgebra::Point3;
    use troupe_algorithms::trajectory::{Knot, Trajectory};

    /// A body at rest at the origin (1 m up) given a plan at 1 m/s along +x for
    /// 10 s, flown with `lag_s` to each of `times`: the position error then.
    fn lagging_errors(lag_s: f64, times: &[f64]) -> Vec<f64> {
        let body = new_body(Isometry3::translation(0.0, 0.0, 1.0));
        let mut body = body.lock().unwrap();
        let knot = |t: f64| Knot {
            time: Time::from_secs_f64(t),
            position_m: Point3::new(t.min(10.0), 0.0, 1.0),
            yaw_rad: 0.0,
        };
        let trajectory =
            Trajectory::new((0..=100).map(|i| knot(f64::from(i) * 0.1)).collect()).unwrap();
        fly_lagging(&mut body, Time::ZERO, lag_s);
        body.plan = Some(Arc::new(Plan {
            stamp: Time::ZERO,
            trajectory,
            reference: None,
            stopping: false,
        }));
        times
            .iter()
            .map(|&t| {
                fly_lagging(&mut body, Time::from_secs_f64(t), lag_s);
                let expected = Vector3::new(t.min(10.0), 0.0, 1.0);
                (body.pose.translation.vector - expected).norm()
            })
            .collect()
    }

    #[test]
    fn a_lagging_vehicle_falls_behind_its_reference_then_settles() {
        let quick = lagging_errors(0.01, &[0.5, 15.0]);
        let slow = lagging_errors(0.3, &[0.5, 15.0]);
        assert!(slow[0] > 0.05, "lag 0.3 s: {} m behind at 0.5 s", slow[0]);
        assert!(slow[0] > 2.0 * quick[0], "{slow:?} vs {quick:?}");
        assert!(slow[1] < 0.01 && quick[1] < 0.01, "{slow:?} {quick:?}");
    }

    #[test]
    fn lag_is_validated_and_zero_by_default() {
        assert_eq!(VehicleConfig::default().lag_s, 0.0);
        let config = VehicleConfig {
            lag_s: -0.1,
            ..VehicleConfig::default()
        };
        assert_eq!(config.validate().unwrap_err().key, "lag_s");
    }
}
