//! ROS 2 drivers over zenoh: a hardware robot's depth camera and odometry in, its
//! plan, map and status out.
//!
//! ROS 2 reaches zenoh in one of two ways, chosen by [`Ros2Config::format`]:
//! rmw_zenoh (ROS 2's zenoh middleware) or zenoh-bridge-ros2dds in front of a DDS
//! robot. [`keyexpr`] maps topics to keys for both; payloads are CDR ([`cdr`],
//! [`msgs`]); rmw_zenoh samples carry an [`Attachment`].
//!
//! | part | job |
//! |---|---|
//! | [`msgs`], [`cdr`] | the ROS message types and their CDR codec |
//! | [`keyexpr`], [`attachment`] | zenoh keys and rmw_zenoh's per-sample metadata |
//! | [`convert`] | ROS ↔ troupe conversions (frames, pixels, stamps) |
//! | [`Ros2Config`] | the `[ros2]` table of a hardware robot file |
//! | [`Ros2Inputs`] | zenoh subscribers → [`Ros2FrameSource`] and [`OdometryInput`] |
//! | [`Ros2Outputs`] | plan, keyframe map and status → ROS topics |
//!
//! See `docs/hardware-ros2.md` for a robot file.

pub mod attachment;
pub mod cdr;
mod config;
pub mod convert;
pub mod keyexpr;
pub mod msgs;

pub use attachment::Attachment;
pub use cdr::{CdrError, RosMessage};
pub use config::{Extrinsics, Ros2Config, Ros2ConfigError, Ros2Topics};
pub use keyexpr::{KeyFormat, WireFormat};
