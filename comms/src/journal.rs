//! A link's durable state on disk (issue 23): an fsync'd append-only log with a
//! CRC-32 per record, for robot processes that may be killed at any instant.
//!
//! What it keeps ([`Recovered`]): the shaper's [`DurableState`] — every accepted
//! store-and-forward message some recipient has not acknowledged, the recipients
//! and the next message id — the envelope sequence, and the store-and-forward
//! messages this robot *received* and acknowledged (so that a restarted robot
//! gets its team map back, and recognises resends of what it already holds).
//!
//! **Format.** The file starts with [`MAGIC`]; then records, each
//! `[len: u32 LE][crc32(payload): u32 LE][payload: postcard Record]`. Writing
//! appends the records of one change and calls `fsync` before returning, so a
//! caller that acknowledges a message after [`DiskJournal::record_received`]
//! returned never acknowledges something a crash can lose. Reading stops at the
//! first record that is short or fails its checksum — the torn tail of a write
//! cut by `kill -9` or a power loss — and truncates the file there: everything
//! before it was fsync'd, and nothing after it was promised to anyone. A change
//! cut in the middle reads back as a prefix of its records; releases are written
//! before additions, so that prefix holds every message that both the last synced
//! state and the state being synced hold.
//!
//! **Message ids** are reserved in blocks of [`ID_BLOCK`]: a record says "ids
//! from here on were never used", written before any id past the previous one is
//! handed out; a restart continues from it, so an id is never reused even if the
//! last messages before a crash were not journaled (at most a block is skipped).
//!
//! **Size.** When the file grows past twice what is live (plus 1 MiB), it is
//! rewritten with only the live records to a temporary file that is fsync'd and
//! renamed over it (then the directory is fsync'd). Received messages are kept
//! up to `max_received_bytes`; past it, the oldest message of the sender holding the
//! most bytes is dropped (and counted, [`DiskJournal::received_evicted`]), so one
//! member sending large messages evicts its own, never another member's, while it
//! holds more than they do.
//!
//! Why not an embedded database: the journal's records are a handful of kinds,
//! written in order by one writer; an append-only log with checksums is the
//! whole of what it needs, and it adds no dependency beyond `crc32fast`.

use std::collections::{BTreeMap, VecDeque};
use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::shaping::{DurableMessage, DurableState, LaneId, MessageId};
use crate::wire::Class;

/// The file's first bytes (format version 1).
pub const MAGIC: &[u8; 8] = b"TRPJRN01";
/// Message ids (and envelope sequence numbers) reserved per journal record.
pub const ID_BLOCK: u32 = 256;
/// The journal file's name in its directory.
pub const FILE_NAME: &str = "link.journal";
/// Largest record accepted when reading (a stored message is at most a few MiB).
const MAX_RECORD_BYTES: usize = 64 * 1024 * 1024;

/// Why the journal could not be opened or written.
#[derive(Debug, Error)]
pub enum JournalError {
    /// An I/O error on the journal file or its directory.
    #[error("journal {}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is not a link journal (its first bytes are not [`MAGIC`]).
    #[error("{} is not a troupe link journal (wrong header)", path.display())]
    NotAJournal {
        /// The file.
        path: PathBuf,
    },
    /// A record could not be serialised.
    #[error("encoding a journal record")]
    Encode(#[source] postcard::Error),
}

/// A store-and-forward message this robot received, validated and acknowledged.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ReceivedMessage {
    /// Its sender.
    pub source: u32,
    /// The sender's message id.
    pub id: u32,
    /// The encoded envelope.
    pub bytes: Arc<[u8]>,
}

/// What a journal held when it was opened.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Recovered {
    /// The shaper's state: `next_id` is the first id never handed out.
    pub state: DurableState,
    /// The first envelope sequence number never used.
    pub sequence: u64,
    /// Received messages, oldest first.
    pub received: Vec<ReceivedMessage>,
    /// Bytes of a torn or corrupt tail that were cut off.
    pub discarded_bytes: u64,
}

