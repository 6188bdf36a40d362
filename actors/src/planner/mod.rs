//! Motion primitives and their libraries (thesis §4.1, paper V-A).
//!
//! - [`primitives`]: snap-continuous forward-arc primitives as 8th-order polynomials
//!   per flat axis (x, y, z, yaw), with minimum-duration line search under
//!   acceleration and jerk limits, and stopping primitives.
//! - [`bounds`]: the steady-state velocity bound of Eq. 4.2.
//! - [`library`]: the motion primitive libraries of thesis Table 4.2 and paper Table I.
//! - [`csqmi`]: the information reward.
//! - [`round`]: one planning round: candidates, feasibility, safety, rewards.
//! - [`problem`]: the round as a generator of scored children of any state, for
//!   tree search (MCTS, thesis §4.1.3).
//! - [`teleop`]: teleoperation commands mapped to the closest safe primitive with
//!   the forward speed adapted to the free space ahead (thesis §5.1.2, Eq. 5.1).
//! - [`TeleopActor`] commits those primitives at a fixed rate; [`ScriptedTeleop`]
//!   publishes a timed command script in place of a joystick.
//! - [`scenes`]: small synthetic snapshots and the camera, for tests and benches.
//! - [`PlannerActor`]: replans at a fixed rate and commits plans with their stopping
//!   primitives; the choice among candidates is an [`ActionSelection`] policy.

mod actor;
pub mod bounds;
mod committed;
pub mod csqmi;
pub mod library;
pub mod primitives;
pub mod problem;
pub mod round;
pub mod scenes;
pub mod teleop;
mod teleop_actor;

pub use actor::{ActionSelection, PLANNING_REPORT, PlannerActor, PlannerConfig, PlanningReport};
pub use teleop_actor::{ScriptedCommand, ScriptedTeleop, TeleopActor, TeleopConfig};
