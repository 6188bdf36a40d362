//! The local grid actor and the occupancy-grid map sharing it can do.
//!
//! - [`GridActor`]: keeps a [`LocalGrid`](troupe_algorithms::grid::LocalGrid) centred
//!   on the robot and publishes snapshots (the grid core is
//!   [`troupe_algorithms::grid`]).
//! - [`changeset`]: occupancy-grid map sharing (the thesis' OG baseline, §8.2.5).

mod actor;
pub mod changeset;

pub use actor::GridActor;

#[cfg(test)]
mod hca_actor_tests;
#[cfg(test)]
mod meter_tests;
#[cfg(test)]
mod view_once_tests;
