//! The receive side: frames back into messages, with bounded memory.

use std::collections::{BTreeMap, HashMap, HashSet, VecDeque};

use super::config::{ConfigError, ReassemblyConfig, s_to_ns};
use super::frame::{self, DataHeader, FrameError, ParsedFrame};
use super::stats::ReassemblyStats;
use crate::wire::Class;

/// What one fragment slot of a partial message costs before its fragment arrives.
const FRAGMENT_SLOT_BYTES: usize = std::mem::size_of::<Option<Vec<u8>>>();

/// A complete message.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ReassembledMessage {
    /// Who sent it (as given to [`Reassembler::push`]).
    pub source: u32,
    /// The sender's per-link message id.
    pub message_id: u32,
    /// Its traffic class.
    pub class: Class,
    /// The sender keeps it until acknowledged: send
    /// [`LinkShaper::queue_ack`](super::LinkShaper::queue_ack)`(sender, message_id)` back.
    pub ack_requested: bool,
    /// The message (an encoded envelope).
    pub bytes: Vec<u8>,
}

/// What a frame completed.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Incoming {
    /// A new complete message.
    Message(ReassembledMessage),
    /// The last fragment of a message already delivered came again (the sender
    /// did not get our acknowledgement): acknowledge it again if `ack_requested`.
    Duplicate {
        /// Sender.
        source: u32,
        /// Its message id.
        message_id: u32,
        /// Whether it wants an acknowledgement.
        ack_requested: bool,
    },
    /// Acknowledgements from `source`, for our shaper towards it
    /// ([`LinkShaper::acknowledge`](super::LinkShaper::acknowledge)).
    Ack {
        /// Sender of the acks.
        source: u32,
        /// Acknowledged message ids.
        ids: Vec<u32>,
    },
}

#[derive(Clone, Debug)]
struct Partial {
    header: DataHeader,
    fragments: Vec<Option<Vec<u8>>>,
    received: usize,
    /// Bytes held: the fragments' and the fragment table's.
    bytes: usize,
    arrival: u64,
    last_ns: u64,
}

#[derive(Clone, Debug, Default)]
struct Completed {
    order: VecDeque<u32>,
    set: HashSet<u32>,
}

/// Reassembles fragments from any number of sources. Memory is bounded by
/// [`ReassemblyConfig::max_bytes`] and [`ReassemblyConfig::max_messages`] for
/// partial messages plus `dedup_window` ids per source; partial messages that
/// stall for `timeout_s` are dropped. Every loss is counted.
#[derive(Clone, Debug)]
pub struct Reassembler {
    config: ReassemblyConfig,
    timeout_ns: u64,
    partial: BTreeMap<(u32, u32), Partial>,
    held_bytes: usize,
    arrivals: u64,
    completed: HashMap<u32, Completed>,
    stats: ReassemblyStats,
}

impl Default for Reassembler {
    fn default() -> Self {
        let config = ReassemblyConfig::default();
        Reassembler {
            config,
            timeout_ns: s_to_ns(config.timeout_s),
            partial: BTreeMap::new(),
            held_bytes: 0,
            arrivals: 0,
            completed: HashMap::new(),
            stats: ReassemblyStats::default(),
        }
    }
}

impl Reassembler {
    /// A reassembler with validated settings.
    pub fn new(config: ReassemblyConfig) -> Result<Self, ConfigError> {
        config.validate()?;
        Ok(Reassembler {
            config,
            timeout_ns: s_to_ns(config.timeout_s),
            ..Reassembler::default()
        })
    }

    /// Counters so far.
    #[must_use]
    pub fn stats(&self) -> &ReassemblyStats {
        &self.stats
    }

    /// Bytes held in partial messages.
    #[must_use]
    pub fn held_bytes(&self) -> usize {
        self.held_bytes
    }

    /// Partial messages held.
    #[must_use]
    pub fn partial_messages(&self) -> usize {
        self.partial.len()
    }

