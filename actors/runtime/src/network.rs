//! The boundary between a robot and the team network.
//!
//! Inside a robot, the link actor is the only one that talks to other robots: it
//! publishes encoded packets on [`LINK_TX`], and the executor's network carries them
//! to the peers, where they appear on [`LINK_RX`]. The network model lives with the
//! executor (deterministic in sim time), so actors never wait on a wire.

use std::sync::Arc;
use std::time::Duration;

use troupe_comms::transport::TransportStats;

use crate::topic::Topic;
use troupe_core::Message;
use troupe_core::RobotId;
use troupe_core::Time;

/// Where a packet goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Destination {
    /// Every other robot of the team.
    Broadcast,
    /// One robot.
    Robot(RobotId),
}

impl Destination {
    /// The robots of a team of `team_size` that a packet from `from` goes to.
    pub fn recipients(self, from: RobotId, team_size: usize) -> impl Iterator<Item = RobotId> {
        (0..team_size as u32).map(RobotId).filter(move |r| {
            *r != from
                && match self {
                    Destination::Broadcast => true,
                    Destination::Robot(to) => *r == to,
                }
        })
    }
}

/// A packet handed to the network by the link actor.
#[derive(Clone, Debug)]
pub struct LinkTx {
    /// Recipient(s).
    pub to: Destination,
    /// Encoded bytes (a wire envelope from `troupe-comms`).
    pub bytes: Arc<[u8]>,
}

impl Message for LinkTx {
    fn payload_bytes(&self) -> usize {
        self.bytes.len()
    }
}

/// A packet delivered by the network to this robot.
#[derive(Clone, Debug)]
pub struct LinkRx {
    /// The robot that sent it (as the network saw it; the envelope names a sender too,
    /// and the link actor checks that they agree).
    pub from: RobotId,
    /// Encoded bytes.
    pub bytes: Arc<[u8]>,
}

impl Message for LinkRx {
    fn payload_bytes(&self) -> usize {
        self.bytes.len()
    }
}

/// Packets to send.
pub const LINK_TX: Topic<LinkTx> = Topic::new("link/tx");
/// Packets received.
pub const LINK_RX: Topic<LinkRx> = Topic::new("link/rx");

/// The counters of the process's network transport, published about once a second
/// on each local robot by an executor that has one (the real-time executor with
/// [`spawn_with_transport`](crate::RealtimeExecutor::spawn_with_transport)); the link
/// actor adds the latest to its `LinkStatus` (`troupe_actors::link`).
pub const LINK_TRANSPORT: Topic<TransportStats> = Topic::new("link/transport");

/// A deterministic network model for the sim-time executor: decides when (if ever)
/// each packet reaches each recipient.
pub trait SimNetwork: Send {
    /// Called for every packet a robot publishes on [`LINK_TX`] (`bytes`: the
    /// frame, whose length and header a model may look at); pushes one
    /// `(recipient, arrival time)` per copy that will be delivered.
    fn route(
        &mut self,
        now: Time,
        from: RobotId,
        to: Destination,
        bytes: &[u8],
        team_size: usize,
        deliveries: &mut Vec<(RobotId, Time)>,
    );

    /// A lower bound on every delivery's delay (arrival − `now` in
    /// [`SimNetwork::route`]). The sim-time executor runs the robots side by side
    /// through windows this long: nothing one robot sends within a window can reach
    /// another before it ends. Zero (the default) allows no overlap beyond one instant.
    fn min_delay(&self) -> Duration {
        Duration::ZERO
    }
}

/// A lossless network with a fixed one-way latency and unlimited rate.
#[derive(Clone, Copy, Debug, Default)]
pub struct IdealNetwork {
    /// One-way latency.
    pub latency: Duration,
}

impl SimNetwork for IdealNetwork {
    fn route(
        &mut self,
        now: Time,
        from: RobotId,
        to: Destination,
        _bytes: &[u8],
        team_size: usize,
        deliveries: &mut Vec<(RobotId, Time)>,
    ) {
        let arrival = now + self.latency;
        deliveries.extend(to.recipients(from, team_size).map(|r| (r, arrival)));
    }

    fn min_delay(&self) -> Duration {
        self.latency
    }
}
