//! Link shaping: what leaves a robot for one peer, when, and in which pieces.
//!
//! A [`LinkShaper`] sits above any transport (DESIGN §5), so a study measures the
//! same thing over the simulated network and over zenoh. It is a plain struct
//! driven by explicit time (`now_ns`, nanoseconds on any monotonic clock — sim
//! or wall); it never reads a clock, sleeps or spawns.
//!
//! - **Token bucket** per link: `rate_bps`, `burst_bytes` (the `tc tbf` the thesis
//!   used for its §8.2.7 study, 0.1 and 0.25 Mbit/s). A frame leaves only when the
//!   bucket holds its size; integer arithmetic, so no drift over long runs.
//! - **Strict priority**: acknowledgements, then [`Class::Odometry`] >
//!   [`Class::Plan`] > [`Class::Keyframe`] > [`Class::Bulk`].
//! - **Fragmentation** at `mtu_bytes` ([`frame`] layout): classes are chosen per
//!   frame, so the bucket only needs to hold one MTU and a plan never waits
//!   behind a whole keyframe. Delay bound: the bucket's credit is never negative
//!   and a lower class is never chosen while a higher one waits, so a message
//!   offered at `t` leaves the shaper by `t + (its own frame bytes +
//!   higher-priority frame bytes offered meanwhile) · 8 / rate_bps`; a link
//!   behind it that serialises at the same rate holds at most `burst_bytes` of
//!   earlier frames, adding `burst_bytes · 8 / rate_bps`. With `burst_bytes =
//!   mtu_bytes = 1200` at 250 kbit/s that is 41.6 ms for odometry and 61.7 ms for
//!   a plan, against 193 ms for one unfragmented 6 kB keyframe (tested).
//! - **Queue policies** per class ([`QueuePolicy`]): keep-latest, drop-oldest,
//!   store-and-forward (a message stays until every intended peer acknowledged
//!   it; each peer's pending set bounded on its own, so a silent peer cannot make
//!   the store refuse messages for the others; per-peer in-order go-back-N, see
//!   [`LinkShaper::add_peer`], [`LinkShaper::suspend_peer`] and the `store` module). Frames carry their
//!   addressee ([`Frame::to`]): broadcast, or one peer (acks, and store-and-forward
//!   fragments while peers are out of step).
//! - **Counters** ([`ShaperStats`]): drops by reason, queue delay, completion delay
//!   and age of information per class.
//! - **Extra lanes** ([`LinkShaper::add_lane`]): a shared topic of a custom actor
//!   gets its own queue with its own policy and capacity, at the priority of the
//!   class it names (after that class's own queue, lanes in the order they were
//!   added), optionally addressed to one peer, with its own [`ClassStats`]
//!   ([`LinkShaper::lane_stats`]; [`ShaperStats::classes`] counts the classes' own
//!   queues only, [`ShaperStats::lane_sent_bytes`] the extra lanes' bytes together).
//!
//! The receive side is a [`Reassembler`]: bounded memory, timeouts, duplicate
//! suppression, counted incomplete and evicted messages.
//!
//! ```
//! use troupe_comms::shaping::{LinkShaper, ShaperConfig, Reassembler, Incoming};
//! use troupe_comms::wire::Class;
//!
//! let mut config = ShaperConfig::default();
//! config.rate_bps = Some(250_000);
//! config.burst_bytes = 2_000;
//! config.mtu_bytes = 1_000;
//! let mut shaper = LinkShaper::new(config).unwrap();
//! let mut receiver = Reassembler::default();
//! shaper.offer(0, Class::Keyframe, vec![7; 5_000]).unwrap();
//! let mut now = 0;
//! let mut got = None;
//! while let Some(t) = shaper.next_send_time(now) {
//!     now = t;
//!     let frame = shaper.poll(now).unwrap();
//!     if let Some(Incoming::Message(m)) = receiver.push(now, 1, &frame.bytes).unwrap() {
//!         got = Some(m);
//!     }
//! }
//! assert_eq!(got.unwrap().bytes, vec![7; 5_000]);
//! // 5 000 bytes + 6 headers at 250 kbit/s, less the 2 000-byte burst: ~97 ms.
//! assert!(now > 90_000_000 && now < 100_000_000);
//! ```

mod config;
pub mod frame;
mod reassembly;
mod stats;
mod store;

