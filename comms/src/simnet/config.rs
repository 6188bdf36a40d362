//! Simulated-network settings (serde, validated).

use serde::{Deserialize, Serialize};

use crate::shaping::ConfigError;

fn fail(key: String, rule: &'static str, value: impl std::fmt::Display) -> ConfigError {
    ConfigError::new(key, rule, value)
}

fn probability(key: String, p: f64) -> Result<(), ConfigError> {
    if (0.0..=1.0).contains(&p) {
        Ok(())
    } else {
        Err(fail(key, "must be a probability in [0, 1]", p))
    }
}

fn non_negative(key: String, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(fail(key, "must be a finite number ≥ 0", v))
    }
}

/// Two-state Gilbert–Elliott bursty loss: the channel is *good* or *bad*; before
/// each packet it moves good → bad with `p_good_to_bad` and bad → good with
/// `p_bad_to_good`, then loses the packet with the state's loss probability.
/// Long-run loss rate: `π_bad · loss_bad + (1 − π_bad) · loss_good` with
/// `π_bad = p_good_to_bad / (p_good_to_bad + p_bad_to_good)`; mean bad-state
/// sojourn `1 / p_bad_to_good` packets.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GilbertElliott {
    /// Per-packet probability of moving from good to bad.
    pub p_good_to_bad: f64,
    /// Per-packet probability of moving from bad to good.
    pub p_bad_to_good: f64,
    /// Loss probability in the good state.
    pub loss_good: f64,
    /// Loss probability in the bad state.
    pub loss_bad: f64,
}

impl Default for GilbertElliott {
    fn default() -> Self {
        GilbertElliott {
            p_good_to_bad: 0.01,
            p_bad_to_good: 0.2,
            loss_good: 0.0,
            loss_bad: 1.0,
        }
    }
}

impl GilbertElliott {
    /// Long-run fraction of packets lost.
    #[must_use]
    pub fn stationary_loss(&self) -> f64 {
        let total = self.p_good_to_bad + self.p_bad_to_good;
        let bad = if total > 0.0 {
            self.p_good_to_bad / total
        } else {
            0.0
        };
        bad * self.loss_bad + (1.0 - bad) * self.loss_good
    }

    fn validate(&self, prefix: &str) -> Result<(), ConfigError> {
        probability(format!("{prefix}.p_good_to_bad"), self.p_good_to_bad)?;
        probability(format!("{prefix}.p_bad_to_good"), self.p_bad_to_good)?;
        probability(format!("{prefix}.loss_good"), self.loss_good)?;
        probability(format!("{prefix}.loss_bad"), self.loss_bad)
    }
}

/// Behaviour of one directed link.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LinkModel {
    /// Fixed propagation and processing latency, seconds.
    pub latency_s: f64,
    /// Extra delay drawn uniformly from `[0, jitter_s]` per packet, seconds.
    /// Jitter alone never reorders a link (arrivals are kept in order).
    pub jitter_s: f64,
    /// Independent per-packet loss probability.
    pub loss_probability: f64,
    /// Bursty loss on top of the independent loss; absent = none.
    pub bursty_loss: Option<GilbertElliott>,
    /// Probability that a packet is held back by `reorder_delay_s`, letting
    /// later packets overtake it.
    pub reorder_probability: f64,
    /// Extra delay of a reordered packet, seconds.
    pub reorder_delay_s: f64,
    /// Probability that a packet arrives twice.
    pub duplicate_probability: f64,
    /// Serialisation rate at short range, bits per second; absent = no
    /// serialisation delay.
    pub rate_bps: Option<u64>,
    /// Communication radius, metres; beyond it nothing arrives. Absent = no limit.
    pub radius_m: Option<f64>,
    /// Up to this distance the full rate applies, metres; between it and
    /// `radius_m` the rate falls linearly to `edge_rate_fraction · rate_bps`.
    pub full_rate_radius_m: f64,
    /// Fraction of the rate left at the radius, in (0, 1].
    pub edge_rate_fraction: f64,
}

impl Default for LinkModel {
    fn default() -> Self {
        LinkModel {
            latency_s: 0.005,
            jitter_s: 0.0,
            loss_probability: 0.0,
            bursty_loss: None,
            reorder_probability: 0.0,
            reorder_delay_s: 0.05,
            duplicate_probability: 0.0,
            rate_bps: None,
            radius_m: None,
            full_rate_radius_m: 0.0,
            edge_rate_fraction: 0.1,
        }
    }
}

