//! A deterministic simulated network for in-process teams (sim time).
//!
//! [`SimNet::route`] decides, for one frame sent at `now_ns` from one robot to
//! another, whether and when it arrives — it carries no bytes and keeps no
//! queue of its own: the caller schedules the deliveries. Effects, in the order
//! they apply:
//!
//! 1. **Scheduled partitions** ([`Partition`]): time windows cutting pairs or
//!    separating groups.
//! 2. **Communication radius** (`radius_m`, from positions the caller passes).
//! 3. **Serialisation** at a rate that falls with distance: full `rate_bps` up
//!    to `full_rate_radius_m`, then linearly down to `edge_rate_fraction ·
//!    rate_bps` at `radius_m`. Frames queue behind each other per directed
//!    pair, and a frame lost later still occupied the channel.
//! 4. **Loss**: bursty (two-state Gilbert–Elliott), then independent.
//! 5. **Latency + jitter** (uniform in `[0, jitter_s]`; jitter alone keeps a
//!    link's order), **reordering** (a held-back packet overtaken by later
//!    ones), **duplication** (a second copy, with its own jitter).
//!
//! Randomness comes from one ChaCha8 stream per directed pair, derived from the
//! seed and the pair, so a pair's fate does not depend on traffic elsewhere: the
//! same seed and the same calls give the same deliveries, bit for bit.

mod config;

use std::collections::BTreeMap;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

pub use config::{GilbertElliott, LinkModel, PairModel, Partition, SimNetConfig};

use crate::shaping::ConfigError;

/// One arrival of a routed frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Delivery {
    /// Receiving robot.
    pub to: u32,
    /// When it arrives, ns.
    pub arrival_ns: u64,
    /// True for the extra copy of a duplicated frame.
    pub duplicate: bool,
}

/// Why a frame did not arrive.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum NetDrop {
    /// A scheduled partition separated the pair.
    Partitioned,
    /// Beyond the communication radius.
    OutOfRange,
    /// Lost by the Gilbert–Elliott channel.
    BurstLoss,
    /// Lost independently.
    RandomLoss,
}

/// The fate of one routed frame.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Routing {
    /// Arrivals (none if dropped; two if duplicated).
    pub deliveries: Vec<Delivery>,
    /// Why it was dropped, if it was.
    pub dropped: Option<NetDrop>,
}

/// Counters of one directed pair (or of all).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct NetStats {
    /// Frames routed.
    pub frames: u64,
    /// Bytes routed.
    pub bytes: u64,
    /// Arrivals (duplicates included).
    pub delivered: u64,
    /// Bytes of arrivals.
    pub delivered_bytes: u64,
    /// Extra copies.
    pub duplicated: u64,
    /// Frames held back for reordering.
    pub reordered: u64,
    /// Dropped by a partition.
    pub partitioned: u64,
    /// Dropped beyond the radius.
    pub out_of_range: u64,
    /// Dropped by bursty loss.
    pub burst_loss: u64,
    /// Dropped by independent loss.
    pub random_loss: u64,
}

impl NetStats {
    fn add(&mut self, other: &NetStats) {
        self.frames += other.frames;
        self.bytes += other.bytes;
        self.delivered += other.delivered;
        self.delivered_bytes += other.delivered_bytes;
        self.duplicated += other.duplicated;
        self.reordered += other.reordered;
        self.partitioned += other.partitioned;
        self.out_of_range += other.out_of_range;
        self.burst_loss += other.burst_loss;
        self.random_loss += other.random_loss;
    }
}

#[derive(Clone, Debug)]
struct PairState {
    rng: ChaCha8Rng,
    bad: bool,
    busy_until_ns: u64,
    last_arrival_ns: u64,
    stats: NetStats,
}

/// The simulated network. See the [module docs](self).
#[derive(Clone, Debug)]
pub struct SimNet {
    config: SimNetConfig,
    seed: u64,
    overrides: BTreeMap<(u32, u32), LinkModel>,
    pairs: BTreeMap<(u32, u32), PairState>,
}

fn s_to_ns(s: f64) -> u64 {
    (s * 1e9).round().clamp(0.0, u64::MAX as f64) as u64
}

impl SimNet {
    /// A network with validated settings; `seed` fixes every random draw.
    pub fn new(config: SimNetConfig, seed: u64) -> Result<Self, ConfigError> {
        config.validate()?;
        let overrides = config
            .pairs
            .iter()
            .map(|p| ((p.from, p.to), p.link))
            .collect();
        Ok(SimNet {
            config,
            seed,
            overrides,
            pairs: BTreeMap::new(),
        })
    }

    /// The least one-way delay of any frame on any pair, nanoseconds: every
    /// [`SimNet::route`] delivery arrives at least this long after it was sent
    /// (serialisation, jitter and reordering only add to it).
    #[must_use]
    pub fn min_latency_ns(&self) -> u64 {
        self.overrides
            .values()
            .chain(std::iter::once(&self.config.default))
            .map(|m| s_to_ns(m.latency_s))
            .min()
            .unwrap_or(0)
    }

    /// The link model of a directed pair.
    #[must_use]
    pub fn model(&self, from: u32, to: u32) -> &LinkModel {
        self.overrides
            .get(&(from, to))
            .unwrap_or(&self.config.default)
    }

