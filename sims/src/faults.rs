//! Scenario-scheduled faults: an actor panic, a robot crash and reboot, a link
//! partition, a burst of packet loss. Each is logged when it strikes and reported in
//! `summary.json` with what it did.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use troupe_core::{RobotId, Time};
use troupe_runtime::{Actor, ActorFactory, ActorResult, Context, Event};

/// Names of the standard actors a fault can target.
pub const ACTOR_NAMES: &[&str] = &[
    "vehicle",
    "sensor",
    "explorer",
    "link",
    "grid",
    "planner",
    "mapper",
    "collision",
];

/// A fault injected at a scheduled time (`[[faults]]` in a scenario).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, tag = "kind", rename_all = "snake_case")]
pub enum Fault {
    /// The named actor's handler panics once at `at_s`; its supervisor restarts it.
    ActorPanic {
        /// Robot index.
        robot: usize,
        /// Actor name (see [`ACTOR_NAMES`]).
        actor: String,
        /// Time of the panic, seconds.
        at_s: f64,
    },
    /// The robot's computer crashes at `at_s` and reboots `down_s` later: every actor
    /// but the vehicle (the flight controller keeps flying the last committed plan,
    /// which ends in its stopping trajectory) stops handling events, and is rebuilt
    /// from scratch, with no memory, at the reboot.
    RobotCrash {
        /// Robot index.
        robot: usize,
        /// Crash time, seconds.
        at_s: f64,
        /// Time until the reboot, seconds.
        down_s: f64,
    },
    /// The link between two robots is cut in both directions during `[at_s, until_s)`.
    LinkPartition {
        /// The two robots.
        robots: [u32; 2],
        /// Start, seconds.
        at_s: f64,
        /// End, seconds.
        until_s: f64,
    },
    /// During `[at_s, until_s)`, every packet from or to one of `robots` (all robots
    /// when empty) is lost with `loss_probability`, on top of the network's own loss.
    LossBurst {
        /// Affected robots (empty: all).
        #[serde(default)]
        robots: Vec<u32>,
        /// Start, seconds.
        at_s: f64,
        /// End, seconds.
        until_s: f64,
        /// Chance that a packet is lost.
        loss_probability: f64,
    },
}

impl Fault {
    /// Checks the fault against a team of `robots`; the error is `(key, reason)`.
    ///
    /// # Errors
    ///
    /// The key inside the fault's table and the rule it breaks.
    pub fn validate(&self, robots: u32) -> Result<(), (&'static str, String)> {
        let robot_ok = |r: usize| {
            if r < robots as usize {
                Ok(())
            } else {
                Err(("robot", format!("must be < robots ({robots}), got {r}")))
            }
        };
        let time_ok = |key: &'static str, t: f64| {
            if t.is_finite() && t >= 0.0 {
                Ok(())
            } else {
                Err((key, format!("must be ≥ 0 seconds, got {t}")))
            }
        };
        let window_ok = |at_s: f64, until_s: f64| {
            time_ok("at_s", at_s)?;
            if until_s.is_finite() && until_s > at_s {
                Ok(())
            } else {
                Err((
                    "until_s",
                    format!("must be after at_s ({at_s}), got {until_s}"),
                ))
            }
        };
        match self {
            Fault::ActorPanic { robot, actor, at_s } => {
                robot_ok(*robot)?;
                if !ACTOR_NAMES.contains(&actor.as_str()) {
                    return Err((
                        "actor",
                        format!("must be one of {}; got {actor:?}", ACTOR_NAMES.join(", ")),
                    ));
                }
                time_ok("at_s", *at_s)
            }
            Fault::RobotCrash {
                robot,
                at_s,
                down_s,
            } => {
                robot_ok(*robot)?;
                time_ok("at_s", *at_s)?;
                if down_s.is_finite() && *down_s > 0.0 {
                    Ok(())
                } else {
                    Err(("down_s", format!("must be > 0 seconds, got {down_s}")))
                }
            }
            Fault::LinkPartition {
                robots: pair,
                at_s,
                until_s,
            } => {
                if pair[0] == pair[1] || pair.iter().any(|r| *r >= robots) {
                    return Err((
                        "robots",
                        format!("must be two different robots < {robots}, got {pair:?}"),
                    ));
                }
                window_ok(*at_s, *until_s)
            }
            Fault::LossBurst {
                robots: affected,
                at_s,
                until_s,
                loss_probability,
            } => {
                if let Some(r) = affected.iter().find(|r| **r >= robots) {
                    return Err(("robots", format!("must be < {robots}, got {r}")));
                }
                if !(0.0..=1.0).contains(loss_probability) {
                    return Err((
                        "loss_probability",
                        format!("must be in [0, 1], got {loss_probability}"),
                    ));
                }
                window_ok(*at_s, *until_s)
            }
        }
    }
}

/// What a fault did, for `summary.json`.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct FaultEffect {
    /// Whether it struck (its time came within the run).
    pub struck: bool,
    /// Events not handled while an actor was down (robot crash).
    pub dropped_events: u64,
    /// Packets lost to it (loss burst; a partition's losses are in
    /// `network.partitioned`).
    pub dropped_packets: u64,
}

