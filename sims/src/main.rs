//! The `troupe` command line (one module per subcommand in `cli/`).

mod cli;

use std::process::ExitCode;

use clap::Parser as _;
use troupe_robot::harness::{exit_code, init_logging};

fn main() -> ExitCode {
    init_logging();
    let result = cli::Cli::parse().command.run();
    exit_code("error", result.as_ref().map(|_| ()).map_err(|e| e.as_ref()))
}
