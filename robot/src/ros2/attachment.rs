//! The attachment rmw_zenoh puts on every published sample (rmw_zenoh ≥ 0.6,
//! `docs/design.md` "Publishers"; the layout zenoh's `ext` serializer gives three
//! values): 33 bytes,
//!
//! | offset | bytes | field |
//! |---|---|---|
//! | 0 | 8 | sequence number, i64 little-endian, per publisher, from 1 |
//! | 8 | 8 | source timestamp, i64 little-endian, ns since the Unix epoch |
//! | 16 | 1 | length of the GID, always 16 (a LEB128 varint) |
//! | 17 | 16 | the publisher's GID |
//!
//! We encode it on what we publish and parse it on receipt; a sample without one,
//! or with one we cannot read, is still accepted (the bridge format has none), and
//! the failure is counted.

/// Bytes of an encoded attachment.
pub const ATTACHMENT_BYTES: usize = 33;

/// The publisher's global id.
pub type Gid = [u8; 16];

/// rmw_zenoh's per-sample metadata.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Attachment {
    /// Per-publisher sequence number (the first sample is 1).
    pub sequence_number: i64,
    /// Publication time, ns since the Unix epoch.
    pub source_timestamp_ns: i64,
    /// The publisher's id.
    pub source_gid: Gid,
}

/// An attachment that is not rmw_zenoh's.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum AttachmentError {
    /// Wrong length.
    #[error("rmw_zenoh attachment has {0} bytes, expected {ATTACHMENT_BYTES}")]
    Length(usize),
    /// The GID length prefix is not 16.
    #[error("rmw_zenoh attachment announces a {0}-byte GID, expected 16")]
    GidLength(u8),
}

impl Attachment {
    /// The 33 bytes of this attachment.
    #[must_use]
    pub fn encode(&self) -> [u8; ATTACHMENT_BYTES] {
        let mut out = [0; ATTACHMENT_BYTES];
        out[..8].copy_from_slice(&self.sequence_number.to_le_bytes());
        out[8..16].copy_from_slice(&self.source_timestamp_ns.to_le_bytes());
        out[16] = 16;
        out[17..].copy_from_slice(&self.source_gid);
        out
    }

    /// Parses an attachment.
    pub fn decode(bytes: &[u8]) -> Result<Self, AttachmentError> {
        let bytes: &[u8; ATTACHMENT_BYTES] = bytes
            .try_into()
            .map_err(|_| AttachmentError::Length(bytes.len()))?;
        if bytes[16] != 16 {
            return Err(AttachmentError::GidLength(bytes[16]));
        }
        let mut sequence = [0; 8];
        let mut stamp = [0; 8];
        let mut gid = [0; 16];
        sequence.copy_from_slice(&bytes[..8]);
        stamp.copy_from_slice(&bytes[8..16]);
        gid.copy_from_slice(&bytes[17..]);
        Ok(Attachment {
            sequence_number: i64::from_le_bytes(sequence),
            source_timestamp_ns: i64::from_le_bytes(stamp),
            source_gid: gid,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_is_two_little_endian_i64_then_a_length_prefixed_gid() {
        let a = Attachment {
            sequence_number: 1,
            source_timestamp_ns: 0x0102_0304_0506_0708,
            source_gid: [0xab; 16],
        };
        let bytes = a.encode();
        assert_eq!(&bytes[..8], &[1, 0, 0, 0, 0, 0, 0, 0]);
        assert_eq!(&bytes[8..16], &[8, 7, 6, 5, 4, 3, 2, 1]);
        assert_eq!(bytes[16], 16);
        assert_eq!(&bytes[17..], &[0xab; 16]);
        assert_eq!(Attachment::decode(&bytes), Ok(a));
    }

    #[test]
    fn foreign_attachments_are_errors() {
        assert_eq!(Attachment::decode(&[]), Err(AttachmentError::Length(0)));
        assert_eq!(
            Attachment::decode(&[0; 34]),
            Err(AttachmentError::Length(34))
        );
        assert_eq!(
            Attachment::decode(&[0; 33]),
            Err(AttachmentError::GidLength(0))
        );
    }
}
