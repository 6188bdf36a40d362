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
//!
//! **Per-peer bounds** (issue 23): the class's `capacity_messages` and
//! `capacity_bytes` bound each recipient's *pending set* (the stored messages it
//! misses) on its own. A new message is stored for every recipient whose pending
//! set has room for it; a recipient without room is skipped for that message
//! (counted as [`DropReason::PeerFull`](super::DropReason::PeerFull)), so a peer
//! that never acknowledges holds at most its own bound and cannot make the store
//! refuse messages for the others. The store refuses (back-pressure) only when no
//! recipient has room. It holds at most `capacity × recipients`; with no recipient
//! known yet, messages wait for the first within one capacity.
//!
//! **Silent peers** are [suspended](Store::suspend_peer): they get only a probe —
//! their oldest pending message, one at a time, every `retransmit_timeout_max_s` —
//! and frames for the others go addressed to them (a suspended peer that comes back
//! never hears a newer message before its backlog). They stay recipients (within
//! their bound), so when heard again (the probe's acknowledgement, or anything
//! else) they [rejoin](Store::add_peer) and get what they missed, oldest first,
//! paced by the window and the token bucket.
//!
//! **Acknowledgements** count only for a message that was sent to that peer:
//! bytes that merely guess an id cannot release a message before it left.

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
    /// Peers its last fragment went to (an acknowledgement before that is not real).
    sent_to: BTreeSet<u32>,
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
    /// False while the peer is suspended (silent for too long).
    active: bool,
}

impl Cursor {
    /// A peer's cursor before anything was sent to it.
    fn new(config: &ClassConfig) -> Self {
        Cursor {
            next_seq: 0,
            next_fragment: 0,
            deadline_ns: None,
            timeout_ns: s_to_ns(config.retransmit_timeout_s),
            active: true,
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

/// What [`Store::acknowledge`] made of an acknowledgement.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum StoreAck {
    /// The peer had it now; `true`: nobody misses it any more and it left.
    Recorded(bool),
    /// The store holds it for that peer but never sent it there.
    NotSent,
    /// Not held for that peer (an unknown id, or a repeat).
    Unknown,
}

/// Whom a new message is stored for ([`Store::admit`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub(super) struct Admission {
    /// Recipients whose pending set has room for it.
    pub recipients: BTreeSet<u32>,
    /// Recipients skipped: their pending set is full.
    pub skipped: u64,
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

    /// Messages and bytes `peer` misses (its pending set).
    pub fn pending(&self, peer: u32) -> (usize, usize) {
        self.messages
            .iter()
            .filter(|m| m.missing.contains(&peer))
            .fold((0, 0), |(n, b), m| (n + 1, b + m.bytes.len()))
    }

    fn has_room(&self, (messages, bytes): (usize, usize), len: usize) -> bool {
        messages < self.config.capacity_messages && bytes + len <= self.config.capacity_bytes
    }

    /// Whom a message of `len` bytes would be stored for, among `wanted` (`None`:
    /// every known peer): those whose pending set has room; `None` when nobody has
    /// room (or, with no peer known, when the store is full).
    pub fn admit(&self, len: usize, wanted: Option<u32>) -> Option<Admission> {
        if self.peers.is_empty() {
            let room = self.has_room((self.messages.len(), self.bytes), len);
            return room.then(|| Admission {
                recipients: wanted.into_iter().collect(),
                skipped: 0,
            });
        }
        let candidates: Vec<u32> = match wanted {
            Some(peer) => vec![peer],
            None => self.peers.keys().copied().collect(),
        };
        let recipients: BTreeSet<u32> = candidates
            .iter()
            .copied()
            .filter(|p| self.has_room(self.pending(*p), len))
            .collect();
        let skipped = (candidates.len() - recipients.len()) as u64;
        (!recipients.is_empty()).then_some(Admission {
            recipients,
            skipped,
        })
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
            sent_to: BTreeSet::new(),
        });
        self.next_seq += 1;
        self.generation += 1;
    }

    /// Adds a recipient: it becomes an intended recipient of everything still
    /// stored. A suspended peer rejoins: its cursor goes back to the oldest
    /// message it misses. Returns false if it was known and active already.
    pub fn add_peer(&mut self, peer: u32) -> bool {
        if let Some(c) = self.peers.get_mut(&peer) {
            if c.active {
                return false;
            }
            *c = Cursor::new(&self.config);
            return true;
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

    /// Stops sending to `peer` (silent for too long) without giving up what it
    /// misses; [`add_peer`](Self::add_peer) resumes it. Returns false if it was
    /// unknown or suspended already.
    pub fn suspend_peer(&mut self, peer: u32) -> bool {
        match self.peers.get_mut(&peer) {
            Some(c) if c.active => {
                c.active = false;
                c.timeout_ns = s_to_ns(self.config.retransmit_timeout_max_s);
                true
            }
            _ => false,
        }
    }

    /// The known peers.
    pub fn peers(&self) -> impl Iterator<Item = u32> + '_ {
        self.peers.keys().copied()
    }

    /// The suspended peers.
    pub fn suspended(&self) -> impl Iterator<Item = u32> + '_ {
        self.peers
            .iter()
            .filter(|(_, c)| !c.active)
            .map(|(p, _)| *p)
    }

    /// Records `peer`'s acknowledgement of message `id` (see [`StoreAck`]).
    pub fn acknowledge(&mut self, now_ns: u64, peer: u32, id: u32) -> StoreAck {
        let Some(index) = self.messages.iter().position(|m| m.id == id) else {
            return StoreAck::Unknown;
        };
        let m = &mut self.messages[index];
        if !m.missing.contains(&peer) {
            return StoreAck::Unknown;
        }
        if !m.sent_to.contains(&peer) {
            return StoreAck::NotSent;
        }
        m.missing.remove(&peer);
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
        StoreAck::Recorded(released)
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
                    if !c.active {
                        c.timeout_ns = max;
                    }
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
        // A suspended peer is probed with one message at a time.
        let window = if c.active {
            self.config.window_messages
        } else {
            1
        };
        if self.in_flight(peer) >= window {
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
                m.sent_to.insert(*peer);
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
