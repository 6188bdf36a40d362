//! The simulated network of a scenario: `troupe_comms::simnet` (latency, jitter,
//! random and bursty loss, reordering, duplication, range-dependent rate and radius,
//! scheduled partitions) behind the sim-time executor's network interface. Robot
//! positions come from the ground-truth monitor.
//!
//! The robots' subscription scope (`[robot.link.subscribe]`, issue 22,
//! [`troupe_comms::scope`]) is applied before anything else, as zenoh's routing
//! does: a broadcast odometry, plan or keyframe goes only to the robots whose subscribed
//! cells hold the sender's cell, judged from the ground-truth positions when it is
//! sent; the others never see it, on the channel or in their counters.

use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use troupe_comms::scope::SubscriptionConfig;
use troupe_comms::shaping::frame;
use troupe_comms::simnet::{NetStats, SimNet, SimNetConfig};
use troupe_core::{ConfigError, RobotId, Time};
use troupe_runtime::{Destination, SimNetwork};

use crate::faults::LossBurst;

/// Positions of the robots (index = robot), metres, shared with the monitor.
pub type Positions = Arc<Mutex<Vec<[f64; 3]>>>;

/// Locks shared state; a poisoned lock still holds usable numbers.
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// See the [module docs](self).
pub struct ScenarioNetwork {
    net: SimNet,
    positions: Positions,
    stats: Arc<Mutex<NetStats>>,
    bursts: Vec<LossBurst>,
    subscription: SubscriptionConfig,
}

impl ScenarioNetwork {
    /// A network from its configuration; `seed` drives every random effect.
    pub fn new(config: SimNetConfig, seed: u64, positions: Positions) -> Result<Self, ConfigError> {
        let net = SimNet::new(config, seed)?;
        Ok(ScenarioNetwork {
            net,
            positions,
            stats: Arc::default(),
            bursts: Vec::new(),
            subscription: SubscriptionConfig::default(),
        })
    }

    /// Applies the team's subscription scope (default: every robot gets every
    /// frame).
    #[must_use]
    pub fn with_subscription(mut self, subscription: SubscriptionConfig) -> Self {
        self.subscription = subscription;
        self
    }

    /// Adds scheduled loss bursts (applied before the network's own model).
    #[must_use]
    pub fn with_loss_bursts(mut self, bursts: Vec<LossBurst>) -> Self {
        self.bursts = bursts;
        self
    }

    /// Shared handle on the network's counters (all pairs together).
    #[must_use]
    pub fn stats(&self) -> Arc<Mutex<NetStats>> {
        self.stats.clone()
    }
}

impl SimNetwork for ScenarioNetwork {
    fn route(
        &mut self,
        now: Time,
        from: RobotId,
        to: Destination,
        bytes: &[u8],
        team_size: usize,
        deliveries: &mut Vec<(RobotId, Time)>,
    ) {
        let positions = lock(&self.positions).clone();
        let position = |r: RobotId| positions.get(r.0 as usize).copied();
        // A frame that does not parse has no class: every subscriber gets it (and
        // the link rejects it).
        let class = frame::class_of(bytes).ok();
        let addressed = matches!(to, Destination::Robot(_));
        for target in to.recipients(from, team_size) {
            if let Some(class) = class
                && !self
                    .subscription
                    .receives(class, addressed, position(from), position(target))
            {
                continue;
            }
            // Every burst draws for every packet it covers, so one burst's losses do
            // not depend on another's.
            let mut lost = false;
            for burst in &mut self.bursts {
                lost |= burst.drops(now, from, target);
            }
            if lost {
                continue;
            }
            let routing = self
                .net
                .route(now.as_nanos(), from.0, target.0, bytes.len(), &positions);
            deliveries.extend(
                routing
                    .deliveries
                    .iter()
                    .map(|d| (RobotId(d.to), Time::from_nanos(d.arrival_ns))),
            );
        }
        *lock(&self.stats) = self.net.stats();
    }

    fn min_delay(&self) -> std::time::Duration {
        std::time::Duration::from_nanos(self.net.min_latency_ns())
    }
}
