//! troupe recordings: what the robots of a run published, in an MCAP file whose
//! channels use Foxglove's well-known schemas (JSON messages with `jsonschema`
//! schemas), so Foxglove, Lichtblick or any MCAP reader can scrub through a run in
//! 3D over time. A [`Recorder`] is a [`Tap`](troupe_runtime::Tap) on an
//! executor: `troupe run` (sim time), the robot processes and the base station (wall
//! time) add one. The channels are listed in [`recorder`]; `docs/recordings.md` is
//! the user's guide.
//!
//! A recording written by hand (an executor's tap does the same for every
//! publication):
//!
//! ```
//! use troupe_core::Time;
//! use troupe_record::{Clock, Recorder, schemas};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let dir = tempfile::tempdir()?;
//! let mut recorder = Recorder::create(&dir.path().join("run.mcap"), Clock::Sim)?;
//! let sample = serde_json::json!({ "time_s": 1.0, "fraction": 0.25, "explored_m3": 918.0 });
//! recorder.write("/coverage", &schemas::COVERAGE, Time::from_nanos(1_000_000_000), &sample);
//! let stats = recorder.finish()?;
//! assert_eq!(stats.messages["/coverage"], 1);
//! assert_eq!(stats.failed, 0);
//! # Ok(())
//! # }
//! ```

pub mod foxglove;
pub mod recorder;
pub mod scene;
pub mod schemas;
pub mod writer;

pub use recorder::{
    Clock, MAX_RECORD_HZ, RecordOptions, Recorder, RecordingStats, SharedRecorder, check_rate_hz,
    period_of_hz,
};
pub use writer::{Compression, RecordError, Recording};

/// File name of a recording in its output directory: a run's report directory
/// (`troupe run`), a robot process's or the base station's `out`.
pub const RUN_RECORDING: &str = "run.mcap";
