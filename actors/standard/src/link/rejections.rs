//! What the link turns down from the network: counted per reason, and logged at
//! most once per reason per interval with the count since the last line, so that a
//! flood of hostile frames costs a counter increment each, not a log line each.

use std::collections::BTreeMap;
use std::time::Duration;

use serde::Serialize;
use troupe_runtime::Time;

/// Why the link rejected a frame or a message from the network.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Rejection {
    /// The sender's id is not in the team roster ([`LinkConfig::roster`](super::LinkConfig::roster)).
    NotInRoster,
    /// The sender claims this robot's own id.
    OwnId,
    /// The frame does not parse, or contradicts earlier fragments of its message.
    MalformedFrame,
    /// The reassembled bytes are not a valid envelope.
    Undecodable,
    /// The envelope names another team.
    WrongTeam,
    /// The envelope names another sender than the network does.
    WrongSender,
    /// The envelope decodes but its payload is invalid (a keyframe or plan that
    /// fails its checks).
    InvalidPayload,
    /// An acknowledgement of a message this robot does not hold for that peer, or
    /// has not sent it yet.
    UnheldAck,
    /// A message on a topic only the base station may send (operator commands,
    /// [`ShareFrom::Base`](super::ShareFrom::Base)) from another id.
    NotFromBase,
    /// The envelope is stamped further ahead of this robot's clock than
    /// [`LinkConfig::max_clock_ahead_s`](super::LinkConfig::max_clock_ahead_s): the
    /// sender's clock runs ahead, or the stamp is forged.
    FromTheFuture,
    /// Odometry, a plan, a keyframe or grid changes from the base station's id
    /// ([`LinkConfig::base_id`](super::LinkConfig::base_id)): the base sends
    /// operator commands, acknowledgements and heartbeats, never a robot's messages.
    BaseAsRobot,
    /// An envelope whose sequence number its sender's run already used (a
    /// captured message sent again under a fresh message id), or one too far below
    /// the highest to tell ([`ReplayWindow`](super::ReplayWindow)).
    Replayed,
}

impl Rejection {
    /// The reason as `snake_case` (the counter's name).
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Rejection::NotInRoster => "not_in_roster",
            Rejection::OwnId => "own_id",
            Rejection::MalformedFrame => "malformed_frame",
            Rejection::Undecodable => "undecodable",
            Rejection::WrongTeam => "wrong_team",
            Rejection::WrongSender => "wrong_sender",
            Rejection::InvalidPayload => "invalid_payload",
            Rejection::UnheldAck => "unheld_ack",
            Rejection::NotFromBase => "not_from_base",
            Rejection::FromTheFuture => "from_the_future",
            Rejection::BaseAsRobot => "base_as_robot",
            Rejection::Replayed => "replayed",
        }
    }
}

/// Rejections per reason (in [`LinkStatus`](super::LinkStatus)).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct RejectionCounts {
    /// See [`Rejection::NotInRoster`].
    pub not_in_roster: u64,
    /// See [`Rejection::OwnId`].
    pub own_id: u64,
    /// See [`Rejection::MalformedFrame`].
    pub malformed_frame: u64,
    /// See [`Rejection::Undecodable`].
    pub undecodable: u64,
    /// See [`Rejection::WrongTeam`].
    pub wrong_team: u64,
    /// See [`Rejection::WrongSender`].
    pub wrong_sender: u64,
    /// See [`Rejection::InvalidPayload`].
    pub invalid_payload: u64,
    /// See [`Rejection::UnheldAck`].
    pub unheld_ack: u64,
    /// See [`Rejection::NotFromBase`].
    pub not_from_base: u64,
    /// See [`Rejection::FromTheFuture`].
    pub from_the_future: u64,
    /// See [`Rejection::BaseAsRobot`].
    pub base_as_robot: u64,
    /// See [`Rejection::Replayed`].
    pub replayed: u64,
}

impl RejectionCounts {
    /// Counts one rejection.
    pub fn count(&mut self, reason: Rejection) {
        *self.slot(reason) += 1;
    }

    /// Rejections for one reason.
    #[must_use]
    pub fn get(&self, reason: Rejection) -> u64 {
        let mut copy = *self;
        *copy.slot(reason)
    }

    fn slot(&mut self, reason: Rejection) -> &mut u64 {
        match reason {
            Rejection::NotInRoster => &mut self.not_in_roster,
            Rejection::OwnId => &mut self.own_id,
            Rejection::MalformedFrame => &mut self.malformed_frame,
            Rejection::Undecodable => &mut self.undecodable,
            Rejection::WrongTeam => &mut self.wrong_team,
            Rejection::WrongSender => &mut self.wrong_sender,
            Rejection::InvalidPayload => &mut self.invalid_payload,
            Rejection::UnheldAck => &mut self.unheld_ack,
            Rejection::NotFromBase => &mut self.not_from_base,
            Rejection::FromTheFuture => &mut self.from_the_future,
            Rejection::BaseAsRobot => &mut self.base_as_robot,
            Rejection::Replayed => &mut self.replayed,
        }
    }

