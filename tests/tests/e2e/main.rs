//! End-to-end tests: whole teams, as `troupe run` runs them.

#![allow(clippy::unwrap_used)]

mod artifacts;
mod crossing;
mod keyframes;
mod map_bytes;
mod planner_team;
mod realtime_team;
mod team_run;

use troupe_sims::scenario::Scenario;
use troupe_sims::team::{RunOutput, Team};

/// Runs `scenario` to its end under the sim-time executor, as `troupe run` does.
fn run(scenario: &Scenario) -> RunOutput {
    Team::new(scenario).expect("assemble").run(|_| {})
}
