//! End-to-end tests: whole teams, as `troupe run` runs them.

#![allow(clippy::unwrap_used)]

mod crossing;
mod keyframes;
mod map_bytes;
mod planner_team;
mod realtime_team;
mod team_run;
