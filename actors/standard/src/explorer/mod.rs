//! The explorer actor: asks an [`ExplorationBehaviour`] for a plan at a fixed rate
//! and commits it on [`PLAN`].
//!
//! Behaviours live in `troupe-policies` (dependency inversion: `troupe-algorithms`
//! defines the trait, the robot assembly picks an implementation by name). The information-driven
//! planner of thesis §4 replaces this actor in a later stage; map-free behaviours
//! (scripted routes) use it meanwhile.
//!
//! With a collision actor ([`ExplorerActor::deferring_to_collision`]) the explorer
//! offers, every round, the rest of its current trajectory as a single candidate on
//! [`PLAN_CANDIDATES`] with "hold here" as the stop, and follows what is committed on
//! [`PLAN`]: while it is held (a stopping plan), its trajectory is delayed by the time
//! spent waiting, so that it resumes where it stopped (waypoint robots yield too,
//! §8.2.3).

use std::sync::Arc;
use std::time::Duration;

use crate::msgs::{ODOMETRY, PLAN, PLAN_CANDIDATES};
use troupe_algorithms::exploration::ExplorationBehaviour;
use troupe_algorithms::frame::Odometry;
use troupe_algorithms::plan::Plan;
use troupe_algorithms::planner::candidates::{CandidatePlan, PlanCandidates};
use troupe_algorithms::trajectory::{Knot, Trajectory};
use troupe_runtime::{Actor, ActorResult, Context, Event, QueuePolicy, Time, TimerId};

const REPLAN: TimerId = TimerId(0);

/// See the [module docs](self).
pub struct ExplorerActor<B> {
    behaviour: B,
    period: Duration,
    latest: Option<Arc<Odometry>>,
    deferred: Option<Deferred>,
}

/// State of an explorer that defers to a collision actor.
#[derive(Default)]
struct Deferred {
    /// The behaviour's latest trajectory.
    route: Option<Trajectory>,
    /// Time spent held since the route was given.
    delay: Duration,
    /// Since when the robot holds (the stop was committed), if it does.
    held_since: Option<Time>,
    /// What the vehicle follows now.
    committed: Option<Trajectory>,
    round: u64,
}

/// `route` delayed by `delay`, from `now` on (a knot at `now`, then the later knots).
#[must_use]
pub fn delayed_from(route: &Trajectory, delay: Duration, now: Time) -> Option<Trajectory> {
    let shifted = |k: &Knot| Knot {
        time: k.time + delay,
        ..*k
    };
    let first = route.state_at(Time::from_nanos(
        now.as_nanos()
            .saturating_sub(delay.as_nanos().min(u128::from(u64::MAX)) as u64),
    ))?;
    let mut knots = vec![Knot {
        time: now,
        position_m: first.position_m,
        yaw_rad: first.yaw_rad,
    }];
    knots.extend(route.knots().iter().map(shifted).filter(|k| k.time > now));
    Trajectory::new(knots).ok()
}

/// Holding still at `position_m` from `now` (the explorer's stopping trajectory).
fn hold(now: Time, position_m: nalgebra::Point3<f64>, yaw_rad: f64) -> Option<Trajectory> {
    Trajectory::new(vec![Knot {
        time: now,
        position_m,
        yaw_rad,
    }])
    .ok()
}

impl<B: ExplorationBehaviour> ExplorerActor<B> {
    /// Replans at `rate_hz` (> 0).
    #[must_use]
    pub fn new(behaviour: B, rate_hz: f64) -> Self {
        ExplorerActor {
            behaviour,
            period: Duration::from_secs_f64(1.0 / rate_hz.max(1e-3)),
            latest: None,
            deferred: None,
        }
    }

    /// Offers each round's trajectory to a collision actor instead of committing it
    /// (module docs).
    #[must_use]
    pub fn deferring_to_collision(mut self) -> Self {
        self.deferred = Some(Deferred::default());
        self
    }

    fn offer(&mut self, ctx: &mut Context<'_>) {
        let now = ctx.now();
        let Some(odometry) = self.latest.clone() else {
            return;
        };
        let fresh = self.behaviour.replan(now, &odometry);
        let Some(d) = self.deferred.as_mut() else {
            return;
        };
        if let Some(since) = d.held_since.take() {
            d.delay += now.saturating_since(since);
        }
        if let Some(route) = fresh {
            d.route = Some(route);
            d.delay = Duration::ZERO;
        }
        let Some(route) = &d.route else {
            return;
        };
        let Some(candidate) = delayed_from(route, d.delay, now) else {
            return;
        };
        let here = d
            .committed
            .as_ref()
            .and_then(|c| c.state_at(now))
            .map_or_else(
                || {
                    let (_, _, yaw) = odometry.pose.rotation.euler_angles();
                    (
                        nalgebra::Point3::from(odometry.pose.translation.vector),
                        yaw,
                    )
                },
                |s| (s.position_m, s.yaw_rad),
            );
        let Some(stop) = hold(now, here.0, here.1) else {
            return;
        };
        d.round += 1;
        ctx.publish(
            &PLAN_CANDIDATES,
            PlanCandidates {
                round: d.round,
                stamp: now,
                candidates: vec![CandidatePlan {
                    trajectory: candidate,
                    reference: None,
                    switch_at: now + self.period,
                    reward: 0.0,
                }],
                stop,
                stop_reference: None,
            },
        );
    }
}

impl<B: ExplorationBehaviour> Actor for ExplorerActor<B> {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&ODOMETRY, QueuePolicy::LATEST);
        if self.deferred.is_some() {
            ctx.subscribe(&PLAN, QueuePolicy::LATEST);
        }
        ctx.set_timer(REPLAN, self.period);
        Ok(())
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        match event {
            Event::Message(m) => {
                if let Some(odometry) = m.get_arc(&ODOMETRY) {
                    self.latest = Some(odometry);
                } else if let Some(plan) = m.get(&PLAN)
                    && let Some(d) = self.deferred.as_mut()
                {
                    if plan.stopping {
                        // Held since the round that offered this stop (its first knot).
                        d.held_since = plan.trajectory.knots().first().map(|k| k.time);
                    }
                    d.committed = Some(plan.trajectory.clone());
                }
                ctx.bookkeeping_only();
            }
            Event::Timer(_) if self.deferred.is_some() => self.offer(ctx),
            Event::Timer(_) => {
                if let Some(odometry) = &self.latest
                    && let Some(trajectory) = self.behaviour.replan(ctx.now(), odometry)
                {
                    ctx.publish(&PLAN, Plan::new(ctx.now(), trajectory));
                }
            }
        }
        Ok(())
    }
}
