//! Which envelope sequence numbers a peer's run has already used (issue 45, item 5):
//! a captured message sent again under a fresh message id passes the reassembler's
//! duplicate filter (it keys on message ids), but not this window over the
//! envelope's own sequence number.
//!
//! A sender numbers its envelopes from a counter its journal keeps across restarts,
//! and the shaper may send them out of order (priorities, store-and-forward
//! resends), so the window remembers the last [`REPLAY_WINDOW`] numbers below the
//! highest seen, as IPsec's anti-replay window does (RFC 4303 §3.4.3). One window per
//! peer, for its latest run: a new run starts a new window (a restarted robot whose
//! journal was lost numbers from 0 again); a message of an earlier run is not
//! checked here (the peer table already voids what earlier runs said).

/// How many sequence numbers below the highest seen a window remembers: at a robot's
/// ~12 messages a second, about 90 minutes of its traffic. Older numbers are taken
/// for replays.
pub const REPLAY_WINDOW: u64 = 1 << 16;

const WORDS: usize = (REPLAY_WINDOW / 64) as usize;

/// The sequence numbers one run of a peer has used, within [`REPLAY_WINDOW`] of the
/// highest.
#[derive(Clone, Debug)]
pub struct ReplayWindow {
    run_start_ns: u64,
    highest: u64,
    /// Bit `s % REPLAY_WINDOW` is set when number `s` (within the window) was seen.
    seen: Box<[u64; WORDS]>,
}

/// What [`ReplayWindow::check`] decided.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// A number this run has not used: accept it (it is now marked as used).
    Fresh,
    /// A number already seen, or too far below the highest to tell.
    Replayed,
    /// A message of a run before the window's: not checked.
    EarlierRun,
}

impl ReplayWindow {
    /// A window for the run that started at `run_start_ns`, having seen `sequence`.
    #[must_use]
    pub fn new(run_start_ns: u64, sequence: u64) -> Self {
        let mut window = ReplayWindow {
            run_start_ns,
            highest: sequence,
            seen: Box::new([0; WORDS]),
        };
        window.mark(sequence);
        window
    }

    fn bit(sequence: u64) -> (usize, u64) {
        let slot = sequence % REPLAY_WINDOW;
        ((slot / 64) as usize, 1 << (slot % 64))
    }

    fn mark(&mut self, sequence: u64) {
        let (word, bit) = Self::bit(sequence);
        self.seen[word] |= bit;
    }

    /// Checks `sequence` of a message from the run that started at `run_start_ns`,
    /// and remembers it when fresh. A later run replaces the window.
    pub fn check(&mut self, run_start_ns: u64, sequence: u64) -> Verdict {
        if run_start_ns > self.run_start_ns {
            *self = ReplayWindow::new(run_start_ns, sequence);
            return Verdict::Fresh;
        }
        if run_start_ns < self.run_start_ns {
            return Verdict::EarlierRun;
        }
        if sequence > self.highest {
            // Forget the numbers that slide out of the window.
            let shift = sequence - self.highest;
            if shift >= REPLAY_WINDOW {
                self.seen.fill(0);
            } else {
                for s in self.highest + 1..=sequence {
                    let (word, bit) = Self::bit(s);
                    self.seen[word] &= !bit;
                }
            }
            self.highest = sequence;
            self.mark(sequence);
            return Verdict::Fresh;
        }
        if self.highest - sequence >= REPLAY_WINDOW {
            return Verdict::Replayed;
        }
        let (word, bit) = Self::bit(sequence);
        if self.seen[word] & bit != 0 {
            return Verdict::Replayed;
        }
        self.seen[word] |= bit;
        Verdict::Fresh
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_number_passes_once_in_any_order_within_the_window() {
        let mut w = ReplayWindow::new(7, 10);
        assert_eq!(w.check(7, 10), Verdict::Replayed);
        for s in [12, 11, 15, 13, 14] {
            assert_eq!(w.check(7, s), Verdict::Fresh, "{s}");
            assert_eq!(w.check(7, s), Verdict::Replayed, "{s} again");
        }
        // Far ahead: the old numbers slide out and are taken for replays.
        let far = 15 + REPLAY_WINDOW + 3;
        assert_eq!(w.check(7, far), Verdict::Fresh);
        assert_eq!(w.check(7, 16), Verdict::Replayed, "below the window");
        assert_eq!(w.check(7, far - 1), Verdict::Fresh, "inside it, never seen");
        // A number whose slot was used before the window slid over it is fresh.
        let reused_slot = 12 + REPLAY_WINDOW;
        assert_eq!(w.check(7, reused_slot), Verdict::Fresh);
    }

    #[test]
    fn a_later_run_starts_a_new_window_and_earlier_runs_are_not_checked() {
        let mut w = ReplayWindow::new(7, 5_000_000);
        assert_eq!(
            w.check(9, 0),
            Verdict::Fresh,
            "a restart that lost its journal"
        );
        assert_eq!(w.check(9, 0), Verdict::Replayed);
        assert_eq!(w.check(7, 5_000_001), Verdict::EarlierRun);
    }
}
