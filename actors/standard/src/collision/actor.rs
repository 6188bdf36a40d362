//! The collision actor: the last gate between planning and the vehicle (thesis §4.1.3,
//! §7, §8.2.3).
//!
//! Each planning round arrives as [`PlanCandidates`], best first. The actor commits the
//! first candidate that passes
//!
//! 1. the distance-field check: every sample of the candidate (primitive and stopping
//!    primitive, every `check_step_s`) keeps the body's bounding radius plus the
//!    field's discretisation slack from unsafe space in the latest [`GridSnapshot`]
//!    — or, when the candidate starts inside that clearance, never comes closer to
//!    unsafe space than its start and hovers or backs away ([`clear_path`]) — (skipped when the robot
//!    has no local grid, e.g. route-following robots);
//! 2. the inter-robot check of a [`PeerAvoidance`] policy against peers' odometry and
//!    plans (priority-based, §8.2.3);
//! 3. when a geofence is set (`[robot.collision] geofence`, a hardware robot's
//!    `[mavlink.geofence]`), the box check, made before the other two: the candidate
//!    from now to its end stays inside ([`within_geofence`]);
//!
//! publishes it on [`PLAN`], or the round's stopping trajectory when none passes or
//! while the operator holds the robot ([`OPERATOR_HOLD`], sent from the base), and
//! answers with a [`PlanDecision`]. Every rejection is counted by reason and logged;
//! the counters go out on [`COLLISION_STATUS`] after each round.
//!
//! Between rounds ([`CollisionActor::braking_for_peers`]): a new plan from a peer this
//! robot must yield to is checked against what the robot has committed, and when they
//! conflict the robot brakes at once — a higher-priority peer expects it to have
//! reacted within `lower_priority_react_s` (1.2 s, troupe-policies' priority check),
//! which the next planning round alone (up to a period later, after the link's
//! delay) does not guarantee.
//!
//! A planning round's plans take over a little after the round (the planner's
//! `lead_s`); every plan committed is sent continued from the one before
//! ([`Trajectory::continued_by`]), and a round decided after its plans should have
//! taken over, or planned from a reference replaced since (a brake), is refused and
//! counted (`stale_rounds`): the robot keeps its committed flight, which ends in its
//! stop, rather than jump.

use std::sync::Arc;
use std::time::Duration;

use nalgebra::Point3;

use serde::{Deserialize, Serialize};

use super::operator::{OPERATOR_HOLD, OperatorHold};
use crate::msgs::{
    GRID_SNAPSHOT, ODOMETRY, PEER_ODOMETRY, PEER_PLAN, PLAN, PLAN_CANDIDATES, PLAN_DECISION,
    VEHICLE_HOLD, VehicleHold,
};
use troupe_algorithms::collision::body::{BodyConfig, BodyError};
use troupe_algorithms::collision::geofence::{Geofence, GeofenceConfig};
use troupe_algorithms::collision::peers::{PeerAvoidance, PeerTable, PeerTrack, must_yield};
use troupe_algorithms::frame::Odometry;
use troupe_algorithms::grid::GridSnapshot;
use troupe_algorithms::plan::Plan;
use troupe_algorithms::planner::candidates::{PlanCandidates, PlanDecision, Rejection};
use troupe_algorithms::planner::committed::Committed;
use troupe_algorithms::planner::primitives::{DynamicLimits, FlatState};
use troupe_algorithms::planner::round::clear_path;
use troupe_algorithms::trajectory::{Knot, Trajectory};
use troupe_runtime::{
    Actor, ActorResult, ConfigError, Context, Event, Message, QueuePolicy, RobotId, Time, Topic,
};

/// Settings of the collision actor (the world part; the peer part is the policy's).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CollisionActorConfig {
    /// The robot body (its bounding radius is the required clearance).
    pub body: BodyConfig,
    /// Extra clearance on top of the body's bounding radius, metres.
    pub margin_m: f64,
    /// Spacing of the samples checked against the distance field, seconds.
    pub check_step_s: f64,
    /// The box no committed plan may leave (world frame, metres); absent: none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub geofence: Option<GeofenceConfig>,
}

impl Default for CollisionActorConfig {
    fn default() -> Self {
        CollisionActorConfig {
            body: BodyConfig::default(),
            margin_m: 0.0,
            check_step_s: 0.1,
            geofence: None,
        }
    }
}

impl CollisionActorConfig {
    /// Checks the numbers and the body; the error names the key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        ConfigError::non_negative("margin_m", self.margin_m)?;
        ConfigError::positive("check_step_s", self.check_step_s)?;
        if let Some(fence) = &self.geofence {
            fence.fence().map_err(|e| e.within("geofence"))?;
        }
        self.body
            .ellipsoid()
            .map(|_| ())
            .map_err(|e: BodyError| ConfigError::new("body", "must describe a valid ellipsoid", e))
    }
}