use std::collections::{BTreeSet, VecDeque};
use std::sync::Arc;

use thiserror::Error;

pub use config::{
    ClassConfig, ConfigError, MAX_MTU_BYTES, MIN_MTU_BYTES, QueuePolicy, ReassemblyConfig,
    ShaperConfig,
};
pub use frame::{Frame, FrameError, FrameKind};
pub use reassembly::{Incoming, ReassembledMessage, Reassembler};
pub use stats::{
    AgeOfInformation, ClassStats, DelayStats, DropCounts, DropReason, ReassemblyStats, ShaperStats,
};

use crate::wire::Class;
use frame::{ACK_HEADER_BYTES, DATA_HEADER_BYTES, DataHeader};
use store::{NextFragment, Store, StoreAck};

/// An extra lane of a [`LinkShaper`] ([`LinkShaper::add_lane`]); ids count from 0
/// in the order lanes were added.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct LaneId(pub u16);

/// Per-link message id, increasing by one per offer (wrapping).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct MessageId(pub u32);

/// A store-and-forward message as kept across a restart of the link
/// ([`DurableState`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DurableMessage {
    /// Its class (a store-and-forward class when it was accepted).
    pub class: Class,
    /// The extra lane it was accepted in; `None` = its class's own queue.
    pub lane: Option<LaneId>,
    /// Its message id (kept, so that a peer that has it already recognises a resend).
    pub id: MessageId,
    /// The encoded envelope.
    pub bytes: Arc<[u8]>,
    /// When it was offered, nanoseconds on the shaper's clock.
    pub offered_ns: u64,
    /// Intended recipients that have not acknowledged it.
    pub missing: Vec<u32>,
}

/// What a link must not forget when it restarts — what a robot would keep in
/// non-volatile storage: the next message id (peers remember the ids they completed
/// and drop repeats, so a restarted link that counted from 0 again would have its
/// first messages discarded as duplicates) and every store-and-forward message some
/// recipient has not acknowledged, with the known peers. Queued keep-latest and
/// drop-oldest messages, the token bucket and the counters start afresh.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct DurableState {
    /// The id the next offered message gets.
    pub next_id: u32,
    /// Store-and-forward recipients.
    pub peers: Vec<u32>,
    /// Accepted store-and-forward messages not yet acknowledged by every recipient,
    /// oldest first per class.
    pub stored: Vec<DurableMessage>,
}

/// What [`LinkShaper::acknowledge`] made of an acknowledgement.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AckOutcome {
    /// The peer was missing the message and now has it.
    Recorded,
    /// A stored message the peer misses, but it was never sent to that peer: the
    /// acknowledgement is not real (bytes that guessed an id) and is ignored.
    NotSent,
    /// No stored message with that id is missing for the peer (a repeated
    /// acknowledgement, or an unknown id): nothing changes.
    Unknown,
}

impl AckOutcome {
    /// Whether it was recorded.
    #[must_use]
    pub fn recorded(self) -> bool {
        self == AckOutcome::Recorded
    }
}

/// Why an offer was not accepted (also counted in [`ClassStats::drops`]).
#[derive(Clone, Copy, Debug, Error, PartialEq, Eq)]
pub enum Refused {
    /// Larger than the class capacity or than 65 535 fragments.
    #[error("message of {bytes} bytes exceeds the {limit}-byte limit")]
    TooLarge {
        /// Offered size.
        bytes: usize,
        /// The limit it broke.
        limit: usize,
    },
    /// Store-and-forward: no recipient's pending set has room; nothing stored
    /// was dropped.
    #[error("store-and-forward store is full")]
    StoreFull,
}

/// Token bucket in exact integer units (bit·ns).
#[derive(Clone, Debug)]
struct Bucket {
    rate_bps: Option<u64>,
    capacity: u128,
    credit: u128,
    last_ns: u64,
}

const NS_PER_S: u128 = 1_000_000_000;

impl Bucket {
    fn new(rate_bps: Option<u64>, burst_bytes: u64) -> Self {
        let capacity = u128::from(burst_bytes) * 8 * NS_PER_S;
        Bucket {
            rate_bps,
            capacity,
            credit: capacity,
            last_ns: 0,
        }
    }

