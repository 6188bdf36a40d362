//! troupe-sims: worlds, the simulated camera and vehicle, in-process teams,
//! ground-truth metrics and reports; home of the `troupe` command.
//!
//! - [`world`]: procedural worlds with a signed distance function as ground truth.
//! - [`camera`]: the pinhole depth + intensity camera, rendered on the CPU.
//! - [`coverage`]: explored-volume coverage.
//! - [`vehicle`], [`sim_sensor`]: the simulated vehicle and camera source a robot is
//!   assembled with.
//! - [`sequence`]: recorded depth + intensity sequences (TUM RGB-D layout).
//! - [`scenario`], [`team`], [`monitor`], [`maps`], [`report`]: `troupe run`.
//! - [`process`], [`launch`]: one robot per process over zenoh (`troupe robot`,
//!   `troupe launch`); [`router`]: a zenoh router (`troupe router`); [`replay`]: a
//!   robot process replaying a recorded sequence.
//!
//! A team in one process, deterministic in sim time (what `troupe run` does):
//!
//! ```
//! use troupe_sims::{scenario::Scenario, team::Team};
//!
//! let mut scenario = Scenario::default();
//! scenario.robots = 1;
//! scenario.duration_s = 1.0;
//! let run = Team::new(&scenario)?.run(|_fraction| {});
//! assert_eq!(run.summary.robots, 1);
//! assert!(run.summary.coverage.final_fraction >= 0.0);
//! # Ok::<(), troupe_robot::AssembleError>(())
//! ```
#![deny(missing_docs)]

pub mod artifact_score;
pub mod base;
pub mod camera;
pub mod coverage;
pub mod faults;
pub mod keys;
pub mod launch;
pub mod maps;
pub mod monitor;
pub mod network;
pub mod og_meter;
pub mod plot;
pub mod process;
pub mod recording;
pub mod replay;
pub mod report;
pub mod router;
pub mod scenario;
pub mod sequence;
pub mod sim_sensor;
pub mod study;
pub mod team;
pub mod vehicle;
pub mod world;

/// Logs to stderr, filtered by `RUST_LOG` (default `warn`); for the `troupe` binary.
pub fn init_logging() {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .init();
}
