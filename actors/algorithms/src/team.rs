//! What a robot learns of its teammates over the link: their odometry, keyframes and
//! committed plans, stamped with the sender and the time they arrived (thesis §8.2).

use troupe_core::{Message, RobotId, Time};

use crate::frame::Odometry;
use crate::keyframe::Keyframe;
use crate::plan::Plan;

/// Another robot's odometry, as received over the link.
#[derive(Clone, Debug, PartialEq)]
pub struct PeerOdometry {
    /// The peer.
    pub robot: RobotId,
    /// Its odometry (stamped in this robot's run time, from the team clock).
    pub odometry: Odometry,
    /// When the peer's current run began, on the team clock (the envelope's
    /// `run_start_ns`): a later run than the one known means the peer restarted, and
    /// what it said in its earlier run no longer holds.
    pub run_start_ns: u64,
    /// When it arrived here.
    pub received_at: Time,
}
impl Message for PeerOdometry {}

/// A keyframe received from a peer.
#[derive(Clone, Debug, PartialEq)]
pub struct PeerKeyframe {
    /// The peer.
    pub robot: RobotId,
    /// Its keyframe (in the peer's world frame: robots of one team share a frame
    /// in simulation; the Eq. 8.1 frame change comes with multi-frame teams), stamped
    /// in this robot's run time: a keyframe made before this run began (resent from a
    /// journal) is stamped with the run's start.
    pub keyframe: Keyframe,
    /// When the peer made it, on the team clock (run time in simulation, Unix time
    /// between processes), nanoseconds: its time whenever it was made, for what
    /// outlives this run (a base station's map files).
    pub made_ns: u64,
    /// When it arrived here.
    pub received_at: Time,
}
impl Message for PeerKeyframe {
    fn payload_bytes(&self) -> usize {
        self.keyframe.payload_bytes()
    }
}

/// Another robot's committed plan, as received over the link (thesis §8.2.3: plans at
/// 1 Hz with the sender's priority).
#[derive(Clone, Debug, PartialEq)]
pub struct PeerPlan {
    /// The peer.
    pub robot: RobotId,
    /// Its priority; larger values are avoided by smaller ones (§8.2.3).
    pub priority: u16,
    /// The plan, moved into this robot's world frame (times in this robot's run
    /// time, from the team clock).
    pub plan: Plan,
    /// When the peer's current run began, on the team clock (the envelope's
    /// `run_start_ns`): a later run than the one known means the peer restarted, and
    /// what it said in its earlier run no longer holds.
    pub run_start_ns: u64,
    /// When it arrived here.
    pub received_at: Time,
}

impl Message for PeerPlan {
    fn payload_bytes(&self) -> usize {
        self.plan.payload_bytes()
    }
}
