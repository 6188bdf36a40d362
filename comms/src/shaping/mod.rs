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
//!   store-and-forward (acknowledged, in-order go-back-N retransmission, bounded
//!   store that refuses rather than drops).
//! - **Counters** ([`ShaperStats`]): drops by reason, queue delay, completion delay
//!   and age of information per class.
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

use std::collections::VecDeque;

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
use config::s_to_ns;
use frame::{ACK_HEADER_BYTES, DATA_HEADER_BYTES, DataHeader};

/// Per-link message id, increasing by one per offer (wrapping).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct MessageId(pub u32);

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
    /// Store-and-forward store full; nothing stored was dropped.
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

/// A message waiting in (or stored by) a class queue.
#[derive(Clone, Debug)]
struct Pending {
    id: u32,
    bytes: Vec<u8>,
    offered_ns: u64,
    count: u16,
    /// Transmissions started (the first counts).
    transmissions: u32,
}

/// One class: a deque whose front part `[0, cursor)` is, for store-and-forward,
/// sent and awaiting acknowledgement; the message at `cursor` is the next to
/// send, `next_fragment` fragments of it already sent. For the other policies
/// `cursor` stays 0 and fully sent messages leave the deque.
#[derive(Clone, Debug)]
struct ClassQueue {
    config: ClassConfig,
    messages: VecDeque<Pending>,
    bytes: usize,
    cursor: usize,
    next_fragment: u16,
    deadline_ns: Option<u64>,
    timeout_ns: u64,
}

impl ClassQueue {
    fn new(config: ClassConfig) -> Self {
        ClassQueue {
            config,
            messages: VecDeque::new(),
            bytes: 0,
            cursor: 0,
            next_fragment: 0,
            deadline_ns: None,
            timeout_ns: s_to_ns(config.retransmit_timeout_s),
        }
    }

    fn saf(&self) -> bool {
        self.config.policy == QueuePolicy::StoreAndForward
    }

    /// Store-and-forward: go back to the oldest unacknowledged message when its
    /// acknowledgement is overdue. Returns true if it did.
    fn run_timers(&mut self, now_ns: u64) -> bool {
        if !self.saf() {
            return false;
        }
        match self.deadline_ns {
            Some(d) if d <= now_ns && self.cursor > 0 => {
                self.cursor = 0;
                self.next_fragment = 0;
                self.deadline_ns = None;
                let max = s_to_ns(self.config.retransmit_timeout_max_s);
                self.timeout_ns = self.timeout_ns.saturating_mul(2).min(max);
                true
            }
            _ => false,
        }
    }

