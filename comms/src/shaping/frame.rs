//! Frames: what the shaper hands to a transport, one datagram each.
//!
//! Fixed little-endian layout, parsed without allocation:
//!
//! | bytes | data frame | ack frame |
//! |---|---|---|
//! | 0 | kind `0` | kind `1` |
//! | 1 | class (0 = odometry … 3 = bulk) | count `n` (u16, bytes 1–2) |
//! | 2 | flags (bit 0: acknowledge me) | |
//! | 3–6 | message id (u32) | `n` message ids (u32 each) from byte 3 |
//! | 7–8 | fragment index (u16) | |
//! | 9–10 | fragment count (u16, ≥ 1) | |
//! | 11… | fragment payload | |

use thiserror::Error;

use crate::wire::Class;

/// Bytes of a data frame's header.
pub const DATA_HEADER_BYTES: usize = 11;
/// Bytes of an ack frame's header (kind + count).
pub const ACK_HEADER_BYTES: usize = 3;

const KIND_DATA: u8 = 0;
const KIND_ACK: u8 = 1;
const FLAG_ACK_REQUESTED: u8 = 1;

/// One datagram produced by [`LinkShaper::poll`](super::LinkShaper::poll).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Frame {
    /// Class it was scheduled in (acks travel first, reported as odometry).
    pub class: Class,
    /// What it carries.
    pub kind: FrameKind,
    /// Recipient: `None` = every peer (broadcast), `Some(p)` = peer `p` only
    /// (acknowledgements, and store-and-forward fragments while peers' cursors
    /// differ). The transport must not deliver a `Some(p)` frame to anyone else.
    pub to: Option<u32>,
    /// The bytes to send, header included.
    pub bytes: Vec<u8>,
}

/// What a frame carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameKind {
    /// A fragment of a message.
    Data {
        /// Per-link message id.
        message_id: u32,
        /// Fragment index.
        index: u16,
        /// Number of fragments of the message.
        count: u16,
    },
    /// Acknowledgements of store-and-forward messages.
    Ack {
        /// How many ids it carries.
        ids: u16,
    },
}

/// A parsed data-frame header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DataHeader {
    /// Traffic class.
    pub class: Class,
    /// The sender wants an acknowledgement when the message is complete.
    pub ack_requested: bool,
    /// Per-link message id.
    pub message_id: u32,
    /// Fragment index, `< count`.
    pub index: u16,
    /// Fragment count, ≥ 1.
    pub count: u16,
}

/// A parsed frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParsedFrame<'a> {
    /// A message fragment.
    Data(DataHeader, &'a [u8]),
    /// Acknowledged ids, as little-endian `u32`s (see [`ack_ids`]).
    Ack(&'a [u8]),
}

/// Why bytes are not a frame.
#[derive(Clone, Copy, Debug, Error, PartialEq, Eq)]
pub enum FrameError {
    /// Fewer bytes than the header needs.
    #[error("frame of {0} bytes is shorter than its header")]
    Truncated(usize),
    /// Unknown frame kind.
    #[error("unknown frame kind {0}")]
    UnknownKind(u8),
    /// Unknown traffic class.
    #[error("unknown traffic class {0}")]
    UnknownClass(u8),
    /// Fragment count 0 or index ≥ count.
    #[error("fragment {index} of {count} is out of range")]
    BadFragment {
        /// Index in the header.
        index: u16,
        /// Count in the header.
        count: u16,
    },
    /// An ack frame whose length does not match its count.
    #[error("ack frame length does not match its count")]
    BadAck,
    /// A fragment that disagrees with earlier fragments of the same message.
    #[error("fragment disagrees with earlier fragments of message {0}")]
    Inconsistent(u32),
}

fn class_from(b: u8) -> Result<Class, FrameError> {
    Class::ALL
        .get(usize::from(b))
        .copied()
        .ok_or(FrameError::UnknownClass(b))
}

pub(crate) fn data_frame(header: &DataHeader, chunk: &[u8]) -> Vec<u8> {
    let mut b = Vec::with_capacity(DATA_HEADER_BYTES + chunk.len());
    b.push(KIND_DATA);
    b.push(header.class.index() as u8);
    b.push(if header.ack_requested {
        FLAG_ACK_REQUESTED
    } else {
        0
    });
    b.extend_from_slice(&header.message_id.to_le_bytes());
    b.extend_from_slice(&header.index.to_le_bytes());
    b.extend_from_slice(&header.count.to_le_bytes());
    b.extend_from_slice(chunk);
    b
}

pub(crate) fn ack_frame(ids: &[u32]) -> Vec<u8> {
    let mut b = Vec::with_capacity(ACK_HEADER_BYTES + 4 * ids.len());
    b.push(KIND_ACK);
    b.extend_from_slice(&(ids.len() as u16).to_le_bytes());
    for id in ids {
        b.extend_from_slice(&id.to_le_bytes());
    }
    b
}

/// Parses a frame's header; never panics.
pub fn parse(bytes: &[u8]) -> Result<ParsedFrame<'_>, FrameError> {
    let Some((&kind, rest)) = bytes.split_first() else {
        return Err(FrameError::Truncated(0));
    };
    match kind {
        KIND_DATA => {
            let Some((h, chunk)) = bytes.split_first_chunk::<DATA_HEADER_BYTES>() else {
                return Err(FrameError::Truncated(bytes.len()));
            };
            let class = class_from(h[1])?;
            let message_id = u32::from_le_bytes([h[3], h[4], h[5], h[6]]);
            let index = u16::from_le_bytes([h[7], h[8]]);
            let count = u16::from_le_bytes([h[9], h[10]]);
            if count == 0 || index >= count {
                return Err(FrameError::BadFragment { index, count });
            }
            Ok(ParsedFrame::Data(
                DataHeader {
                    class,
                    ack_requested: h[2] & FLAG_ACK_REQUESTED != 0,
                    message_id,
                    index,
                    count,
                },
                chunk,
            ))
        }
        KIND_ACK => {
            let Some((n, ids)) = rest.split_first_chunk::<2>() else {
                return Err(FrameError::Truncated(bytes.len()));
            };
            if ids.len() != 4 * usize::from(u16::from_le_bytes(*n)) {
                return Err(FrameError::BadAck);
            }
            Ok(ParsedFrame::Ack(ids))
        }
        other => Err(FrameError::UnknownKind(other)),
    }
}

/// The class a frame travels in: its header's, and odometry for acks (the
/// shaper's first class, which schedules them).
pub fn class_of(bytes: &[u8]) -> Result<Class, FrameError> {
    Ok(match parse(bytes)? {
        ParsedFrame::Data(header, _) => header.class,
        ParsedFrame::Ack(_) => Class::Odometry,
    })
}

/// The ids of an ack frame's body (from [`ParsedFrame::Ack`]).
pub fn ack_ids(body: &[u8]) -> impl Iterator<Item = u32> + '_ {
    body.chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
}
