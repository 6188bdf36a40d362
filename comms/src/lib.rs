//! troupe-comms: what crosses between robots, and how.
//!
//! - [`wire`]: the versioned envelope and its payloads (odometry, plan, keyframe
//!   GMM exact or compact, occupancy-grid change set), encoded with postcard and
//!   validated on both ends. Postcard is positional: the order of fields and enum
//!   variants *is* the protocol. Changing it means bumping
//!   [`wire::FORMAT_VERSION`].
//! - [`shaping`]: per-link token bucket, strict priority classes, fragmentation,
//!   queue policies (keep-latest, drop-oldest, store-and-forward) and their
//!   counters; the [`shaping::Reassembler`] on the receive side. Runtime-free,
//!   driven by explicit time.
//! - [`journal`]: a link's durable state on disk for robot processes (an fsync'd
//!   append-only log with CRC-32 per record): stored messages, acknowledgements,
//!   the next message id, messages received.
//! - [`scope`]: what each robot receives of its peers' broadcasts (all peers,
//!   peers near its own position, the base station only), as key-expression cells
//!   for zenoh and as a routing rule for the simulated network.
//! - [`simnet`]: a deterministic simulated network (latency, jitter, random and
//!   bursty loss, reordering, duplication, range, partitions) for sim-time teams.
//! - [`transport`]: the runtime-free [`transport::PacketTransport`] trait an
//!   executor hands frames to; [`zenoh`] (feature `zenoh`, default on) implements
//!   it over zenoh sessions for separate processes and hosts.
//!
//! ```
//! use troupe_comms::wire::{self, Envelope, Odometry, Payload};
//! let envelope = Envelope::new(1, 0, 42, 1_000_000_000, Payload::Odometry(Odometry {
//!     position_m: [1.0, 2.0, 0.5],
//!     orientation_xyzw: [0.0, 0.0, 0.0, 1.0],
//!     velocity_mps: [0.5, 0.0, 0.0],
//! }));
//! let bytes = wire::encode(&envelope).unwrap();
//! assert_eq!(wire::decode(&bytes).unwrap(), envelope);
//! ```
#![deny(missing_docs)]

pub mod journal;
pub mod scope;
pub mod shaping;
pub mod simnet;
pub mod transport;
pub mod wire;
#[cfg(feature = "zenoh")]
pub mod zenoh;
