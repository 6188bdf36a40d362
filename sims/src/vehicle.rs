//! The simulated vehicle: follows the committed plan, optionally with a tracking
//! error, and reports odometry.
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
use troupe_actors::msgs::{ODOMETRY, Odometry, PLAN, Plan};
use troupe_actors::runtime::ConfigError;
use troupe_actors::runtime::{
    Actor, ActorError, ActorResult, Context, Event, QueuePolicy, Time, TimerId,
};

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
}

impl Default for VehicleConfig {
    fn default() -> Self {
        VehicleConfig {
            odometry_rate_hz: 10.0,
            tracking_error_std_m: 0.05,
            tracking_error_tau_s: 2.0,
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
    }))
}

const ODOMETRY_TICK: TimerId = TimerId(0);

/// See the [module docs](self).
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

    fn publish(&self, ctx: &mut Context<'_>) -> ActorResult {
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
        if let Some(state) = body.plan.as_ref().and_then(|p| p.trajectory.state_at(now)) {
            let mut pose = state.pose();
            pose.translation = Translation3::from(pose.translation.vector + body.tracking_error_m);
            body.pose = pose;
            body.velocity_mps = state.velocity_mps;
        }
        let odometry = Odometry {
            stamp: now,
            pose: body.pose,
            velocity_mps: body.velocity_mps,
        };
        drop(body);
        ctx.publish(&ODOMETRY, odometry);
        Ok(())
    }
}

impl Actor for SimVehicle {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&PLAN, QueuePolicy::LATEST);
        ctx.set_timer(
            ODOMETRY_TICK,
            Duration::from_secs_f64(1.0 / self.config.odometry_rate_hz.max(1e-3)),
        );
        self.publish(ctx)
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        match event {
            Event::Message(m) => {
                if let Some(plan) = m.get_arc(&PLAN) {
                    self.body()?.plan = Some(plan);
                }
                Ok(())
            }
            Event::Timer(_) => self.publish(ctx),
        }
    }
}
