//! What the link reports: [`LinkStatus`], published every second on
//! [`LINK_STATUS`](super::LINK_STATUS), with per shared topic [`SharedStats`].

use std::collections::BTreeMap;

use serde::Serialize;
use troupe_comms::shaping::{ClassStats, ReassemblyStats, ShaperStats};
use troupe_comms::transport::TransportStats;
use troupe_comms::wire::Class;
use troupe_runtime::{Message, Time};

use super::rejections::RejectionCounts;

/// The link's counters, published every second.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LinkStatus {
    /// When.
    #[serde(skip)]
    pub stamp: Time,
    /// Outgoing: per class offered, sent, dropped by reason, queue delay, age of information.
    pub shaper: ShaperStats,
    /// Incoming: frames, completed messages, duplicates, timeouts, evictions.
    pub reassembly: ReassemblyStats,
    /// Messages rejected after reassembly (decode errors, wrong team or sender,
    /// invalid payloads).
    pub rejected_messages: u64,
    /// Frames and messages rejected, per reason (roster, own id, malformed frames,
    /// envelopes, payloads, acknowledgements of messages not held).
    pub rejections: RejectionCounts,
    /// Store-and-forward recipients suspended now: silent for longer than
    /// `peer_timeout_s` (what they miss is kept for them, within their bounds).
    pub silent_peers: Vec<u32>,
    /// How many times a recipient was suspended for its silence.
    pub peer_timeouts: u64,
    /// Received messages the journal on disk dropped for room: the sender holding
    /// the most bytes loses its oldest first, so one member cannot push out what the
    /// others sent (robot processes; 0 in simulation).
    pub journal_evicted: u64,
    /// The process's network transport counters, when it has one (robot processes
    /// over zenoh; `None` in simulation), as last published on `link/transport`.
    pub transport: Option<TransportStats>,
    /// Per shared topic (by name): what went out in its lane and what came in,
    /// including names this robot does not share (`registered = false`).
    pub shared: BTreeMap<String, SharedStats>,
}
impl Message for LinkStatus {}

/// Counters of one shared topic ([`SharedTopic`](super::SharedTopic)).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SharedStats {
    /// Whether this robot shares the topic (else every message of it that
    /// arrives is rejected as `unknown_name`).
    pub registered: bool,
    /// Its traffic class and schema version here.
    pub class: Option<Class>,
    /// The schema version of the topic's type here.
    pub version: u16,
    /// Outgoing: its lane's counters (offered, sent, drops, queue delay, age).
    pub sent: ClassStats,
    /// Local messages that could not be serialised.
    pub unencodable: u64,
    /// Messages received, decoded and published on the peer topic.
    pub received: u64,
    /// Rejected: this robot does not share the name.
    pub unknown_name: u64,
    /// Rejected: the sender's schema version is older than ours.
    pub older_version: u64,
    /// Rejected: the sender's schema version is newer than ours.
    pub newer_version: u64,
    /// Rejected: the bytes are not a valid message of our type.
    pub undecodable: u64,
    /// Dropped: addressed to another robot.
    pub not_addressed: u64,
}

/// Most distinct unknown names counted one by one; more are counted under
/// [`OTHER_UNKNOWN_NAMES`] (a hostile peer cannot grow the table without bound).
pub const MAX_UNKNOWN_NAMES: usize = 32;
/// The counter name for unknown names beyond [`MAX_UNKNOWN_NAMES`].
pub const OTHER_UNKNOWN_NAMES: &str = "(other unknown names)";
