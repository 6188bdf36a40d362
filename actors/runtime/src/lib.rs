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
//!
//! A custom actor depends on this crate alone:
//!
//! ```
//! use std::time::Duration;
//! use troupe_runtime::{
//!     Actor, ActorResult, ActorSpec, Context, Event, Message, QueuePolicy, RobotSpec, SimExecutor,
//!     Time, TimerId, Topic,
//! };
//!
//! struct Tick(u32);
//! impl Message for Tick {}
//! const TICKS: Topic<Tick> = Topic::new("ticks");
//!
//! /// Publishes a tick every 100 ms.
//! struct Clock(u32);
//! impl Actor for Clock {
//!     fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
//!         ctx.set_timer(TimerId(0), Duration::from_millis(100));
//!         Ok(())
//!     }
//!     fn handle(&mut self, _: &Event, ctx: &mut Context<'_>) -> ActorResult {
//!         self.0 += 1;
//!         ctx.publish(&TICKS, Tick(self.0));
//!         Ok(())
//!     }
//! }
//!
//! /// Counts what it receives.
//! struct Counter;
//! impl Actor for Counter {
//!     fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
//!         ctx.subscribe(&TICKS, QueuePolicy::fifo(16));
//!         Ok(())
//!     }
//!     fn handle(&mut self, _: &Event, _: &mut Context<'_>) -> ActorResult {
//!         Ok(())
//!     }
//! }
//!
//! let robot = RobotSpec::new("r0")
//!     .with(ActorSpec::new("clock", || Clock(0)))
//!     .with(ActorSpec::new("counter", || Counter));
//! let mut team = SimExecutor::new(vec![robot], 7);
//! team.run_until(Time::from_secs_f64(1.0));
//! let report = &team.reports()[0];
//! assert_eq!(report.topics["ticks"].messages, 10);
//! ```

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
pub use troupe_core::{ConfigError, ErrorChain, Message, RobotId, TeamClock, Time, TimeSource};

mod topic;

#[cfg(test)]
mod tests;
