//! The collision actor (thesis §7, §8.2.3); the collision cores are
//! [`troupe_algorithms::collision`], re-exported here.
//!
//! - [`CollisionActor`]: commits the first of a planning round's candidates that is
//!   clear of the local grid's unsafe space and of higher-priority peers, or the stop.

mod actor;

pub use actor::{
    COLLISION_STATUS, CollisionActor, CollisionActorConfig, CollisionStatus, clear_of_unsafe_space,
};
pub use troupe_algorithms::collision::*;