/// The collision actor's counters (published after every round).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct CollisionStatus {
    /// Rounds decided.
    pub rounds: u64,
    /// Rounds that committed a candidate.
    pub committed: u64,
    /// Rounds that committed the stopping trajectory.
    pub stopped: u64,
    /// Candidates rejected by the distance field.
    pub rejected_clearance: u64,
    /// Candidates rejected against a peer's plan.
    pub rejected_peer_plan: u64,
    /// Candidates rejected against a peer's stopping envelope.
    pub rejected_peer_envelope: u64,
    /// Candidates rejected for leaving the geofence.
    pub rejected_geofence: u64,
    /// Rounds that committed the stopping trajectory because the operator held the
    /// robot (counted in `stopped` too; their candidates are not judged).
    pub held: u64,
    /// This robot's priority in the last round.
    pub priority: u16,
    /// Times the robot braked between rounds because a peer it must yield to sent a
    /// plan that conflicts with the committed one.
    pub braked_for_peers: u64,
    /// Rounds refused because their plans would not continue the committed flight:
    /// decided after they should have taken over (the planner's `lead_s` overran), or
    /// planned from a reference replaced since (a brake). The robot kept the flight
    /// committed, which ends in its stop.
    pub stale_rounds: u64,
    /// Rounds that committed hovering where the vehicle driver holds the robot
    /// ([`VEHICLE_HOLD`]: a hardware robot's sensor or odometry timeout, an autopilot
    /// heartbeat lost and back, the geofence), their candidates not judged.
    pub vehicle_holds: u64,
}
impl Message for CollisionStatus {}

/// The collision actor's counters.
pub const COLLISION_STATUS: Topic<CollisionStatus> = Topic::new("collision/status");

/// Whether `trajectory`, sampled every `step_s` from `from` to its end, is clear of
/// unsafe space in `snapshot` for a required `clearance_m` ([`clear_path`]: keeps it,
/// or — from a start the map has closed in on — hovers or backs away).
#[must_use]
pub fn clear_of_unsafe_space(
    trajectory: &Trajectory,
    from: Time,
    snapshot: &GridSnapshot,
    clearance_m: f64,
    step_s: f64,
) -> bool {
    let span_s = trajectory.end_time().saturating_since(from).as_secs_f64();
    let n = (span_s / step_s.max(1e-3)).ceil().max(1.0) as usize;
    let mut positions = Vec::with_capacity(n + 1);
    for i in 0..=n {
        let t = from + Duration::from_secs_f64(span_s * i as f64 / n as f64);
        let Some(state) = trajectory.state_at(t) else {
            return false;
        };
        positions.push(Point3::from(state.position_m));
    }
    clear_path(positions, snapshot, clearance_m)
}

/// Whether `trajectory` from `from` to its end stays inside `fence` (exactly: linear
/// between knots, so the state at `from` and the later knots decide; the span is the
/// one [`clear_of_unsafe_space`] samples). Logs where it leaves at debug level.
#[must_use]
pub fn within_geofence(trajectory: &Trajectory, from: Time, fence: &Geofence) -> bool {
    match fence.check_from(trajectory, from) {
        Ok(()) => true,
        Err(violation) => {
            tracing::debug!(time = %from, "candidate rejected: {violation}");
            false
        }
    }
}

/// Commits the first candidate of each planning round that passes the checks (see `actors::collision`).
pub struct CollisionActor<P> {
    config: CollisionActorConfig,
    body_radius_m: f64,
    /// `Err`: the configured fence is invalid.
    geofence: Result<Option<Geofence>, ConfigError>,
    avoidance: P,
    snapshot: Option<Arc<GridSnapshot>>,
    odometry: Option<Arc<Odometry>>,
    peers: PeerTable,
    /// Whether it listens to [`OPERATOR_HOLD`] ([`CollisionActor::obeying_operator`]).
    operator: bool,
    held: bool,
    status: CollisionStatus,
    /// Limits and knot spacing of braking between rounds
    /// ([`CollisionActor::braking_for_peers`]).
    braking: Option<(DynamicLimits, f64)>,
    /// The plan committed last.
    committed: Option<Plan>,
    /// Where the vehicle driver holds the robot, if it does ([`VEHICLE_HOLD`]).
    vehicle_hold: Option<(Point3<f64>, f64)>,
}

