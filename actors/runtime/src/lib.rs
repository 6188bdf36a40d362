//! troupe-runtime: the actor runtime every troupe robot runs on.
//!
//! Actors, topics, queues, supervision and the two executors; what a custom actor
//! needs and nothing more (no algorithms, no robot assembly).
//!
//! - [`Actor`] is the one trait a behaviour implements; [`Context`] is what a hook
//!   may do (publish, subscribe, set timers, read the time).
//! - [`Topic`] names a typed, robot-local stream of shared ([`Arc`](std::sync::Arc))
//!   messages; each subscription has a bounded queue with a [`QueuePolicy`] and drop
//!   counters.
//! - [`ActorSpec`] and [`RobotSpec`] describe a robot; [`SimExecutor`] runs a team in
//!   deterministic simulated time, [`RealtimeExecutor`] on tokio against the wall clock.
//! - Panics are contained and supervised per [`RestartPolicy`].

mod actor;
mod context;
mod inputs;
mod network;
mod queue;
mod realtime;
mod registry;
mod sim;
mod slot;
mod spec;
mod stats;
mod tap;

pub use actor::{Actor, ActorError, ActorResult, Event};
pub use context::{Context, TimerId};
pub use network::{
    Destination, IdealNetwork, LINK_RX, LINK_TRANSPORT, LINK_TX, LinkRx, LinkTx, SimNetwork,
};
pub use queue::QueuePolicy;
pub use realtime::{RealtimeExecutor, RealtimeHandle, RobotIdsError};
pub use sim::SimExecutor;
pub use spec::{ActorFactory, ActorOptions, ActorSpec, LatencyModel, RestartPolicy, RobotSpec};
pub use stats::{
    ActorReport, ActorStats, LatencyHistogram, LatencySummary, RobotReport, TopicStats,
};
pub use tap::{Publication, Tap};
pub use topic::{Payload, Received, Topic};
pub use troupe_core::{ConfigError, ErrorChain, Message, RobotId, Time};

mod topic;

#[cfg(test)]
mod tests;
