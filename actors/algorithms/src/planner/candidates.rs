//! A planning round as the collision checker sees it: ranked candidates, the
//! stopping trajectory, and the verdict.

use troupe_core::{Message, Time};

use super::committed::Committed;
use crate::trajectory::Trajectory;

/// One candidate of a planning round: a primitive followed by its stopping primitive.
#[derive(Clone, Debug, PartialEq)]
pub struct CandidatePlan {
    /// The primitive, then its stopping primitive from `switch_at` on.
    pub trajectory: Trajectory,
    /// The primitives `trajectory` samples (`None` for candidates that are not motion
    /// primitives, e.g. scripted routes); committed with it as
    /// [`Plan::reference`](crate::plan::Plan::reference).
    pub reference: Option<Committed>,
    /// When the stopping primitive takes over (the next replanning time at the latest).
    pub switch_at: Time,
    /// The planner's score (higher is better).
    pub reward: f64,
}

/// The candidates of one planning round, best first (planner → collision). The
/// collision actor commits the first one it accepts, or `stop` when it accepts none
/// (thesis §4.1.3: the stopping trajectory is always available).
#[derive(Clone, Debug, PartialEq)]
pub struct PlanCandidates {
    /// Round number (per planner, increasing).
    pub round: u64,
    /// When the round ran.
    pub stamp: Time,
    /// Ranked candidates.
    pub candidates: Vec<CandidatePlan>,
    /// The stopping trajectory from the current reference state.
    pub stop: Trajectory,
    /// The stopping primitive `stop` samples, if any.
    pub stop_reference: Option<Committed>,
}

impl Message for PlanCandidates {
    fn payload_bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + self.stop.payload_bytes()
            + self
                .candidates
                .iter()
                .map(|c| c.trajectory.payload_bytes())
                .sum::<usize>()
    }
}

/// Why the collision actor rejected a candidate.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Rejection {
    /// Too close to unsafe space in the local grid's distance field.
    Clearance,
    /// Conflicts with a higher-priority peer's plan (thesis §8.2.3).
    PeerPlan,
    /// Conflicts with a peer's stopping envelope (stale or missing plan).
    PeerEnvelope,
    /// Leaves the robot's geofence box.
    Geofence,
}

impl Rejection {
    /// Short name used in logs and reports.
    #[must_use]
    pub fn as_str(self) -> &'static str {
        match self {
            Rejection::Clearance => "clearance",
            Rejection::PeerPlan => "peer_plan",
            Rejection::PeerEnvelope => "peer_envelope",
            Rejection::Geofence => "geofence",
        }
    }

    /// Whether a peer, not the map, caused it.
    #[must_use]
    pub fn is_peer(self) -> bool {
        !matches!(self, Rejection::Clearance | Rejection::Geofence)
    }
}

impl std::fmt::Display for Rejection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Which candidate of a round the collision actor committed.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PlanDecision {
    /// The round decided.
    pub round: u64,
    /// Index into the round's candidates, or `None`: the stopping trajectory.
    pub chosen: Option<usize>,
    /// Candidates rejected before the chosen one, with the reason for each.
    pub rejected: Vec<(usize, Rejection)>,
    /// The round was refused whole: it came too late to continue the committed flight
    /// (or planned from a reference replaced since), which was kept; `chosen` and
    /// `rejected` are then empty.
    pub stale: bool,
}
impl Message for PlanDecision {}
