//! troupe-tests: end-to-end tests across crates (see `tests/`), and the home of the
//! workspace examples (`examples/` at the repository root).
//!
//! The tests drive whole teams through the public APIs of every crate, the way a user
//! would: assemble a scenario's team, add their own actors, run, read the results.
//!
//! ```
//! use std::sync::atomic::{AtomicU64, Ordering};
//! use std::sync::Arc;
//! use troupe_actors::msgs::ODOMETRY;
//! use troupe_runtime::{Actor, ActorResult, ActorSpec, Context, Event, QueuePolicy};
//! use troupe_sims::{scenario::Scenario, team::Team};
//!
//! /// Counts the odometry messages its robot publishes.
//! struct Count(Arc<AtomicU64>);
//! impl Actor for Count {
//!     fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
//!         ctx.subscribe(&ODOMETRY, QueuePolicy::fifo(64));
//!         Ok(())
//!     }
//!     fn handle(&mut self, _: &Event, _: &mut Context<'_>) -> ActorResult {
//!         self.0.fetch_add(1, Ordering::Relaxed);
//!         Ok(())
//!     }
//! }
//!
//! let mut scenario = Scenario::default();
//! (scenario.robots, scenario.duration_s) = (1, 1.0);
//! let seen = Arc::new(AtomicU64::new(0));
//! let counter = seen.clone();
//! let team = Team::new_with(&scenario, move |_, robot| {
//!     let counter = counter.clone();
//!     robot.add(ActorSpec::new("count", move || Count(counter.clone())));
//! })?;
//! team.run(|_| {});
//! assert!(seen.load(Ordering::Relaxed) >= 5, "the vehicle publishes odometry");
//! # Ok::<(), troupe_robot::AssembleError>(())
//! ```
#![deny(missing_docs)]
