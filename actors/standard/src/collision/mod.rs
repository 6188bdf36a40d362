//! The collision actor (thesis §7, §8.2.3); the collision cores are
//! [`troupe_algorithms::collision`].
//!
//! - [`CollisionActor`]: commits the first of a planning round's candidates that is
//!   clear of the local grid's unsafe space, of higher-priority peers and inside the
//!   geofence, or the stop.
//! - [`OperatorActor`]: the base station's hold / resume / velocity commands for this
//!   robot (issue 17).

mod actor;
mod operator;

pub use actor::{
    COLLISION_STATUS, CollisionActor, CollisionActorConfig, CollisionStatus, clear_of_unsafe_space,
    within_geofence,
};
pub use operator::{
    BASE_COMMAND, BaseCommand, CommandParseError, OPERATOR_HOLD, OperatorActor, OperatorCommand,
    OperatorHold,
};
