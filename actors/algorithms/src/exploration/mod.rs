//! Exploration beyond the grid window: a team frontier memory, global guidance
//! towards remembered frontiers and implicit coordination between teammates.
//!
//! The local planner (thesis §4.1.3, paper Alg. 1) scores primitives by CSQMI plus the
//! frontier-distance reward V = d(ξ₀) − d(ξτ) (paper V-B), but its grid is a 20 m
//! window: once what is left to see lies outside it, nothing pulls a robot there.
//!
//! - [`FrontierMemory`]: coarse world-fixed cells (1 m by default) remembering what was
//!   seen, where a robot fits and where frontiers are. Fed by every grid snapshot (the
//!   robot's own frames and, inside the window, its peers' keyframes) and by the peers'
//!   keyframe GMMs sampled at the memory's resolution (thesis §6.1.4–6.1.5: a GMM can
//!   be resampled at any resolution), which retire the frontiers anyone has looked into.
//! - [`GuidanceField`]: route distance through known passable cells to the nearest
//!   remembered frontier (multi-source Dijkstra), the global `d` of V, seeded at each
//!   frontier's [`viewpoints`] — the passable places from which the level camera sees it
//!   (optionally only frontier regions of a few cells). Frontiers assigned to peers
//!   ([`Coordination`]: greedy assignment by route cost over every known robot's
//!   [`PeerIntent`]) are made longer by a penalty, so teammates spread over different
//!   openings.
//! - [`Guide`]: one robot's memory, its peers' intents and the rule for when a round
//!   follows the field.
//! - [`GuidanceConfig`]: the settings, table `robot.planner.guidance`.
//! - [`Mission`]: how a mission ends — exploring until nothing is left, then home and
//!   hold ([`MissionConfig`], table `robot.planner.mission`).
//! - [`ExplorationBehaviour`]: the plug-in a map-free explorer asks where to go next
//!   (scripted routes), apart from the memory and the field.
//!
//! The planner uses the field when the window is uninformative (see
//! [`PlanningProblem::guided`](crate::planner::problem::PlanningProblem::guided)); the
//! primitives it scores pass the same safety checks as ever.

mod behaviour;
mod config;
mod guidance;
mod guide;
mod memory;
mod mission;

pub use behaviour::ExplorationBehaviour;
pub use config::GuidanceConfig;
pub use guidance::{Coordination, FieldParams, GuidanceField, PeerIntent, ViewCone, viewpoints};
pub use guide::Guide;
pub use memory::{CellKey, CellRecord, FrontierMemory, MemoryUpdate};
pub use mission::{Mission, MissionConfig, MissionEnd, MissionPhase, MissionStatus};

#[cfg(test)]
mod tests;
