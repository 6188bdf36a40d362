//! What a robot knows about its teammates for inter-robot avoidance (thesis §8.2.3):
//! their latest odometry (10 Hz over the link) and committed plan with its priority
//! (1 Hz), and the [`PeerAvoidance`] trait through which the collision actor asks a
//! policy (`troupe_policies::priority`) whether a candidate is safe against them.

use std::collections::BTreeMap;

use crate::frame::Odometry;
use crate::team::{PeerOdometry, PeerPlan};
use crate::trajectory::Trajectory;
use troupe_core::{RobotId, Time};

/// The latest of what arrived from one peer, in its current run.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PeerTrack {
    /// The peer's run this track belongs to (its start on the team clock): a message
    /// from a later run replaces the whole track, one from an earlier run is ignored.
    pub run_start_ns: u64,
    /// Latest odometry, if any.
    pub odometry: Option<PeerOdometry>,
    /// Latest committed plan (with the sender's priority), if any.
    pub plan: Option<PeerPlan>,
}

impl PeerTrack {
    /// The peer's priority as it last announced it (`None` before its first plan).
    #[must_use]
    pub fn priority(&self) -> Option<u16> {
        self.plan.as_ref().map(|p| p.priority)
    }
}

/// Whether this robot (`me`, priority `mine`) must avoid a peer (`peer`, `theirs`):
/// higher priority wins, ties go to the lower robot id (thesis §8.2.3). A peer whose
/// priority is unknown (no plan yet) is avoided.
#[must_use]
pub fn must_yield(me: RobotId, mine: u16, peer: RobotId, theirs: Option<u16>) -> bool {
    match theirs {
        None => true,
        Some(theirs) => theirs > mine || (theirs == mine && peer < me),
    }
}

/// Stores `message` in `held` unless what is held has a later `stamp`.
fn keep_latest<T: Clone>(held: &mut Option<T>, message: &T, stamp: impl Fn(&T) -> Time) {
    if held.as_ref().is_none_or(|h| stamp(h) <= stamp(message)) {
        *held = Some(message.clone());
    }
}

/// Latest odometry and plan per peer, keyed by robot.
///
/// Stamps are on the team clock (`troupe_core::TeamClock`), so they keep increasing
/// across a peer's restarts; each message also names the peer's run, and a restart
/// (a later run) voids what the earlier run said — its last plan no longer describes
/// where the peer goes.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PeerTable {
    tracks: BTreeMap<RobotId, PeerTrack>,
}

impl PeerTable {
    /// The track of `robot` for a message of its run `run_start_ns`: a new run starts
    /// a new track; `None` for a message of an earlier run (it arrived late).
    fn track_of_run(&mut self, robot: RobotId, run_start_ns: u64) -> Option<&mut PeerTrack> {
        let track = self.tracks.entry(robot).or_default();
        if run_start_ns > track.run_start_ns {
            *track = PeerTrack {
                run_start_ns,
                ..PeerTrack::default()
            };
        }
        (run_start_ns == track.run_start_ns).then_some(track)
    }

    /// Records a peer's odometry (an older stamp than the one held is ignored: the link
    /// may reorder).
    pub fn update_odometry(&mut self, odometry: &PeerOdometry) {
        if let Some(track) = self.track_of_run(odometry.robot, odometry.run_start_ns) {
            keep_latest(&mut track.odometry, odometry, |o| o.odometry.stamp);
        }
    }

    /// Records a peer's plan (an older plan than the one held is ignored).
    pub fn update_plan(&mut self, plan: &PeerPlan) {
        if let Some(track) = self.track_of_run(plan.robot, plan.run_start_ns) {
            keep_latest(&mut track.plan, plan, |p| p.plan.stamp);
        }
    }

    /// What is known of `peer`, if it has been heard from.
    #[must_use]
    pub fn get(&self, peer: RobotId) -> Option<&PeerTrack> {
        self.tracks.get(&peer)
    }

    /// A table of `peer` alone (empty if it has not been heard from): to check one
    /// peer's plan whatever the others do.
    #[must_use]
    pub fn only(&self, peer: RobotId) -> PeerTable {
        PeerTable {
            tracks: self
                .tracks
                .get(&peer)
                .map(|t| (peer, t.clone()))
                .into_iter()
                .collect(),
        }
    }

    /// Every peer heard from, by robot id.
    pub fn iter(&self) -> impl Iterator<Item = (RobotId, &PeerTrack)> {
        self.tracks.iter().map(|(id, t)| (*id, t))
    }

    /// Number of peers heard from.
    #[must_use]
    pub fn len(&self) -> usize {
        self.tracks.len()
    }

    /// Whether no peer has been heard from.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.tracks.is_empty()
    }
}