    /// The message to send a fragment of next, if the policy allows one now.
    fn sendable(&self) -> Option<&Pending> {
        if self.saf() && self.cursor >= self.config.window_messages {
            return None;
        }
        self.messages.get(self.cursor)
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

/// Shapes one directed link. See the [module docs](self).
#[derive(Clone, Debug)]
pub struct LinkShaper {
    config: ShaperConfig,
    chunk_bytes: usize,
    bucket: Bucket,
    classes: [ClassQueue; 4],
    next_id: u32,
    pending_acks: VecDeque<u32>,
    stats: ShaperStats,
}

/// What [`LinkShaper::poll`] would send next.
enum Next {
    Ack(usize),
    Data(Class, usize),
}

impl LinkShaper {
    /// A shaper with validated settings; the bucket starts full at time 0.
    pub fn new(config: ShaperConfig) -> Result<Self, ConfigError> {
        config.validate()?;
        Ok(LinkShaper {
            config,
            chunk_bytes: config.mtu_bytes - DATA_HEADER_BYTES,
            bucket: Bucket::new(config.rate_bps, config.burst_bytes),
            classes: Class::ALL.map(|c| ClassQueue::new(*config.class(c))),
            next_id: 0,
            pending_acks: VecDeque::new(),
            stats: ShaperStats::default(),
        })
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
        self.classes[class.index()].messages.len()
    }

    /// Bytes held by a class.
    #[must_use]
    pub fn queued_bytes(&self, class: Class) -> usize {
        self.classes[class.index()].bytes
    }

    /// Offers an encoded message (an envelope from [`wire::encode`](crate::wire::encode)).
    pub fn offer(
        &mut self,
        now_ns: u64,
        class: Class,
        message: Vec<u8>,
    ) -> Result<MessageId, Refused> {
        let len = message.len();
        let chunk = self.chunk_bytes;
        let stats = &mut self.stats.classes[class.index()];
        stats.offered_messages += 1;
        stats.offered_bytes += len as u64;
        let queue = &mut self.classes[class.index()];
        let limit = queue
            .config
            .capacity_bytes
            .min(chunk * usize::from(u16::MAX));
        if len > limit {
            stats.drops.count(DropReason::TooLarge);
            return Err(Refused::TooLarge { bytes: len, limit });
        }
        match queue.config.policy {
            QueuePolicy::KeepLatest => {
                while let Some(i) = queue.first_droppable() {
                    queue.remove(i);
                    stats.drops.count(DropReason::Superseded);
                }
            }
            QueuePolicy::DropOldest => {
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
            QueuePolicy::StoreAndForward => {
                if queue.messages.len() >= queue.config.capacity_messages
                    || queue.bytes + len > queue.config.capacity_bytes
                {
                    stats.drops.count(DropReason::StoreFull);
                    return Err(Refused::StoreFull);
                }
            }
        }
        let id = self.next_id;
        self.next_id = self.next_id.wrapping_add(1);
        let count = len.div_ceil(chunk).max(1) as u16;
        queue.bytes += len;
        queue.messages.push_back(Pending {
            id,
            bytes: message,
            offered_ns: now_ns,
            count,
            transmissions: 0,
        });
        Ok(MessageId(id))
    }

    /// Records that the peer has a store-and-forward message (from an ack frame
    /// it sent back). Returns false if no stored message has that id.
    pub fn acknowledge(&mut self, now_ns: u64, id: MessageId) -> bool {
        for (ci, queue) in self.classes.iter_mut().enumerate() {
            if !queue.saf() {
                continue;
            }
            let Some(i) = queue.messages.iter().position(|p| p.id == id.0) else {
                continue;
            };
            queue.remove(i);
            if i < queue.cursor {
                queue.cursor -= 1;
            } else if i == queue.cursor {
                queue.next_fragment = 0;
            }
            // Progress: back to the initial timeout, timer restarted.
            queue.timeout_ns = s_to_ns(queue.config.retransmit_timeout_s);
            queue.deadline_ns = (queue.cursor > 0).then(|| now_ns + queue.timeout_ns);
            self.stats.classes[ci].acknowledged_messages += 1;
            return true;
        }
        false
    }

    /// Queues an acknowledgement for the peer (of a message it sent with the
    /// acknowledge-me flag, see [`ReassembledMessage::ack_requested`]). Acks
    /// travel ahead of every class, batched.
    pub fn queue_ack(&mut self, id: u32) {
        self.pending_acks.push_back(id);
    }

    fn run_timers(&mut self, now_ns: u64) {
        self.bucket.refill(now_ns);
        for q in &mut self.classes {
            q.run_timers(now_ns);
        }
    }

    fn max_acks_per_frame(&self) -> usize {
        ((self.config.mtu_bytes - ACK_HEADER_BYTES) / 4).min(usize::from(u16::MAX))
    }

    /// The next frame by priority, and its size.
    fn select(&self) -> Option<Next> {
        if !self.pending_acks.is_empty() {
            let n = self.pending_acks.len().min(self.max_acks_per_frame());
            return Some(Next::Ack(n));
        }
        for (class, queue) in Class::ALL.iter().zip(&self.classes) {
            if let Some(p) = queue.sendable() {
                let start = usize::from(queue.next_fragment) * self.chunk_bytes;
                let end = (start + self.chunk_bytes).min(p.bytes.len());
                return Some(Next::Data(*class, DATA_HEADER_BYTES + end - start));
            }
        }
        None
    }

    fn frame_len(next: &Next) -> usize {
        match next {
            Next::Ack(n) => ACK_HEADER_BYTES + 4 * n,
            Next::Data(_, len) => *len,
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
            .classes
            .iter()
            .filter(|q| q.cursor > 0)
            .filter_map(|q| q.deadline_ns)
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
            Next::Ack(n) => {
                let ids: Vec<u32> = self.pending_acks.drain(..n).collect();
                let bytes = frame::ack_frame(&ids);
                self.stats.ack_frames += 1;
                self.stats.ack_bytes += bytes.len() as u64;
                Some(Frame {
                    class: Class::Odometry,
                    kind: FrameKind::Ack { ids: n as u16 },
                    bytes,
                })
            }
            Next::Data(class, _) => Some(self.send_fragment(now_ns, class)),
        }
    }

    fn send_fragment(&mut self, now_ns: u64, class: Class) -> Frame {
        let chunk_bytes = self.chunk_bytes;
        let queue = &mut self.classes[class.index()];
        let stats = &mut self.stats.classes[class.index()];
        let index = queue.next_fragment;
        let cursor = queue.cursor;
        let saf = queue.saf();
        // `select` found a message at `cursor`.
        let p = &mut queue.messages[cursor];
        if index == 0 {
            p.transmissions += 1;
            if p.transmissions == 1 {
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
            ack_requested: saf,
            message_id: p.id,
            index,
            count: p.count,
        };
        let bytes = frame::data_frame(&header, &p.bytes[start..end]);
        let (id, count, offered_ns, first) = (p.id, p.count, p.offered_ns, p.transmissions == 1);
        stats.sent_frames += 1;
        stats.sent_bytes += bytes.len() as u64;
        if index + 1 == count {
            queue.next_fragment = 0;
            if first {
                stats.sent_messages += 1;
                stats
                    .completion_delay
                    .record(now_ns.saturating_sub(offered_ns));
                stats.age.record(now_ns, offered_ns);
            }
            if saf {
                queue.cursor += 1;
                if queue.deadline_ns.is_none() {
                    queue.deadline_ns = Some(now_ns + queue.timeout_ns);
                }
            } else {
                queue.remove(0);
            }
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
            bytes,
        }
    }
}

#[cfg(test)]
mod tests;