    /// Counters of one directed pair.
    #[must_use]
    pub fn pair_stats(&self, from: u32, to: u32) -> NetStats {
        self.pairs
            .get(&(from, to))
            .map(|p| p.stats)
            .unwrap_or_default()
    }

    /// Counters over all pairs.
    #[must_use]
    pub fn stats(&self) -> NetStats {
        let mut total = NetStats::default();
        for p in self.pairs.values() {
            total.add(&p.stats);
        }
        total
    }

    /// True if a scheduled partition separates `a` and `b` at `now_ns`.
    #[must_use]
    pub fn partitioned(&self, now_ns: u64, a: u32, b: u32) -> bool {
        let t = now_ns as f64 * 1e-9;
        self.config.partitions.iter().any(|p| p.separates(t, a, b))
    }

    /// Serialisation rate at `distance_m` (`None`: no serialisation delay;
    /// `Some(0.0)`: out of range).
    #[must_use]
    pub fn rate_at(model: &LinkModel, distance_m: f64) -> Option<f64> {
        if model.radius_m.is_some_and(|r| distance_m > r) {
            return Some(0.0);
        }
        let rate = model.rate_bps? as f64;
        let Some(radius) = model.radius_m else {
            return Some(rate);
        };
        if distance_m <= model.full_rate_radius_m || radius <= model.full_rate_radius_m {
            return Some(rate);
        }
        let x = (distance_m - model.full_rate_radius_m) / (radius - model.full_rate_radius_m);
        Some(rate * (1.0 - x * (1.0 - model.edge_rate_fraction)))
    }

    /// Routes one frame of `bytes` bytes sent at `now_ns` from `from` to `to`.
    /// `positions[i]` is robot `i`'s position in a common frame, metres; a robot
    /// without an entry counts as being at the sender's position.
    pub fn route(
        &mut self,
        now_ns: u64,
        from: u32,
        to: u32,
        bytes: usize,
        positions: &[[f64; 3]],
    ) -> Routing {
        let model = *self.model(from, to);
        let partitioned = self.partitioned(now_ns, from, to);
        let seed = self.seed;
        let state = self.pairs.entry((from, to)).or_insert_with(|| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            rng.set_stream((u64::from(from) << 32) | u64::from(to));
            PairState {
                rng,
                bad: false,
                busy_until_ns: 0,
                last_arrival_ns: 0,
                stats: NetStats::default(),
            }
        });
        state.stats.frames += 1;
        state.stats.bytes += bytes as u64;
        let dropped = |state: &mut PairState, why: NetDrop| {
            match why {
                NetDrop::Partitioned => state.stats.partitioned += 1,
                NetDrop::OutOfRange => state.stats.out_of_range += 1,
                NetDrop::BurstLoss => state.stats.burst_loss += 1,
                NetDrop::RandomLoss => state.stats.random_loss += 1,
            }
            Routing {
                deliveries: Vec::new(),
                dropped: Some(why),
            }
        };
        if partitioned {
            return dropped(state, NetDrop::Partitioned);
        }
        let position = |i: u32| positions.get(i as usize).copied();
        let distance = match (position(from), position(to)) {
            (Some(a), Some(b)) => {
                ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
            }
            _ => 0.0,
        };
        let rate = Self::rate_at(&model, distance);
        if rate == Some(0.0) {
            return dropped(state, NetDrop::OutOfRange);
        }
        // Serialisation: the channel is busy even for frames lost afterwards.
        let sent_ns = match rate {
            Some(r) => {
                let start = now_ns.max(state.busy_until_ns);
                let done = start + s_to_ns(bytes as f64 * 8.0 / r);
                state.busy_until_ns = done;
                done
            }
            None => now_ns,
        };
        if let Some(ge) = &model.bursty_loss {
            let flip = if state.bad {
                ge.p_bad_to_good
            } else {
                ge.p_good_to_bad
            };
            if state.rng.random_bool(flip) {
                state.bad = !state.bad;
            }
            let loss = if state.bad { ge.loss_bad } else { ge.loss_good };
            if state.rng.random_bool(loss) {
                return dropped(state, NetDrop::BurstLoss);
            }
        }
        if state.rng.random_bool(model.loss_probability) {
            return dropped(state, NetDrop::RandomLoss);
        }
        let jitter = |rng: &mut ChaCha8Rng| s_to_ns(model.jitter_s * rng.random::<f64>());
        let mut arrival = sent_ns + s_to_ns(model.latency_s) + jitter(&mut state.rng);
        if state.rng.random_bool(model.reorder_probability) {
            // Held back and not part of the link's order: later frames overtake it.
            arrival += s_to_ns(model.reorder_delay_s);
            state.stats.reordered += 1;
        } else {
            arrival = arrival.max(state.last_arrival_ns);
            state.last_arrival_ns = arrival;
        }
        let mut deliveries = vec![Delivery {
            to,
            arrival_ns: arrival,
            duplicate: false,
        }];
        if state.rng.random_bool(model.duplicate_probability) {
            deliveries.push(Delivery {
                to,
                arrival_ns: arrival + jitter(&mut state.rng),
                duplicate: true,
            });
            state.stats.duplicated += 1;
        }
        state.stats.delivered += deliveries.len() as u64;
        state.stats.delivered_bytes += (deliveries.len() * bytes) as u64;
        Routing {
            deliveries,
            dropped: None,
        }
    }
}

#[cfg(test)]
mod tests;
