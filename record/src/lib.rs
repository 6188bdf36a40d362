//! troupe recordings: what the robots of a run published, in an MCAP file whose
//! channels use Foxglove's well-known schemas (JSON messages with `jsonschema`
//! schemas), so Foxglove, Lichtblick or any MCAP reader can scrub through a run in
//! 3D over time. A [`Recorder`] is a [`Tap`](troupe_actors::runtime::Tap) on an
//! executor: `troupe run` (sim time), the robot processes and the base station (wall
//! time) add one. The channels are listed in [`recorder`]; `docs/recordings.md` is
//! the user's guide.

pub mod foxglove;
pub mod recorder;
pub mod scene;
pub mod schemas;
pub mod writer;

pub use recorder::{Clock, RecordOptions, Recorder, RecordingStats, SharedRecorder};
pub use writer::{RecordError, Recording};