    fn refill(&mut self, now_ns: u64) {
        if let Some(rate) = self.rate_bps
            && now_ns > self.last_ns
        {
            let add = u128::from(now_ns - self.last_ns) * u128::from(rate);
            self.credit = (self.credit + add).min(self.capacity);
        }
        self.last_ns = self.last_ns.max(now_ns);
    }

    fn cost(bytes: u64) -> u128 {
        u128::from(bytes) * 8 * NS_PER_S
    }

    /// Nanoseconds until `bytes` can be sent (0 = now), as of the last refill.
    fn wait_ns(&self, bytes: u64) -> u64 {
        let Some(rate) = self.rate_bps else {
            return 0;
        };
        let need = Self::cost(bytes);
        if self.credit >= need {
            0
        } else {
            let missing = need - self.credit;
            u64::try_from(missing.div_ceil(u128::from(rate))).unwrap_or(u64::MAX)
        }
    }

    fn take(&mut self, bytes: u64) {
        if self.rate_bps.is_some() {
            self.credit = self.credit.saturating_sub(Self::cost(bytes));
        }
    }
}

/// A message waiting in a keep-latest or drop-oldest class queue.
#[derive(Clone, Debug)]
struct Pending {
    id: u32,
    bytes: Vec<u8>,
    offered_ns: u64,
    count: u16,
    /// Addressee of its frames; `None` = broadcast.
    to: Option<u32>,
}

/// A keep-latest or drop-oldest class: a deque whose front message may be partly
/// sent (`next_fragment` fragments of it); fully sent messages leave it.
#[derive(Clone, Debug)]
struct ClassQueue {
    config: ClassConfig,
    messages: VecDeque<Pending>,
    bytes: usize,
    next_fragment: u16,
}

impl ClassQueue {
    fn new(config: ClassConfig) -> Self {
        ClassQueue {
            config,
            messages: VecDeque::new(),
            bytes: 0,
            next_fragment: 0,
        }
    }

    /// Index of the first message that may be dropped (not partly sent).
    fn first_droppable(&self) -> Option<usize> {
        let start = usize::from(self.next_fragment > 0);
        (start < self.messages.len()).then_some(start)
    }

    fn remove(&mut self, index: usize) -> Option<Pending> {
        let p = self.messages.remove(index)?;
        self.bytes -= p.bytes.len();
        Some(p)
    }
}

/// One traffic class: a plain queue, or a store-and-forward store.
#[derive(Clone, Debug)]
enum Lane {
    Queue(ClassQueue),
    Store(Store),
}

impl Lane {
    fn new(config: ClassConfig) -> Self {
        match config.policy {
            QueuePolicy::StoreAndForward => Lane::Store(Store::new(config)),
            QueuePolicy::KeepLatest | QueuePolicy::DropOldest => {
                Lane::Queue(ClassQueue::new(config))
            }
        }
    }
}

/// Shapes what one robot sends to its peers. See the [module docs](self).
#[derive(Clone, Debug)]
pub struct LinkShaper {
    config: ShaperConfig,
    chunk_bytes: usize,
    bucket: Bucket,
    /// The classes' own lanes (indexed by [`Class::index`]), then the extra lanes.
    lanes: Vec<Lane>,
    /// The class of each lane.
    lane_classes: Vec<Class>,
    /// Lane indices in sending order: by class priority, then by index.
    order: Vec<usize>,
    /// Counters of the extra lanes.
    lane_stats: Vec<ClassStats>,
    /// Store-and-forward recipients (also for lanes added later).
    peers: BTreeSet<u32>,
    next_id: u32,
    /// (peer, message id) acknowledgements to send, oldest first.
    pending_acks: VecDeque<(u32, u32)>,
    stats: ShaperStats,
}

/// What [`LinkShaper::poll`] would send next.
enum Next {
    /// Acknowledgements for one peer: that peer and how many ids.
    Ack(u32, usize),
    /// A fragment of a plain queue's front message: lane and frame length.
    Queued(usize, usize),
    /// A fragment from a store: lane, frame length, and which.
    Stored(usize, usize, NextFragment),
}