impl LinkModel {
    /// Checks ranges; `prefix` is this table's key.
    pub fn validate(&self, prefix: &str) -> Result<(), ConfigError> {
        let key = |k: &str| format!("{prefix}.{k}");
        non_negative(key("latency_s"), self.latency_s)?;
        non_negative(key("jitter_s"), self.jitter_s)?;
        probability(key("loss_probability"), self.loss_probability)?;
        if let Some(ge) = &self.bursty_loss {
            ge.validate(&key("bursty_loss"))?;
        }
        probability(key("reorder_probability"), self.reorder_probability)?;
        non_negative(key("reorder_delay_s"), self.reorder_delay_s)?;
        probability(key("duplicate_probability"), self.duplicate_probability)?;
        if self.rate_bps == Some(0) {
            return Err(fail(
                key("rate_bps"),
                "must be at least 1 (leave it out for no serialisation delay)",
                0,
            ));
        }
        if let Some(r) = self.radius_m
            && !(r.is_finite() && r > 0.0)
        {
            return Err(fail(key("radius_m"), "must be a finite number > 0", r));
        }
        non_negative(key("full_rate_radius_m"), self.full_rate_radius_m)?;
        if !(self.edge_rate_fraction > 0.0 && self.edge_rate_fraction <= 1.0) {
            return Err(fail(
                key("edge_rate_fraction"),
                "must be in (0, 1]",
                self.edge_rate_fraction,
            ));
        }
        Ok(())
    }
}

/// A per-directed-pair override of [`SimNetConfig::default`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PairModel {
    /// Sending robot.
    pub from: u32,
    /// Receiving robot.
    pub to: u32,
    /// Its behaviour (a whole table; unspecified keys take [`LinkModel`]'s defaults).
    #[serde(default)]
    pub link: LinkModel,
}

/// A scheduled partition: during `[start_s, end_s)`, robots talk only within
/// their group (robots in no group are cut off from everyone when `groups` is
/// not empty), and the `cut` pairs not at all (both directions).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Partition {
    /// Start, seconds of sim time.
    pub start_s: f64,
    /// End (exclusive), seconds.
    pub end_s: f64,
    /// Groups that can still talk inside themselves; empty = no group rule.
    pub groups: Vec<Vec<u32>>,
    /// Pairs cut in both directions.
    pub cut: Vec<[u32; 2]>,
}

impl Default for Partition {
    fn default() -> Self {
        Partition {
            start_s: 0.0,
            end_s: 0.0,
            groups: Vec::new(),
            cut: Vec::new(),
        }
    }
}

impl Partition {
    /// True if this partition separates `a` and `b` at `t_s`.
    #[must_use]
    pub fn separates(&self, t_s: f64, a: u32, b: u32) -> bool {
        if !(self.start_s <= t_s && t_s < self.end_s) {
            return false;
        }
        if self
            .cut
            .iter()
            .any(|&[x, y]| (x == a && y == b) || (x == b && y == a))
        {
            return true;
        }
        !self.groups.is_empty() && !self.groups.iter().any(|g| g.contains(&a) && g.contains(&b))
    }
}

/// The whole simulated network.
///
/// ```
/// use troupe_comms::simnet::SimNetConfig;
/// let c: SimNetConfig = toml::from_str(r#"
///     [default]
///     latency_s = 0.02
///     rate_bps = 250_000
///     radius_m = 50.0
///     [default.bursty_loss]
///     p_good_to_bad = 0.01
///     p_bad_to_good = 0.25
///     [[pairs]]
///     from = 0
///     to = 1
///     link = { latency_s = 0.1 }
///     [[partitions]]
///     start_s = 30.0
///     end_s = 60.0
///     groups = [[0, 1], [2]]
/// "#).unwrap();
/// c.validate().unwrap();
/// ```
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimNetConfig {
    /// Behaviour of every directed pair without an override.
    pub default: LinkModel,
    /// Overrides for directed pairs.
    pub pairs: Vec<PairModel>,
    /// Scheduled partitions.
    pub partitions: Vec<Partition>,
}

impl SimNetConfig {
    /// Checks every range and names the first key out of it.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.default.validate("default")?;
        for (i, p) in self.pairs.iter().enumerate() {
            p.link.validate(&format!("pairs[{i}].link"))?;
            if p.from == p.to {
                return Err(fail(
                    format!("pairs[{i}].to"),
                    "must differ from `from`",
                    p.to,
                ));
            }
        }
        for (i, p) in self.partitions.iter().enumerate() {
            non_negative(format!("partitions[{i}].start_s"), p.start_s)?;
            if !(p.end_s.is_finite() && p.end_s >= p.start_s) {
                return Err(fail(
                    format!("partitions[{i}].end_s"),
                    "must be finite and ≥ start_s",
                    p.end_s,
                ));
            }
        }
        Ok(())
    }
}
