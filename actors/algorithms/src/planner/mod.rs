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
//! - [`selection`]: the [`ActionSelection`](selection::ActionSelection) policy that
//!   chooses among a round's candidates.
//! - [`teleop`]: teleoperation commands mapped to the closest safe primitive with
//!   the forward speed adapted to the free space ahead (thesis §5.1.2, Eq. 5.1).
//! - [`scenes`]: small synthetic snapshots and the camera, for tests and benches.
//! - [`candidates`]: a round's ranked candidates and the collision checker's verdict.
//! - [`committed`]: the committed reference a planner replans from.

pub mod bounds;
pub mod candidates;
pub mod committed;
pub mod csqmi;
pub mod library;
pub mod primitives;
pub mod problem;
pub mod round;
pub mod scenes;
pub mod selection;
pub mod teleop;