impl LinkShaper {
    /// A shaper with validated settings; the bucket starts full at time 0.
    pub fn new(config: ShaperConfig) -> Result<Self, ConfigError> {
        config.validate()?;
        Ok(LinkShaper {
            config,
            chunk_bytes: config.mtu_bytes - DATA_HEADER_BYTES,
            bucket: Bucket::new(config.rate_bps, config.burst_bytes),
            lanes: Class::ALL
                .iter()
                .map(|c| Lane::new(*config.class(*c)))
                .collect(),
            lane_classes: Class::ALL.to_vec(),
            order: (0..Class::ALL.len()).collect(),
            lane_stats: Vec::new(),
            peers: BTreeSet::new(),
            next_id: 0,
            pending_acks: VecDeque::new(),
            stats: ShaperStats::default(),
        })
    }

    /// A shaper that resumes from `state` (see [`DurableState`]): message ids go on
    /// from `state.next_id`, every stored message is kept for the recipients still
    /// missing it, even beyond the class capacity (what was accepted is never
    /// dropped), and is sent again as if new. A stored message whose class is no
    /// longer store-and-forward in `config` joins that class's queue.
    pub fn restore(config: ShaperConfig, state: &DurableState) -> Result<Self, ConfigError> {
        let mut shaper = LinkShaper::new(config)?;
        shaper.resume(state);
        Ok(shaper)
    }

    /// Takes up `state` on a fresh shaper, as [`restore`](Self::restore) does; add
    /// the extra lanes first, in the same order as before, so that their messages
    /// return to them (a message of a lane that does not exist joins its class's
    /// own queue).
    pub fn resume(&mut self, state: &DurableState) {
        self.next_id = state.next_id;
        for &peer in &state.peers {
            self.add_peer(peer);
        }
        let chunk = self.chunk_bytes;
        for m in &state.stored {
            let count = u16::try_from(m.bytes.len().div_ceil(chunk).max(1)).unwrap_or(u16::MAX);
            let lane = m
                .lane
                .map(|l| Class::ALL.len() + usize::from(l.0))
                .filter(|l| *l < self.lanes.len() && self.lane_classes[*l] == m.class)
                .unwrap_or(m.class.index());
            match &mut self.lanes[lane] {
                Lane::Store(store) => store.push_for(
                    m.id.0,
                    m.bytes.clone(),
                    m.offered_ns,
                    count,
                    m.missing.iter().copied().collect(),
                ),
                Lane::Queue(queue) => {
                    queue.bytes += m.bytes.len();
                    queue.messages.push_back(Pending {
                        id: m.id.0,
                        bytes: m.bytes.to_vec(),
                        offered_ns: m.offered_ns,
                        count,
                        to: None,
                    });
                }
            }
        }
    }

    /// Adds a lane of its own for one kind of message (a shared topic): the
    /// `config` policy and capacity, at `class`'s priority after that class's own
    /// queue and the lanes added before it. Offer to it with
    /// [`offer_to_lane`](Self::offer_to_lane).
    pub fn add_lane(&mut self, class: Class, config: ClassConfig) -> Result<LaneId, ConfigError> {
        let id = u16::try_from(self.lane_stats.len())
            .map_err(|_| ConfigError::new("lanes", "at most 65 536 extra lanes", "more"))?;
        config.validate("lane")?;
        let mut lane = Lane::new(config);
        if let Lane::Store(store) = &mut lane {
            for peer in self.peers() {
                store.add_peer(peer);
            }
        }
        self.lanes.push(lane);
        self.lane_classes.push(class);
        self.lane_stats.push(ClassStats::default());
        let classes = &self.lane_classes;
        self.order = (0..self.lanes.len()).collect();
        self.order.sort_by_key(|&l| (classes[l].index(), l));
        Ok(LaneId(id))
    }

    /// Counters of an extra lane (`None` for a lane that was never added).
    #[must_use]
    pub fn lane_stats(&self, lane: LaneId) -> Option<&ClassStats> {
        self.lane_stats.get(usize::from(lane.0))
    }

    /// Messages held by an extra lane.
    #[must_use]
    pub fn lane_queued_messages(&self, lane: LaneId) -> usize {
        match self.lanes.get(Class::ALL.len() + usize::from(lane.0)) {
            Some(Lane::Queue(q)) => q.messages.len(),
            Some(Lane::Store(s)) => s.len(),
            None => 0,
        }
    }

    /// The counters of a lane by index (a class's own, or an extra one).
    fn stats_of(&mut self, lane: usize) -> &mut ClassStats {
        match lane.checked_sub(Class::ALL.len()) {
            Some(extra) => &mut self.lane_stats[extra],
            None => &mut self.stats.classes[lane],
        }
    }

