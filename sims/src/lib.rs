//! troupe-sims: worlds, the simulated camera and vehicle, in-process teams,
//! ground-truth metrics and reports; home of the `troupe` command (one module per
//! subcommand in `src/cli/`). Running processes — the harness, the base station, the
//! router, keys and the launcher — is `troupe_robot`'s.
//!
//! - [`world`]: procedural worlds with a signed distance function as ground truth.
//! - [`camera`]: the pinhole depth + intensity camera, rendered on the CPU.
//! - [`coverage`]: explored-volume coverage.
//! - [`vehicle`], [`sim_sensor`]: the simulated vehicle and camera source a robot is
//!   assembled with; [`parts`]: them and a recorded sequence by name in the registry
//!   ([`troupe_robot::registry`]) that builds a robot from the parts its file names.
//! - [`cli`]: the `troupe` command as a library ([`cli::main_with`]: a user's binary
//!   with its own parts).
//! - [`sequence`]: recorded depth + intensity sequences (TUM RGB-D layout).
//! - [`scenario`], [`team`], [`monitor`], [`maps`], [`report`]: `troupe run`;
//!   [`reexploration`]: who re-flew what a peer had already seen (thesis §8.2.7).
//! - [`process`]: one simulated robot per process over zenoh (`troupe robot`, on
//!   [`troupe_robot::harness`]) and its robot files for `troupe launch`
//!   ([`troupe_robot::launch`]); [`replay`]: a robot process replaying a recorded
//!   sequence.
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
pub mod camera;
pub mod cli;
pub mod coverage;
pub mod faults;
pub mod maps;
pub mod monitor;
pub mod network;
pub mod og_meter;
pub mod parts;
pub mod plot;
pub mod process;
pub mod recording;
pub mod reexploration;
pub mod replay;
pub mod report;
pub mod scenario;
pub mod sequence;
pub mod sim_sensor;
pub mod study;
pub mod team;
pub mod vehicle;
pub mod world;
