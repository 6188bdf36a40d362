//! Store-and-forward with per-peer acknowledgement (DESIGN §5, issue 3).
//!
//! One store per class holds every accepted message until **each intended
//! recipient** has acknowledged it, or the recipient was removed (counted as
//! [`DropReason::PeerRemoved`](super::DropReason::PeerRemoved)). The intended
//! recipients of a message are the peers known when it is offered, plus any peer
//! added while it is still stored (a newly heard peer receives the backlog).
//!
//! Each peer has its own go-back-N cursor: a window of messages sent and not yet
//! acknowledged by *that* peer, a retransmission deadline with exponential
//! back-off, and ordered sending (after a go-back the peer's cursor restarts at
//! its oldest unacknowledged message, and nothing newer is sent to it before
//! that). A partitioned peer therefore stalls only its own cursor; the others go
//! on, and after the partition heals the peer receives its backlog in order.
//! (The receiver does not hold messages back: under random loss, a message sent
//! after a lost one may still arrive before the lost one's retransmission.)
//!
//! While every peer's cursor stands at the same fragment, that fragment goes out
//! once to all of them (a broadcast frame, the common case on a healthy link);
//! otherwise fragments go to one peer at a time, oldest message first, so that a
//! lagging peer never hears a newer message before an older one it still misses.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::sync::Arc;

use super::config::{ClassConfig, s_to_ns};

/// A stored message.
#[derive(Clone, Debug)]
pub(super) struct Stored {
    /// Store-internal order (never wraps in practice).
    pub seq: u64,
    /// Per-link message id.
    pub id: u32,
    /// Shared, so that a [durable snapshot](super::LinkShaper::durable_state) costs no copy.
    pub bytes: Arc<[u8]>,
    pub offered_ns: u64,
    pub count: u16,
    /// Fragment-0 transmissions so far (the first counts).
    pub transmissions: u32,
    /// Its last fragment has gone out at least once (to some peer).
    sent_once: bool,
    /// Intended recipients that have not acknowledged it yet.
    missing: BTreeSet<u32>,
}

/// One peer's go-back-N state.
#[derive(Clone, Copy, Debug)]
struct Cursor {
    /// Messages with `seq < next_seq` have been sent to this peer since its last
    /// go-back; when `next_fragment > 0`, the message `next_seq` is partly sent.
    next_seq: u64,
    next_fragment: u16,
    deadline_ns: Option<u64>,
    timeout_ns: u64,
}

impl Cursor {
    /// A peer's cursor before anything was sent to it.
    fn new(config: &ClassConfig) -> Self {
        Cursor {
            next_seq: 0,
            next_fragment: 0,
            deadline_ns: None,
            timeout_ns: s_to_ns(config.retransmit_timeout_s),
        }
    }
}

/// The next fragment the store wants to send.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(super) struct NextFragment {
    /// Position of the message in the store.
    pub index: usize,
    /// Fragment index.
    pub fragment: u16,
    /// `None`: every known peer (one broadcast frame); `Some(p)`: peer `p` only.
    pub to: Option<u32>,
}

/// See the [module docs](self).
#[derive(Clone, Debug)]
pub(super) struct Store {
    config: ClassConfig,
    messages: VecDeque<Stored>,
    bytes: usize,
    next_seq: u64,
    peers: BTreeMap<u32, Cursor>,
    /// Bumped whenever the stored messages, their recipients or the peers change
    /// (what a durable snapshot holds).
    generation: u64,
}

impl Store {
    pub fn new(config: ClassConfig) -> Self {
        Store {
            config,
            messages: VecDeque::new(),
            bytes: 0,
            next_seq: 0,
            peers: BTreeMap::new(),
            generation: 0,
        }
    }

    /// The class settings it was built with.
    pub fn config(&self) -> &ClassConfig {
        &self.config
    }

    /// Changes whenever [`snapshot`](Self::snapshot) would.
    pub fn generation(&self) -> u64 {
        self.generation
    }