    /// What must survive a restart ([`DurableState`]); cheap (message bytes are shared).
    #[must_use]
    pub fn durable_state(&self) -> DurableState {
        let mut stored = Vec::new();
        for (index, (class, lane)) in self.lane_classes.iter().zip(&self.lanes).enumerate() {
            if let Lane::Store(s) = lane {
                let extra = index
                    .checked_sub(Class::ALL.len())
                    .map(|l| LaneId(l as u16));
                stored.extend(s.snapshot().map(|(id, bytes, offered_ns, missing)| {
                    DurableMessage {
                        class: *class,
                        lane: extra,
                        id: MessageId(id),
                        bytes,
                        offered_ns,
                        missing,
                    }
                }));
            }
        }
        DurableState {
            next_id: self.next_id,
            peers: self.peers(),
            stored,
        }
    }

    /// Changes whenever [`durable_state`](Self::durable_state)'s peers or stored
    /// messages do (not with `next_id`): a caller keeping a journal copies the
    /// stored messages only when it moved.
    #[must_use]
    pub fn store_generation(&self) -> u64 {
        self.lanes
            .iter()
            .map(|lane| match lane {
                Lane::Store(s) => s.generation(),
                Lane::Queue(_) => 0,
            })
            .sum()
    }

    /// The id the next offered message gets.
    #[must_use]
    pub fn next_id(&self) -> MessageId {
        MessageId(self.next_id)
    }

    /// The settings.
    #[must_use]
    pub fn config(&self) -> &ShaperConfig {
        &self.config
    }

    /// Counters so far.
    #[must_use]
    pub fn stats(&self) -> &ShaperStats {
        &self.stats
    }

    /// Messages held by a class (waiting, partly sent, or stored unacknowledged).
    #[must_use]
    pub fn queued_messages(&self, class: Class) -> usize {
        match &self.lanes[class.index()] {
            Lane::Queue(q) => q.messages.len(),
            Lane::Store(s) => s.len(),
        }
    }

    /// Bytes held by a class.
    #[must_use]
    pub fn queued_bytes(&self, class: Class) -> usize {
        match &self.lanes[class.index()] {
            Lane::Queue(q) => q.bytes,
            Lane::Store(s) => s.bytes(),
        }
    }

    /// Adds a peer as a recipient of store-and-forward messages: of every message
    /// offered from now on, and of everything still stored (a newly heard peer
    /// gets the backlog). Store-and-forward messages offered while no peer is
    /// known wait for the first. A [suspended](Self::suspend_peer) peer rejoins
    /// and gets what it missed. Returns false if the peer was known and active.
    pub fn add_peer(&mut self, peer: u32) -> bool {
        let mut added = self.peers.insert(peer);
        for lane in &mut self.lanes {
            if let Lane::Store(s) = lane {
                added |= s.add_peer(peer);
            }
        }
        added
    }

    /// Removes a peer (for example one silent for too long): every stored message
    /// it had not acknowledged is given up for it, counted once per message as
    /// [`DropReason::PeerRemoved`]; messages no other peer misses are released.
    /// Returns how many were given up.
    pub fn remove_peer(&mut self, peer: u32) -> u64 {
        self.peers.remove(&peer);
        let mut total = 0;
        for lane in 0..self.lanes.len() {
            if let Lane::Store(s) = &mut self.lanes[lane] {
                let given_up = s.remove_peer(peer);
                self.stats_of(lane).drops.peer_removed += given_up;
                total += given_up;
            }
        }
        total
    }

    /// Stops sending store-and-forward messages to `peer` (silent for too long)
    /// while keeping, within its own bounds, what it misses: it rejoins with
    /// [`add_peer`](Self::add_peer) and then gets its backlog, oldest first.
    /// Returns false if it was not an active recipient.
    pub fn suspend_peer(&mut self, peer: u32) -> bool {
        let mut suspended = false;
        for lane in &mut self.lanes {
            if let Lane::Store(s) = lane {
                suspended |= s.suspend_peer(peer);
            }
        }
        suspended
    }

    /// The suspended peers ([`suspend_peer`](Self::suspend_peer)).
    #[must_use]
    pub fn suspended_peers(&self) -> Vec<u32> {
        let mut peers = BTreeSet::new();
        for lane in &self.lanes {
            if let Lane::Store(s) = lane {
                peers.extend(s.suspended());
            }
        }
        peers.into_iter().collect()
    }

