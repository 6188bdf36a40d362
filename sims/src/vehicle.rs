//! The simulated vehicle: follows the committed plan exactly and reports odometry.
//!
//! The body's state lives outside the actor (in a [`SimBody`] shared with the
//! factory), so that a restarted vehicle actor continues from where the physical
//! robot is — a crash of the control software does not teleport the robot. After a
//! restart it keeps following the last plan it had.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use nalgebra::{Isometry3, Vector3};
use troupe_actors::msgs::{ODOMETRY, Odometry, PLAN, Plan};
use troupe_actors::runtime::{
    Actor, ActorError, ActorResult, Context, Event, QueuePolicy, TimerId,
};

/// The physical state of one simulated robot.
#[derive(Debug)]
pub struct BodyState {
    /// Current pose.
    pub pose: Isometry3<f64>,
    /// Current velocity, m/s.
    pub velocity_mps: Vector3<f64>,
    /// The plan being followed.
    pub plan: Option<Arc<Plan>>,
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
    }))
}

const ODOMETRY_TICK: TimerId = TimerId(0);

/// See the [module docs](self).
pub struct SimVehicle {
    body: SimBody,
    period: Duration,
}

impl SimVehicle {
    /// A vehicle publishing odometry at `rate_hz`.
    #[must_use]
    pub fn new(body: SimBody, rate_hz: f64) -> Self {
        SimVehicle {
            body,
            period: Duration::from_secs_f64(1.0 / rate_hz.max(1e-3)),
        }
    }

    fn body(&self) -> Result<std::sync::MutexGuard<'_, BodyState>, ActorError> {
        self.body
            .lock()
            .map_err(|_| ActorError::msg("vehicle body lock poisoned"))
    }

    fn publish(&self, ctx: &mut Context<'_>) -> ActorResult {
        let mut body = self.body()?;
        if let Some(state) = body
            .plan
            .as_ref()
            .and_then(|p| p.trajectory.state_at(ctx.now()))
        {
            body.pose = state.pose();
            body.velocity_mps = state.velocity_mps;
        }
        let odometry = Odometry {
            stamp: ctx.now(),
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
        ctx.set_timer(ODOMETRY_TICK, self.period);
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
