//! Counters: drops by reason, queue delay and age of information per class.

use serde::Serialize;

use crate::wire::Class;

/// Why a message did not (or will not) reach the link.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DropReason {
    /// Keep-latest: replaced by a newer message before it started.
    Superseded,
    /// Drop-oldest: pushed out of a full queue by a newer message.
    Overflow,
    /// Store-and-forward: refused because no recipient's pending set had room.
    StoreFull,
    /// Refused: larger than the class capacity or than 65 535 fragments.
    TooLarge,
    /// Store-and-forward: given up for one peer because that peer was removed
    /// (counted once per message and peer; see `LinkShaper::remove_peer`).
    PeerRemoved,
    /// Store-and-forward: stored for the other recipients but not for one whose
    /// pending set was full (counted once per message and skipped peer).
    PeerFull,
}

/// Drops of one class, by reason.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct DropCounts {
    /// See [`DropReason::Superseded`].
    pub superseded: u64,
    /// See [`DropReason::Overflow`].
    pub overflow: u64,
    /// See [`DropReason::StoreFull`].
    pub store_full: u64,
    /// See [`DropReason::TooLarge`].
    pub too_large: u64,
    /// See [`DropReason::PeerRemoved`].
    pub peer_removed: u64,
    /// See [`DropReason::PeerFull`].
    pub peer_full: u64,
}

impl DropCounts {
    pub(crate) fn count(&mut self, reason: DropReason) {
        match reason {
            DropReason::Superseded => self.superseded += 1,
            DropReason::Overflow => self.overflow += 1,
            DropReason::StoreFull => self.store_full += 1,
            DropReason::TooLarge => self.too_large += 1,
            DropReason::PeerRemoved => self.peer_removed += 1,
            DropReason::PeerFull => self.peer_full += 1,
        }
    }

    /// All drops together.
    #[must_use]
    pub fn total(&self) -> u64 {
        self.superseded
            + self.overflow
            + self.store_full
            + self.too_large
            + self.peer_removed
            + self.peer_full
    }
}

/// Count, mean and extremes of a delay, nanoseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct DelayStats {
    /// Samples.
    pub count: u64,
    /// Sum of samples.
    pub sum_ns: u128,
    /// Largest sample.
    pub max_ns: u64,
}

impl DelayStats {
    pub(crate) fn record(&mut self, delay_ns: u64) {
        self.count += 1;
        self.sum_ns += u128::from(delay_ns);
        self.max_ns = self.max_ns.max(delay_ns);
    }

    /// Mean delay in seconds (0 without samples).
    #[must_use]
    pub fn mean_s(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            self.sum_ns as f64 / self.count as f64 * 1e-9
        }
    }

    /// Largest delay in seconds.
    #[must_use]
    pub fn max_s(&self) -> f64 {
        self.max_ns as f64 * 1e-9
    }
}

/// Age of information: at time `t`, `t − (generation time of the newest update
/// delivered so far)`. Tracks its time average and peaks. An update older than
/// one already delivered does not lower the age.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct AgeOfInformation {
    /// Generation time of the newest delivered update, ns.
    pub newest_generated_ns: Option<u64>,
    first_delivery_ns: u64,
    last_event_ns: u64,
    /// Integral of the age since the first delivery, ns² (as `f64`).
    area_ns2: f64,
    /// Largest age reached just before an update, ns.
    pub peak_ns: u64,
}

impl AgeOfInformation {
    /// Records the delivery at `delivered_ns` of an update generated at `generated_ns`.
    pub fn record(&mut self, delivered_ns: u64, generated_ns: u64) {
        match self.newest_generated_ns {
            None => {
                self.first_delivery_ns = delivered_ns;
                self.last_event_ns = delivered_ns;
                self.newest_generated_ns = Some(generated_ns);
            }
            Some(newest) => {
                self.advance(delivered_ns);
                self.peak_ns = self.peak_ns.max(delivered_ns.saturating_sub(newest));
                if generated_ns > newest {
                    self.newest_generated_ns = Some(generated_ns);
                }
            }
        }
    }