    /// Messages and bytes a class's store holds for `peer` (its pending set, bounded
    /// by the class capacity on its own); (0, 0) for a class that is not stored.
    #[must_use]
    pub fn pending_for(&self, class: Class, peer: u32) -> (usize, usize) {
        match &self.lanes[class.index()] {
            Lane::Store(s) => s.pending(peer),
            Lane::Queue(_) => (0, 0),
        }
    }

    /// The peers store-and-forward messages are kept for.
    #[must_use]
    pub fn peers(&self) -> Vec<u32> {
        let mut peers = self.peers.clone();
        for lane in &self.lanes {
            if let Lane::Store(s) = lane {
                peers.extend(s.peers());
            }
        }
        peers.into_iter().collect()
    }

    /// Offers an encoded message (an envelope from [`wire::encode`](crate::wire::encode)).
    pub fn offer(
        &mut self,
        now_ns: u64,
        class: Class,
        message: Vec<u8>,
    ) -> Result<MessageId, Refused> {
        self.offer_at(now_ns, class.index(), None, message)
    }

    /// Offers an encoded message to an extra lane ([`add_lane`](Self::add_lane)),
    /// for every peer or, with `to`, for one (its frames are addressed to it; a
    /// store-and-forward lane keeps it for that peer only). A lane that was never
    /// added refuses it as too large for a 0-byte capacity.
    pub fn offer_to_lane(
        &mut self,
        now_ns: u64,
        lane: LaneId,
        to: Option<u32>,
        message: Vec<u8>,
    ) -> Result<MessageId, Refused> {
        let index = Class::ALL.len() + usize::from(lane.0);
        if index >= self.lanes.len() {
            return Err(Refused::TooLarge {
                bytes: message.len(),
                limit: 0,
            });
        }
        self.offer_at(now_ns, index, to, message)
    }

    fn offer_at(
        &mut self,
        now_ns: u64,
        lane: usize,
        to: Option<u32>,
        message: Vec<u8>,
    ) -> Result<MessageId, Refused> {
        let len = message.len();
        let chunk = self.chunk_bytes;
        let stats = match lane.checked_sub(Class::ALL.len()) {
            Some(extra) => &mut self.lane_stats[extra],
            None => &mut self.stats.classes[lane],
        };
        stats.offered_messages += 1;
        stats.offered_bytes += len as u64;
        let config = match &self.lanes[lane] {
            Lane::Queue(q) => q.config,
            Lane::Store(s) => *s.config(),
        };
        let limit = config.capacity_bytes.min(chunk * usize::from(u16::MAX));
        if len > limit {
            stats.drops.count(DropReason::TooLarge);
            return Err(Refused::TooLarge { bytes: len, limit });
        }
        let count = len.div_ceil(chunk).max(1) as u16;
        let id = self.next_id;
        match &mut self.lanes[lane] {
            Lane::Store(store) => {
                let Some(admission) = store.admit(len, to) else {
                    stats.drops.count(DropReason::StoreFull);
                    return Err(Refused::StoreFull);
                };
                stats.drops.peer_full += admission.skipped;
                store.push_for(id, message.into(), now_ns, count, admission.recipients);
            }
            Lane::Queue(queue) => {
                if queue.config.policy == QueuePolicy::KeepLatest {
                    while let Some(i) = queue.first_droppable() {
                        queue.remove(i);
                        stats.drops.count(DropReason::Superseded);
                    }
                } else {
                    while queue.messages.len() >= queue.config.capacity_messages
                        || queue.bytes + len > queue.config.capacity_bytes
                    {
                        let Some(i) = queue.first_droppable() else {
                            break; // only the message being sent is left
                        };
                        queue.remove(i);
                        stats.drops.count(DropReason::Overflow);
                    }
                }
                queue.bytes += len;
                queue.messages.push_back(Pending {
                    id,
                    bytes: message,
                    offered_ns: now_ns,
                    count,
                    to,
                });
            }
        }
        self.next_id = self.next_id.wrapping_add(1);
        Ok(MessageId(id))
    }

