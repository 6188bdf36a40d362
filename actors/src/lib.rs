//! troupe-actors: the actor runtime and the standard actors of a troupe robot.
//!
//! The [`runtime`] module is the message-passing core every robot runs on: write an
//! [`Actor`](runtime::Actor), describe a robot as a [`RobotSpec`](runtime::RobotSpec),
//! and run a team under the deterministic [`SimExecutor`](runtime::SimExecutor) or the
//! real-time [`RealtimeExecutor`](runtime::RealtimeExecutor).
#![deny(missing_docs)]

pub mod runtime;
