//! Bounded per-subscription input queues.

use std::collections::VecDeque;

use serde::{Deserialize, Serialize};

/// What a subscription keeps when messages arrive faster than its actor handles them.
///
/// Every queue is bounded; what does not fit is dropped and counted, never silently.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum QueuePolicy {
    /// Keep the newest `depth` messages; an arrival into a full queue evicts the oldest.
    /// Right for streams where only the latest value matters (frames, odometry).
    KeepLatest {
        /// Capacity (at least 1).
        depth: usize,
    },
    /// Keep messages in arrival order up to `capacity`; an arrival into a full queue
    /// is rejected. Right for streams where every item matters and order is meaning
    /// (keyframes).
    Fifo {
        /// Capacity (at least 1).
        capacity: usize,
    },
    /// Like [`Fifo`](QueuePolicy::Fifo), and also at most `max_bytes` of queued
    /// payload ([`Message::payload_bytes`](crate::Message::payload_bytes)): an
    /// arrival that would pass either bound is rejected (one arrival into an empty
    /// queue is always taken). Right for input a stranger controls (received
    /// network frames), whose items may be large.
    FifoBytes {
        /// Capacity in messages (at least 1).
        capacity: usize,
        /// Capacity in payload bytes.
        max_bytes: usize,
    },
}

impl QueuePolicy {
    /// Keep only the newest message.
    pub const LATEST: QueuePolicy = QueuePolicy::KeepLatest { depth: 1 };

    /// A FIFO queue of the given capacity.
    #[must_use]
    pub const fn fifo(capacity: usize) -> Self {
        QueuePolicy::Fifo { capacity }
    }

    /// A FIFO queue bounded in messages and in payload bytes.
    #[must_use]
    pub const fn fifo_bytes(capacity: usize, max_bytes: usize) -> Self {
        QueuePolicy::FifoBytes {
            capacity,
            max_bytes,
        }
    }

    fn capacity(self) -> usize {
        match self {
            QueuePolicy::KeepLatest { depth } => depth.max(1),
            QueuePolicy::Fifo { capacity } | QueuePolicy::FifoBytes { capacity, .. } => {
                capacity.max(1)
            }
        }
    }

    fn max_bytes(self) -> usize {
        match self {
            QueuePolicy::FifoBytes { max_bytes, .. } => max_bytes,
            _ => usize::MAX,
        }
    }
}

/// A bounded queue that applies a [`QueuePolicy`] and counts what it drops.
///
/// Items carry an arrival sequence number so that an actor with several
/// subscriptions handles its inputs in global arrival order.
#[derive(Debug)]
pub(crate) struct BoundedQueue<T> {
    policy: QueuePolicy,
    /// Arrival, item, its payload bytes.
    items: VecDeque<(u64, T, usize)>,
    /// Payload bytes queued.
    bytes: usize,
    dropped: u64,
}

impl<T> BoundedQueue<T> {
    pub(crate) fn new(policy: QueuePolicy) -> Self {
        BoundedQueue {
            policy,
            items: VecDeque::with_capacity(policy.capacity().min(64)),
            bytes: 0,
            dropped: 0,
        }
    }

    /// Offers an item of no counted size; returns `true` if it was accepted.
    #[cfg(test)]
    pub(crate) fn push(&mut self, arrival: u64, item: T) -> bool {
        self.push_sized(arrival, item, 0)
    }

    /// Offers an item of `bytes` payload bytes; returns `true` if it was accepted.
    pub(crate) fn push_sized(&mut self, arrival: u64, item: T, bytes: usize) -> bool {
        let fits_bytes =
            self.items.is_empty() || self.bytes.saturating_add(bytes) <= self.policy.max_bytes();
        if self.items.len() < self.policy.capacity() && fits_bytes {
            self.bytes += bytes;
            self.items.push_back((arrival, item, bytes));
            return true;
        }
        self.dropped += 1;
        match self.policy {
            QueuePolicy::KeepLatest { .. } => {
                self.pop();
                self.bytes += bytes;
                self.items.push_back((arrival, item, bytes));
                true
            }
            QueuePolicy::Fifo { .. } | QueuePolicy::FifoBytes { .. } => false,
        }
    }

    pub(crate) fn front_arrival(&self) -> Option<u64> {
        self.items.front().map(|(seq, _, _)| *seq)
    }

    pub(crate) fn pop(&mut self) -> Option<T> {
        let (_, item, bytes) = self.items.pop_front()?;
        self.bytes -= bytes;
        Some(item)
    }

    pub(crate) fn len(&self) -> usize {
        self.items.len()
    }

    pub(crate) fn dropped(&self) -> u64 {
        self.dropped
    }

    pub(crate) fn set_policy(&mut self, policy: QueuePolicy) {
        self.policy = policy;
        while self.items.len() > policy.capacity()
            || (self.items.len() > 1 && self.bytes > policy.max_bytes())
        {
            self.pop();
            self.dropped += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keep_latest_evicts_oldest_and_counts() {
        let mut q = BoundedQueue::new(QueuePolicy::KeepLatest { depth: 2 });
        for i in 0..5 {
            assert!(q.push(i, i));
        }
        assert_eq!(q.dropped(), 3);
        assert_eq!(q.pop(), Some(3));
        assert_eq!(q.pop(), Some(4));
        assert_eq!(q.pop(), None);
    }

    #[test]
    fn fifo_rejects_newest_when_full() {
        let mut q = BoundedQueue::new(QueuePolicy::fifo(2));
        assert!(q.push(0, 'a'));
        assert!(q.push(1, 'b'));
        assert!(!q.push(2, 'c'));
        assert_eq!(q.dropped(), 1);
        assert_eq!(q.front_arrival(), Some(0));
        assert_eq!(q.pop(), Some('a'));
        assert_eq!(q.pop(), Some('b'));
    }

    #[test]
    fn fifo_bytes_rejects_what_passes_either_bound() {
        let mut q = BoundedQueue::new(QueuePolicy::fifo_bytes(3, 100));
        // One item larger than the byte bound is taken into an empty queue.
        assert!(q.push_sized(0, 'a', 150));
        assert!(!q.push_sized(1, 'b', 1));
        assert_eq!(q.pop(), Some('a'));
        assert!(q.push_sized(2, 'c', 60));
        assert!(q.push_sized(3, 'd', 40));
        assert!(!q.push_sized(4, 'e', 1), "100 bytes queued: full");
        assert_eq!(q.pop(), Some('c'));
        assert!(q.push_sized(5, 'f', 10));
        assert!(q.push_sized(6, 'g', 0));
        assert!(!q.push_sized(7, 'h', 0), "three messages: full");
        assert_eq!(q.dropped(), 3);
        assert_eq!(q.len(), 3);
    }

    #[test]
    fn zero_capacity_means_one() {
        let mut q = BoundedQueue::new(QueuePolicy::Fifo { capacity: 0 });
        assert!(q.push(0, 1));
        assert!(!q.push(1, 2));
        assert_eq!(q.len(), 1);
    }
}