    /// Records that `peer` has a store-and-forward message (from an ack frame it
    /// sent back). The message leaves the store once every intended recipient has
    /// it. Only a message already sent to `peer` can be acknowledged by it.
    pub fn acknowledge(&mut self, now_ns: u64, peer: u32, id: MessageId) -> AckOutcome {
        let mut outcome = AckOutcome::Unknown;
        for lane in 0..self.lanes.len() {
            let Lane::Store(store) = &mut self.lanes[lane] else {
                continue;
            };
            match store.acknowledge(now_ns, peer, id.0) {
                StoreAck::Recorded(released) => {
                    if released {
                        self.stats_of(lane).acknowledged_messages += 1;
                    }
                    return AckOutcome::Recorded;
                }
                StoreAck::NotSent => outcome = AckOutcome::NotSent,
                StoreAck::Unknown => {}
            }
        }
        outcome
    }

    /// Queues an acknowledgement for `peer` (of a message it sent with the
    /// acknowledge-me flag, see [`ReassembledMessage::ack_requested`]). Acks
    /// travel ahead of every class, batched per peer, addressed to that peer
    /// only (message ids are per sender).
    pub fn queue_ack(&mut self, peer: u32, id: u32) {
        self.pending_acks.push_back((peer, id));
    }

    fn run_timers(&mut self, now_ns: u64) {
        self.bucket.refill(now_ns);
        for lane in &mut self.lanes {
            if let Lane::Store(s) = lane {
                s.run_timers(now_ns);
            }
        }
    }

    fn max_acks_per_frame(&self) -> usize {
        ((self.config.mtu_bytes - ACK_HEADER_BYTES) / 4).min(usize::from(u16::MAX))
    }

    fn fragment_len(&self, bytes: usize, fragment: u16) -> usize {
        let start = usize::from(fragment) * self.chunk_bytes;
        DATA_HEADER_BYTES + (start + self.chunk_bytes).min(bytes) - start
    }

    /// The next frame by priority, and its size.
    fn select(&self) -> Option<Next> {
        if let Some(&(peer, _)) = self.pending_acks.front() {
            let n = self
                .pending_acks
                .iter()
                .filter(|(p, _)| *p == peer)
                .count()
                .min(self.max_acks_per_frame());
            return Some(Next::Ack(peer, n));
        }
        for &index in &self.order {
            match &self.lanes[index] {
                Lane::Queue(q) => {
                    if let Some(p) = q.messages.front() {
                        let len = self.fragment_len(p.bytes.len(), q.next_fragment);
                        return Some(Next::Queued(index, len));
                    }
                }
                Lane::Store(s) => {
                    if let Some(next) = s.next() {
                        let len =
                            self.fragment_len(s.message(next.index).bytes.len(), next.fragment);
                        return Some(Next::Stored(index, len, next));
                    }
                }
            }
        }
        None
    }

    fn frame_len(next: &Next) -> usize {
        match next {
            Next::Ack(_, n) => ACK_HEADER_BYTES + 4 * n,
            Next::Queued(_, len) | Next::Stored(_, len, _) => *len,
        }
    }

    /// The earliest time at or after `now_ns` at which [`poll`](Self::poll) may
    /// return a frame: now, when the bucket will hold the next frame, or when a
    /// store-and-forward retransmission falls due. `None` when there is nothing
    /// to send and no retransmission pending.
    pub fn next_send_time(&mut self, now_ns: u64) -> Option<u64> {
        self.run_timers(now_ns);
        let by_bucket = self.select().map(|next| {
            let cost = Self::frame_len(&next) as u64 + self.config.frame_overhead_bytes;
            now_ns.saturating_add(self.bucket.wait_ns(cost))
        });
        let by_timer = self
            .lanes
            .iter()
            .filter_map(|lane| match lane {
                Lane::Store(s) => s.next_deadline(),
                Lane::Queue(_) => None,
            })
            .min();
        match (by_bucket, by_timer) {
            (Some(a), Some(b)) => Some(a.min(b.max(now_ns))),
            (a, b) => a.or(b.map(|b| b.max(now_ns))),
        }
    }

