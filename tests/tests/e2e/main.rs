//! End-to-end tests: whole teams, as `troupe run` runs them.

mod realtime_team;
mod team_run;
