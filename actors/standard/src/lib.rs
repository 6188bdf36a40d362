//! troupe-actors: the standard actors of a troupe robot.
//!
//! Each actor is a thin wrapper that connects an algorithm core of
//! [`troupe_algorithms`] to the robot's topics on the [`troupe_runtime`] executors:
//!
//! - [`msgs`]: the standard topics and their message types (the data flow of a robot).
//! - [`sensor`]: captures depth frames from a [`FrameSource`](sensor::FrameSource).
//! - [`vehicle`]: the robot's `vehicle` actor around a [`Vehicle`](vehicle::Vehicle)
//!   driver (follows the committed plan, publishes odometry).
//! - [`mapper`]: keyframe selection and SOGMM fits (thesis §6, §8.2.2).
//! - [`grid`]: the local occupancy grid (§3.2.3) and occupancy-grid map sharing.
//! - [`planner`]: the motion-primitive planner (§4) and teleoperation (§5.1.2).
//! - [`collision`]: commits plans clear of unsafe space and higher-priority peers (§8.2.3).
//! - [`explorer`]: route behaviours chosen by name.
//! - [`link`]: the only actor that talks to other robots.
//!
//! One import path for every type: this crate re-exports nothing of the crates below
//! it; name the runtime's types from [`troupe_runtime`] and the algorithm cores (grid,
//! planner, collision, map models, message types) from [`troupe_algorithms`].
//!
//! ```
//! use troupe_actors::grid::GridActor;
//! use troupe_algorithms::grid::GridConfig;
//! use troupe_actors::msgs::GRID_SNAPSHOT;
//! use troupe_runtime::{ActorSpec, RobotSpec, SimExecutor, Time};
//!
//! // A robot with only a grid actor: with no odometry it publishes nothing.
//! let robot = RobotSpec::new("r0").with(ActorSpec::new("grid", || GridActor::new(GridConfig::default())));
//! let mut team = SimExecutor::new(vec![robot], 1);
//! team.run_until(Time::from_secs_f64(2.0));
//! assert_eq!(GRID_SNAPSHOT.name(), "grid/snapshot");
//! ```
#![deny(missing_docs)]

pub mod artifacts;
pub mod collision;
pub mod explorer;
pub mod grid;
pub mod link;
pub mod mapper;
pub mod msgs;
pub mod planner;
pub mod sensor;
pub mod vehicle;
