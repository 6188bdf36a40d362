//! Link settings.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use troupe_comms::shaping::{ClassConfig, QueuePolicy, ReassemblyConfig, ShaperConfig};
use troupe_comms::wire::valid_user_name;
use troupe_runtime::ConfigError;

use super::frames::PeerFrame;
use super::shared::{ShareClass, SharePolicy, ShareTo};

/// Link settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LinkConfig {
    /// Team id written in every envelope; packets of other teams are rejected.
    pub team: u32,
    /// How often odometry is sent to peers, Hz (thesis §8.2.3: 10 Hz).
    pub odometry_rate_hz: f64,
    /// Most committed plans sent per second, Hz (thesis §8.2.3: 1 Hz); the latest
    /// plan goes out as soon as the rate allows. 0 = plans are not shared.
    pub plan_rate_hz: f64,
    /// This robot's priority, sent with its plans (§8.2.3: lower-priority robots
    /// avoid higher-priority ones; larger = higher).
    pub priority: u16,
    /// Outgoing shaping (rate, burst, MTU, per-class policies).
    pub shaper: ShaperConfig,
    /// Incoming reassembly limits.
    pub reassembly: ReassemblyConfig,
    /// Team members known in advance (robot indices; our own is ignored): they
    /// are store-and-forward recipients from the start. Other peers become
    /// recipients when first heard.
    pub peers: Vec<u32>,
    /// A store-and-forward recipient silent for longer than this is removed and
    /// what it missed is given up (counted as `peer_removed`), seconds; 0 = never.
    pub peer_timeout_s: f64,
    /// Peers whose world frame differs from ours (Eq. 8.1); others share our frame.
    pub peer_frames: Vec<PeerFrame>,
    /// How keyframe mixtures go on the wire.
    pub keyframe_encoding: KeyframeEncoding,
    /// Per shared topic (by name), what overrides the policy its
    /// [`SharedTopic`](super::SharedTopic) declares.
    pub shared: BTreeMap<String, SharedConfig>,
}

/// Overrides for one shared topic (`[link.shared."artifacts/report"]`); what is
/// left out keeps the topic's declared [`SharePolicy`].
///
/// ```
/// use troupe_actors::link::LinkConfig;
/// let config: LinkConfig = toml::from_str(r#"
///     [shared."artifacts/report"]
///     class = "plan"
///     policy = "store_and_forward"
///     capacity_messages = 500
/// "#).unwrap();
/// config.validate().unwrap();
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SharedConfig {
    /// Priority class: `odometry`, `plan`, `keyframe` or `bulk`.
    pub class: Option<ShareClass>,
    /// `keep_latest`, `drop_oldest` or `store_and_forward`.
    pub policy: Option<QueuePolicy>,
    /// `"peers"` or `{ robot = 2 }`.
    pub to: Option<ShareTo>,
    /// Most messages waiting or stored in the topic's lane.
    pub capacity_messages: Option<usize>,
    /// Most bytes waiting or stored in the topic's lane.
    pub capacity_bytes: Option<usize>,
}

impl SharedConfig {
    /// The declared policy with these overrides: the class, the lane's settings
    /// and the addressee.
    #[must_use]
    pub fn apply(&self, declared: SharePolicy) -> (ShareClass, ClassConfig, ShareTo) {
        let defaults = ClassConfig::default();
        let lane = ClassConfig {
            policy: self.policy.unwrap_or(declared.policy),
            capacity_messages: self.capacity_messages.unwrap_or(defaults.capacity_messages),
            capacity_bytes: self.capacity_bytes.unwrap_or(defaults.capacity_bytes),
            ..defaults
        };
        (
            self.class.unwrap_or(declared.class),
            lane,
            self.to.unwrap_or(declared.to),
        )
    }
}

/// How keyframe mixtures are encoded ([`troupe_comms::wire::Mixture`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum KeyframeEncoding {
    /// `f32` means, covariances and weights: 60 bytes per 4D component, the
    /// thesis' accounting (§8.2.5).
    Exact,
    /// Log standard deviations and quantised correlations: 44 bytes per 4D
    /// component, losing ~10⁻⁵ nats of mean log-likelihood per point. A mixture
    /// outside the compact range goes exact.
    #[default]
    Compact,
}

impl Default for LinkConfig {
    fn default() -> Self {
        LinkConfig {
            team: 0,
            odometry_rate_hz: 10.0,
            plan_rate_hz: 1.0,
            priority: 0,
            shaper: ShaperConfig::default(),
            reassembly: ReassemblyConfig::default(),
            peers: Vec::new(),
            peer_timeout_s: 0.0,
            peer_frames: Vec::new(),
            keyframe_encoding: KeyframeEncoding::default(),
            shared: BTreeMap::new(),
        }
    }
}

impl LinkConfig {
    /// Checks the settings; the error names the key (relative to the link table).
    pub fn validate(&self) -> Result<(), ConfigError> {
        ConfigError::non_negative("odometry_rate_hz", self.odometry_rate_hz)?;
        ConfigError::non_negative("plan_rate_hz", self.plan_rate_hz)?;
        ConfigError::non_negative("peer_timeout_s", self.peer_timeout_s)?;
        self.shaper.validate().map_err(|e| e.within("shaper"))?;
        for (name, shared) in &self.shared {
            let key = format!("shared.\"{name}\"");
            if !valid_user_name(name) {
                return Err(ConfigError::new(
                    key,
                    "must be 1 to 64 ASCII letters, digits and / _ - .",
                    name,
                ));
            }
            shared
                .apply(SharePolicy::store_and_forward_in_plan_class())
                .1
                .validate(&key)?;
        }
        self.reassembly
            .validate()
            .map_err(|e| e.within("reassembly"))
    }
}
