//! User payload: a message of a type the wire format does not know, sent by a
//! custom actor through a shared topic (`troupe_actors::link::SharedTopic`).
//!
//! The wire carries the topic's registered name, the schema version of its type,
//! an optional addressee and the type's own postcard bytes; the receiving link
//! looks the name up among its registrations and decodes the bytes there, so an
//! unknown name, another version or undecodable bytes are rejected and counted
//! per name, never a panic.
//!
//! Size: 1 (class) + varint(name length) + name + 2 (`version`, fixed) + 1 or 5
//! (`to`) + varint(body length) + body bytes; a 20-byte report on the 16-byte
//! name `artifacts/report` is 1 + 1 + 16 + 2 + 1 + 1 + 20 = 42 bytes.

use serde::{Deserialize, Serialize};

use super::{Class, ContentError};

/// Longest shared-topic name accepted, bytes.
pub const MAX_USER_NAME_BYTES: usize = 64;

/// A message on a shared topic.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct UserMessage {
    /// Traffic class the topic travels in (from its share policy).
    pub class: Class,
    /// The shared topic's name: 1 to [`MAX_USER_NAME_BYTES`] bytes of ASCII
    /// letters, digits and `/ _ - .`.
    pub name: String,
    /// Schema version of the topic's type; a receiver accepts only its own.
    #[serde(with = "postcard::fixint::le")]
    pub version: u16,
    /// The one robot it is for; `None` = every peer.
    pub to: Option<u32>,
    /// The message, postcard-encoded by the sender's type.
    pub body: Vec<u8>,
}

/// Whether `name` is acceptable as a shared-topic name (see [`UserMessage::name`]).
#[must_use]
pub fn valid_user_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= MAX_USER_NAME_BYTES
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'/' | b'_' | b'-' | b'.'))
}

impl UserMessage {
    pub(super) fn validate(&self) -> Result<(), ContentError> {
        if valid_user_name(&self.name) {
            Ok(())
        } else {
            Err(ContentError::Message(
                "user message name is empty, longer than 64 bytes, or not ASCII letters, digits and / _ - .",
            ))
        }
    }
}
