//! Simulation and wall-clock time as one type.

use std::fmt;
use std::ops::{Add, Sub};
use std::time::Duration;

/// A point in time since the start of a run, in nanoseconds.
///
/// Both executors use it: the sim-time executor advances it event by event, the
/// real-time executor reads it from a monotonic clock. Integer nanoseconds keep
/// event ordering exact and runs bit-reproducible.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Time(u64);

impl Time {
    /// The start of a run.
    pub const ZERO: Time = Time(0);
    /// The latest representable time (used as "never").
    pub const MAX: Time = Time(u64::MAX);

    /// From whole nanoseconds since the start of the run.
    #[must_use]
    pub const fn from_nanos(nanos: u64) -> Self {
        Time(nanos)
    }

    /// From seconds; negative or NaN inputs clamp to zero, huge ones to [`Time::MAX`].
    #[must_use]
    pub fn from_secs_f64(secs: f64) -> Self {
        if secs.is_nan() || secs <= 0.0 {
            Time(0)
        } else {
            let nanos = secs * 1e9;
            if nanos >= u64::MAX as f64 {
                Time::MAX
            } else {
                Time(nanos.round() as u64)
            }
        }
    }

    /// Nanoseconds since the start of the run.
    #[must_use]
    pub const fn as_nanos(self) -> u64 {
        self.0
    }

    /// Seconds since the start of the run.
    #[must_use]
    pub fn as_secs_f64(self) -> f64 {
        self.0 as f64 * 1e-9
    }

    /// The time elapsed since `earlier` (zero if `earlier` is later).
    #[must_use]
    pub fn saturating_since(self, earlier: Time) -> Duration {
        Duration::from_nanos(self.0.saturating_sub(earlier.0))
    }
}

impl Add<Duration> for Time {
    type Output = Time;
    fn add(self, rhs: Duration) -> Time {
        let nanos = u64::try_from(rhs.as_nanos()).unwrap_or(u64::MAX);
        Time(self.0.saturating_add(nanos))
    }
}

impl Sub<Time> for Time {
    type Output = Duration;
    fn sub(self, rhs: Time) -> Duration {
        self.saturating_since(rhs)
    }
}

impl fmt::Display for Time {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:.3}s", self.as_secs_f64())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seconds_round_trip_and_clamp() {
        assert_eq!(Time::from_secs_f64(1.5).as_nanos(), 1_500_000_000);
        assert_eq!(Time::from_secs_f64(-3.0), Time::ZERO);
        assert_eq!(Time::from_secs_f64(f64::NAN), Time::ZERO);
        assert_eq!(Time::from_secs_f64(1e30), Time::MAX);
        let t = Time::from_secs_f64(2.0) + Duration::from_millis(250);
        assert_eq!(t.as_secs_f64(), 2.25);
        assert_eq!(t - Time::from_secs_f64(3.0), Duration::ZERO);
        assert_eq!(Time::MAX + Duration::from_secs(1), Time::MAX);
    }
}

/// Where a robot's run time sits on the clock its team shares.
///
/// Every robot counts [`Time`] from the start of its own run. Robots of one process
/// (the simulator) share that start, so their times compare directly: the team
/// clock is run time ([`TeamClock::SHARED`]). Robots in separate processes start at
/// different moments and restart: there the team clock is Unix time (the hosts'
/// clocks synchronised, e.g. by NTP or PTP, as any multi-robot ROS 2 system needs),
/// and a process's run starts at its [`origin_ns`](TeamClock::origin_ns) on it.
/// Stamps sent to other robots are on the team clock, so they keep increasing across
/// a robot's restarts; the origin also names the run (its incarnation), so a
/// restart is announced by every message of the new run.
///
/// ```
/// use troupe_core::{TeamClock, Time};
///
/// let clock = TeamClock::starting_at(1_000);
/// assert_eq!(clock.to_team_ns(Time::from_nanos(5)), 1_005);
/// assert_eq!(clock.from_team_ns(1_005), Time::from_nanos(5));
/// // Before this run began: the run's start.
/// assert_eq!(clock.from_team_ns(10), Time::ZERO);
/// assert_eq!(TeamClock::SHARED.to_team_ns(Time::from_nanos(7)), 7);
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct TeamClock {
    origin_ns: u64,
}

impl TeamClock {
    /// The team clock of robots that share one run (the simulator): run time itself.
    pub const SHARED: TeamClock = TeamClock { origin_ns: 0 };

    /// A run that starts `origin_ns` nanoseconds into the team clock.
    #[must_use]
    pub const fn starting_at(origin_ns: u64) -> Self {
        TeamClock { origin_ns }
    }

    /// A run that starts now on the host's clock (Unix time): the team clock of a
    /// robot process.
    #[must_use]
    pub fn starting_now() -> Self {
        let origin_ns = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX));
        TeamClock { origin_ns }
    }

    /// The run's start on the team clock, nanoseconds: it names the run, and a
    /// restarted robot's is later than its previous run's.
    #[must_use]
    pub const fn origin_ns(self) -> u64 {
        self.origin_ns
    }

    /// A time of this run on the team clock, nanoseconds.
    #[must_use]
    pub const fn to_team_ns(self, time: Time) -> u64 {
        self.origin_ns.saturating_add(time.as_nanos())
    }

    /// A team-clock stamp as a time of this run; stamps from before the run began
    /// are its start ([`Time::ZERO`]).
    #[must_use]
    pub const fn from_team_ns(self, team_ns: u64) -> Time {
        Time::from_nanos(team_ns.saturating_sub(self.origin_ns))
    }
}

/// What moves a run's [`Time`] forward: how an actor may spend time on its work.
///
/// Under [`TimeSource::Simulated`] (the sim-time executor) time advances by events
/// and modelled latencies only, whatever a handler call costs the machine: work that
/// measures the wall clock — an anytime search stopping on a wall-clock budget — would
/// make a run depend on the machine and its load instead of the seed alone, so it
/// must stop on a fixed amount of work there. Under [`TimeSource::WallClock`] (the
/// real-time executor) the wall clock is the run's time, and a wall-clock budget is
/// the honest anytime bound.
///
/// ```
/// use troupe_core::TimeSource;
///
/// assert!(TimeSource::Simulated.is_simulated());
/// assert!(!TimeSource::WallClock.is_simulated());
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TimeSource {
    /// Simulated time: deterministic, nothing may depend on wall-clock time.
    Simulated,
    /// The wall clock (the real-time executor, robot processes, hardware).
    WallClock,
}

impl TimeSource {
    /// Whether time is simulated.
    #[must_use]
    pub const fn is_simulated(self) -> bool {
        matches!(self, TimeSource::Simulated)
    }
}
