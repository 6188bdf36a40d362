//! Hardware safety as plain types, apart from any actor or wire protocol.
//!
//! - [`Watchdog`]: notices when an input (depth frames, odometry, the autopilot's
//!   heartbeat) stops arriving, reports the loss once and the recovery once.
//! - [`Geofence`]: an axis-aligned box in the world frame (ENU) that no setpoint may
//!   leave, with a check of whole trajectories (defined with the collision cores,
//!   `troupe_algorithms::collision::geofence`, whose collision actor checks plans against
//!   the same box before committing them).
//! - [`SetpointGuard`]: combines them with the committed plan into the one setpoint a
//!   vehicle driver may stream at each tick (track, hold, or nothing).
//!
//! A vehicle driver (the MAVLink vehicle, [`crate::mavlink`]) combines them: a stale
//! input makes it hold still, a lost heartbeat makes it stop streaming, and a setpoint
//! outside the fence is replaced by a hold inside it.

mod guard;
mod watchdog;

pub use guard::{
    GuardConfig, GuardCounters, GuardInput, HoldReason, RESUME_TOLERANCE_M, Reference, Setpoint,
    SetpointGuard, reference_at,
};
pub use troupe_algorithms::collision::geofence::{
    Geofence, GeofenceConfig, GeofenceError, GeofenceViolation,
};
pub use watchdog::{Watchdog, WatchdogChange};
