//! Counters and latency histograms that a run reports.

use std::collections::BTreeMap;
use std::time::Duration;

use serde::Serialize;

/// A compact log-linear histogram of durations (8 sub-buckets per power of two:
/// quantiles are within 12.5% of the true value). Fixed size, no allocation per sample.
#[derive(Clone, Debug)]
pub struct LatencyHistogram {
    buckets: Box<[u64; Self::BUCKETS]>,
    count: u64,
    max_ns: u64,
    sum_ns: u128,
}

impl Default for LatencyHistogram {
    fn default() -> Self {
        LatencyHistogram {
            buckets: Box::new([0; Self::BUCKETS]),
            count: 0,
            max_ns: 0,
            sum_ns: 0,
        }
    }
}

impl LatencyHistogram {
    const SUB: u32 = 8;
    const BUCKETS: usize = 62 * Self::SUB as usize;

    fn index(ns: u64) -> usize {
        if ns < u64::from(Self::SUB) {
            return ns as usize;
        }
        let exp = 63 - ns.leading_zeros(); // ≥ 3
        let mantissa = (ns >> (exp - 3)) & u64::from(Self::SUB - 1);
        ((exp - 2) * Self::SUB) as usize + mantissa as usize
    }

    /// Lower edge of a bucket in nanoseconds.
    fn lower(index: usize) -> u64 {
        let sub = Self::SUB as usize;
        if index < sub {
            return index as u64;
        }
        let exp = (index / sub) as u32 + 2;
        let mantissa = (index % sub) as u64;
        (8 + mantissa) << (exp - 3)
    }

    /// Adds one sample.
    pub fn record(&mut self, duration: Duration) {
        let ns = u64::try_from(duration.as_nanos()).unwrap_or(u64::MAX);
        self.buckets[Self::index(ns).min(Self::BUCKETS - 1)] += 1;
        self.count += 1;
        self.max_ns = self.max_ns.max(ns);
        self.sum_ns += u128::from(ns);
    }

    /// Adds every sample of another histogram.
    pub fn merge(&mut self, other: &LatencyHistogram) {
        for (a, b) in self.buckets.iter_mut().zip(other.buckets.iter()) {
            *a += b;
        }
        self.count += other.count;
        self.max_ns = self.max_ns.max(other.max_ns);
        self.sum_ns += other.sum_ns;
    }

    /// Number of samples.
    #[must_use]
    pub fn count(&self) -> u64 {
        self.count
    }

    /// The `q`-quantile (0 ≤ q ≤ 1) in nanoseconds, as the midpoint of its bucket.
    #[must_use]
    pub fn quantile_ns(&self, q: f64) -> u64 {
        if self.count == 0 {
            return 0;
        }
        let rank = ((q.clamp(0.0, 1.0) * self.count as f64).ceil() as u64).max(1);
        let mut seen = 0;
        for (i, n) in self.buckets.iter().enumerate() {
            seen += n;
            if seen >= rank {
                let lo = Self::lower(i);
                let hi = if i + 1 < Self::BUCKETS {
                    Self::lower(i + 1)
                } else {
                    lo
                };
                return ((lo + hi) / 2).min(self.max_ns);
            }
        }
        self.max_ns
    }

    /// Summary in microseconds for reports.
    #[must_use]
    pub fn summary(&self) -> LatencySummary {
        let us = |ns: u64| ns as f64 / 1e3;
        LatencySummary {
            count: self.count,
            median_us: us(self.quantile_ns(0.5)),
            p95_us: us(self.quantile_ns(0.95)),
            max_us: us(self.max_ns),
            mean_us: if self.count == 0 {
                0.0
            } else {
                self.sum_ns as f64 / self.count as f64 / 1e3
            },
        }
    }
}

/// Quantiles of a [`LatencyHistogram`], in microseconds.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct LatencySummary {
    /// Number of samples.
    pub count: u64,
    /// Median.
    pub median_us: f64,
    /// 95th percentile.
    pub p95_us: f64,
    /// Largest sample.
    pub max_us: f64,
    /// Mean.
    pub mean_us: f64,
}

/// Counters of one actor over a run. All but `handler_wall` are deterministic under
/// the sim-time executor.
#[derive(Clone, Debug, Default)]
pub struct ActorStats {
    /// Events handled (messages and timer ticks).
    pub handled: u64,
    /// Hooks that returned an error.
    pub errors: u64,
    /// Hooks that panicked.
    pub panics: u64,
    /// Times the actor was rebuilt after a panic.
    pub restarts: u64,
    /// Whether the actor was stopped for good after repeated panics.
    pub stopped: bool,
    /// Messages dropped because the actor was stopped.
    pub dropped_while_stopped: u64,
    /// Timer ticks coalesced because the previous tick was not handled yet.
    pub timer_overruns: u64,
    /// Wall-clock time spent in handlers.
    pub handler_wall: LatencyHistogram,
}

/// Counters of one topic of one robot.
#[derive(Clone, Copy, Debug, Default, Serialize, PartialEq, Eq)]
pub struct TopicStats {
    /// Messages published.
    pub messages: u64,
    /// Sum of [`Message::payload_bytes`](crate::Message::payload_bytes) over them.
    pub bytes: u64,
    /// Publications rejected because the message type did not match the topic's type.
    pub type_mismatches: u64,
}

/// What one actor did during a run.
#[derive(Clone, Debug)]
pub struct ActorReport {
    /// Actor name.
    pub name: String,
    /// Counters.
    pub stats: ActorStats,
    /// Messages dropped by each subscription's queue policy, by topic.
    pub dropped_by_topic: BTreeMap<String, u64>,
}

/// What one robot did during a run.
#[derive(Clone, Debug)]
pub struct RobotReport {
    /// Robot name.
    pub name: String,
    /// One entry per actor, in the order they were added.
    pub actors: Vec<ActorReport>,
    /// Per-topic counters, sorted by topic name.
    pub topics: BTreeMap<String, TopicStats>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_within_bucket_resolution() {
        let mut h = LatencyHistogram::default();
        for us in 1..=1000u64 {
            h.record(Duration::from_micros(us));
        }
        let median = h.quantile_ns(0.5) as f64;
        assert!((median - 500_000.0).abs() / 500_000.0 < 0.125, "{median}");
        let p95 = h.quantile_ns(0.95) as f64;
        assert!((p95 - 950_000.0).abs() / 950_000.0 < 0.125, "{p95}");
        assert_eq!(h.quantile_ns(1.0), 1_000_000);
        assert_eq!(h.count(), 1000);
    }

    #[test]
    fn bucket_edges_are_monotone() {
        let mut last = 0;
        for i in 1..LatencyHistogram::BUCKETS {
            let lo = LatencyHistogram::lower(i);
            assert!(lo > last, "bucket {i}");
            assert_eq!(LatencyHistogram::index(lo), i);
            last = lo;
        }
    }
}
