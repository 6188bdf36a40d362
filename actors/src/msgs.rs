//! The standard topics of a robot and their message types.
//!
//! | topic | type | from → to |
//! |---|---|---|
//! | `odometry` | [`Odometry`] | vehicle → sensor, explorer, link |
//! | `sensor/frame` | [`DepthFrame`] | sensor → mapper |
//! | `plan/committed` | [`Plan`] | explorer/planner → vehicle, link |
//! | `mapper/keyframe` | [`Keyframe`] | mapper → link |
//! | `peer/keyframe` | [`PeerKeyframe`] | link → local grid |
//! | `grid/snapshot` | [`GridSnapshot`] | local grid → planner, collision |
//! | `peer/odometry` | [`PeerOdometry`] | link → planner, collision |
//! | `peer/plan` | [`PeerPlan`] | link → collision |
//! | `plan/candidates` | [`PlanCandidates`] | planner → collision |
//! | `plan/decision` | [`PlanDecision`] | collision → planner |
//! | `grid/changes` | [`GridChanges`] | local grid → link (occupancy-grid map sharing) |
//! | `peer/grid_changes` | [`PeerGridChanges`] | link → local grid |
//! | `link/tx`, `link/rx` | [`LinkTx`](crate::runtime::LinkTx), [`LinkRx`](crate::runtime::LinkRx) | link ↔ network |

use nalgebra::{Isometry3, Vector3};

use crate::grid::LocalGrid;
use crate::runtime::{Message, RobotId, Time, Topic};
use crate::trajectory::Trajectory;

/// The robot's pose (body frame: x forward, y left, z up) and velocity in its world frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Odometry {
    /// When the pose was valid.
    pub stamp: Time,
    /// Body pose in the world frame.
    pub pose: Isometry3<f64>,
    /// Linear velocity in the world frame, m/s.
    pub velocity_mps: Vector3<f64>,
}
impl Message for Odometry {}

/// Pinhole intrinsics of a depth camera (pixel centres at integer + 0.5).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PinholeIntrinsics {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Focal length in x, pixels.
    pub fx: f64,
    /// Focal length in y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// Largest valid depth, metres.
    pub max_depth_m: f64,
}

/// A registered depth + intensity image and the sensor pose it was taken from
/// (assumption A3 of the thesis: poses are given).
#[derive(Clone, Debug, PartialEq)]
pub struct DepthFrame {
    /// Capture time.
    pub stamp: Time,
    /// Camera body pose in the world frame (camera looks along body +x; image x is
    /// body −y, image y is body −z).
    pub pose: Isometry3<f64>,
    /// Intrinsics.
    pub intrinsics: PinholeIntrinsics,
    /// Row-major z-depth in metres; 0 means no return.
    pub depth_m: Vec<f32>,
    /// Row-major intensity in [0, 1]; 0 where there is no return.
    pub intensity: Vec<f32>,
}

impl Message for DepthFrame {
    fn payload_bytes(&self) -> usize {
        std::mem::size_of::<Self>() + 4 * (self.depth_m.len() + self.intensity.len())
    }
}

impl DepthFrame {
    /// Number of pixels with a depth return.
    #[must_use]
    pub fn valid_pixels(&self) -> usize {
        self.depth_m.iter().filter(|d| **d > 0.0).count()
    }
}

/// A committed trajectory for the vehicle to follow.
#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    /// When it was committed.
    pub stamp: Time,
    /// The trajectory.
    pub trajectory: Trajectory,
}

impl Message for Plan {
    fn payload_bytes(&self) -> usize {
        std::mem::size_of::<Self>() + self.trajectory.payload_bytes()
    }
}

/// Another robot's odometry, as received over the link.
#[derive(Clone, Debug, PartialEq)]
pub struct PeerOdometry {
    /// The peer.
    pub robot: RobotId,
    /// Its odometry (stamp on the peer's clock).
    pub odometry: Odometry,
    /// When it arrived here.
    pub received_at: Time,
}
impl Message for PeerOdometry {}

/// The local grid and its distance fields, as the planner and collision checker read
/// them. Published shared (one `Arc`, no copies per subscriber).
#[derive(Clone, Debug, PartialEq)]
pub struct GridSnapshot {
    /// When it was taken.
    pub stamp: Time,
    /// The grid.
    pub grid: LocalGrid,
    /// Distance from each cell to unsafe (occupied or unknown) space, metres.
    pub unsafe_distance_m: Vec<f64>,
    /// Distance from each cell to the nearest frontier, metres (∞ without one).
    pub frontier_distance_m: Vec<f64>,
}

impl Message for GridSnapshot {
    fn payload_bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + 4 * self.grid.values().len()
            + 8 * (self.unsafe_distance_m.len() + self.frontier_distance_m.len())
    }
}

impl GridSnapshot {
    /// Voxel size of this snapshot's grid, metres: fixed, or adapted between α_min
    /// and α_max by Hierarchical Collision Avoidance (thesis §5.1) when it is on.
    #[must_use]
    pub fn resolution_m(&self) -> f64 {
        self.grid.resolution_m()
    }

    /// Distance to unsafe space at a world point (0 outside the grid: unknown).
    #[must_use]
    pub fn clearance_m(&self, p: &nalgebra::Point3<f64>) -> f64 {
        self.grid
            .cell_of(p)
            .map_or(0.0, |c| self.unsafe_distance_m[self.grid.index(c)])
    }

    /// Distance to the nearest frontier at a world point (∞ outside the grid).
    #[must_use]
    pub fn frontier_distance(&self, p: &nalgebra::Point3<f64>) -> f64 {
        self.grid.cell_of(p).map_or(f64::INFINITY, |c| {
            self.frontier_distance_m[self.grid.index(c)]
        })
    }
}

