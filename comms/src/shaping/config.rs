//! Shaper and reassembler settings (serde, validated).

use serde::{Deserialize, Serialize};

use super::frame::DATA_HEADER_BYTES;
use crate::wire::Class;

pub use troupe_core::ConfigError;

fn fail(key: impl Into<String>, rule: &'static str, value: impl std::fmt::Display) -> ConfigError {
    ConfigError::new(key, rule, value)
}

/// What a class queue does when it fills (DESIGN §5).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum QueuePolicy {
    /// At most one message waits; a newer one replaces it (counted as
    /// superseded). A message already partly sent is finished first.
    KeepLatest,
    /// A bounded FIFO; when full, the oldest waiting message is dropped (counted
    /// as overflow).
    DropOldest,
    /// A bounded store that keeps every accepted message until the peer
    /// acknowledges it, retransmitting in order (go-back-N with a window and
    /// exponential back-off). When full, new offers are refused (and counted),
    /// never the stored ones dropped.
    StoreAndForward,
}

/// Settings of one traffic class. A class table given in a file changes only the
/// keys it names: the others keep that class's default (keep-latest for odometry and
/// plans, drop-oldest for keyframes and bulk).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ClassConfig {
    /// Queue policy.
    pub policy: QueuePolicy,
    /// Most messages waiting (drop-oldest) or stored (store-and-forward).
    pub capacity_messages: usize,
    /// Most bytes waiting or stored; a single larger message is refused.
    pub capacity_bytes: usize,
    /// Store-and-forward: wait this long for an acknowledgement before going
    /// back to the oldest unacknowledged message, seconds.
    pub retransmit_timeout_s: f64,
    /// Store-and-forward: the timeout doubles after each go-back, up to this, seconds.
    pub retransmit_timeout_max_s: f64,
    /// Store-and-forward: most messages sent and not yet acknowledged.
    pub window_messages: usize,
}

impl Default for ClassConfig {
    fn default() -> Self {
        ClassConfig {
            policy: QueuePolicy::DropOldest,
            capacity_messages: 64,
            capacity_bytes: 4 * 1024 * 1024,
            retransmit_timeout_s: 1.0,
            retransmit_timeout_max_s: 8.0,
            window_messages: 8,
        }
    }
}

impl ClassConfig {
    /// Keep-latest with the other fields at their defaults.
    #[must_use]
    pub fn keep_latest() -> Self {
        ClassConfig {
            policy: QueuePolicy::KeepLatest,
            ..ClassConfig::default()
        }
    }

    /// Store-and-forward with the other fields at their defaults.
    #[must_use]
    pub fn store_and_forward() -> Self {
        ClassConfig {
            policy: QueuePolicy::StoreAndForward,
            ..ClassConfig::default()
        }
    }

    /// Checks ranges; `prefix` is the class table's key.
    pub fn validate(&self, prefix: &str) -> Result<(), ConfigError> {
        let key = |k: &str| format!("{prefix}.{k}");
        if self.capacity_messages == 0 {
            return Err(fail(
                key("capacity_messages"),
                "must be at least 1",
                self.capacity_messages,
            ));
        }
        if self.capacity_bytes == 0 {
            return Err(fail(
                key("capacity_bytes"),
                "must be at least 1",
                self.capacity_bytes,
            ));
        }
        if !(self.retransmit_timeout_s.is_finite() && self.retransmit_timeout_s > 0.0) {
            return Err(fail(
                key("retransmit_timeout_s"),
                "must be a finite number > 0",
                self.retransmit_timeout_s,
            ));
        }
        if !(self.retransmit_timeout_max_s.is_finite()
            && self.retransmit_timeout_max_s >= self.retransmit_timeout_s)
        {
            return Err(fail(
                key("retransmit_timeout_max_s"),
                "must be finite and ≥ retransmit_timeout_s",
                self.retransmit_timeout_max_s,
            ));
        }
        if self.window_messages == 0 {
            return Err(fail(
                key("window_messages"),
                "must be at least 1",
                self.window_messages,
            ));
        }
        Ok(())
    }
}

/// A class table as a file gives it: the keys it names, laid over the class's default.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ClassTable {
    policy: Option<QueuePolicy>,
    capacity_messages: Option<usize>,
    capacity_bytes: Option<usize>,
    retransmit_timeout_s: Option<f64>,
    retransmit_timeout_max_s: Option<f64>,
    window_messages: Option<usize>,
}

impl ClassTable {
    fn over(self, class: ClassConfig) -> ClassConfig {
        ClassConfig {
            policy: self.policy.unwrap_or(class.policy),
            capacity_messages: self.capacity_messages.unwrap_or(class.capacity_messages),
            capacity_bytes: self.capacity_bytes.unwrap_or(class.capacity_bytes),
            retransmit_timeout_s: self
                .retransmit_timeout_s
                .unwrap_or(class.retransmit_timeout_s),
            retransmit_timeout_max_s: self
                .retransmit_timeout_max_s
                .unwrap_or(class.retransmit_timeout_max_s),
            window_messages: self.window_messages.unwrap_or(class.window_messages),
        }
    }
}

/// A keep-latest class's table (odometry, plans).
fn keep_latest_class<'de, D: serde::Deserializer<'de>>(d: D) -> Result<ClassConfig, D::Error> {
    Ok(ClassTable::deserialize(d)?.over(ClassConfig::keep_latest()))
}

