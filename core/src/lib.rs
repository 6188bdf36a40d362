//! troupe-core: the vocabulary every layer of troupe shares.
//!
//! Small types that the actor runtime (`troupe-runtime`) and the algorithm
//! cores (`troupe-algorithms`) both speak, so that neither depends on the other:
//!
//! - [`Time`]: a point in a run's time (simulated or wall clock), integer nanoseconds;
//! - [`TeamClock`]: where a run's time sits on the clock the team shares;
//! - [`TimeSource`]: whether a run's time is simulated or the wall clock;
//! - [`RobotId`]: a robot's index in its team;
//! - [`Message`]: what may be published on a topic;
//! - [`ErrorChain`]: an error and its causes on one line, for logs;
//! - [`ConfigError`]: a configuration value that breaks a rule.
//!
//! ```
//! use std::time::Duration;
//! use troupe_core::{Message, RobotId, Time};
//!
//! struct Battery { volts: f64 }
//! impl Message for Battery {}
//!
//! let t = Time::from_secs_f64(1.5) + Duration::from_millis(500);
//! assert_eq!(t.as_secs_f64(), 2.0);
//! assert_eq!(RobotId(3).to_string(), "robot3");
//! assert!(Battery { volts: 11.1 }.payload_bytes() >= 8);
//! ```
#![deny(missing_docs)]

mod config;
mod time;

pub use config::ConfigError;
pub use time::{TeamClock, Time, TimeSource};

/// Index of a robot in its team.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize, serde::Deserialize,
)]
pub struct RobotId(pub u32);

impl std::fmt::Display for RobotId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "robot{}", self.0)
    }
}

/// A value that can be published on a topic.
///
/// Messages are shared, never copied: a publication is one `Arc` handed to every
/// subscriber. Implement it with `impl Message for MyType {}`; override
/// [`Message::payload_bytes`] when the value owns heap data, so that the per-topic
/// byte counters of a run report mean something.
pub trait Message: std::any::Any + Send + Sync {
    /// Approximate size of the payload in bytes (default: the inline size of the value).
    fn payload_bytes(&self) -> usize {
        std::mem::size_of_val(self)
    }
}

/// Displays an error followed by its causes (`source()` chain), separated by `: `.
///
/// troupe's errors display only their own message and expose their cause through
/// [`std::error::Error::source`]; log lines and command-line tools print the whole
/// chain with this.
///
/// ```
/// #[derive(Debug)]
/// struct Inner;
/// impl std::fmt::Display for Inner {
///     fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result { f.write_str("disk full") }
/// }
/// impl std::error::Error for Inner {}
/// #[derive(Debug)]
/// struct Outer(Inner);
/// impl std::fmt::Display for Outer {
///     fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result { f.write_str("saving the map") }
/// }
/// impl std::error::Error for Outer {
///     fn source(&self) -> Option<&(dyn std::error::Error + 'static)> { Some(&self.0) }
/// }
/// assert_eq!(troupe_core::ErrorChain(&Outer(Inner)).to_string(), "saving the map: disk full");
/// ```
pub struct ErrorChain<'a>(pub &'a (dyn std::error::Error + 'static));

impl std::fmt::Display for ErrorChain<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.0)?;
        let mut cause = self.0.source();
        while let Some(e) = cause {
            write!(f, ": {e}")?;
            cause = e.source();
        }
        Ok(())
    }
}