    /// The next frame, if the bucket allows one at `now_ns`.
    pub fn poll(&mut self, now_ns: u64) -> Option<Frame> {
        self.run_timers(now_ns);
        let next = self.select()?;
        let len = Self::frame_len(&next);
        let cost = len as u64 + self.config.frame_overhead_bytes;
        if self.bucket.wait_ns(cost) > 0 {
            return None;
        }
        self.bucket.take(cost);
        match next {
            Next::Ack(peer, n) => {
                let mut ids = Vec::with_capacity(n);
                self.pending_acks.retain(|&(p, id)| {
                    if p == peer && ids.len() < n {
                        ids.push(id);
                        false
                    } else {
                        true
                    }
                });
                let bytes = frame::ack_frame(&ids);
                self.stats.ack_frames += 1;
                self.stats.ack_bytes += bytes.len() as u64;
                Some(Frame {
                    class: Class::Odometry,
                    kind: FrameKind::Ack { ids: n as u16 },
                    to: Some(peer),
                    bytes,
                })
            }
            Next::Queued(lane, _) | Next::Stored(lane, _, _) => {
                let class = self.lane_classes[lane];
                let stats = match lane.checked_sub(Class::ALL.len()) {
                    Some(extra) => {
                        self.stats.lane_sent_bytes += len as u64;
                        &mut self.lane_stats[extra]
                    }
                    None => &mut self.stats.classes[lane],
                };
                match (&mut self.lanes[lane], &next) {
                    (Lane::Queue(q), Next::Queued(..)) => {
                        Some(send_queued(q, stats, self.chunk_bytes, now_ns, class))
                    }
                    (Lane::Store(s), Next::Stored(_, _, which)) => Some(send_stored(
                        s,
                        stats,
                        self.chunk_bytes,
                        now_ns,
                        class,
                        which,
                    )),
                    _ => None,
                }
            }
        }
    }
}

/// Counts a message's first complete transmission.
fn record_first(stats: &mut ClassStats, now_ns: u64, offered_ns: u64) {
    stats.sent_messages += 1;
    stats
        .completion_delay
        .record(now_ns.saturating_sub(offered_ns));
    stats.age.record(now_ns, offered_ns);
}

/// Sends the next fragment of a plain queue's front message (`select` found one).
fn send_queued(
    queue: &mut ClassQueue,
    stats: &mut ClassStats,
    chunk_bytes: usize,
    now_ns: u64,
    class: Class,
) -> Frame {
    let index = queue.next_fragment;
    // `select` found a front message.
    let p = &queue.messages[0];
    if index == 0 {
        stats
            .queue_delay
            .record(now_ns.saturating_sub(p.offered_ns));
    }
    let start = usize::from(index) * chunk_bytes;
    let end = (start + chunk_bytes).min(p.bytes.len());
    let header = DataHeader {
        class,
        ack_requested: false,
        message_id: p.id,
        index,
        count: p.count,
    };
    let bytes = frame::data_frame(&header, &p.bytes[start..end]);
    let (id, count, offered_ns, to) = (p.id, p.count, p.offered_ns, p.to);
    stats.sent_frames += 1;
    stats.sent_bytes += bytes.len() as u64;
    if index + 1 == count {
        queue.next_fragment = 0;
        queue.remove(0);
        record_first(stats, now_ns, offered_ns);
    } else {
        queue.next_fragment = index + 1;
    }
    Frame {
        class,
        kind: FrameKind::Data {
            message_id: id,
            index,
            count,
        },
        to,
        bytes,
    }
}

/// Sends the store's chosen fragment (`select` found it).
fn send_stored(
    store: &mut Store,
    stats: &mut ClassStats,
    chunk_bytes: usize,
    now_ns: u64,
    class: Class,
    next: &NextFragment,
) -> Frame {
    let transmissions = store.sent(now_ns, next);
    let p = store.message(next.index);
    let index = next.fragment;
    if index == 0 {
        if transmissions == 1 {
            stats
                .queue_delay
                .record(now_ns.saturating_sub(p.offered_ns));
        } else {
            stats.retransmitted_messages += 1;
        }
    }
    let start = usize::from(index) * chunk_bytes;
    let end = (start + chunk_bytes).min(p.bytes.len());
    let header = DataHeader {
        class,
        ack_requested: true,
        message_id: p.id,
        index,
        count: p.count,
    };
    let bytes = frame::data_frame(&header, &p.bytes[start..end]);
    stats.sent_frames += 1;
    stats.sent_bytes += bytes.len() as u64;
    if index + 1 == p.count && transmissions == 1 {
        record_first(stats, now_ns, p.offered_ns);
    }
    Frame {
        class,
        kind: FrameKind::Data {
            message_id: p.id,
            index,
            count: p.count,
        },
        to: next.to,
        bytes,
    }
}

#[cfg(test)]
mod tests;
