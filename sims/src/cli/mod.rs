//! The `troupe` command line: [`main_with`] (the `troupe` binary calls [`main`]), the
//! parsed command line and one module per subcommand, each with its arguments (their
//! help text beside them), what it does, and a parse test.
//!
//! A user's own binary adds its parts (sensor and vehicle drivers, extra actors) to
//! the simulator's registry and hands it over; its scenario files then name them, and
//! `run`, `robot` and `launch` build robots with them (`examples/custom_parts/`):
//!
//! ```no_run
//! fn main() -> std::process::ExitCode {
//!     let registry = troupe_sims::parts::registry();
//!     // registry.add_sensor("my_camera", …); registry.add_actor("my_actor", …);
//!     troupe_sims::cli::main_with(registry)
//! }
//! ```

mod base;
mod keys;
mod launch;
mod map;
mod replay;
mod robot;
mod router;
mod run;
mod sweep;

use std::io::IsTerminal as _;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use troupe_robot::harness::{exit_code, init_logging};
use troupe_robot::registry::Registry;

/// The `troupe` command with the simulator's parts ([`crate::parts::registry`]).
#[must_use]
pub fn main() -> ExitCode {
    main_with(crate::parts::registry())
}

/// The `troupe` command (logging, the command line of this process, the subcommand,
/// the exit code) building robots from the parts in `registry`.
#[must_use]
pub fn main_with(registry: Registry) -> ExitCode {
    init_logging();
    let result = Cli::parse().command.run(&registry);
    exit_code("error", result.as_ref().map(|_| ()).map_err(|e| e.as_ref()))
}

/// troupe: teams of robots that explore and map unknown places over weak links.
#[derive(Debug, Parser)]
#[command(name = "troupe", version, about, long_about = None)]
pub(crate) struct Cli {
    #[command(subcommand)]
    pub(crate) command: Command,
}

/// The subcommands, each in its module (`run.rs` for `troupe run`, …).
#[derive(Debug, Subcommand)]
pub(crate) enum Command {
    /// Run a team of simulated robots in one process (sim time, deterministic) and
    /// write a report to `OUT/<scenario name>/`.
    Run(run::RunArgs),
    /// Run a study: every combination of the study's levels under every seed, in
    /// parallel; writes `OUT/<study>/results.csv` (one row per run), `aggregate.csv`
    /// (means and 95% intervals over seeds), plots, and each run's report under
    /// `OUT/<study>/runs/`. Across machines: `--shard K/N` on each, then `--merge`.
    Sweep(sweep::SweepArgs),
    /// Build a map from a recorded sequence (TUM RGB-D layout: camera.toml, depth.txt,
    /// rgb.txt, groundtruth.txt, depth/ and rgb/ PNGs); write `map.troupe` (the
    /// keyframe mixtures) and `map.ply` (points sampled from it, with intensity) to
    /// OUT, and print one JSON line of statistics.
    Map(map::MapArgs),
    /// Run a scenario's team as separate `troupe robot` processes on this machine,
    /// talking over zenoh on loopback (robot i listens on BASE_PORT + i and connects
    /// to the others; with `--router`, through one zenoh router on BASE_PORT);
    /// writes the robot files, each robot's `summary.json` and `trajectory.csv`, and
    /// `launch.json` (exit codes, closest approach) to `OUT/<scenario name>/`. Ctrl-C
    /// stops every robot cleanly.
    Launch(launch::LaunchArgs),
    /// Run one robot of a team in this process: its simulated vehicle and camera in
    /// the scenario's world (or, with `sequence` in the robot file, a recorded
    /// sequence replayed as its sensor), the standard actors on the wall clock, the
    /// link over zenoh. Writes `summary.json` and `trajectory.csv` on exit (end of
    /// `duration_s`, Ctrl-C or SIGTERM).
    Robot(robot::RobotArgs),
    /// Run a zenoh router until Ctrl-C or SIGTERM: robots in client mode
    /// (`[zenoh] mode = "client"`, `connect = ["tcp/<this host>:7447"]`) reach each
    /// other through it instead of connecting to every other robot.
    Router(router::RouterArgs),
    /// Write a team's credentials for mutual TLS with access control
    /// (`docs/security.md`): a CA, one certificate and key per robot, for the base
    /// station and for a router, each named by its link id (`robot<i>`), and the
    /// `[zenoh]` tables that use them (`<member>.zenoh.toml`).
    Keys(keys::KeysArgs),
    /// Run the base station: join the team over zenoh without flying, collect every
    /// robot's keyframes, odometry and plans, print one status line per robot per
    /// second, and on exit (end of `duration_s`, Ctrl-C or SIGTERM) write
    /// `merged_map.ply`, `merged_map.troupe`, `maps/robot<i>.troupe|.ply` and
    /// `summary.json`.
    Base(base::BaseArgs),
    /// Read a recording (`run.mcap` of `troupe run`, a robot process or the base
    /// station): print its channels (schema, messages) and time span, and with
    /// `--plots DIR` draw a run's plots again from the recording alone.
    Replay(replay::ReplayArgs),
}

impl Command {
    /// Does what the subcommand says, with robots' parts from `registry` (`sweep`
    /// runs the simulator's own).
    pub(crate) fn run(self, registry: &Registry) -> anyhow::Result<()> {
        match self {
            Command::Run(args) => run::run(args, registry),
            Command::Sweep(args) => sweep::run(args),
            Command::Map(args) => map::run(args),
            Command::Launch(args) => launch::run(args, registry),
            Command::Robot(args) => robot::run(args, registry),
            Command::Router(args) => router::run(args),
            Command::Keys(args) => keys::run(args),
            Command::Base(args) => base::run(args),
            Command::Replay(args) => replay::run(args),
        }
    }
}

/// A progress bar on a terminal (hidden when `hidden`, or when stderr is not one).
pub(crate) fn progress_bar(len: u64, hidden: bool) -> ProgressBar {
    if hidden || !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(len);
    bar.set_style(
        ProgressStyle::with_template("{spinner} [{elapsed_precise}] {wide_bar} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar
}

/// Parses `troupe ARGS…` as the shell would hand them over.
#[cfg(test)]
pub(crate) fn parse(args: &[&str]) -> Result<Cli, clap::Error> {
    Cli::try_parse_from(std::iter::once("troupe").chain(args.iter().copied()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory as _;

    #[test]
    fn help_names_the_new_flags_and_commands() {
        Cli::command().debug_assert();
        let mut cli = Cli::command();
        let top = cli.render_long_help().to_string();
        for command in ["robot", "router", "sweep", "launch"] {
            assert!(top.contains(command), "{command} missing from: {top}");
        }
        let sweep = cli
            .find_subcommand_mut("sweep")
            .expect("sweep")
            .render_long_help()
            .to_string();
        for flag in ["--shard <K/N>", "--merge <DIR>", "modulo N"] {
            assert!(sweep.contains(flag), "{flag} missing from: {sweep}");
        }
    }
}
