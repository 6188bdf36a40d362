//! A vehicle driver for PX4 and ArduPilot flight controllers over MAVLink 2.
//!
//! [`MavlinkVehicle`] is the robot's vehicle driver on hardware (a
//! [`Vehicle`](troupe_actors::vehicle::Vehicle); the registry's `mavlink`, or build its
//! `vehicle` actor with [`mavlink_vehicle`] and hand it to
//! [`RobotParts::vehicle`](crate::RobotParts)):
//!
//! - it samples the committed plan (`plan/committed`) at `setpoint_rate_hz` (≥ 20 Hz;
//!   PX4 leaves offboard mode when setpoints arrive at under 2 Hz) and streams
//!   `SET_POSITION_TARGET_LOCAL_NED` (position, velocity, acceleration, yaw in
//!   `MAV_FRAME_LOCAL_NED`, converted from troupe's ENU by [`crate::frames`]);
//! - it reads `HEARTBEAT`, `LOCAL_POSITION_NED` and `ATTITUDE`, publishes `odometry`
//!   from them when the autopilot is the odometry source, and publishes
//!   [`AutopilotStatus`] on [`AUTOPILOT_STATUS`] (armed, mode, heartbeat age, why it
//!   holds, counters);
//! - a [`SetpointGuard`](crate::safety::SetpointGuard) decides every setpoint: hold
//!   still when depth frames or odometry stop, send nothing when the autopilot's
//!   heartbeat stops, never a setpoint outside the geofence;
//! - it **never arms the vehicle and never changes its mode**: the pilot arms and
//!   switches to offboard (PX4) or guided (ArduPilot); [`Outbound`] has no message
//!   that could do either.
//!
//! The wire runs on its own threads ([`MavlinkLink`]), joined to the actor by bounded
//! channels; the actor's handlers never wait on the connection.

mod config;
mod link;
mod setpoint;
mod status;
mod vehicle;

pub use crate::safety::GeofenceConfig;
pub use config::{
    MAX_SETPOINT_RATE_HZ, MIN_SETPOINT_RATE_HZ, MavlinkConfig, MavlinkSettings, OdometrySource,
};
pub use link::{
    INBOUND_CAPACITY, Inbound, LinkStats, MavlinkLink, OUTBOUND_CAPACITY, Outbound,
    RECONNECT_PERIOD,
};
pub use setpoint::{Target, full_state_mask, position_target};
pub use status::{
    AUTOPILOT_STATUS, AutopilotStatus, GaveUp, VehicleState, flight_mode, in_control, is_armed,
};
pub use vehicle::{MavlinkVehicle, mavlink_vehicle};
