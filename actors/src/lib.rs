//! troupe-actors: the actor runtime and the standard actors of a troupe robot.
//!
//! - [`runtime`]: the message-passing core every robot runs on. Write an
//!   [`Actor`](runtime::Actor), describe a robot as a [`RobotSpec`](runtime::RobotSpec),
//!   and run a team under the deterministic [`SimExecutor`](runtime::SimExecutor) or
//!   the real-time [`RealtimeExecutor`](runtime::RealtimeExecutor).
//! - [`msgs`]: the standard topics and message types.
//! - [`mapper`]: map models fitted to depth + intensity frames (SOGMM, thesis §6).
//! - [`collision`]: ellipsoid distance, gradient and collision probability against
//!   Gaussian surface models (thesis §7).
//! - Standard actors: [`sensor`], [`explorer`], [`link`].
//! - [`trajectory`]: sampled trajectories that plans carry.
#![deny(missing_docs)]

pub mod collision;
pub mod explorer;
pub mod geometry;
pub mod grid;
pub mod link;
pub mod mapper;
pub mod msgs;
pub mod planner;
pub mod runtime;
pub mod sensor;
pub mod trajectory;