    fn advance(&mut self, now_ns: u64) {
        let Some(newest) = self.newest_generated_ns else {
            return;
        };
        if now_ns <= self.last_event_ns {
            return;
        }
        let a0 = self.last_event_ns.saturating_sub(newest) as f64;
        let a1 = now_ns.saturating_sub(newest) as f64;
        self.area_ns2 += (now_ns - self.last_event_ns) as f64 * 0.5 * (a0 + a1);
        self.last_event_ns = now_ns;
    }

    /// Age at `now_ns`, seconds (`None` before the first delivery).
    #[must_use]
    pub fn age_s(&self, now_ns: u64) -> Option<f64> {
        self.newest_generated_ns
            .map(|g| now_ns.saturating_sub(g) as f64 * 1e-9)
    }

    /// Time-average age from the first delivery to `now_ns`, seconds.
    #[must_use]
    pub fn mean_s(&self, now_ns: u64) -> Option<f64> {
        let mut copy = *self;
        copy.advance(now_ns);
        let span = now_ns.saturating_sub(self.first_delivery_ns);
        copy.newest_generated_ns?;
        Some(if span == 0 {
            self.age_s(now_ns).unwrap_or(0.0)
        } else {
            copy.area_ns2 / span as f64 * 1e-9
        })
    }
}

/// Counters of one class on one shaped link.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ClassStats {
    /// Messages offered (accepted or refused).
    pub offered_messages: u64,
    /// Bytes offered.
    pub offered_bytes: u64,
    /// Messages whose last fragment was sent (retransmissions not counted).
    pub sent_messages: u64,
    /// Frames sent, retransmissions included.
    pub sent_frames: u64,
    /// Bytes sent in frames (headers included), retransmissions included.
    pub sent_bytes: u64,
    /// Messages sent again by store-and-forward.
    pub retransmitted_messages: u64,
    /// Store-and-forward messages acknowledged by the peer.
    pub acknowledged_messages: u64,
    /// Drops and refusals by reason.
    pub drops: DropCounts,
    /// From offer to the first fragment on the link.
    pub queue_delay: DelayStats,
    /// From offer to the last fragment on the link (first transmission).
    pub completion_delay: DelayStats,
    /// Age of information at the link's egress (generation = offer time).
    pub age: AgeOfInformation,
}

/// Counters of one shaped link.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ShaperStats {
    /// Per class, indexed by [`Class::index`].
    pub classes: [ClassStats; 4],
    /// Ack frames sent.
    pub ack_frames: u64,
    /// Bytes of ack frames sent.
    pub ack_bytes: u64,
    /// Bytes sent in frames by the extra lanes (shared topics), retransmissions
    /// included; per lane in [`LinkShaper::lane_stats`](super::LinkShaper::lane_stats).
    pub lane_sent_bytes: u64,
}

impl ShaperStats {
    /// Counters of one class.
    #[must_use]
    pub fn class(&self, class: Class) -> &ClassStats {
        &self.classes[class.index()]
    }

    /// Every byte sent on the link (data frames of the classes and of the extra
    /// lanes, and ack frames).
    #[must_use]
    pub fn total_sent_bytes(&self) -> u64 {
        self.classes.iter().map(|c| c.sent_bytes).sum::<u64>()
            + self.lane_sent_bytes
            + self.ack_bytes
    }
}

/// Counters of a [`Reassembler`](super::Reassembler).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct ReassemblyStats {
    /// Frames accepted.
    pub frames: u64,
    /// Frames that did not parse or disagreed with earlier fragments.
    pub malformed_frames: u64,
    /// Messages completed and returned.
    pub completed: u64,
    /// Fragments or whole messages already received (retransmissions).
    pub duplicates: u64,
    /// Partial messages dropped after the timeout.
    pub incomplete_timed_out: u64,
    /// Partial messages dropped to stay within the memory bounds.
    pub evicted: u64,
    /// Messages larger than the whole reassembly budget.
    pub too_large: u64,
}
