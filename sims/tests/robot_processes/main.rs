//! Robot processes with a base station and the artifact reporter, as a team runs
//! them: `troupe robot`, `troupe-robot` and `troupe base` processes on loopback over
//! zenoh. One test binary, so that its tests, which mostly wait on real time, run
//! side by side (one build and link instead of four).

use troupe_testkit as common;

mod artifacts;
mod base;
mod base_teleop;
mod hardware_base;