/// A keyframe: a SOGMM fitted to one observation, with its sensor pose (§8.2.2).
#[derive(Clone, Debug, PartialEq)]
pub struct Keyframe {
    /// Per-robot keyframe counter.
    pub id: u32,
    /// Observation time.
    pub stamp: Time,
    /// Sensor (body) pose of the observation, in the owner's world frame.
    pub pose: nalgebra::Isometry3<f64>,
    /// Number of points the mixture was fitted to.
    pub support_size: u32,
    /// The mixture over (x, y, z, intensity) in the world frame.
    pub gmm: crate::mapper::sogmm::Gmm4,
}

impl Message for Keyframe {
    fn payload_bytes(&self) -> usize {
        // Mean 4 + covariance 16 + weight, f64.
        std::mem::size_of::<Self>() + self.gmm.len() * 21 * 8
    }
}

/// A keyframe received from a peer.
#[derive(Clone, Debug, PartialEq)]
pub struct PeerKeyframe {
    /// The peer.
    pub robot: RobotId,
    /// Its keyframe (in the peer's world frame: robots of one team share a frame
    /// in simulation; the Eq. 8.1 frame change comes with multi-frame teams).
    pub keyframe: Keyframe,
    /// When it arrived here.
    pub received_at: Time,
}
impl Message for PeerKeyframe {
    fn payload_bytes(&self) -> usize {
        self.keyframe.payload_bytes()
    }
}

/// This robot's keyframes.
pub const KEYFRAME: Topic<Keyframe> = Topic::new("mapper/keyframe");
/// Peers' keyframes from the link.
pub const PEER_KEYFRAME: Topic<PeerKeyframe> = Topic::new("peer/keyframe");

/// Body pose and velocity from the vehicle.
pub const ODOMETRY: Topic<Odometry> = Topic::new("odometry");
/// Depth + intensity frames from the sensor.
pub const DEPTH_FRAME: Topic<DepthFrame> = Topic::new("sensor/frame");
/// The committed plan.
pub const PLAN: Topic<Plan> = Topic::new("plan/committed");
/// Local grid snapshots.
pub const GRID_SNAPSHOT: Topic<GridSnapshot> = Topic::new("grid/snapshot");
/// Peers' odometry from the link.
pub const PEER_ODOMETRY: Topic<PeerOdometry> = Topic::new("peer/odometry");
/// Peers' committed plans from the link.
pub const PEER_PLAN: Topic<PeerPlan> = Topic::new("peer/plan");
/// Ranked candidates of a planning round, for the collision actor.
pub const PLAN_CANDIDATES: Topic<PlanCandidates> = Topic::new("plan/candidates");
/// The collision actor's verdict on a planning round.
pub const PLAN_DECISION: Topic<PlanDecision> = Topic::new("plan/decision");

/// Changed cells of this robot's own occupancy observations since the last set: the
/// occupancy-grid map sharing the thesis compares GMM keyframes with (§8.2.5, "OG").
/// Values are the robot's own-evidence log-odds, not including what peers shared.
#[derive(Clone, Debug, PartialEq)]
pub struct GridChanges {
    /// When the set was taken.
    pub stamp: Time,
    /// The cells, indexed in the grid window given with them.
    pub set: troupe_comms::wire::GridChangeSet,
}
impl Message for GridChanges {
    fn payload_bytes(&self) -> usize {
        self.set.thesis_bytes()
    }
}

/// A peer's [`GridChanges`], as received over the link.
#[derive(Clone, Debug, PartialEq)]
pub struct PeerGridChanges {
    /// The peer.
    pub robot: RobotId,
    /// Its changed cells, in its world frame.
    pub set: troupe_comms::wire::GridChangeSet,
    /// The transform from the peer's world frame into ours (Eq. 8.1), if they differ:
    /// cell centres are moved with it and land in our nearest cell.
    pub frame: Option<Isometry3<f64>>,
    /// When it arrived here.
    pub received_at: Time,
}
impl Message for PeerGridChanges {
    fn payload_bytes(&self) -> usize {
        self.set.thesis_bytes()
    }
}

/// This robot's occupancy change sets (when it shares its map as a grid).
pub const GRID_CHANGES: Topic<GridChanges> = Topic::new("grid/changes");
/// Peers' occupancy change sets from the link.
pub const PEER_GRID_CHANGES: Topic<PeerGridChanges> = Topic::new("peer/grid_changes");

/// Another robot's committed plan, as received over the link (thesis §8.2.3: plans at
/// 1 Hz with the sender's priority).
#[derive(Clone, Debug, PartialEq)]
pub struct PeerPlan {
    /// The peer.
    pub robot: RobotId,
    /// Its priority; larger values are avoided by smaller ones (§8.2.3).
    pub priority: u16,
    /// The plan, moved into this robot's world frame.
    pub plan: Plan,
    /// When it arrived here.
    pub received_at: Time,
}

impl Message for PeerPlan {
    fn payload_bytes(&self) -> usize {
        self.plan.payload_bytes()
    }
}

/// One candidate of a planning round: a primitive followed by its stopping primitive.
#[derive(Clone, Debug, PartialEq)]
pub struct CandidatePlan {
    /// The primitive, then its stopping primitive from `switch_at` on.
    pub trajectory: Trajectory,
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

/// Which candidate of a round the collision actor committed.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PlanDecision {
    /// The round decided.
    pub round: u64,
    /// Index into the round's candidates, or `None`: the stopping trajectory.
    pub chosen: Option<usize>,
    /// Candidates rejected before the chosen one, with the reason for each.
    pub rejected: Vec<(usize, String)>,
}
impl Message for PlanDecision {}
