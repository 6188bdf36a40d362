//! The simulated network of a scenario: `troupe_comms::simnet` (latency, jitter,
//! random and bursty loss, reordering, duplication, range-dependent rate and radius,
//! scheduled partitions) behind the sim-time executor's network interface. Robot
//! positions come from the ground-truth monitor.

use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use troupe_actors::runtime::{ConfigError, Destination, RobotId, SimNetwork, Time};
use troupe_comms::simnet::{NetStats, SimNet, SimNetConfig};

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
        })
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
        bytes: usize,
        team_size: usize,
        deliveries: &mut Vec<(RobotId, Time)>,
    ) {
        let positions = lock(&self.positions).clone();
        for target in to.recipients(from, team_size) {
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
                .route(now.as_nanos(), from.0, target.0, bytes, &positions);
            deliveries.extend(
                routing
                    .deliveries
                    .iter()
                    .map(|d| (RobotId(d.to), Time::from_nanos(d.arrival_ns))),
            );
        }
        *lock(&self.stats) = self.net.stats();
    }
}
