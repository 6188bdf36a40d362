//! Timeout on one input stream.

use troupe_core::Time;

/// A change of a [`Watchdog`]'s state, reported once per change (so a driver logs a
/// loss once, not at every tick).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WatchdogChange {
    /// The input has been silent for longer than the timeout.
    Lost,
    /// The input arrived again after a loss.
    Restored,
}

/// Watches one input: it is *stale* once nothing arrived for `timeout_s`.
///
/// The clock starts when the watchdog is armed, so an input that never arrives goes
/// stale one timeout after the start, like one that stops.
#[derive(Clone, Debug, PartialEq)]
pub struct Watchdog {
    timeout_s: f64,
    last: Time,
    fed: bool,
    stale: bool,
}

impl Watchdog {
    /// A watchdog armed at `now` with a timeout in seconds (callers validate it > 0).
    #[must_use]
    pub fn new(timeout_s: f64, now: Time) -> Self {
        Watchdog {
            timeout_s,
            last: now,
            fed: false,
            stale: false,
        }
    }

    /// Records an arrival at `now`. Returns [`WatchdogChange::Restored`] if the input
    /// was stale.
    pub fn feed(&mut self, now: Time) -> Option<WatchdogChange> {
        self.last = self.last.max(now);
        self.fed = true;
        if self.stale {
            self.stale = false;
            Some(WatchdogChange::Restored)
        } else {
            None
        }
    }

    /// Checks the timeout at `now`. Returns [`WatchdogChange::Lost`] on the first
    /// check past it.
    pub fn check(&mut self, now: Time) -> Option<WatchdogChange> {
        if !self.stale && self.age_s(now) > self.timeout_s {
            self.stale = true;
            Some(WatchdogChange::Lost)
        } else {
            None
        }
    }

    /// Whether the input is stale (as of the last [`check`](Self::check)).
    #[must_use]
    pub fn is_stale(&self) -> bool {
        self.stale
    }

    /// Whether anything ever arrived.
    #[must_use]
    pub fn ever_fed(&self) -> bool {
        self.fed
    }

    /// Seconds since the last arrival (or since arming, if none).
    #[must_use]
    pub fn age_s(&self, now: Time) -> f64 {
        now.saturating_since(self.last).as_secs_f64()
    }

    /// The timeout, seconds.
    #[must_use]
    pub fn timeout_s(&self) -> f64 {
        self.timeout_s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t(s: f64) -> Time {
        Time::from_secs_f64(s)
    }

    #[test]
    fn goes_stale_once_and_recovers_once() {
        let mut w = Watchdog::new(0.5, t(0.0));
        assert_eq!(w.check(t(0.4)), None);
        assert!(!w.is_stale() && !w.ever_fed());
        // Never fed: stale one timeout after arming.
        assert_eq!(w.check(t(0.6)), Some(WatchdogChange::Lost));
        assert!(w.is_stale());
        // Reported once, not at every check.
        assert_eq!(w.check(t(0.7)), None);
        assert_eq!(w.check(t(5.0)), None);
        assert_eq!(w.feed(t(5.1)), Some(WatchdogChange::Restored));
        assert!(!w.is_stale() && w.ever_fed());
        assert_eq!(w.feed(t(5.2)), None);
        assert_eq!(w.check(t(5.6)), None);
        assert_eq!(w.check(t(5.71)), Some(WatchdogChange::Lost));
        assert!((w.age_s(t(6.2)) - 1.0).abs() < 1e-9);
    }

    #[test]
    fn a_late_stamp_does_not_rewind() {
        let mut w = Watchdog::new(1.0, t(0.0));
        w.feed(t(2.0));
        w.feed(t(1.0));
        assert!((w.age_s(t(2.5)) - 0.5).abs() < 1e-9);
    }
}
