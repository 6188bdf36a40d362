//! The CDR codec: the 4-byte encapsulation header ROS 2 puts before every payload,
//! then the message in OMG CDR (XCDR1) through `cdr-encoding`.
//!
//! Decoding never panics: hostile bytes (a truncated buffer, a sequence length that
//! runs past the end, a bad boolean, an unknown encapsulation) become a
//! [`CdrError`]. Payloads larger than [`MAX_PAYLOAD_BYTES`] are refused before any
//! decoding, so a hostile peer cannot make us allocate more than that.

use byteorder::{BigEndian, LittleEndian};
use cdr_encoding::{from_bytes, to_vec};
use serde::Serialize;
use serde::de::DeserializeOwned;

/// The largest payload we decode (a 1280×720 32FC1 image is 3.7 MB; a dense
/// 848×480 point cloud with 32-byte points is 13 MB).
pub const MAX_PAYLOAD_BYTES: usize = 64 << 20;

/// Padding bytes an encoder may leave after the last field (some pad the payload
/// to a multiple of 4 or 8); more left over is an error.
const MAX_TRAILING_BYTES: usize = 7;

/// Encapsulation header of little-endian plain CDR (`CDR_LE`).
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// Why a payload could not be encoded or decoded.
#[derive(Debug, thiserror::Error)]
pub enum CdrError {
    /// Shorter than the encapsulation header.
    #[error("payload of {0} bytes is shorter than the 4-byte CDR encapsulation header")]
    NoHeader(usize),
    /// Not plain CDR (e.g. a parameter list or XCDR2).
    #[error("unsupported CDR encapsulation {0:#06x} (expected plain CDR, 0x0000 or 0x0001)")]
    Encapsulation(u16),
    /// Over [`MAX_PAYLOAD_BYTES`].
    #[error("payload of {0} bytes exceeds the {MAX_PAYLOAD_BYTES}-byte limit")]
    TooLarge(usize),
    /// The bytes do not hold the expected message.
    #[error("malformed {type_name} payload")]
    Malformed {
        /// The ROS type expected.
        type_name: &'static str,
        /// What the CDR decoder said.
        #[source]
        source: cdr_encoding::Error,
    },
    /// Bytes left over after the message.
    #[error("{type_name} payload has {extra} bytes after the message")]
    TrailingBytes {
        /// The ROS type expected.
        type_name: &'static str,
        /// How many bytes were left.
        extra: usize,
    },
    /// The message could not be encoded.
    #[error("cannot encode a {type_name}")]
    Encode {
        /// The ROS type.
        type_name: &'static str,
        /// What the CDR encoder said.
        #[source]
        source: cdr_encoding::Error,
    },
}

/// A ROS 2 message type with its interface name and type hash.
pub trait RosMessage: Serialize + DeserializeOwned {
    /// Interface name, e.g. `sensor_msgs/msg/Image`.
    const TYPE_NAME: &'static str;
    /// The RIHS01 type hash (`RIHS01_` + 64 hex digits) of the type description.
    const TYPE_HASH: &'static str;
}

/// Encodes a message as little-endian CDR with its encapsulation header.
pub fn encode<T: RosMessage>(message: &T) -> Result<Vec<u8>, CdrError> {
    let body = to_vec::<T, LittleEndian>(message).map_err(|source| CdrError::Encode {
        type_name: T::TYPE_NAME,
        source,
    })?;
    let mut out = Vec::with_capacity(body.len() + 4);
    out.extend_from_slice(&CDR_LE_HEADER);
    out.extend_from_slice(&body);
    Ok(out)
}

/// Decodes a message from CDR with its encapsulation header (either byte order).
pub fn decode<T: RosMessage>(bytes: &[u8]) -> Result<T, CdrError> {
    if bytes.len() > MAX_PAYLOAD_BYTES {
        return Err(CdrError::TooLarge(bytes.len()));
    }
    let (header, body) = match bytes.split_first_chunk::<4>() {
        Some((header, body)) => (header, body),
        None => return Err(CdrError::NoHeader(bytes.len())),
    };
    let (message, used) = match [header[0], header[1]] {
        [0x00, 0x01] => from_bytes::<T, LittleEndian>(body),
        [0x00, 0x00] => from_bytes::<T, BigEndian>(body),
        id => return Err(CdrError::Encapsulation(u16::from_be_bytes(id))),
    }
    .map_err(|source| CdrError::Malformed {
        type_name: T::TYPE_NAME,
        source,
    })?;
    let extra = body.len().saturating_sub(used);
    if extra > MAX_TRAILING_BYTES {
        return Err(CdrError::TrailingBytes {
            type_name: T::TYPE_NAME,
            extra,
        });
    }
    Ok(message)
}