    /// Every stored message (id, bytes, offered at, recipients still missing it).
    pub fn snapshot(&self) -> impl Iterator<Item = (u32, Arc<[u8]>, u64, Vec<u32>)> + '_ {
        self.messages.iter().map(|m| {
            (
                m.id,
                m.bytes.clone(),
                m.offered_ns,
                m.missing.iter().copied().collect(),
            )
        })
    }

    pub fn len(&self) -> usize {
        self.messages.len()
    }

    pub fn bytes(&self) -> usize {
        self.bytes
    }

    /// Would a message of `len` bytes fit?
    pub fn has_room(&self, len: usize) -> bool {
        self.messages.len() < self.config.capacity_messages
            && self.bytes + len <= self.config.capacity_bytes
    }

    /// Stores a message for every known peer (call [`has_room`](Self::has_room) first).
    pub fn push(&mut self, id: u32, bytes: Arc<[u8]>, offered_ns: u64, count: u16) {
        let missing = self.peers.keys().copied().collect();
        self.push_for(id, bytes, offered_ns, count, missing);
    }

    /// Stores a message for the given recipients (a restored one, see
    /// [`LinkShaper::restore`](super::LinkShaper::restore)); recipients not yet known
    /// become peers (without becoming recipients of other stored messages). Capacity
    /// is not checked: what was accepted stays.
    pub fn push_for(
        &mut self,
        id: u32,
        bytes: Arc<[u8]>,
        offered_ns: u64,
        count: u16,
        missing: BTreeSet<u32>,
    ) {
        for &peer in &missing {
            self.peers
                .entry(peer)
                .or_insert_with(|| Cursor::new(&self.config));
        }
        self.bytes += bytes.len();
        self.messages.push_back(Stored {
            seq: self.next_seq,
            id,
            bytes,
            offered_ns,
            count,
            transmissions: 0,
            sent_once: false,
            missing,
        });
        self.next_seq += 1;
        self.generation += 1;
    }

    /// Adds a recipient: it becomes an intended recipient of everything still
    /// stored. Returns false if it was known already.
    pub fn add_peer(&mut self, peer: u32) -> bool {
        if self.peers.contains_key(&peer) {
            return false;
        }
        self.peers.insert(peer, Cursor::new(&self.config));
        for m in &mut self.messages {
            m.missing.insert(peer);
        }
        self.generation += 1;
        true
    }

    /// Removes a recipient. Returns how many stored messages it was still missing
    /// (given up for it); messages nobody else misses are released.
    pub fn remove_peer(&mut self, peer: u32) -> u64 {
        if self.peers.remove(&peer).is_none() {
            return 0;
        }
        let mut given_up = 0;
        for m in &mut self.messages {
            given_up += u64::from(m.missing.remove(&peer));
        }
        self.release_complete();
        self.generation += 1;
        given_up
    }

    /// The known peers.
    pub fn peers(&self) -> impl Iterator<Item = u32> + '_ {
        self.peers.keys().copied()
    }

    /// Records `peer`'s acknowledgement of message `id`. Returns `Some(released)`
    /// if the peer was missing it (`released`: nobody misses it any more and it
    /// left the store), `None` otherwise (unknown id or peer, or a repeat).
    pub fn acknowledge(&mut self, now_ns: u64, peer: u32, id: u32) -> Option<bool> {
        let index = self.messages.iter().position(|m| m.id == id)?;
        if !self.messages[index].missing.remove(&peer) {
            return None;
        }
        self.generation += 1;
        let initial = s_to_ns(self.config.retransmit_timeout_s);
        let in_flight = self.in_flight(peer);
        if let Some(c) = self.peers.get_mut(&peer) {
            // Progress: back to the initial timeout, timer restarted.
            c.timeout_ns = initial;
            c.deadline_ns = (in_flight > 0).then(|| now_ns + initial);
        }
        let released = self.messages[index].missing.is_empty();
        if released {
            self.release_complete();
        }
        Some(released)
    }

    /// Drops every message that no recipient misses. With no peer known at all,
    /// messages wait for the first one.
    fn release_complete(&mut self) {
        let no_peers = self.peers.is_empty();
        let bytes = &mut self.bytes;
        self.messages.retain(|m| {
            let keep = no_peers || !m.missing.is_empty();
            if !keep {
                *bytes -= m.bytes.len();
            }
            keep
        });
    }

    /// Messages sent to `peer` since its last go-back and not acknowledged by it.
    fn in_flight(&self, peer: u32) -> usize {
        let Some(c) = self.peers.get(&peer) else {
            return 0;
        };
        self.messages
            .iter()
            .take_while(|m| m.seq < c.next_seq)
            .filter(|m| m.missing.contains(&peer))
            .count()
    }

    /// Goes back for every peer whose acknowledgement is overdue.
    pub fn run_timers(&mut self, now_ns: u64) {
        let max = s_to_ns(self.config.retransmit_timeout_max_s);
        let overdue: Vec<u32> = self
            .peers
            .iter()
            .filter(|(_, c)| c.deadline_ns.is_some_and(|d| d <= now_ns))
            .map(|(p, _)| *p)
            .collect();
        for peer in overdue {
            let in_flight = self.in_flight(peer);
            if let Some(c) = self.peers.get_mut(&peer) {
                c.deadline_ns = None;
                if in_flight > 0 {
                    c.next_seq = 0;
                    c.next_fragment = 0;
                    c.timeout_ns = c.timeout_ns.saturating_mul(2).min(max);
                }
            }
        }
    }

    /// The earliest retransmission deadline.
    pub fn next_deadline(&self) -> Option<u64> {
        self.peers.values().filter_map(|c| c.deadline_ns).min()
    }

    /// `peer`'s next (message index, fragment), if its window allows one.
    fn next_for(&self, peer: u32, c: &Cursor) -> Option<(usize, u16)> {
        if self.in_flight(peer) >= self.config.window_messages {
            return None;
        }
        let index = self
            .messages
            .iter()
            .position(|m| m.seq >= c.next_seq && m.missing.contains(&peer))?;
        let m = &self.messages[index];
        let fragment = if m.seq == c.next_seq {
            c.next_fragment
        } else {
            0
        };
        Some((index, fragment))
    }

    /// What to send next: the oldest pending fragment over all peers, to all of
    /// them at once when every peer is at that fragment. Messages not yet sent to
    /// anyone go before repeats (a go-back burst for a lagging peer does not delay
    /// fresh messages to the others); under saturation the store fills and
    /// refuses new offers, so repeats are not starved for long.
    pub fn next(&self) -> Option<NextFragment> {
        let wanted: Vec<(u32, (usize, u16))> = self
            .peers
            .iter()
            .filter_map(|(p, c)| self.next_for(*p, c).map(|n| (*p, n)))
            .collect();
        let (peer, best) = wanted
            .iter()
            .min_by_key(|(_, n)| (self.messages[n.0].sent_once, *n))
            .copied()?;
        let all = wanted.len() == self.peers.len() && wanted.iter().all(|(_, n)| *n == best);
        Some(NextFragment {
            index: best.0,
            fragment: best.1,
            to: if all { None } else { Some(peer) },
        })
    }

    /// The message at `index`.
    pub fn message(&self, index: usize) -> &Stored {
        &self.messages[index]
    }

    /// Records that `next` was sent: advances the recipients' cursors and counts
    /// fragment-0 transmissions. Returns the message's transmissions so far.
    pub fn sent(&mut self, now_ns: u64, next: &NextFragment) -> u32 {
        let Some(m) = self.messages.get_mut(next.index) else {
            return 0;
        };
        if next.fragment == 0 {
            m.transmissions += 1;
        }
        let (seq, count, transmissions) = (m.seq, m.count, m.transmissions);
        let last = next.fragment + 1 == count;
        m.sent_once |= last;
        for (peer, c) in &mut self.peers {
            if next.to.is_some_and(|to| to != *peer) {
                continue;
            }
            if last {
                c.next_seq = seq + 1;
                c.next_fragment = 0;
                if c.deadline_ns.is_none() {
                    c.deadline_ns = Some(now_ns + c.timeout_ns);
                }
            } else {
                c.next_seq = seq;
                c.next_fragment = next.fragment + 1;
            }
        }
        transmissions
    }
}
