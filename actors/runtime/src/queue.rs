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
}

impl QueuePolicy {
    /// Keep only the newest message.
    pub const LATEST: QueuePolicy = QueuePolicy::KeepLatest { depth: 1 };

    /// A FIFO queue of the given capacity.
    #[must_use]
    pub const fn fifo(capacity: usize) -> Self {
        QueuePolicy::Fifo { capacity }
    }

    fn capacity(self) -> usize {
        match self {
            QueuePolicy::KeepLatest { depth } => depth.max(1),
            QueuePolicy::Fifo { capacity } => capacity.max(1),
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
    items: VecDeque<(u64, T)>,
    dropped: u64,
}

impl<T> BoundedQueue<T> {
    pub(crate) fn new(policy: QueuePolicy) -> Self {
        BoundedQueue {
            policy,
            items: VecDeque::with_capacity(policy.capacity().min(64)),
            dropped: 0,
        }
    }

    /// Offers an item; returns `true` if it was accepted.
    pub(crate) fn push(&mut self, arrival: u64, item: T) -> bool {
        if self.items.len() < self.policy.capacity() {
            self.items.push_back((arrival, item));
            return true;
        }
        self.dropped += 1;
        match self.policy {
            QueuePolicy::KeepLatest { .. } => {
                self.items.pop_front();
                self.items.push_back((arrival, item));
                true
            }
            QueuePolicy::Fifo { .. } => false,
        }
    }

    pub(crate) fn front_arrival(&self) -> Option<u64> {
        self.items.front().map(|(seq, _)| *seq)
    }

    pub(crate) fn pop(&mut self) -> Option<T> {
        self.items.pop_front().map(|(_, item)| item)
    }

    pub(crate) fn len(&self) -> usize {
        self.items.len()
    }

    pub(crate) fn dropped(&self) -> u64 {
        self.dropped
    }

    pub(crate) fn set_policy(&mut self, policy: QueuePolicy) {
        self.policy = policy;
        while self.items.len() > policy.capacity() {
            self.items.pop_front();
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
    fn zero_capacity_means_one() {
        let mut q = BoundedQueue::new(QueuePolicy::Fifo { capacity: 0 });
        assert!(q.push(0, 1));
        assert!(!q.push(1, 2));
        assert_eq!(q.len(), 1);
    }
}