    /// Takes one frame from `source`. Malformed frames are an error (and
    /// counted); `Ok(None)` means the frame was absorbed (a fragment of a message
    /// still incomplete, or a dropped duplicate).
    pub fn push(
        &mut self,
        now_ns: u64,
        source: u32,
        bytes: &[u8],
    ) -> Result<Option<Incoming>, FrameError> {
        self.expire(now_ns);
        let parsed = frame::parse(bytes).inspect_err(|_| self.stats.malformed_frames += 1)?;
        self.stats.frames += 1;
        let (header, chunk) = match parsed {
            ParsedFrame::Ack(body) => {
                return Ok(Some(Incoming::Ack {
                    source,
                    ids: frame::ack_ids(body).collect(),
                }));
            }
            ParsedFrame::Data(h, chunk) => (h, chunk),
        };
        let key = (source, header.message_id);
        if self
            .completed
            .get(&source)
            .is_some_and(|c| c.set.contains(&header.message_id))
        {
            self.stats.duplicates += 1;
            let last = header.index + 1 == header.count;
            return Ok(last.then_some(Incoming::Duplicate {
                source,
                message_id: header.message_id,
                ack_requested: header.ack_requested,
            }));
        }
        if header.count == 1 {
            return Ok(Some(self.complete(source, header, chunk.to_vec())));
        }
        if let Some(p) = self.partial.get(&key)
            && (p.header.count != header.count || p.header.class != header.class)
        {
            self.stats.malformed_frames += 1;
            return Err(FrameError::Inconsistent(header.message_id));
        }
        // A new partial message costs its fragment table too (up to 65 535 slots:
        // 1.5 MiB announced by one small frame), so it counts against the budget.
        let table = if self.partial.contains_key(&key) {
            0
        } else {
            usize::from(header.count) * FRAGMENT_SLOT_BYTES
        };
        let needed = chunk.len() + table;
        if needed > self.config.max_bytes {
            self.stats.too_large += 1;
            self.drop_partial(key);
            return Ok(None);
        }
        // Make room: evict the oldest partial messages (not this one).
        while self.held_bytes + needed > self.config.max_bytes
            || (!self.partial.contains_key(&key) && self.partial.len() >= self.config.max_messages)
        {
            let oldest = self
                .partial
                .iter()
                .filter(|(k, _)| **k != key)
                .min_by_key(|(_, p)| p.arrival)
                .map(|(k, _)| *k);
            let Some(oldest) = oldest else {
                // Only this message is held and it alone outgrows the budget.
                self.stats.too_large += 1;
                self.drop_partial(key);
                return Ok(None);
            };
            self.stats.evicted += 1;
            self.drop_partial(oldest);
        }
        let arrival = self.arrivals;
        let p = self.partial.entry(key).or_insert_with(|| Partial {
            header,
            fragments: vec![None; usize::from(header.count)],
            received: 0,
            bytes: table,
            arrival,
            last_ns: now_ns,
        });
        self.held_bytes += table;
        self.arrivals += 1;
        p.last_ns = now_ns;
        let slot = &mut p.fragments[usize::from(header.index)];
        if slot.is_some() {
            self.stats.duplicates += 1;
            return Ok(None);
        }
        *slot = Some(chunk.to_vec());
        p.received += 1;
        p.bytes += chunk.len();
        self.held_bytes += chunk.len();
        if p.received < p.fragments.len() {
            return Ok(None);
        }
        let Some(p) = self.partial.remove(&key) else {
            return Ok(None);
        };
        self.held_bytes -= p.bytes;
        let mut bytes = Vec::with_capacity(p.bytes - p.fragments.len() * FRAGMENT_SLOT_BYTES);
        for f in p.fragments.into_iter().flatten() {
            bytes.extend_from_slice(&f);
        }
        Ok(Some(self.complete(source, header, bytes)))
    }

    /// Remembers message `message_id` of `source` as completed (one held from
    /// before a restart): a copy of it is a duplicate.
    pub fn remember(&mut self, source: u32, message_id: u32) {
        self.record_completed(source, message_id);
    }

    /// Forgets that message `message_id` of `source` was completed, so that a later
    /// copy is delivered again instead of dropped as a duplicate: for a message that
    /// failed validation above the reassembler (bytes that prove nothing about the
    /// sender must not shadow its real message with that id).
    pub fn forget(&mut self, source: u32, message_id: u32) {
        if let Some(done) = self.completed.get_mut(&source)
            && done.set.remove(&message_id)
        {
            done.order.retain(|id| *id != message_id);
        }
    }

    fn drop_partial(&mut self, key: (u32, u32)) {
        if let Some(p) = self.partial.remove(&key) {
            self.held_bytes -= p.bytes;
        }
    }

    fn complete(&mut self, source: u32, header: DataHeader, bytes: Vec<u8>) -> Incoming {
        self.stats.completed += 1;
        self.record_completed(source, header.message_id);
        Incoming::Message(ReassembledMessage {
            source,
            message_id: header.message_id,
            class: header.class,
            ack_requested: header.ack_requested,
            bytes,
        })
    }

    fn record_completed(&mut self, source: u32, message_id: u32) {
        let done = self.completed.entry(source).or_default();
        if done.set.insert(message_id) {
            done.order.push_back(message_id);
            while done.order.len() > self.config.dedup_window {
                if let Some(old) = done.order.pop_front() {
                    done.set.remove(&old);
                }
            }
        }
    }

    /// Drops partial messages that received nothing for `timeout_s` (counted as
    /// incomplete). [`push`](Self::push) calls it too.
    pub fn expire(&mut self, now_ns: u64) {
        let timeout = self.timeout_ns;
        let stale: Vec<(u32, u32)> = self
            .partial
            .iter()
            .filter(|(_, p)| now_ns.saturating_sub(p.last_ns) >= timeout)
            .map(|(k, _)| *k)
            .collect();
        for k in stale {
            self.stats.incomplete_timed_out += 1;
            self.drop_partial(k);
        }
    }
}
