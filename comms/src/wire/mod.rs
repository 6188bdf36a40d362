//! The wire format: a versioned [`Envelope`] around a [`Payload`], postcard-encoded.
//!
//! Decoding never panics: bad input is a [`DecodeError`] that says why, and the
//! caller counts and drops it.

mod odometry;

use serde::{Deserialize, Serialize};
use thiserror::Error;

pub use odometry::Odometry;

/// Version of the wire format. Receivers reject envelopes of any other version.
pub const FORMAT_VERSION: u16 = 1;

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
}

impl Payload {
    /// The traffic class this payload travels in.
    #[must_use]
    pub fn class(&self) -> Class {
        match self {
            Payload::Odometry(_) | Payload::Heartbeat(_) => Class::Odometry,
        }
    }

    fn validate(&self) -> Result<(), DecodeError> {
        match self {
            Payload::Odometry(o) => o.validate(),
            Payload::Heartbeat(h) if !(h.uptime_s.is_finite() && h.uptime_s >= 0.0) => Err(
                DecodeError::Invalid("heartbeat uptime is not a finite number ≥ 0"),
            ),
            Payload::Heartbeat(_) => Ok(()),
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
    /// Per-sender sequence number.
    pub sequence: u64,
    /// Traffic class (derived from the payload).
    pub class: Class,
    /// Sender's clock (sim or wall time of its run), nanoseconds.
    pub stamp_ns: u64,
    /// The message.
    pub payload: Payload,
}

impl Envelope {
    /// An envelope of the current format version; the class follows the payload.
    #[must_use]
    pub fn new(team: u32, sender: u32, sequence: u64, stamp_ns: u64, payload: Payload) -> Self {
        Envelope {
            version: FORMAT_VERSION,
            team,
            sender,
            sequence,
            class: payload.class(),
            stamp_ns,
            payload,
        }
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
    Invalid(&'static str),
}

/// Why an envelope could not be encoded.
#[derive(Debug, Error)]
#[error("cannot encode message: {0}")]
pub struct EncodeError(#[from] postcard::Error);

/// Encodes an envelope.
pub fn encode(envelope: &Envelope) -> Result<Vec<u8>, EncodeError> {
    Ok(postcard::to_allocvec(envelope)?)
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
    envelope.payload.validate()?;
    Ok(envelope)
}

#[cfg(test)]
mod tests;
