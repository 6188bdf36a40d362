//! The standard topics of a robot and their message types (most of them plain types
//! of `troupe_algorithms`; import them from there).
//!
//! | topic | type | from → to |
//! |---|---|---|
//! | `odometry` | [`Odometry`] | vehicle → sensor, grid, planner, collision, explorer, teleop, link |
//! | `sensor/frame` | [`DepthFrame`] | sensor → mapper, grid |
//! | `plan/committed` | [`Plan`] | collision (planner, explorer or teleop without it) → vehicle, link, planner, explorer |
//! | `mapper/keyframe` | [`Keyframe`] | mapper → grid, link |
//! | `peer/keyframe` | [`PeerKeyframe`] | link → grid, planner |
//! | `grid/snapshot` | [`GridSnapshot`] | grid → planner, collision, teleop |
//! | `peer/odometry` | [`PeerOdometry`] | link → collision |
//! | `peer/plan` | [`PeerPlan`] | link → collision, planner |
//! | `plan/candidates` | [`PlanCandidates`] | planner or explorer → collision |
//! | `plan/decision` | [`PlanDecision`] | collision → planner |
//! | `grid/changes` | [`GridChanges`] | grid → link (occupancy-grid map sharing) |
//! | `peer/grid_changes` | [`PeerGridChanges`] | link → grid, planner |
//! | `vehicle/hold` | [`VehicleHold`] | vehicle driver (MAVLink) → collision |
//! | `link/tx`, `link/rx` | [`LinkTx`](troupe_runtime::LinkTx), [`LinkRx`](troupe_runtime::LinkRx) | link ↔ network |

use nalgebra::Isometry3;
use troupe_algorithms::frame::{DepthFrame, Odometry};
use troupe_algorithms::grid::GridSnapshot;
use troupe_algorithms::keyframe::Keyframe;
use troupe_algorithms::plan::Plan;
use troupe_algorithms::planner::candidates::{PlanCandidates, PlanDecision};
use troupe_algorithms::team::{PeerKeyframe, PeerOdometry, PeerPlan};
use troupe_runtime::{Message, RobotId, Time, Topic};

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
/// Whether the vehicle driver holds the robot where it stands.
pub const VEHICLE_HOLD: Topic<VehicleHold> = Topic::new("vehicle/hold");

/// A vehicle driver holds the robot where it stands instead of following the committed
/// plan (a hardware robot's sensor or odometry timeout, an autopilot heartbeat lost
/// and back, a reference outside the geofence), or no longer does. While it holds, the
/// collision actor commits hovering there, so that planning goes on from where the
/// robot is and the driver resumes on a plan that starts where it holds, without a
/// jump to where the flight committed before the hold would have led.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VehicleHold {
    /// When the hold began or ended.
    pub stamp: Time,
    /// Where it holds (world frame) and its heading (radians); `None`: it follows the
    /// plan again.
    pub at: Option<(nalgebra::Point3<f64>, f64)>,
}
impl Message for VehicleHold {}

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
