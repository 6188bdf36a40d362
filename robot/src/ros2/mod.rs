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

use troupe_comms::transport::TransportError;

use crate::ConfigError;

pub mod attachment;
pub mod cdr;
mod config;
pub mod convert;
mod inputs;
pub mod keyexpr;
pub mod msgs;
mod outputs;

pub use attachment::Attachment;
pub use cdr::{CdrError, RosMessage};
pub use config::{Extrinsics, Ros2Config, Ros2Topics};
pub use inputs::{InputStats, OdometryInput, Ros2FrameSource, Ros2Inputs};
pub use keyexpr::{BridgeNamespace, KeyFormat, NamespaceError, TopicNameError, WireFormat};
pub use outputs::{OutputStats, Ros2Outputs, Ros2Publisher};

/// Why the ROS 2 drivers could not start.
#[derive(Debug, thiserror::Error)]
pub enum Ros2Error {
    /// A value of the `[ros2]` table breaks a rule (the key is relative to the table).
    #[error("invalid `[ros2]` table")]
    Config(#[from] ConfigError),
    /// The `[ros2.zenoh]` table is invalid.
    #[error("invalid `[ros2.zenoh]` table")]
    ZenohSettings(#[source] TransportError),
    /// A topic name cannot be put on zenoh.
    #[error(transparent)]
    TopicName(#[from] TopicNameError),
    /// zenoh refused something.
    #[error("zenoh: {context}")]
    Zenoh {
        /// What we were doing.
        context: String,
        /// zenoh's error.
        #[source]
        source: zenoh::Error,
    },
    /// A configured input topic delivered nothing in time.
    #[error(
        "ROS 2 topic `{topic}` (zenoh key `{key}`) sent nothing within {timeout_s} s: check the \
         topic name, `format`, `domain_id`, `bridge_namespace` and the zenoh endpoints"
    )]
    TopicSilent {
        /// The topic.
        topic: String,
        /// The key subscribed to.
        key: String,
        /// The startup timeout, seconds.
        timeout_s: f64,
    },
    /// The publishing thread could not start.
    #[error("cannot start the ROS 2 publishing thread")]
    Thread(#[source] std::io::Error),
}

/// The largest ROS 2 message the session accepts when `[ros2.zenoh]` does not set
/// `max_message_bytes`: a 1280 × 720 32FC1 depth image is 3.7 MB and a point cloud can
/// be larger, far above the team link's default (sized for link frames).
pub const ROS2_DEFAULT_MAX_MESSAGE_BYTES: usize = 64 * 1024 * 1024;

/// Opens the zenoh session of the `[ros2]` table (its `zenoh` endpoints).
pub fn open_session(config: &Ros2Config) -> Result<zenoh::Session, Ros2Error> {
    config.validate()?;
    let mut zenoh = config.zenoh.clone();
    if zenoh.max_message_bytes == 0 {
        zenoh.max_message_bytes = ROS2_DEFAULT_MAX_MESSAGE_BYTES;
    }
    let zenoh_config = zenoh.to_zenoh().map_err(Ros2Error::ZenohSettings)?;
    zenoh::Wait::wait(zenoh::open(zenoh_config)).map_err(|source| Ros2Error::Zenoh {
        context: "opening the session".into(),
        source,
    })
}