impl<P: PeerAvoidance> CollisionActor<P> {
    /// A collision actor; `config` must be valid ([`CollisionActorConfig::validate`]),
    /// else the body falls back to the default one and an invalid geofence rejects
    /// every candidate (the robot stops rather than fly unfenced).
    #[must_use]
    pub fn new(config: CollisionActorConfig, avoidance: P) -> Self {
        let body = config
            .body
            .ellipsoid()
            .or_else(|_| BodyConfig::default().ellipsoid());
        let body_radius_m = body.map_or(0.3, |b| b.center().norm() + b.bounding_radius());
        let geofence = config.geofence.map(|f| f.fence()).transpose();
        CollisionActor {
            config,
            body_radius_m,
            geofence,
            avoidance,
            snapshot: None,
            odometry: None,
            peers: PeerTable::default(),
            operator: false,
            held: false,
            status: CollisionStatus::default(),
            braking: None,
            committed: None,
            vehicle_hold: None,
        }
    }

    /// The same actor, braking between rounds when a peer it must yield to sends a
    /// plan that conflicts with the committed one (module docs): the stop is the
    /// shortest within `limits` from the committed reference's state, sampled every
    /// `knot_step_s` (the planner's).
    #[must_use]
    pub fn braking_for_peers(mut self, limits: DynamicLimits, knot_step_s: f64) -> Self {
        self.braking = Some((limits, knot_step_s));
        self
    }

    /// A peer's new plan has been stored: brakes now if the peer is one this robot
    /// must yield to and its plan conflicts with the committed one. Returns whether it
    /// braked.
    fn brake_if_in_the_way_of(&mut self, peer: RobotId, ctx: &mut Context<'_>) -> bool {
        let (Some((limits, knot_step_s)), Some(plan)) = (self.braking, &self.committed) else {
            return false;
        };
        let Some(reference) = plan.reference.as_ref().filter(|_| !plan.stopping) else {
            return false;
        };
        let now = ctx.now();
        let mine = self.avoidance.priority(now);
        let theirs = self.peers.get(peer).and_then(PeerTrack::priority);
        if theirs.is_none() || !must_yield(ctx.robot(), mine, peer, theirs) {
            return false;
        }
        let own = match &self.odometry {
            Some(o) => (**o).clone(),
            None => return false,
        };
        // The sender's plan alone: another peer in the way (one that yields to us, or
        // whose plan went stale) must not hide it.
        let sender = self.peers.only(peer);
        let conflict = self
            .avoidance
            .conflict(now, ctx.robot(), &own, &plan.trajectory, &sender);
        if conflict.is_none_or(|c| c.envelope) {
            return false;
        }
        // Before the committed plan takes over, the flight that leads to it is kept:
        // the stop begins where it does.
        let from = now.max(reference.start);
        let Some(stop) = Committed::braking(&limits, &reference.state_at(from), from) else {
            return false;
        };
        tracing::info!(robot = ctx.robot_name(), time = %now, peer = peer.0, "a peer's new plan crosses the committed one: braking");
        self.status.braked_for_peers += 1;
        let brake = Plan {
            stamp: now,
            trajectory: plan
                .trajectory
                .continued_by(now, &stop.trajectory(knot_step_s)),
            reference: Some(Box::new(stop)),
            stopping: true,
        };
        self.committed = Some(brake.clone());
        ctx.publish(&PLAN, brake);
        ctx.publish(&COLLISION_STATUS, self.status.clone());
        true
    }

    /// Commits hovering where the vehicle holds (`at`, heading `yaw_rad`) from `now`: what
    /// the robot does, whatever the flight committed before would have done, so that
    /// the next rounds plan from there.
    fn commit_hover(&mut self, (at, yaw_rad): (Point3<f64>, f64), ctx: &mut Context<'_>) {
        let now = ctx.now();
        let rest = FlatState::at_rest(at.coords, yaw_rad);
        let hover = self.braking.and_then(|(limits, knot_step_s)| {
            let hover = Committed::braking(&limits, &rest, now)?;
            Some((hover.trajectory(knot_step_s), hover))
        });
        let plan = match hover {
            Some((trajectory, reference)) => Plan {
                stamp: now,
                trajectory,
                reference: Some(Box::new(reference)),
                stopping: true,
            },
            // One knot: held after its end.
            None => Plan {
                stamp: now,
                trajectory: Trajectory::new(vec![Knot {
                    time: now,
                    position_m: at,
                    yaw_rad,
                }])
                .unwrap_or_default(),
                reference: None,
                stopping: true,
            },
        };
        self.status.vehicle_holds += 1;
        self.committed = Some(plan.clone());
        ctx.publish(&PLAN, plan);
        ctx.publish(&COLLISION_STATUS, self.status.clone());
    }