/// Why a candidate conflicts with a peer.
#[derive(Clone, Debug, PartialEq)]
pub struct PeerConflict {
    /// The peer.
    pub peer: RobotId,
    /// True when the peer was modelled by its stopping envelope at its last known
    /// position (plan stale or missing), false when its plan was followed in time.
    pub envelope: bool,
    /// Seconds after the check when the cylinders first overlap.
    pub at_s: f64,
    /// Horizontal distance between the centres there, metres.
    pub separation_m: f64,
}

/// The inter-robot check of the collision actor (thesis §8.2.3), implemented by
/// policies (`troupe_policies::priority::PriorityAvoidance`).
pub trait PeerAvoidance: Send + 'static {
    /// This robot's priority at `now` (announced to peers with its plans).
    fn priority(&self, now: Time) -> u16;

    /// Whether `candidate` (a primitive followed by its stopping primitive, from `now`)
    /// conflicts with a peer that this robot must avoid; `None` when it is safe.
    fn conflict(
        &mut self,
        now: Time,
        me: RobotId,
        own: &Odometry,
        candidate: &Trajectory,
        peers: &PeerTable,
    ) -> Option<PeerConflict>;

    /// Tells the policy whether the last round committed a candidate (`true`) or had to
    /// stop because of peers (`false`); dynamic priority rules use it.
    fn record_round(&mut self, now: Time, blocked_by_peers: bool) {
        let _ = (now, blocked_by_peers);
    }
}

impl PeerAvoidance for Box<dyn PeerAvoidance> {
    fn priority(&self, now: Time) -> u16 {
        (**self).priority(now)
    }

    fn conflict(
        &mut self,
        now: Time,
        me: RobotId,
        own: &Odometry,
        candidate: &Trajectory,
        peers: &PeerTable,
    ) -> Option<PeerConflict> {
        (**self).conflict(now, me, own, candidate, peers)
    }

    fn record_round(&mut self, now: Time, blocked_by_peers: bool) {
        (**self).record_round(now, blocked_by_peers);
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::{Isometry3, Point3, Vector3};

    use super::*;
    use crate::plan::Plan;
    use crate::trajectory::Knot;

    fn odometry(run_start_ns: u64, stamp_s: f64, x: f64) -> PeerOdometry {
        PeerOdometry {
            robot: RobotId(0),
            odometry: Odometry {
                stamp: Time::from_secs_f64(stamp_s),
                pose: Isometry3::translation(x, 0.0, 1.0),
                velocity_mps: Vector3::zeros(),
            },
            run_start_ns,
            received_at: Time::from_secs_f64(stamp_s),
        }
    }

    fn plan(run_start_ns: u64, stamp_s: f64) -> PeerPlan {
        let at = Time::from_secs_f64(stamp_s);
        let knot = |time, x| Knot {
            time,
            position_m: Point3::new(x, 0.0, 1.0),
            yaw_rad: 0.0,
        };
        let trajectory = Trajectory::new(vec![
            knot(at, 0.0),
            knot(at + std::time::Duration::from_secs(2), 2.0),
        ])
        .expect("a trajectory");
        PeerPlan {
            robot: RobotId(0),
            priority: 3,
            plan: Plan::new(at, trajectory),
            run_start_ns,
            received_at: at,
        }
    }

    #[test]
    fn a_restart_voids_the_earlier_run_and_its_late_messages() {
        let mut table = PeerTable::default();
        table.update_plan(&plan(0, 50.0));
        table.update_odometry(&odometry(0, 50.0, 1.0));
        // The peer restarts at 60 s: its new run's odometry replaces the track, and
        // the earlier run's plan no longer describes where it goes.
        let restart_ns = 60_000_000_000;
        table.update_odometry(&odometry(restart_ns, 60.5, 7.0));
        let track = table.get(RobotId(0)).expect("heard from");
        assert_eq!(track.run_start_ns, restart_ns);
        assert_eq!(track.plan, None);
        assert_eq!(
            track.priority(),
            None,
            "avoided until it announces a priority"
        );
        // A message of the earlier run that arrives late changes nothing.
        table.update_odometry(&odometry(0, 59.0, 3.0));
        table.update_plan(&plan(0, 59.0));
        let track = table.get(RobotId(0)).expect("heard from");
        assert_eq!(track.plan, None);
        let x = track
            .odometry
            .as_ref()
            .map(|o| o.odometry.pose.translation.x);
        assert_eq!(x, Some(7.0));
        // Within one run, newer stamps win and older ones are ignored.
        table.update_odometry(&odometry(restart_ns, 60.4, 5.0));
        table.update_plan(&plan(restart_ns, 61.0));
        let track = table.get(RobotId(0)).expect("heard from");
        let x = track
            .odometry
            .as_ref()
            .map(|o| o.odometry.pose.translation.x);
        assert_eq!(x, Some(7.0));
        assert_eq!(track.priority(), Some(3));
    }
}
