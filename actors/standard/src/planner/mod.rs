//! The planning actors (thesis §4.1, §5.1.2); the planning cores are
//! [`troupe_algorithms::planner`].
//!
//! - [`PlannerActor`]: replans at a fixed rate and commits plans with their stopping
//!   primitives; the choice among candidates is an
//!   [`ActionSelection`](troupe_algorithms::planner::selection::ActionSelection) policy.
//! - [`TeleopActor`] commits teleoperation primitives at a fixed rate;
//!   [`ScriptedTeleop`] publishes a timed command script in place of a joystick.

mod actor;
mod memory_share;
mod teleop_actor;

pub use actor::{
    MISSION_RETURN, MISSION_STATUS, PLANNING_REPORT, PlannerActor, PlannerConfig, PlanningReport,
    REMEMBERED_FRONTIERS, RememberedFrontiers, ReturnCommand,
};
pub use memory_share::{
    DecodedCells, GIVEN_UP_BIT, MAX_SHARED_CELLS, MEMORY_CELLS, MemoryCells, MemoryCellsError,
};
pub use teleop_actor::{
    ScriptedCommand, ScriptedTeleop, TELEOP_COMMAND, TeleopActor, TeleopConfig,
};
