//! The wire format: a versioned [`Envelope`] around a [`Payload`], postcard-encoded.
//!
//! Decoding never panics: bad input is a [`DecodeError`] that says why, and the
//! caller counts and drops it. Encoding refuses content a receiver would refuse
//! ([`EncodeError::Invalid`]), so garbage never costs link bandwidth.
//!
//! One module per message class: [`Odometry`] (10 Hz, §8.2.3), [`Plan`]
//! (committed trajectory + priority, §8.2.3), [`Keyframe`] (GMM + sensor pose +
//! support size, §8.2.2; exact or [compact](Mixture::compact)), and
//! [`GridChangeSet`] (the occupancy-grid baseline of §8.2.5), and [`UserMessage`]
//! (a custom actor's type on a shared topic, in the class its policy names). Each
//! module's docs give its exact encoded size.
//!
//! Postcard is positional: the order of fields and of [`Payload`] variants is the
//! protocol. New variants go at the end; anything else bumps [`FORMAT_VERSION`].

mod check;
pub mod grid;
pub mod keyframe;
mod odometry;
pub mod plan;
pub mod user;

use serde::{Deserialize, Serialize};
use thiserror::Error;

pub use check::{QUATERNION_NORM_TOLERANCE, WEIGHT_SUM_TOLERANCE};
pub use grid::{CellChange, GridChangeSet, GridDims};
pub use keyframe::{
    CompactComponent3, CompactComponent4, Component3, Component4, Keyframe, Mixture, SensorPose,
};
pub use odometry::Odometry;
pub use plan::{Plan, PlanKnot};
pub use user::{MAX_USER_NAME_BYTES, UserMessage, valid_user_name};

/// Version of the wire format. Receivers reject envelopes of any other version.
///
/// Version 2 put stamps on the team clock (`troupe_core::TeamClock`: Unix time between
/// processes) and added [`Envelope::run_start_ns`]; version 1 stamped messages from
/// each process's own start, so they went backwards when a robot restarted.
pub const FORMAT_VERSION: u16 = 2;

/// Largest encoded envelope a receiver accepts, in bytes.
pub const MAX_MESSAGE_BYTES: usize = 4 * 1024 * 1024;

/// Traffic class, in strict priority order (lower value goes first on a shaped link).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub enum Class {
    /// Odometry and heartbeats (10 Hz, small).
    Odometry,
    /// Committed plans (1 Hz).
    Plan,
    /// Map keyframes.
    Keyframe,
    /// Everything else.
    Bulk,
}

impl Class {
    /// Every class, highest priority first.
    pub const ALL: [Class; 4] = [Class::Odometry, Class::Plan, Class::Keyframe, Class::Bulk];

    /// Position in [`Class::ALL`] (0 = highest priority).
    #[must_use]
    pub const fn index(self) -> usize {
        self as usize
    }
}

/// A robot is alive (sent when it has nothing else to say).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Heartbeat {
    /// Seconds since the robot started.
    pub uptime_s: f64,
}

/// What an envelope carries.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Payload {
    /// The sender's pose and velocity.
    Odometry(Odometry),
    /// Liveness.
    Heartbeat(Heartbeat),
    /// A keyframe GMM (class [`Class::Keyframe`]).
    Keyframe(Keyframe),
    /// A committed plan (class [`Class::Plan`]).
    Plan(Plan),
    /// An occupancy-grid change set, the map-sharing baseline; it competes with
    /// keyframes, so it travels in [`Class::Keyframe`] too.
    GridChanges(GridChangeSet),
    /// A custom actor's message on a shared topic; it travels in the class its
    /// share policy names ([`UserMessage::class`]).
    User(UserMessage),
}

impl Payload {
    /// The traffic class this payload travels in.
    #[must_use]
    pub fn class(&self) -> Class {
        match self {
            Payload::Odometry(_) | Payload::Heartbeat(_) => Class::Odometry,
            Payload::Plan(_) => Class::Plan,
            Payload::Keyframe(_) | Payload::GridChanges(_) => Class::Keyframe,
            Payload::User(u) => u.class,
        }
    }

    /// Checks the values (what [`decode`] checks after parsing, and [`encode`]
    /// before writing).
    pub fn validate(&self) -> Result<(), ContentError> {
        match self {
            Payload::Odometry(o) => o.validate(),
            Payload::Heartbeat(h) if !(h.uptime_s.is_finite() && h.uptime_s >= 0.0) => Err(
                ContentError::Message("heartbeat uptime is not a finite number ≥ 0"),
            ),
            Payload::Heartbeat(_) => Ok(()),
            Payload::Keyframe(k) => k.validate(),
            Payload::Plan(p) => p.validate(),
            Payload::GridChanges(g) => g.validate(),
            Payload::User(u) => u.validate(),
        }
    }
}

/// Header + payload of every message between robots. Field order is the protocol.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Envelope {
    /// Always [`FORMAT_VERSION`] when built by [`Envelope::new`].
    pub version: u16,
    /// Team id; a robot ignores other teams.
    pub team: u32,
    /// Sending robot's index in the team.
    pub sender: u32,
    /// When the sender's current run began, on the team clock, nanoseconds: it names
    /// the run, so a larger value than before announces that the sender restarted
    /// (0 in the simulator, where robots never restart their process).
    pub run_start_ns: u64,
    /// Per-sender sequence number.
    pub sequence: u64,
    /// Traffic class (derived from the payload).
    pub class: Class,
    /// When it was made, on the team clock (sim time in the simulator, Unix time
    /// between processes), nanoseconds; never before `run_start_ns`.
    pub stamp_ns: u64,
    /// The message.
    pub payload: Payload,
}