    /// All rejections together.
    #[must_use]
    pub fn total(&self) -> u64 {
        self.not_in_roster
            + self.own_id
            + self.malformed_frame
            + self.undecodable
            + self.wrong_team
            + self.wrong_sender
            + self.invalid_payload
            + self.unheld_ack
            + self.not_from_base
            + self.from_the_future
            + self.base_as_robot
            + self.replayed
    }
}

#[derive(Clone, Copy, Debug, Default)]
struct Slot {
    last_line: Option<Time>,
    /// Events since the last line.
    pending: u64,
}

/// Decides when a repeated event may be logged: at most one line per key per
/// `interval`, each carrying how many events of that key happened since the
/// previous line. A plain type driven by the caller's clock (`now`), so it is the
/// same under sim time and wall time.
///
/// ```
/// use std::time::Duration;
/// use troupe_actors::link::RateLimitedLog;
/// use troupe_runtime::Time;
///
/// let mut log = RateLimitedLog::new(Duration::from_secs(1));
/// let t = |s: f64| Time::from_secs_f64(s);
/// assert_eq!(log.note("junk", t(0.0)), Some(1)); // the first one is logged
/// assert_eq!(log.note("junk", t(0.5)), None); // held back
/// assert_eq!(log.note("junk", t(0.7)), None);
/// assert_eq!(log.flush(t(1.0)), vec![("junk", 2)]); // one line for both
/// ```
#[derive(Clone, Debug)]
pub struct RateLimitedLog<K> {
    interval: Duration,
    slots: BTreeMap<K, Slot>,
}

impl<K: Ord + Copy> RateLimitedLog<K> {
    /// At most one line per key per `interval`.
    #[must_use]
    pub fn new(interval: Duration) -> Self {
        RateLimitedLog {
            interval,
            slots: BTreeMap::new(),
        }
    }

    /// Notes one event of `key` at `now`. `Some(n)`: log a line now for the `n`
    /// events since the last line (this one included); `None`: held back until a
    /// later [`note`](Self::note) or [`flush`](Self::flush) after the interval.
    pub fn note(&mut self, key: K, now: Time) -> Option<u64> {
        let interval = self.interval;
        let slot = self.slots.entry(key).or_default();
        slot.pending += 1;
        Self::due(slot, now, interval)
    }

    /// The lines due at `now` for events held back: (key, events since its last line).
    pub fn flush(&mut self, now: Time) -> Vec<(K, u64)> {
        let interval = self.interval;
        self.slots
            .iter_mut()
            .filter(|(_, slot)| slot.pending > 0)
            .filter_map(|(key, slot)| Self::due(slot, now, interval).map(|n| (*key, n)))
            .collect()
    }

    fn due(slot: &mut Slot, now: Time, interval: Duration) -> Option<u64> {
        if slot
            .last_line
            .is_some_and(|last| now.saturating_since(last) < interval)
        {
            return None;
        }
        slot.last_line = Some(now);
        Some(std::mem::take(&mut slot.pending))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t(ms: u64) -> Time {
        Time::from_nanos(ms * 1_000_000)
    }

    #[test]
    fn a_flood_gives_one_line_per_reason_per_interval_with_the_count() {
        let mut log = RateLimitedLog::new(Duration::from_secs(1));
        let mut lines = Vec::new();
        // 10 000 events of two reasons over 2.5 s.
        for i in 0..10_000u64 {
            let now = t(i / 4);
            let key = if i % 2 == 0 { "a" } else { "b" };
            if let Some(n) = log.note(key, now) {
                lines.push((now, key, n));
            }
            lines.extend(log.flush(now).into_iter().map(|(k, n)| (now, k, n)));
        }
        lines.extend(
            log.flush(t(10_000))
                .into_iter()
                .map(|(k, n)| (t(10_000), k, n)),
        );
        for key in ["a", "b"] {
            let mine: Vec<_> = lines.iter().filter(|l| l.1 == key).collect();
            // Lines at 0, 1, 2 s and the final flush.
            assert_eq!(mine.len(), 4, "{mine:?}");
            for pair in mine.windows(2) {
                assert!(pair[1].0.saturating_since(pair[0].0) >= Duration::from_secs(1));
            }
            // Every event is accounted for exactly once.
            assert_eq!(mine.iter().map(|l| l.2).sum::<u64>(), 5_000);
        }
    }

    #[test]
    fn nothing_held_back_means_nothing_to_flush() {
        let mut log = RateLimitedLog::new(Duration::from_secs(1));
        assert_eq!(log.note(1, t(0)), Some(1));
        assert!(log.flush(t(5_000)).is_empty());
        // After a quiet interval the next event is logged at once.
        assert_eq!(log.note(1, t(5_000)), Some(1));
        assert_eq!(log.note(1, t(5_001)), None);
        assert_eq!(log.note(2, t(5_001)), Some(1));
    }

    #[test]
    fn counts_per_reason_add_up() {
        let mut counts = RejectionCounts::default();
        counts.count(Rejection::NotInRoster);
        counts.count(Rejection::NotInRoster);
        counts.count(Rejection::UnheldAck);
        assert_eq!(counts.get(Rejection::NotInRoster), 2);
        assert_eq!(counts.not_in_roster, 2);
        assert_eq!(counts.total(), 3);
        assert_eq!(Rejection::UnheldAck.name(), "unheld_ack");
    }
}