    fn judge(
        &mut self,
        now: Time,
        ctx: &Context<'_>,
        trajectory: &Trajectory,
    ) -> Result<(), Rejection> {
        if let Some(snapshot) = &self.snapshot {
            let clearance = self.body_radius_m
                + self.config.margin_m
                + snapshot.grid.resolution_m() * (3f64.sqrt() + 1.0) / 2.0;
            if !clear_of_unsafe_space(
                trajectory,
                now,
                snapshot,
                clearance,
                self.config.check_step_s,
            ) {
                return Err(Rejection::Clearance);
            }
        }
        let own = match &self.odometry {
            Some(o) => (**o).clone(),
            None => {
                let Some(state) = trajectory.state_at(now) else {
                    return Ok(());
                };
                Odometry {
                    stamp: now,
                    pose: state.pose(),
                    velocity_mps: state.velocity_mps,
                }
            }
        };
        match self
            .avoidance
            .conflict(now, ctx.robot(), &own, trajectory, &self.peers)
        {
            None => Ok(()),
            Some(c) if c.envelope => Err(Rejection::PeerEnvelope),
            Some(_) => Err(Rejection::PeerPlan),
        }
    }

    /// The same actor, holding the robot while the operator says so
    /// ([`OPERATOR_HOLD`], from the operator actor).
    #[must_use]
    pub fn obeying_operator(mut self) -> Self {
        self.operator = true;
        self
    }

    /// The geofence check, apart from the others (an invalid fence rejects all).
    fn fence_check(&self, now: Time, trajectory: &Trajectory) -> Result<(), Rejection> {
        match &self.geofence {
            Ok(None) => Ok(()),
            Ok(Some(fence)) if within_geofence(trajectory, now, fence) => Ok(()),
            _ => Err(Rejection::Geofence),
        }
    }

    /// Whether the plans of `round` continue the committed flight: they take over after
    /// `now` from the committed reference's state there. A round that fails this would
    /// make the reference jump — by what the robot flew since it should have taken
    /// over, or to where a replaced reference would have led — so the committed flight,
    /// which ends in its stop, is kept instead (thesis §4.1.3: the robot replans from a
    /// future reference point). Rounds without references (routes) always continue,
    /// and so does any round once the committed flight is over and the robot hovers
    /// where it ended (a restarted planner, which lost the reference, plans from the
    /// body's pose).
    fn continues_committed(&self, round: &PlanCandidates, now: Time) -> bool {
        let (Some(last), Some(planned)) = (self.committed.as_ref(), round.stop_reference.as_ref())
        else {
            return true;
        };
        let Some(committed) = last
            .reference
            .as_deref()
            .filter(|_| now < last.trajectory.end_time())
        else {
            return true;
        };
        let start = planned.start;
        let there = committed.state_at(start.max(committed.start)).position_m();
        start >= now && (planned.state_at(start).position_m() - there).norm() < 1e-9
    }

    fn decide(&mut self, round: &PlanCandidates, ctx: &mut Context<'_>) {
        let now = ctx.now();
        if let Some(at) = self.vehicle_hold {
            self.status.rounds += 1;
            self.commit_hover(at, ctx);
            return;
        }
        if !self.held && !self.continues_committed(round, now) {
            self.status.stale_rounds += 1;
            tracing::debug!(robot = ctx.robot_name(), time = %now, round = round.round, "round would not continue the committed flight: kept it");
            ctx.publish(
                &PLAN_DECISION,
                PlanDecision {
                    round: round.round,
                    chosen: None,
                    rejected: Vec::new(),
                    stale: true,
                },
            );
            ctx.publish(&COLLISION_STATUS, self.status.clone());
            return;
        }
        let mut rejected = Vec::new();
        let mut chosen = None;
        let candidates = if self.held {
            self.status.held += 1;
            &[][..]
        } else {
            &round.candidates[..]
        };
        for (i, candidate) in candidates.iter().enumerate() {
            let verdict = self
                .fence_check(now, &candidate.trajectory)
                .and_then(|()| self.judge(now, ctx, &candidate.trajectory));
            match verdict {
                Ok(()) => {
                    chosen = Some(i);
                    break;
                }
                Err(reason) => {
                    match reason {
                        Rejection::Clearance => self.status.rejected_clearance += 1,
                        Rejection::PeerPlan => self.status.rejected_peer_plan += 1,
                        Rejection::PeerEnvelope => self.status.rejected_peer_envelope += 1,
                        Rejection::Geofence => self.status.rejected_geofence += 1,
                    }
                    tracing::debug!(robot = ctx.robot_name(), time = %now, round = round.round, candidate = i, reason = reason.as_str(), "candidate rejected");
                    rejected.push((i, reason));
                }
            }
        }
        let blocked_by_peers = chosen.is_none() && rejected.iter().any(|(_, r)| r.is_peer());
        self.avoidance.record_round(now, blocked_by_peers);
        self.status.rounds += 1;
        self.status.priority = self.avoidance.priority(now);
        // A round's plans begin a little ahead of it (the planner's `lead_s`): the
        // flight committed before leads there.
        let continued = |trajectory: &Trajectory| match &self.committed {
            Some(last) => last.trajectory.continued_by(now, trajectory),
            None => trajectory.clone(),
        };
        let plan = match chosen.and_then(|i| round.candidates.get(i)) {
            Some(c) => {
                self.status.committed += 1;
                Plan {
                    stamp: now,
                    trajectory: continued(&c.trajectory),
                    reference: c.reference.clone().map(Box::new),
                    stopping: false,
                }
            }
            None => {
                self.status.stopped += 1;
                if !candidates.is_empty() {
                    tracing::info!(robot = ctx.robot_name(), time = %now, round = round.round, rejected = rejected.len(), "every candidate rejected: stopping");
                }
                Plan {
                    stamp: now,
                    trajectory: continued(&round.stop),
                    reference: round.stop_reference.clone().map(Box::new),
                    stopping: true,
                }
            }
        };
        self.committed = Some(plan.clone());
        ctx.publish(&PLAN, plan);
        ctx.publish(
            &PLAN_DECISION,
            PlanDecision {
                round: round.round,
                chosen,
                rejected,
                stale: false,
            },
        );
        ctx.publish(&COLLISION_STATUS, self.status.clone());
    }
}

