//! The explorer actor: asks an [`ExplorationBehaviour`] for a plan at a fixed rate
//! and commits it on [`PLAN`].
//!
//! Behaviours live in `troupe-policies` (dependency inversion: this crate defines the
//! trait, the robot assembly picks an implementation by name). The information-driven
//! planner of thesis §4 replaces this actor in a later stage; map-free behaviours
//! (scripted routes) use it meanwhile.

use std::sync::Arc;
use std::time::Duration;

use crate::msgs::{ODOMETRY, Odometry, PLAN, Plan};
use crate::runtime::{Actor, ActorResult, Context, Event, QueuePolicy, Time, TimerId};
use crate::trajectory::Trajectory;

/// Decides where the robot goes next.
pub trait ExplorationBehaviour: Send + 'static {
    /// A new trajectory to commit, or `None` to keep the current one. Called at the
    /// replanning rate once odometry is known.
    fn replan(&mut self, now: Time, odometry: &Odometry) -> Option<Trajectory>;
}

impl ExplorationBehaviour for Box<dyn ExplorationBehaviour> {
    fn replan(&mut self, now: Time, odometry: &Odometry) -> Option<Trajectory> {
        (**self).replan(now, odometry)
    }
}

const REPLAN: TimerId = TimerId(0);

/// See the [module docs](self).
pub struct ExplorerActor<B> {
    behaviour: B,
    period: Duration,
    latest: Option<Arc<Odometry>>,
}

impl<B: ExplorationBehaviour> ExplorerActor<B> {
    /// Replans at `rate_hz` (> 0).
    #[must_use]
    pub fn new(behaviour: B, rate_hz: f64) -> Self {
        ExplorerActor {
            behaviour,
            period: Duration::from_secs_f64(1.0 / rate_hz.max(1e-3)),
            latest: None,
        }
    }
}

impl<B: ExplorationBehaviour> Actor for ExplorerActor<B> {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&ODOMETRY, QueuePolicy::LATEST);
        ctx.set_timer(REPLAN, self.period);
        Ok(())
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        match event {
            Event::Message(m) => {
                if let Some(odometry) = m.get_arc(&ODOMETRY) {
                    self.latest = Some(odometry);
                }
            }
            Event::Timer(_) => {
                if let Some(odometry) = &self.latest
                    && let Some(trajectory) = self.behaviour.replan(ctx.now(), odometry)
                {
                    ctx.publish(
                        &PLAN,
                        Plan {
                            stamp: ctx.now(),
                            trajectory,
                        },
                    );
                }
            }
        }
        Ok(())
    }
}
