//! One robot's guide: its frontier memory, what it knows of where its peers are
//! heading, and the rule that decides when a planning round follows the global field.

use std::collections::BTreeMap;

use nalgebra::Point3;
use troupe_core::RobotId;

use super::config::GuidanceConfig;
use super::guidance::{FieldParams, GuidanceField, PeerIntent};
use super::memory::{FrontierMemory, MemoryUpdate};
use crate::grid::GridSnapshot;
use crate::planner::round::Candidate;
use crate::team::{PeerKeyframe, PeerPlan};

/// The frontier memory of one robot, fed by its grid snapshots and its peers'
/// keyframes and plans, and the guidance field built from it each round.
#[derive(Clone, Debug)]
pub struct Guide {
    config: GuidanceConfig,
    memory: FrontierMemory,
    peers: BTreeMap<RobotId, PeerIntent>,
    retired_by_peers: u64,
}

/// The sampling seed of a peer keyframe: the same keyframe always gives the same rays.
fn keyframe_seed(robot: RobotId, id: u32) -> u64 {
    (u64::from(robot.0) << 32 | u64::from(id)).wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ 0xf00d
}

impl Guide {
    /// An empty guide.
    #[must_use]
    pub fn new(config: GuidanceConfig) -> Self {
        Guide {
            config,
            memory: FrontierMemory::new(config.cell_m, config.max_cells),
            peers: BTreeMap::new(),
            retired_by_peers: 0,
        }
    }

    /// The memory.
    #[must_use]
    pub fn memory(&self) -> &FrontierMemory {
        &self.memory
    }

    /// Remembered frontiers retired by peers' keyframes so far.
    #[must_use]
    pub fn retired_by_peers(&self) -> u64 {
        self.retired_by_peers
    }

    /// Folds the robot's own grid snapshot in; `margin_m` is the clearance a robot
    /// centre needs (the planner's [`margin_m`](crate::planner::round::RoundConfig::margin_m)).
    pub fn observe_snapshot(&mut self, snapshot: &GridSnapshot, margin_m: f64) -> MemoryUpdate {
        self.memory
            .observe_window(snapshot, margin_m, self.config.min_frontier_cells)
    }

    /// Folds a peer's keyframe in: its rays retire the frontiers they cross.
    pub fn observe_peer_keyframe(&mut self, peer: &PeerKeyframe) -> MemoryUpdate {
        let update = self.memory.observe_keyframe(
            &peer.keyframe,
            self.config.peer_keyframe_samples,
            keyframe_seed(peer.robot, peer.keyframe.id),
        );
        self.retired_by_peers += update.retired as u64;
        update
    }

    /// Records where a peer is and where it is heading (its plan's first and last
    /// knots); its position is passable.
    pub fn observe_peer_plan(&mut self, peer: &PeerPlan) {
        let knots = peer.plan.trajectory.knots();
        let (Some(first), Some(last)) = (knots.first(), knots.last()) else {
            return;
        };
        let finite = |p: &Point3<f64>| p.coords.iter().all(|v| v.is_finite());
        if !(finite(&first.position_m) && finite(&last.position_m)) {
            return;
        }
        self.memory.mark_body(&first.position_m);
        self.peers.insert(
            peer.robot,
            PeerIntent {
                position_m: first.position_m,
                goal_m: last.position_m,
            },
        );
    }

    /// Marks the robot's own cell passable and builds the field for a robot at
    /// `robot_m`, with the peers' claims.
    pub fn field(&mut self, robot_m: &Point3<f64>) -> GuidanceField {
        self.memory.mark_body(robot_m);
        let peers: Vec<PeerIntent> = self.peers.values().copied().collect();
        GuidanceField::build(
            &self.memory,
            robot_m,
            &peers,
            &FieldParams {
                claim_radius_m: self.config.claim_radius_m,
                claim_penalty_m: self.config.claim_penalty_m,
                look_ahead_m: self.config.look_ahead_m,
            },
        )
    }

    /// Whether a round from `root_m` should score the frontier reward over `field`:
    /// whenever the field reaches the robot, unless
    /// [`GuidanceConfig::window_reward_above_nats`] is set, some candidate's information
    /// reaches it and the window shows a frontier (`local_frontier_m` finite).
    #[must_use]
    pub fn should_guide(
        &self,
        field: &GuidanceField,
        root_m: &Point3<f64>,
        candidates: &[Candidate],
        local_frontier_m: f64,
    ) -> bool {
        if !field.distance_m(root_m).is_finite() {
            return false;
        }
        let best = candidates.iter().map(|c| c.information).fold(0.0, f64::max);
        self.config
            .window_reward_above_nats
            .is_none_or(|nats| best < nats || !local_frontier_m.is_finite())
    }
}