/// One journal record (postcard is positional: variant and field order are the
/// format).
#[derive(Debug, Serialize, Deserialize)]
enum Record {
    /// Message ids from this one on were never handed out.
    IdCeiling(u32),
    /// Envelope sequence numbers from this one on were never used.
    SequenceCeiling(u64),
    /// The store-and-forward recipients.
    Peers(Vec<u32>),
    /// An accepted store-and-forward message.
    Stored {
        class: Class,
        lane: Option<u16>,
        id: u32,
        offered_ns: u64,
        missing: Vec<u32>,
        bytes: Vec<u8>,
    },
    /// The recipients a stored message still misses changed.
    Missing { id: u32, missing: Vec<u32> },
    /// A stored message left the store.
    Released { id: u32 },
    /// A message received and acknowledged.
    Received {
        source: u32,
        id: u32,
        bytes: Vec<u8>,
    },
}

/// The journal file of one link. See the [module docs](self).
#[derive(Debug)]
pub struct DiskJournal {
    path: PathBuf,
    file: File,
    file_bytes: u64,
    id_ceiling: u32,
    sequence_ceiling: u64,
    peers: Vec<u32>,
    /// Stored messages as journaled, by id.
    stored: BTreeMap<u32, DurableMessage>,
    /// Their order (oldest first).
    stored_order: Vec<u32>,
    received: VecDeque<ReceivedMessage>,
    received_bytes: usize,
    /// Bytes of `received` per sender.
    received_bytes_by_source: BTreeMap<u32, usize>,
    max_received_bytes: usize,
    /// Received messages dropped for room since the journal was opened.
    received_evicted: u64,
}

fn io_error(path: &Path) -> impl FnOnce(std::io::Error) -> JournalError + '_ {
    move |source| JournalError::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn frame(record: &Record, out: &mut Vec<u8>) -> Result<(), JournalError> {
    let payload = postcard::to_allocvec(record).map_err(JournalError::Encode)?;
    out.extend_from_slice(&(payload.len() as u32).to_le_bytes());
    out.extend_from_slice(&crc32fast::hash(&payload).to_le_bytes());
    out.extend_from_slice(&payload);
    Ok(())
}

/// Whether `id` is at or past `ceiling` in wrapping order.
fn reached(id: u32, ceiling: u32) -> bool {
    id.wrapping_sub(ceiling) < u32::MAX / 2
}

impl DiskJournal {
    /// Opens (or creates) `dir/link.journal`, creating `dir`, and reads what it
    /// holds; a torn tail is cut off. A new journal's ids start at `first_id`.
    pub fn open(
        dir: &Path,
        first_id: u32,
        max_received_bytes: usize,
    ) -> Result<(DiskJournal, Recovered), JournalError> {
        std::fs::create_dir_all(dir).map_err(io_error(dir))?;
        let path = dir.join(FILE_NAME);
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(io_error(&path))?;
        let mut bytes = Vec::new();
        file.read_to_end(&mut bytes).map_err(io_error(&path))?;
        let mut journal = DiskJournal {
            path: path.clone(),
            file,
            file_bytes: 0,
            id_ceiling: first_id,
            sequence_ceiling: 0,
            peers: Vec::new(),
            stored: BTreeMap::new(),
            stored_order: Vec::new(),
            received: VecDeque::new(),
            received_bytes: 0,
            received_bytes_by_source: BTreeMap::new(),
            max_received_bytes,
            received_evicted: 0,
        };
        let discarded_bytes;
        if bytes.is_empty() {
            journal.rewrite()?;
            discarded_bytes = 0;
        } else {
            if bytes.len() < MAGIC.len() || &bytes[..MAGIC.len()] != MAGIC {
                return Err(JournalError::NotAJournal { path });
            }
            let good = journal.replay(&bytes[MAGIC.len()..]) + MAGIC.len();
            discarded_bytes = (bytes.len() - good) as u64;
            if discarded_bytes > 0 {
                journal
                    .file
                    .set_len(good as u64)
                    .and_then(|()| journal.file.sync_all())
                    .map_err(io_error(&path))?;
            }
            journal.file_bytes = good as u64;
            journal
                .file
                .seek(SeekFrom::Start(good as u64))
                .map_err(io_error(&path))?;
        }
        let recovered = Recovered {
            state: journal.state(),
            sequence: journal.sequence_ceiling,
            received: journal.received.iter().cloned().collect(),
            discarded_bytes,
        };
        Ok((journal, recovered))
    }