impl<P: PeerAvoidance> Actor for CollisionActor<P> {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&PLAN_CANDIDATES, QueuePolicy::LATEST);
        ctx.subscribe(&GRID_SNAPSHOT, QueuePolicy::LATEST);
        ctx.subscribe(&ODOMETRY, QueuePolicy::LATEST);
        ctx.subscribe(&PEER_ODOMETRY, QueuePolicy::Fifo { capacity: 64 });
        ctx.subscribe(&PEER_PLAN, QueuePolicy::Fifo { capacity: 16 });
        if self.operator {
            ctx.subscribe(&OPERATOR_HOLD, QueuePolicy::LATEST);
        }
        ctx.subscribe(&VEHICLE_HOLD, QueuePolicy::LATEST);
        Ok(())
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        if let Event::Message(m) = event {
            if let Some(round) = m.get_arc(&PLAN_CANDIDATES) {
                self.decide(&round, ctx);
                return Ok(());
            }
            if let Some(plan) = m.get_arc(&PEER_PLAN) {
                self.peers.update_plan(&plan);
                if self.vehicle_hold.is_none() && self.brake_if_in_the_way_of(plan.robot, ctx) {
                    return Ok(());
                }
            }
            if let Some(&VehicleHold { at, .. }) = m.get(&VEHICLE_HOLD) {
                let began = at.is_some() && at != self.vehicle_hold;
                self.vehicle_hold = at;
                if let (true, Some(at)) = (began, at) {
                    tracing::info!(robot = ctx.robot_name(), position = ?at.0.coords.as_slice(), "the vehicle holds: hovering there until it follows plans again");
                    self.commit_hover(at, ctx);
                }
                return Ok(());
            }
            // Everything else is stored for the next decision.
            ctx.bookkeeping_only();
            if let Some(snapshot) = m.get_arc(&GRID_SNAPSHOT) {
                self.snapshot = Some(snapshot);
            } else if let Some(odometry) = m.get_arc(&ODOMETRY) {
                self.odometry = Some(odometry);
            } else if let Some(peer) = m.get_arc(&PEER_ODOMETRY) {
                self.peers.update_odometry(&peer);
            } else if let Some(&OperatorHold { held }) = m.get(&OPERATOR_HOLD) {
                if held != self.held {
                    tracing::info!(robot = ctx.robot_name(), held, "operator hold");
                }
                self.held = held;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Mutex;

    use nalgebra::Point3;

    use super::*;
    use troupe_algorithms::collision::peers::PeerConflict;
    use troupe_algorithms::planner::candidates::CandidatePlan;
    use troupe_runtime::{ActorSpec, Publication, RobotId, RobotSpec, SimExecutor, TimerId};

    /// Rejects every trajectory that ends beyond `x_max` (as if a peer were there).
    struct Wall {
        x_max: f64,
    }

    impl PeerAvoidance for Wall {
        fn priority(&self, _now: Time) -> u16 {
            4
        }
        fn conflict(
            &mut self,
            _now: Time,
            _me: RobotId,
            _own: &Odometry,
            candidate: &Trajectory,
            _peers: &PeerTable,
        ) -> Option<PeerConflict> {
            let end = candidate.knots().last()?.position_m;
            (end.x > self.x_max).then_some(PeerConflict {
                peer: RobotId(9),
                envelope: false,
                at_s: 0.0,
                separation_m: 0.0,
            })
        }
    }

    fn line(now: Time, to_x: f64) -> Trajectory {
        Trajectory::new(vec![
            Knot {
                time: now,
                position_m: Point3::new(0.0, 0.0, 1.0),
                yaw_rad: 0.0,
            },
            Knot {
                time: now + Duration::from_secs(2),
                position_m: Point3::new(to_x, 0.0, 1.0),
                yaw_rad: 0.0,
            },
        ])
        .unwrap()
    }

    /// What a test round offers: its candidates, stopping trajectory and reference.
    type Offer = (Vec<CandidatePlan>, Trajectory, Option<Committed>);

    /// Publishes one planning round per second with what `offer(round, now)` gives
    /// (rounds counted from 1; nothing when it gives `None`).
    struct Rounds {
        round: u64,
        offer: fn(u64, Time) -> Option<Offer>,
    }

    impl Rounds {
        fn spec(offer: fn(u64, Time) -> Option<Offer>) -> ActorSpec {
            ActorSpec::new("rounds", move || Rounds { round: 0, offer })
        }
    }

    impl Actor for Rounds {
        fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
            ctx.set_timer(TimerId(0), Duration::from_secs(1));
            Ok(())
        }
        fn handle(&mut self, _event: &Event, ctx: &mut Context<'_>) -> ActorResult {
            self.round += 1;
            let now = ctx.now();
            let Some((candidates, stop, stop_reference)) = (self.offer)(self.round, now) else {
                return Ok(());
            };
            ctx.publish(
                &PLAN_CANDIDATES,
                PlanCandidates {
                    round: self.round,
                    stamp: now,
                    candidates,
                    stop,
                    stop_reference,
                },
            );
            Ok(())
        }
    }

    /// Every round: candidates ending at x = 3, 2, 1.
    fn lines(_round: u64, now: Time) -> Option<Offer> {
        let candidates = [3.0, 2.0, 1.0]
            .iter()
            .map(|&x| CandidatePlan {
                trajectory: line(now, x),
                reference: None,
                switch_at: now + Duration::from_secs(1),
                reward: x,
            })
            .collect();
        Some((candidates, line(now, 0.0), None))
    }

    type Log = (Vec<PlanDecision>, Vec<Plan>, Option<CollisionStatus>);

    fn run(x_max: f64) -> Log {
        run_with(CollisionActorConfig::default(), x_max, None)
    }

    /// Runs the rounds through a collision actor with `config` and a [`Wall`] at
    /// `x_max`, with `extra` beside them, for 3.5 s.
    fn run_with(config: CollisionActorConfig, x_max: f64, extra: Option<ActorSpec>) -> Log {
        run_rounds(Rounds::spec(lines), config, x_max, extra)
    }

    /// [`run_with`] with another source of planning rounds.
    fn run_rounds(
        rounds: ActorSpec,
        config: CollisionActorConfig,
        x_max: f64,
        extra: Option<ActorSpec>,
    ) -> Log {
        let mut robot = RobotSpec::new("r0")
            .with(rounds)
            .with(ActorSpec::new("collision", move || {
                CollisionActor::new(config.clone(), Wall { x_max }).obeying_operator()
            }));
        if let Some(extra) = extra {
            robot.add(extra);
        }
        let log = Arc::new(Mutex::new((Vec::new(), Vec::new(), None)));
        let tap = log.clone();
        let mut exec = SimExecutor::new(vec![robot], 1);
        exec.add_tap(move |p: &Publication<'_>| {
            let mut log = tap.lock().unwrap();
            if let Some(d) = p.get(&PLAN_DECISION) {
                log.0.push(d.clone());
            }
            if let Some(plan) = p.get(&PLAN) {
                log.1.push(plan.clone());
            }
            if let Some(s) = p.get(&COLLISION_STATUS) {
                log.2 = Some(s.clone());
            }
        });
        exec.run_until(Time::from_secs_f64(3.5));
        let _ = exec.finish();
        let log = log.lock().unwrap();
        (log.0.clone(), log.1.clone(), log.2.clone())
    }

    /// A round at 1 s whose plans take over at 1.2 s, then one at 2 s whose plans
    /// should have taken over at 1.7 s (a planner that overran).
    fn late(round: u64, now: Time) -> Option<Offer> {
        use troupe_algorithms::planner::primitives::FlatState;
        let start = match round {
            1 => now + Duration::from_millis(200),
            2 => Time::from_secs_f64(1.7),
            _ => return None,
        };
        let hover = FlatState::at_rest(nalgebra::Vector3::new(0.0, 0.0, 1.0), 0.0);
        let stop = Committed::braking(&DynamicLimits::THESIS, &hover, start).unwrap();
        let candidates = vec![CandidatePlan {
            trajectory: stop.trajectory(0.1),
            reference: Some(stop.clone()),
            switch_at: start,
            reward: 1.0,
        }];
        Some((candidates, stop.trajectory(0.1), Some(stop)))
    }

    #[test]
    fn a_round_decided_after_its_plans_should_have_taken_over_is_refused() {
        let rounds = Rounds::spec(late);
        let (_, plans, status) = run_rounds(rounds, CollisionActorConfig::default(), 100.0, None);
        let status = status.unwrap();
        assert_eq!(plans.len(), 1, "only the round on time commits");
        assert_eq!((status.rounds, status.stale_rounds), (1, 1));
    }

    #[test]
    fn rejects_candidates_leaving_the_geofence() {
        use troupe_algorithms::collision::geofence::GeofenceConfig;
        let config = CollisionActorConfig {
            geofence: Some(GeofenceConfig {
                min_m: [-1.0, -1.0, 0.0],
                max_m: [2.5, 1.0, 2.0],
            }),
            ..CollisionActorConfig::default()
        };
        assert_eq!(config.validate(), Ok(()));
        // No peer in the way: only the fence (x ≤ 2.5) rejects the candidate to x = 3.
        let (decisions, plans, status) = run_with(config.clone(), 100.0, None);
        assert_eq!(decisions.len(), 3);
        for d in &decisions {
            assert_eq!(d.chosen, Some(1));
            assert_eq!(d.rejected, vec![(0, Rejection::Geofence)]);
        }
        assert!(
            plans
                .iter()
                .all(|p| p.trajectory.knots().last().unwrap().position_m.x == 2.0)
        );
        let status = status.unwrap();
        assert_eq!((status.rejected_geofence, status.committed), (3, 3));
        // A fence that the start is outside of rejects everything: the robot stops.
        let outside = CollisionActorConfig {
            geofence: Some(GeofenceConfig {
                min_m: [0.5, -1.0, 0.0],
                max_m: [4.0, 1.0, 2.0],
            }),
            ..config.clone()
        };
        let (decisions, _, status) = run_with(outside, 100.0, None);
        assert!(decisions.iter().all(|d| d.chosen.is_none()));
        assert_eq!(status.unwrap().rejected_geofence, 9);
        // An invalid fence fails safe (validation names it first).
        let invalid = CollisionActorConfig {
            geofence: Some(GeofenceConfig {
                min_m: [0.0, 0.0, 0.0],
                max_m: [f64::NAN, 1.0, 1.0],
            }),
            ..config
        };
        assert_eq!(invalid.validate().unwrap_err().key, "geofence");
        let (_, _, status) = run_with(invalid, 100.0, None);
        assert_eq!(status.unwrap().stopped, 3);
    }

    /// Holds the robot from 1.5 s to 2.5 s, as the operator actor does.
    struct Operator(u32);

    impl Actor for Operator {
        fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
            ctx.set_timer(TimerId(0), Duration::from_millis(500));
            Ok(())
        }
        fn handle(&mut self, _event: &Event, ctx: &mut Context<'_>) -> ActorResult {
            self.0 += 1;
            match self.0 {
                3 => ctx.publish(&OPERATOR_HOLD, OperatorHold { held: true }),
                5 => ctx.publish(&OPERATOR_HOLD, OperatorHold { held: false }),
                _ => {}
            }
            Ok(())
        }
    }

    #[test]
    fn commits_the_stop_while_the_operator_holds() {
        let operator = ActorSpec::new("operator", || Operator(0));
        let (decisions, plans, status) =
            run_with(CollisionActorConfig::default(), 1.5, Some(operator));
        let chosen: Vec<_> = decisions.iter().map(|d| d.chosen).collect();
        assert_eq!(chosen, vec![Some(2), None, Some(2)]);
        assert!(decisions[1].rejected.is_empty(), "held: nothing judged");
        let stopping: Vec<_> = plans.iter().map(|p| p.stopping).collect();
        assert_eq!(stopping, vec![false, true, false]);
        let status = status.unwrap();
        assert_eq!((status.held, status.stopped, status.committed), (1, 1, 2));
    }

    #[test]
    fn commits_the_first_accepted_candidate_and_counts_rejections() {
        let (decisions, plans, status) = run(1.5);
        assert_eq!(decisions.len(), 3);
        for d in &decisions {
            assert_eq!(d.chosen, Some(2));
            assert_eq!(
                d.rejected,
                vec![(0, Rejection::PeerPlan), (1, Rejection::PeerPlan)]
            );
        }
        // The committed plan is the accepted candidate (ends at x = 1).
        assert!(
            plans
                .iter()
                .all(|p| p.trajectory.knots().last().unwrap().position_m.x == 1.0)
        );
        let status = status.unwrap();
        assert_eq!((status.rounds, status.committed, status.stopped), (3, 3, 0));
        assert_eq!(status.rejected_peer_plan, 6);
        assert_eq!(status.priority, 4);
    }

    #[test]
    fn stops_when_every_candidate_is_rejected() {
        let (decisions, plans, status) = run(0.5);
        assert!(
            decisions
                .iter()
                .all(|d| d.chosen.is_none() && d.rejected.len() == 3)
        );
        assert!(
            plans
                .iter()
                .all(|p| p.trajectory.knots().last().unwrap().position_m.x == 0.0)
        );
        assert_eq!(status.unwrap().stopped, 3);
    }

    /// The vehicle driver holds at (5, 5, 1) from 1.5 s to 2.5 s.
    struct Holder;

    impl Actor for Holder {
        fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
            ctx.set_timer(TimerId(1), Duration::from_millis(500));
            Ok(())
        }
        fn handle(&mut self, _event: &Event, ctx: &mut Context<'_>) -> ActorResult {
            let now = ctx.now();
            let at = if now.as_secs_f64() < 1.4 || now.as_secs_f64() > 2.4 {
                None
            } else {
                Some((Point3::new(5.0, 5.0, 1.0), 0.5))
            };
            ctx.publish(&VEHICLE_HOLD, VehicleHold { stamp: now, at });
            Ok(())
        }
    }

    /// Issue 40, item 3: while the vehicle holds, the collision actor commits hovering
    /// where it holds — at once, and in every round — whatever the candidates; planning
    /// resumes from there when it stops holding.
    #[test]
    fn a_vehicle_hold_commits_hovering_where_it_holds() {
        let robot = RobotSpec::new("r0")
            .with(Rounds::spec(lines))
            .with(ActorSpec::new("holder", || Holder))
            .with(ActorSpec::new("collision", move || {
                CollisionActor::new(CollisionActorConfig::default(), Wall { x_max: 10.0 })
                    .braking_for_peers(DynamicLimits::THESIS, 0.1)
            }));
        let plans: Arc<Mutex<Vec<Plan>>> = Arc::default();
        let status: Arc<Mutex<Option<CollisionStatus>>> = Arc::default();
        let (tap_plans, tap_status) = (plans.clone(), status.clone());
        let mut exec = SimExecutor::new(vec![robot], 1);
        exec.add_tap(move |p: &Publication<'_>| {
            if let Some(plan) = p.get(&PLAN) {
                tap_plans.lock().unwrap().push(plan.clone());
            } else if let Some(s) = p.get(&COLLISION_STATUS) {
                *tap_status.lock().unwrap() = Some(s.clone());
            }
        });
        exec.run_until(Time::from_secs_f64(3.5));
        let _ = exec.finish();
        let plans = plans.lock().unwrap();
        let at = |plan: &Plan, s: f64| plan.trajectory.state_at(Time::from_secs_f64(s));
        let hovers: Vec<&Plan> = plans
            .iter()
            .filter(|p| p.stamp.as_secs_f64() > 1.4 && p.stamp.as_secs_f64() < 2.4)
            .collect();
        // The hold at 1.5 s, and the round at 2 s.
        assert_eq!(hovers.len(), 2, "{plans:?}");
        for hover in &hovers {
            let t = hover.stamp.as_secs_f64();
            for s in [t, t + 0.5, t + 5.0] {
                let state = at(hover, s).expect("a state");
                assert!((state.position_m - Point3::new(5.0, 5.0, 1.0)).norm() < 1e-9);
                assert!(state.velocity_mps.norm() < 1e-9);
            }
            let reference = hover.reference.as_ref().expect("a primitive");
            assert!((reference.state_at(hover.stamp).yaw_rad() - 0.5).abs() < 1e-9);
            assert!(hover.stopping);
        }
        // Rounds before and after the hold commit their candidates.
        let after = plans.last().expect("plans");
        assert!(after.stamp.as_secs_f64() > 2.9 && !after.stopping);
        let status = status.lock().unwrap().clone().expect("a status");
        assert_eq!(status.vehicle_holds, 2);
        assert_eq!(status.rounds, 3);
    }
}