/// Settings of one shaped link (DESIGN §5; the thesis' §8.2.7 study uses a token
/// bucket at 0.1 and 0.25 Mbit/s).
///
/// ```
/// use troupe_comms::shaping::{QueuePolicy, ShaperConfig};
/// let config: ShaperConfig = toml::from_str(r#"
///     rate_bps = 250_000
///     burst_bytes = 4096
///     mtu_bytes = 1200
///     [keyframe]
///     policy = "store_and_forward"
///     capacity_messages = 100
/// "#).unwrap();
/// config.validate().unwrap();
/// assert_eq!(config.keyframe.policy, QueuePolicy::StoreAndForward);
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ShaperConfig {
    /// Token-bucket rate, bits per second; absent = unlimited.
    pub rate_bps: Option<u64>,
    /// Token-bucket depth, bytes; must hold one whole frame.
    pub burst_bytes: u64,
    /// Largest frame (fragment header included), bytes.
    pub mtu_bytes: usize,
    /// Bytes charged to the bucket per frame on top of the frame itself (for
    /// example 28 for UDP/IPv4 headers); 0 counts only what the shaper emits.
    pub frame_overhead_bytes: u64,
    /// Odometry and heartbeats (default keep-latest).
    #[serde(deserialize_with = "keep_latest_class")]
    pub odometry: ClassConfig,
    /// Plans (default keep-latest).
    #[serde(deserialize_with = "keep_latest_class")]
    pub plan: ClassConfig,
    /// Keyframes and grid change sets (default drop-oldest).
    pub keyframe: ClassConfig,
    /// Everything else (default drop-oldest).
    pub bulk: ClassConfig,
}

impl Default for ShaperConfig {
    fn default() -> Self {
        ShaperConfig {
            rate_bps: None,
            burst_bytes: 16 * 1024,
            mtu_bytes: 1200,
            frame_overhead_bytes: 0,
            odometry: ClassConfig::keep_latest(),
            plan: ClassConfig::keep_latest(),
            keyframe: ClassConfig::default(),
            bulk: ClassConfig::default(),
        }
    }
}

/// Smallest MTU accepted (a fragment header and at least 53 bytes of payload).
pub const MIN_MTU_BYTES: usize = 64;
/// Largest MTU accepted (a UDP datagram).
pub const MAX_MTU_BYTES: usize = 65_507;

impl ShaperConfig {
    /// The settings of one class.
    #[must_use]
    pub fn class(&self, class: Class) -> &ClassConfig {
        match class {
            Class::Odometry => &self.odometry,
            Class::Plan => &self.plan,
            Class::Keyframe => &self.keyframe,
            Class::Bulk => &self.bulk,
        }
    }

    /// Checks every range and names the first key that is out of it.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.rate_bps == Some(0) {
            return Err(fail(
                "rate_bps",
                "must be at least 1 (leave it out for an unlimited link)",
                0,
            ));
        }
        if !(MIN_MTU_BYTES..=MAX_MTU_BYTES).contains(&self.mtu_bytes) {
            return Err(fail(
                "mtu_bytes",
                "must be between 64 and 65507",
                self.mtu_bytes,
            ));
        }
        if self.rate_bps.is_some()
            && self.burst_bytes < self.mtu_bytes as u64 + self.frame_overhead_bytes
        {
            return Err(fail(
                "burst_bytes",
                "must hold one whole frame (≥ mtu_bytes + frame_overhead_bytes)",
                self.burst_bytes,
            ));
        }
        const { assert!(MIN_MTU_BYTES > DATA_HEADER_BYTES) };
        for (name, class) in [
            ("odometry", &self.odometry),
            ("plan", &self.plan),
            ("keyframe", &self.keyframe),
            ("bulk", &self.bulk),
        ] {
            class.validate(name)?;
        }
        Ok(())
    }
}

/// Settings of a [`Reassembler`](super::Reassembler).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReassemblyConfig {
    /// Most bytes held in partly received messages (all sources together).
    pub max_bytes: usize,
    /// Most partly received messages held.
    pub max_messages: usize,
    /// A partly received message with no new fragment for this long is evicted,
    /// seconds.
    pub timeout_s: f64,
    /// How many completed message ids per source are remembered to drop
    /// retransmitted duplicates.
    pub dedup_window: usize,
}

impl Default for ReassemblyConfig {
    fn default() -> Self {
        ReassemblyConfig {
            max_bytes: 8 * 1024 * 1024,
            max_messages: 256,
            timeout_s: 30.0,
            dedup_window: 1024,
        }
    }
}

impl ReassemblyConfig {
    /// Checks ranges and names the key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.max_bytes == 0 {
            return Err(fail("max_bytes", "must be at least 1", 0));
        }
        if self.max_messages == 0 {
            return Err(fail("max_messages", "must be at least 1", 0));
        }
        if !(self.timeout_s.is_finite() && self.timeout_s > 0.0) {
            return Err(fail(
                "timeout_s",
                "must be a finite number > 0",
                self.timeout_s,
            ));
        }
        Ok(())
    }
}

/// Seconds to nanoseconds, saturating (for validated, finite, positive values).
pub(crate) fn s_to_ns(s: f64) -> u64 {
    (s * 1e9).round().clamp(0.0, u64::MAX as f64) as u64
}