    /// Applies the records in `bytes`; returns how many bytes were good.
    fn replay(&mut self, bytes: &[u8]) -> usize {
        let mut at = 0;
        while let Some(header) = bytes.get(at..at + 8) {
            let len = u32::from_le_bytes([header[0], header[1], header[2], header[3]]) as usize;
            let crc = u32::from_le_bytes([header[4], header[5], header[6], header[7]]);
            if len > MAX_RECORD_BYTES {
                break;
            }
            let Some(payload) = bytes.get(at + 8..at + 8 + len) else {
                break;
            };
            if crc32fast::hash(payload) != crc {
                break;
            }
            let Ok(record) = postcard::from_bytes::<Record>(payload) else {
                break;
            };
            self.apply(record);
            at += 8 + len;
        }
        at
    }

    fn apply(&mut self, record: Record) {
        match record {
            Record::IdCeiling(id) => self.id_ceiling = id,
            Record::SequenceCeiling(s) => self.sequence_ceiling = s,
            Record::Peers(peers) => self.peers = peers,
            Record::Stored {
                class,
                lane,
                id,
                offered_ns,
                missing,
                bytes,
            } => {
                let message = DurableMessage {
                    class,
                    lane: lane.map(LaneId),
                    id: MessageId(id),
                    bytes: bytes.into(),
                    offered_ns,
                    missing,
                };
                if self.stored.insert(id, message).is_none() {
                    self.stored_order.push(id);
                }
            }
            Record::Missing { id, missing } => {
                if let Some(m) = self.stored.get_mut(&id) {
                    m.missing = missing;
                }
            }
            Record::Released { id } => {
                self.stored.remove(&id);
                self.stored_order.retain(|i| *i != id);
            }
            Record::Received { source, id, bytes } => self.keep_received(ReceivedMessage {
                source,
                id,
                bytes: bytes.into(),
            }),
        }
    }

    fn keep_received(&mut self, message: ReceivedMessage) {
        self.received_bytes += message.bytes.len();
        *self
            .received_bytes_by_source
            .entry(message.source)
            .or_default() += message.bytes.len();
        self.received.push_back(message);
        while self.received_bytes > self.max_received_bytes {
            // The sender holding the most bytes gives up its oldest message.
            let Some((&largest, _)) = self
                .received_bytes_by_source
                .iter()
                .max_by_key(|(source, bytes)| (**bytes, std::cmp::Reverse(**source)))
            else {
                break;
            };
            let Some(at) = self.received.iter().position(|m| m.source == largest) else {
                break;
            };
            let Some(old) = self.received.remove(at) else {
                break;
            };
            self.received_bytes -= old.bytes.len();
            self.received_evicted += 1;
            if let Some(bytes) = self.received_bytes_by_source.get_mut(&largest) {
                *bytes -= old.bytes.len();
                if *bytes == 0 {
                    self.received_bytes_by_source.remove(&largest);
                }
            }
        }
    }

    /// Received messages dropped for room since the journal was opened (while
    /// reading it back included): the sender holding the most bytes loses its
    /// oldest first.
    #[must_use]
    pub fn received_evicted(&self) -> u64 {
        self.received_evicted
    }

    /// The shaper state as journaled.
    fn state(&self) -> DurableState {
        DurableState {
            next_id: self.id_ceiling,
            peers: self.peers.clone(),
            stored: self
                .stored_order
                .iter()
                .filter_map(|id| self.stored.get(id).cloned())
                .collect(),
        }
    }

    /// Bytes the live records take (what a rewrite would write, about).
    fn live_bytes(&self) -> u64 {
        let stored: usize = self.stored.values().map(|m| m.bytes.len() + 32).sum();
        (stored + self.received_bytes + 16 * self.received.len() + 64) as u64
    }