/// Counters a fault fills in while the run goes on.
#[derive(Debug, Default)]
pub struct FaultCounters {
    struck: AtomicBool,
    dropped_events: AtomicU64,
    dropped_packets: AtomicU64,
}

impl FaultCounters {
    /// The counters as reported.
    #[must_use]
    pub fn effect(&self) -> FaultEffect {
        FaultEffect {
            struck: self.struck.load(Ordering::Relaxed),
            dropped_events: self.dropped_events.load(Ordering::Relaxed),
            dropped_packets: self.dropped_packets.load(Ordering::Relaxed),
        }
    }

    /// Marks the fault as having struck.
    pub fn strike(&self) {
        self.struck.store(true, Ordering::Relaxed);
    }
}

/// Wraps an actor so that its handler panics once, at the first event at or after
/// `at` (the flag is shared across restarts, so the rebuilt actor runs normally).
pub struct PanicOnce {
    inner: Box<dyn Actor>,
    at: Time,
    fired: Arc<FaultCounters>,
}

impl PanicOnce {
    /// Wraps `inner`.
    #[must_use]
    pub fn new(inner: Box<dyn Actor>, at: Time, fired: Arc<FaultCounters>) -> Self {
        PanicOnce { inner, at, fired }
    }
}

impl Actor for PanicOnce {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        self.inner.start(ctx)
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        if ctx.now() >= self.at && !self.fired.struck.swap(true, Ordering::SeqCst) {
            panic!(
                "injected fault: {} panics at {}",
                ctx.actor_name(),
                ctx.now()
            );
        }
        self.inner.handle(event, ctx)
    }

    fn stop(&mut self, ctx: &mut Context<'_>) {
        self.inner.stop(ctx);
    }
}

/// Makes the factory's actors crash at `at` and reboot (a fresh instance from the
/// factory, started anew) at the first event at or after `reboot`; events in between
/// are dropped and counted.
#[must_use]
pub fn crashing_factory(
    factory: ActorFactory,
    at: Time,
    reboot: Time,
    counters: Arc<FaultCounters>,
) -> ActorFactory {
    let factory = Arc::new(Mutex::new(factory));
    Box::new(move || {
        let inner = (factory.lock().unwrap_or_else(PoisonError::into_inner))();
        Box::new(Crashing {
            inner: Some(inner),
            factory: factory.clone(),
            at,
            reboot,
            counters: counters.clone(),
        })
    })
}

struct Crashing {
    inner: Option<Box<dyn Actor>>,
    factory: Arc<Mutex<ActorFactory>>,
    at: Time,
    reboot: Time,
    counters: Arc<FaultCounters>,
}

impl Actor for Crashing {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        match &mut self.inner {
            Some(inner) => inner.start(ctx),
            None => Ok(()),
        }
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        let now = ctx.now();
        if now >= self.at && now < self.reboot {
            if self.inner.take().is_some() {
                self.counters.strike();
                tracing::warn!(robot = ctx.robot_name(), actor = ctx.actor_name(), time = %now, "injected fault: crash");
            }
            self.counters.dropped_events.fetch_add(1, Ordering::Relaxed);
            return Ok(());
        }
        if self.inner.is_none() {
            let mut fresh = (self.factory.lock().unwrap_or_else(PoisonError::into_inner))();
            tracing::warn!(robot = ctx.robot_name(), actor = ctx.actor_name(), time = %now, "injected fault: reboot");
            fresh.start(ctx)?;
            self.inner = Some(fresh);
        }
        match &mut self.inner {
            Some(inner) => inner.handle(event, ctx),
            None => Ok(()),
        }
    }

    fn stop(&mut self, ctx: &mut Context<'_>) {
        if let Some(inner) = &mut self.inner {
            inner.stop(ctx);
        }
    }
}

/// A scheduled loss burst as the network applies it.
pub struct LossBurst {
    robots: Vec<u32>,
    from: Time,
    until: Time,
    loss_probability: f64,
    rng: ChaCha8Rng,
    counters: Arc<FaultCounters>,
}

impl LossBurst {
    /// A burst; `seed` makes the losses reproducible.
    #[must_use]
    pub fn new(
        robots: Vec<u32>,
        window_s: [f64; 2],
        loss_probability: f64,
        seed: u64,
        counters: Arc<FaultCounters>,
    ) -> Self {
        LossBurst {
            robots,
            from: Time::from_secs_f64(window_s[0]),
            until: Time::from_secs_f64(window_s[1]),
            loss_probability,
            rng: ChaCha8Rng::seed_from_u64(seed),
            counters,
        }
    }

    /// Whether the packet from `from` to `to` at `now` is lost to this burst.
    pub fn drops(&mut self, now: Time, from: RobotId, to: RobotId) -> bool {
        if now < self.from || now >= self.until {
            return false;
        }
        if !(self.robots.is_empty() || self.robots.contains(&from.0) || self.robots.contains(&to.0))
        {
            return false;
        }
        if !self.counters.struck.swap(true, Ordering::Relaxed) {
            tracing::warn!(time = %now, robots = ?self.robots, p = self.loss_probability, "injected fault: loss burst begins");
        }
        let lost = self.rng.random::<f64>() < self.loss_probability;
        if lost {
            self.counters
                .dropped_packets
                .fetch_add(1, Ordering::Relaxed);
        }
        lost
    }
}
