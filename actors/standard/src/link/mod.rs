//! The link actor: the only actor that talks to other robots (DESIGN §5).
//!
//! Outgoing: the robot's odometry and keyframes are encoded in a versioned envelope
//! (`troupe_comms::wire`) at a fixed rate and offered to a [`LinkShaper`](troupe_comms::shaping::LinkShaper) — token
//! bucket, strict priority classes, fragmentation to the MTU, per-class queue
//! policies — whose frames go out on [`LINK_TX`](troupe_runtime::LINK_TX) as the bucket allows. Incoming frames
//! from [`LINK_RX`](troupe_runtime::LINK_RX) are reassembled, decoded and validated; odometry is published as
//! [`PEER_ODOMETRY`](crate::msgs::PEER_ODOMETRY), keyframes (from the mapper's [`KEYFRAME`](crate::msgs::KEYFRAME)) as
//! [`PEER_KEYFRAME`](crate::msgs::PEER_KEYFRAME), committed plans ([`PLAN`](crate::msgs::PLAN), thesis §8.2.3: at most
//! [`LinkConfig::plan_rate_hz`], with [`LinkConfig::priority`], in the plan class)
//! as [`PEER_PLAN`](crate::msgs::PEER_PLAN). Peers' keyframes, odometry and plans are moved into this
//! robot's world frame with Eq. 8.1 when a [`PeerFrame`] is configured. A frame or message that does not decode, comes from another
//! team, or whose envelope sender disagrees with the network's sender is rejected
//! with a reason and counted (as an actor error). Every second the shaper and
//! reassembler counters are published on [`LINK_STATUS`].
//!
//! The state and logic behind all this are a plain [`LinkCore`], with no runtime
//! context and no executor: it takes the time and each input (a frame with its
//! sender, a local message, a timer's tick) and returns, in order, the frames to
//! transmit, the messages to publish and the timers to arm ([`LinkOutput`]). The
//! [`LinkActor`] subscribes, forwards each event to its core and publishes what
//! comes back.
//!
//! Custom actors share their own topics with the team through the link: see
//! [`SharedTopic`] (per-name lanes, policies and counters, `Peer<T>` on the
//! receivers).

mod actor;
mod config;
mod convert;
mod core;
mod frames;
mod journal;
mod rejections;
mod replay;
mod shared;
mod status;

#[cfg(test)]
mod core_tests;

pub use actor::{LINK_RX_MAX_BYTES, LINK_RX_MAX_FRAMES, LINK_STATUS, LinkActor};
pub use config::{DEFAULT_PEER_TIMEOUT_S, KeyframeEncoding, LinkConfig, SharedConfig};
pub use convert::{keyframe_from_wire, keyframe_to_wire, plan_from_wire, plan_to_wire};
pub use core::{HEARTBEAT_AFTER, LinkCore, LinkIdentity, LinkInput, LinkOutput, LinkTimer};
pub use frames::{PeerFrame, transform_gmm, transform_keyframe, transform_plan};
pub use journal::{LANES_FILE, LinkJournal, MAX_RECEIVED_BYTES};
pub use rejections::{RateLimitedLog, Rejection, RejectionCounts};
pub use replay::{REPLAY_WINDOW, ReplayWindow, Verdict};
pub use shared::{
    Peer, SHARE_REQUESTS, ShareClass, ShareFrom, SharePolicy, ShareRequest, ShareTo,
    SharedDelivery, SharedTopic,
};
pub use status::{LinkStatus, MAX_UNKNOWN_NAMES, OTHER_UNKNOWN_NAMES, SharedStats};
