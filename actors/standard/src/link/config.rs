//! Link settings.

use std::collections::BTreeMap;
use std::path::PathBuf;

use serde::{Deserialize, Serialize};
use troupe_comms::scope::SubscriptionConfig;
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
    /// are store-and-forward recipients from the start. Other roster members
    /// become recipients when first heard.
    pub peers: Vec<u32>,
    /// The robot ids that may talk to this robot. A frame from any other id, or
    /// claiming this robot's own id, is rejected and counted before anything else
    /// looks at it (it never becomes a recipient or gets per-peer state). Empty:
    /// filled in by the robot's assembly from the team ([`with_team`](Self::with_team):
    /// ids `0..team size` and the base station's [`base_id`](Self::base_id)); a link
    /// built with an empty roster hears every id but its own.
    pub roster: Vec<u32>,
    /// The base station's id on the link (thesis §8.2.6), in the roster; absent:
    /// the team size, as in a base file.
    pub base_id: Option<u32>,
    /// A store-and-forward recipient silent for longer than this leaves the set
    /// the link sends to (reported in the log and in [`LinkStatus`](super::LinkStatus)):
    /// what it misses is still kept for it, within its own bounds, and resent when
    /// it is heard again; seconds, 0 = never.
    pub peer_timeout_s: f64,
    /// A message stamped further ahead of this robot's clock than this is rejected
    /// and counted (`from_the_future`): a sender whose clock runs ahead, or a forged
    /// stamp, would otherwise freeze what this robot knows of it. Robots on separate
    /// hosts need clocks synchronised better than this (NTP, PTP); seconds.
    pub max_clock_ahead_s: f64,
    /// Robot processes (`troupe robot`, `troupe-robot`): where the link's journal
    /// lives (`link.journal`: stored messages, acknowledgements, the next message
    /// id, messages received), relative to the robot's output directory; absent:
    /// `state/` in it. Simulated teams keep their journal in memory.
    pub journal_dir: Option<PathBuf>,
    /// Peers whose world frame differs from ours (Eq. 8.1); others share our frame.
    pub peer_frames: Vec<PeerFrame>,
    /// How keyframe mixtures go on the wire.
    pub keyframe_encoding: KeyframeEncoding,
    /// Per shared topic (by name), what overrides the policy its
    /// [`SharedTopic`](super::SharedTopic) declares.
    pub shared: BTreeMap<String, SharedConfig>,
    /// Which peers' broadcast odometry, plans and keyframes reach this robot: all, those
    /// near its own odometry, or none but the base station's (issue 22,
    /// [`troupe_comms::scope`]). The network applies it, not the link: the zenoh
    /// transport of a robot process through its subscriptions, the simulated
    /// network of a sim-time team through its routing. A team shares one value.
    pub subscribe: SubscriptionConfig,
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
            roster: Vec::new(),
            base_id: None,
            journal_dir: None,
            peer_timeout_s: DEFAULT_PEER_TIMEOUT_S,
            max_clock_ahead_s: DEFAULT_MAX_CLOCK_AHEAD_S,
            peer_frames: Vec::new(),
            keyframe_encoding: KeyframeEncoding::default(),
            shared: BTreeMap::new(),
            subscribe: SubscriptionConfig::default(),
        }
    }
}

/// Default [`LinkConfig::peer_timeout_s`]: 100 periods of 10 Hz odometry.
pub const DEFAULT_PEER_TIMEOUT_S: f64 = 10.0;

/// Default [`LinkConfig::max_clock_ahead_s`]: five periods of 10 Hz odometry, far
/// above what NTP keeps hosts apart on a LAN (milliseconds).
pub const DEFAULT_MAX_CLOCK_AHEAD_S: f64 = 0.5;

impl LinkConfig {
    /// Fills an empty [`roster`](Self::roster) with the team of `team_size`
    /// robots (ids `0..team_size`) and the base station, and an absent
    /// [`base_id`](Self::base_id) with its default, `team_size`; a roster given in
    /// the file is kept as written.
    ///
    /// ```
    /// use troupe_actors::link::LinkConfig;
    /// let config = LinkConfig::default().with_team(3);
    /// assert_eq!(config.roster, vec![0, 1, 2, 3]);
    /// assert_eq!(config.base_id, Some(3));
    /// ```
    #[must_use]
    pub fn with_team(mut self, team_size: u32) -> Self {
        let base_id = *self.base_id.get_or_insert(team_size);
        if self.roster.is_empty() {
            self.roster = (0..team_size).chain([base_id]).collect();
            self.roster.sort_unstable();
            self.roster.dedup();
        }
        self
    }

    /// Makes every member of the [`roster`](Self::roster) (the base station
    /// included) a store-and-forward recipient from the start, when
    /// [`peers`](Self::peers) is empty. Robot processes and the base station do
    /// this: a member that starts late, or restarts, then still gets what the
    /// others sent before it was first heard (a message every member heard so
    /// far would otherwise be released); a member that never comes is suspended
    /// after [`peer_timeout_s`](Self::peer_timeout_s) and holds at most its own
    /// bound of stored messages.
    ///
    /// ```
    /// use troupe_actors::link::LinkConfig;
    /// let config = LinkConfig::default().with_team(2).with_roster_as_peers();
    /// assert_eq!(config.peers, vec![0, 1, 2]);
    /// ```
    #[must_use]
    pub fn with_roster_as_peers(mut self) -> Self {
        if self.peers.is_empty() {
            self.peers.clone_from(&self.roster);
        }
        self
    }

    /// What robot processes (and the base station) do with keyframes unless their
    /// file names `[robot.link.shaper.keyframe] policy` (`policy_named`): keep each
    /// until every member acknowledged it (store-and-forward, in the journal on
    /// disk, at most the class's `capacity_messages` and `capacity_bytes` per
    /// member). A robot restarted after `kill -9`, or a base station that joins
    /// late, then gets every keyframe its peers made before; simulated teams keep
    /// the class's own default (drop-oldest), the setting the link studies fly.
    ///
    /// ```
    /// use troupe_actors::link::LinkConfig;
    /// use troupe_comms::shaping::QueuePolicy;
    /// let config = LinkConfig::default().with_process_keyframes(false);
    /// assert_eq!(config.shaper.keyframe.policy, QueuePolicy::StoreAndForward);
    /// let named = LinkConfig::default().with_process_keyframes(true);
    /// assert_eq!(named.shaper.keyframe.policy, QueuePolicy::DropOldest);
    /// ```
    #[must_use]
    pub fn with_process_keyframes(mut self, policy_named: bool) -> Self {
        if !policy_named {
            self.shaper.keyframe.policy = QueuePolicy::StoreAndForward;
        }
        self
    }

    /// The journal directory of a robot process whose outputs go to `out`.
    #[must_use]
    pub fn journal_dir_in(&self, out: &std::path::Path) -> PathBuf {
        out.join(self.journal_dir.as_deref().unwrap_or("state".as_ref()))
    }

    /// Checks the settings; the error names the key (relative to the link table).
    pub fn validate(&self) -> Result<(), ConfigError> {
        ConfigError::non_negative("odometry_rate_hz", self.odometry_rate_hz)?;
        ConfigError::non_negative("plan_rate_hz", self.plan_rate_hz)?;
        ConfigError::non_negative("peer_timeout_s", self.peer_timeout_s)?;
        ConfigError::positive("max_clock_ahead_s", self.max_clock_ahead_s)?;
        self.shaper.validate().map_err(|e| e.within("shaper"))?;
        self.subscribe
            .validate()
            .map_err(|e| e.within("subscribe"))?;
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
