//! The boundary between a robot's link and a real network (DESIGN §5): a
//! runtime-free trait that an executor hands frames to and that hands received
//! frames back through a callback.
//!
//! The trait lives here, not in `troupe-actors`, because the dependency direction
//! is `comms ← actors`: comms cannot implement a trait of actors, while a comms
//! trait needs nothing from actors (robots are `u32` indices, frames are bytes).
//! So comms implements it ([`ZenohTransport`](crate::zenoh::ZenohTransport), behind
//! the `zenoh` feature) and the real-time executor in actors consumes it, without
//! actors ever naming zenoh.

use std::sync::Arc;

use thiserror::Error;

/// A frame received from a peer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ReceivedPacket<'a> {
    /// The sending robot, as the transport authenticated it (for zenoh: the robot
    /// named in the key expression the frame arrived on). The link checks that the
    /// envelope inside names the same sender.
    pub from: u32,
    /// `None`: sent to every peer; `Some(r)`: addressed to robot `r` only.
    pub to: Option<u32>,
    /// The frame (see [`shaping::frame`](crate::shaping::frame)).
    pub bytes: &'a [u8],
}

/// Where a transport delivers what it receives. Called from the transport's own
/// threads; it must not block for long.
pub type PacketSink = Arc<dyn Fn(ReceivedPacket<'_>) + Send + Sync>;

/// Why a transport could not open or take a frame.
#[derive(Debug, Error)]
pub enum TransportError {
    /// The settings are not usable; names the key.
    #[error("transport setting `{key}`: {reason}")]
    Config {
        /// The offending key.
        key: String,
        /// What is wrong.
        reason: String,
    },
    /// The network layer refused to open or declare something.
    #[error("transport: {context}")]
    Network {
        /// What was being done.
        context: String,
        /// The underlying error.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// The outgoing queue is full; the frame was dropped (and counted).
    #[error("transport send queue is full")]
    QueueFull,
    /// The frame does not parse, so it has no class to travel in.
    #[error("not a frame: {0}")]
    BadFrame(#[from] crate::shaping::FrameError),
    /// The transport was closed.
    #[error("transport is closed")]
    Closed,
}

/// Counters every transport can report (a network-independent summary; a concrete
/// transport may keep more, e.g. [`ZenohStats`](crate::zenoh::ZenohStats)).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct TransportStats {
    /// Frames handed to the network.
    pub sent_frames: u64,
    /// Bytes handed to the network.
    pub sent_bytes: u64,
    /// Frames not sent: the send queue was full or the network refused them.
    pub send_failures: u64,
    /// Frames received and handed on.
    pub received_frames: u64,
    /// Frames received and rejected (malformed, wrong team, wrong class, spoofed
    /// sender).
    pub rejected_frames: u64,
}

/// Published inside a robot on the runtime's `link/transport` topic.
impl troupe_core::Message for TransportStats {}

/// Carries a robot's frames to its peers and theirs to it. Implementations never
/// block the caller on the network: [`send`](Self::send) queues and returns.
pub trait PacketTransport: Send + Sync {
    /// Starts delivering frames received from peers to `sink`. Frames a local
    /// robot sent are not delivered back.
    fn start(&self, sink: PacketSink) -> Result<(), TransportError>;

    /// Hands one frame sent by local robot `from` to the network, for robot `to`
    /// or (`None`) every peer.
    fn send(&self, from: u32, to: Option<u32>, frame: &[u8]) -> Result<(), TransportError>;

    /// Counters so far (all zero for a transport that keeps none).
    fn stats(&self) -> TransportStats {
        TransportStats::default()
    }
}