    /// Writes what changed since the last call: the recipients, stored messages
    /// added, changed or released, and a new id or sequence ceiling when `state`
    /// or `sequence` reached the last one; fsync'd before it returns.
    pub fn sync(&mut self, state: &DurableState, sequence: u64) -> Result<(), JournalError> {
        let mut out = Vec::new();
        if reached(state.next_id, self.id_ceiling) {
            self.id_ceiling = state.next_id.wrapping_add(ID_BLOCK);
            frame(&Record::IdCeiling(self.id_ceiling), &mut out)?;
        }
        if sequence >= self.sequence_ceiling {
            self.sequence_ceiling = sequence + u64::from(ID_BLOCK);
            frame(&Record::SequenceCeiling(self.sequence_ceiling), &mut out)?;
        }
        if state.peers != self.peers {
            self.peers.clone_from(&state.peers);
            frame(&Record::Peers(self.peers.clone()), &mut out)?;
        }
        let live: BTreeMap<u32, &DurableMessage> =
            state.stored.iter().map(|m| (m.id.0, m)).collect();
        for id in self.stored_order.clone() {
            if !live.contains_key(&id) {
                frame(&Record::Released { id }, &mut out)?;
                self.apply(Record::Released { id });
            }
        }
        for m in &state.stored {
            match self.stored.get_mut(&m.id.0) {
                Some(known) if known.missing == m.missing => {}
                Some(known) => {
                    known.missing.clone_from(&m.missing);
                    frame(
                        &Record::Missing {
                            id: m.id.0,
                            missing: m.missing.clone(),
                        },
                        &mut out,
                    )?;
                }
                None => {
                    frame(&stored_record(m), &mut out)?;
                    self.stored.insert(m.id.0, m.clone());
                    self.stored_order.push(m.id.0);
                }
            }
        }
        self.append(&out)?;
        if self.file_bytes > 2 * self.live_bytes() + (1 << 20) {
            self.rewrite()?;
        }
        Ok(())
    }

    /// Whether `next_id` or `sequence` reached the reserved ceiling, so that the
    /// next [`sync`](Self::sync) must write a new one even if nothing else changed.
    #[must_use]
    pub fn ceiling_reached(&self, next_id: u32, sequence: u64) -> bool {
        reached(next_id, self.id_ceiling) || sequence >= self.sequence_ceiling
    }

    /// Journals a message received from `source` (fsync'd before it returns: call
    /// it before acknowledging the message).
    pub fn record_received(
        &mut self,
        source: u32,
        id: u32,
        bytes: &[u8],
    ) -> Result<(), JournalError> {
        let mut out = Vec::new();
        frame(
            &Record::Received {
                source,
                id,
                bytes: bytes.to_vec(),
            },
            &mut out,
        )?;
        self.append(&out)?;
        self.keep_received(ReceivedMessage {
            source,
            id,
            bytes: bytes.into(),
        });
        Ok(())
    }

    fn append(&mut self, out: &[u8]) -> Result<(), JournalError> {
        if out.is_empty() {
            return Ok(());
        }
        self.file
            .write_all(out)
            .and_then(|()| self.file.sync_data())
            .map_err(io_error(&self.path))?;
        self.file_bytes += out.len() as u64;
        Ok(())
    }

    /// Rewrites the file with only the live records (temporary file, fsync,
    /// rename, fsync of the directory).
    fn rewrite(&mut self) -> Result<(), JournalError> {
        let mut out = MAGIC.to_vec();
        frame(&Record::IdCeiling(self.id_ceiling), &mut out)?;
        frame(&Record::SequenceCeiling(self.sequence_ceiling), &mut out)?;
        frame(&Record::Peers(self.peers.clone()), &mut out)?;
        for id in &self.stored_order {
            if let Some(m) = self.stored.get(id) {
                frame(&stored_record(m), &mut out)?;
            }
        }
        for r in &self.received {
            frame(
                &Record::Received {
                    source: r.source,
                    id: r.id,
                    bytes: r.bytes.to_vec(),
                },
                &mut out,
            )?;
        }
        let tmp = self.path.with_extension("journal.tmp");
        let mut file = File::create(&tmp).map_err(io_error(&tmp))?;
        file.write_all(&out)
            .and_then(|()| file.sync_all())
            .map_err(io_error(&tmp))?;
        std::fs::rename(&tmp, &self.path).map_err(io_error(&self.path))?;
        if let Some(dir) = self.path.parent() {
            File::open(dir)
                .and_then(|d| d.sync_all())
                .map_err(io_error(dir))?;
        }
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .open(&self.path)
            .map_err(io_error(&self.path))?;
        file.seek(SeekFrom::End(0)).map_err(io_error(&self.path))?;
        self.file = file;
        self.file_bytes = out.len() as u64;
        Ok(())
    }

    /// The journal file.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The file's size now, bytes.
    #[must_use]
    pub fn file_bytes(&self) -> u64 {
        self.file_bytes
    }
}

fn stored_record(m: &DurableMessage) -> Record {
    Record::Stored {
        class: m.class,
        lane: m.lane.map(|l| l.0),
        id: m.id.0,
        offered_ns: m.offered_ns,
        missing: m.missing.clone(),
        bytes: m.bytes.to_vec(),
    }
}

#[cfg(test)]
#[path = "journal_tests.rs"]
mod tests;