impl Envelope {
    /// An envelope of the current format version from a run that started at 0 on the
    /// team clock (the simulator's); the class follows the payload.
    #[must_use]
    pub fn new(team: u32, sender: u32, sequence: u64, stamp_ns: u64, payload: Payload) -> Self {
        Envelope {
            version: FORMAT_VERSION,
            team,
            sender,
            run_start_ns: 0,
            sequence,
            class: payload.class(),
            stamp_ns,
            payload,
        }
    }

    /// A message cannot be made before the run that made it.
    fn check_stamps(&self) -> Result<(), ContentError> {
        if self.stamp_ns < self.run_start_ns {
            return Err(ContentError::Message(
                "stamp is earlier than the start of the sender's run",
            ));
        }
        Ok(())
    }

    /// The same envelope from a run that started at `run_start_ns` on the team clock.
    #[must_use]
    pub fn from_run(mut self, run_start_ns: u64) -> Self {
        self.run_start_ns = run_start_ns;
        self
    }
}

/// Why bytes were not accepted as an envelope.
#[derive(Debug, Error, PartialEq)]
pub enum DecodeError {
    /// Empty input.
    #[error("empty message")]
    Empty,
    /// More than [`MAX_MESSAGE_BYTES`].
    #[error("message of {0} bytes exceeds the {MAX_MESSAGE_BYTES}-byte limit")]
    TooLarge(usize),
    /// A format version this build does not speak.
    #[error("unsupported wire format version {0} (this build speaks {FORMAT_VERSION})")]
    UnsupportedVersion(u16),
    /// Postcard could not decode it (truncated, bad variant, …).
    #[error("malformed message: {0}")]
    Malformed(#[from] postcard::Error),
    /// Bytes left over after a complete envelope.
    #[error("{0} trailing bytes after the message")]
    TrailingBytes(usize),
    /// The header's class does not match the payload.
    #[error("class {header:?} in the header does not match the payload's {payload:?}")]
    ClassMismatch {
        /// From the header.
        header: Class,
        /// From the payload.
        payload: Class,
    },
    /// Decoded, but the values are not acceptable (NaN, not normalised, …).
    #[error("invalid content: {0}")]
    Invalid(#[from] ContentError),
}

/// Why a payload's values are not acceptable; shared by [`decode`] and [`encode`].
#[derive(Clone, Copy, Debug, Error, PartialEq, Eq)]
pub enum ContentError {
    /// A property of the whole message.
    #[error("{0}")]
    Message(&'static str),
    /// A property of one element of a list (component, knot, cell).
    #[error("element {index}: {reason}")]
    Element {
        /// Position in its list.
        index: usize,
        /// What is wrong with it.
        reason: &'static str,
    },
}

/// Why an envelope could not be encoded.
#[derive(Debug, Error)]
pub enum EncodeError {
    /// Postcard failed (should not happen for in-memory output).
    #[error("cannot encode message: {0}")]
    Postcard(#[from] postcard::Error),
    /// The content would be rejected by a receiver.
    #[error("refusing to encode invalid content: {0}")]
    Invalid(#[from] ContentError),
    /// The header's class does not match the payload (built without
    /// [`Envelope::new`]).
    #[error("class {header:?} in the header does not match the payload's {payload:?}")]
    ClassMismatch {
        /// From the header.
        header: Class,
        /// From the payload.
        payload: Class,
    },
    /// Encoded, but larger than [`MAX_MESSAGE_BYTES`].
    #[error("message of {0} bytes exceeds the {MAX_MESSAGE_BYTES}-byte limit")]
    TooLarge(usize),
}

/// Encodes an envelope, refusing content that [`decode`] would reject.
pub fn encode(envelope: &Envelope) -> Result<Vec<u8>, EncodeError> {
    let payload_class = envelope.payload.class();
    if envelope.class != payload_class {
        return Err(EncodeError::ClassMismatch {
            header: envelope.class,
            payload: payload_class,
        });
    }
    envelope.check_stamps()?;
    envelope.payload.validate()?;
    let bytes = postcard::to_allocvec(envelope)?;
    if bytes.len() > MAX_MESSAGE_BYTES {
        return Err(EncodeError::TooLarge(bytes.len()));
    }
    Ok(bytes)
}

/// Decodes and validates an envelope.
pub fn decode(bytes: &[u8]) -> Result<Envelope, DecodeError> {
    if bytes.is_empty() {
        return Err(DecodeError::Empty);
    }
    if bytes.len() > MAX_MESSAGE_BYTES {
        return Err(DecodeError::TooLarge(bytes.len()));
    }
    let (version, _) = postcard::take_from_bytes::<u16>(bytes)?;
    if version != FORMAT_VERSION {
        return Err(DecodeError::UnsupportedVersion(version));
    }
    let (envelope, rest) = postcard::take_from_bytes::<Envelope>(bytes)?;
    if !rest.is_empty() {
        return Err(DecodeError::TrailingBytes(rest.len()));
    }
    let payload_class = envelope.payload.class();
    if envelope.class != payload_class {
        return Err(DecodeError::ClassMismatch {
            header: envelope.class,
            payload: payload_class,
        });
    }
    envelope.check_stamps()?;
    envelope.payload.validate()?;
    Ok(envelope)
}

#[cfg(test)]
mod payload_tests;
#[cfg(test)]
mod tests;
#[cfg(test)]
mod testutil;
#[cfg(test)]
mod user_tests;
