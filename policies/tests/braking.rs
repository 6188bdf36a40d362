//! The collision actor with the priority check brakes between planning rounds when a
//! peer it must yield to sends a plan across the one it committed (thesis §8.2.3; the
//! higher-priority peer counts on it to react within `lower_priority_react_s`).

#![allow(clippy::unwrap_used)]

use std::sync::{Arc, Mutex};
use std::time::Duration;

use nalgebra::{Isometry3, Point3, Vector3};
use troupe_actors::collision::{COLLISION_STATUS, CollisionActor, CollisionActorConfig};
use troupe_actors::msgs::{ODOMETRY, PEER_PLAN, PLAN, PLAN_CANDIDATES};
use troupe_algorithms::frame::Odometry;
use troupe_algorithms::plan::Plan;
use troupe_algorithms::planner::candidates::{CandidatePlan, PlanCandidates};
use troupe_algorithms::planner::committed::Committed;
use troupe_algorithms::planner::primitives::{Action, DynamicLimits, FlatState, Primitive};
use troupe_algorithms::team::PeerPlan;
use troupe_algorithms::trajectory::{Knot, Trajectory};
use troupe_core::{RobotId, Time};
use troupe_policies::priority::{PriorityAvoidance, PriorityConfig};
use troupe_runtime::{
    Actor, ActorResult, ActorSpec, Context, Event, Publication, RobotSpec, SimExecutor, TimerId,
};

const KNOT_STEP_S: f64 = 0.1;

/// Our robot at rest at the origin, 1 m up.
fn start() -> FlatState {
    FlatState::at_rest(Vector3::new(0.0, 0.0, 1.0), 0.0)
}

/// Flying +x from the origin from `now`: the primitive until 1 s, then its stop.
fn forward(limits: &DynamicLimits, now: Time) -> Committed {
    let action = Action {
        vx_mps: 1.0,
        vy_mps: 0.0,
        vz_mps: 0.0,
        yaw_rate_rad_s: 0.0,
    };
    let primitive = Primitive::forward_arc(&start(), action, 2.0);
    let stopping = limits.stopping(&primitive.state_at(1.0)).unwrap();
    Committed {
        start: now,
        primitive,
        switch_s: 1.0,
        stopping,
    }
}

/// A peer's straight flight from `a` to `b` at 2 m/s, from `t0`.
fn peer_line(t0: Time, a: Point3<f64>, b: Point3<f64>) -> Trajectory {
    let duration_s = (b - a).norm() / 2.0;
    let n = (duration_s / KNOT_STEP_S).ceil() as usize;
    Trajectory::new(
        (0..=n)
            .map(|i| Knot {
                time: t0 + Duration::from_secs_f64(duration_s * i as f64 / n as f64),
                position_m: a + (b - a) * (i as f64 / n as f64),
                yaw_rad: 0.0,
            })
            .collect(),
    )
    .unwrap()
}

/// Plays the rest of the robot: odometry at 0.5 s, one planning round at 1 s (the
/// forward flight), the peer's plan at 1.5 s, and at 2 s a round planned from the
/// forward flight as if nothing had happened (taking over at 2.2 s).
struct Script {
    tick: u32,
    limits: DynamicLimits,
    /// The peers' ids, priorities, and where they fly from and to, announced in order.
    peers: Vec<(RobotId, u16, Point3<f64>, Point3<f64>)>,
}

impl Actor for Script {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.set_timer(TimerId(0), Duration::from_millis(500));
        Ok(())
    }
    fn handle(&mut self, _event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        self.tick += 1;
        let now = ctx.now();
        match self.tick {
            1 => ctx.publish(
                &ODOMETRY,
                Odometry {
                    stamp: now,
                    pose: Isometry3::translation(0.0, 0.0, 1.0),
                    velocity_mps: Vector3::zeros(),
                },
            ),
            2 => {
                let plan = forward(&self.limits, now);
                let stop = Committed::braking(&self.limits, &start(), now).unwrap();
                ctx.publish(
                    &PLAN_CANDIDATES,
                    PlanCandidates {
                        round: 1,
                        stamp: now,
                        candidates: vec![CandidatePlan {
                            trajectory: plan.trajectory(KNOT_STEP_S),
                            switch_at: now + Duration::from_secs(1),
                            reference: Some(plan),
                            reward: 1.0,
                        }],
                        stop: stop.trajectory(KNOT_STEP_S),
                        stop_reference: Some(stop),
                    },
                );
            }
            4 => {
                let flight = forward(&self.limits, Time::from_secs_f64(1.0));
                let start = now + Duration::from_millis(200);
                let stop =
                    Committed::braking(&self.limits, &flight.state_at(start), start).unwrap();
                ctx.publish(
                    &PLAN_CANDIDATES,
                    PlanCandidates {
                        round: 2,
                        stamp: now,
                        candidates: Vec::new(),
                        stop: stop.trajectory(KNOT_STEP_S),
                        stop_reference: Some(stop),
                    },
                );
            }
            3 => {
                for &(robot, priority, a, b) in &self.peers {
                    ctx.publish(
                        &PEER_PLAN,
                        PeerPlan {
                            robot,
                            priority,
                            plan: Plan::new(now, peer_line(now, a, b)),
                            run_start_ns: 0,
                            received_at: now,
                        },
                    );
                }
            }
            _ => {}
        }
        Ok(())
    }
}

/// The plans our robot commits, how often it braked for peers and how many rounds it
/// refused as stale, with a peer (`id`, `priority`) flying from `a` to `b` announced
/// at 1.5 s.
fn fly_with_peer(id: u32, priority: u16, a: [f64; 3], b: [f64; 3]) -> (Vec<Plan>, u64, u64) {
    fly_with_peers(&[(id, priority, a, b)])
}

/// [`fly_with_peer`] with several peers, their plans announced in this order.
fn fly_with_peers(peers: &[(u32, u16, [f64; 3], [f64; 3])]) -> (Vec<Plan>, u64, u64) {
    let limits = DynamicLimits::THESIS;
    let peers: Vec<_> = peers
        .iter()
        .map(|&(id, priority, a, b)| (RobotId(id), priority, Point3::from(a), Point3::from(b)))
        .collect();
    let robot = RobotSpec::new("r0")
        .with(ActorSpec::new("script", move || Script {
            tick: 0,
            limits,
            peers: peers.clone(),
        }))
        .with(ActorSpec::new("collision", move || {
            CollisionActor::new(
                CollisionActorConfig::default(),
                PriorityAvoidance::new(PriorityConfig::default()),
            )
            .braking_for_peers(limits, KNOT_STEP_S)
        }));
    let log = Arc::new(Mutex::new((Vec::new(), 0, 0)));
    let tap = log.clone();
    let mut exec = SimExecutor::new(vec![robot], 1);
    exec.add_tap(move |p: &Publication<'_>| {
        let mut log = tap.lock().unwrap();
        if let Some(plan) = p.get(&PLAN) {
            log.0.push(plan.clone());
        }
        if let Some(status) = p.get(&COLLISION_STATUS) {
            log.1 = status.braked_for_peers;
            log.2 = status.stale_rounds;
        }
    });
    exec.run_until(Time::from_secs_f64(3.0));
    let _ = exec.finish();
    let log = log.lock().unwrap();
    (log.0.clone(), log.1, log.2)
}

#[test]
fn a_robot_brakes_at_once_when_a_peer_it_must_yield_to_plans_across_its_path() {
    let limits = DynamicLimits::THESIS;
    // Head on, along our path, from a peer of higher priority.
    let (plans, braked, stale) = fly_with_peer(1, 5, [6.0, 0.0, 1.0], [0.0, 0.0, 1.0]);
    assert_eq!(braked, 1);
    // The round at 2 s was planned from the forward flight the brake replaced: it
    // would jump back onto it, and is refused.
    assert_eq!(stale, 1);
    assert_eq!(plans.len(), 2, "{plans:?}");
    assert!(!plans[0].stopping);
    let stop = &plans[1];
    assert!(stop.stopping);
    assert_eq!(stop.stamp, Time::from_secs_f64(1.5));
    // It brakes from where the committed flight had it at 1.5 s, and stops short of
    // where that flight would have stopped.
    let committed = forward(&limits, Time::from_secs_f64(1.0));
    let here = committed.state_at(Time::from_secs_f64(1.5)).position_m();
    let first = stop.trajectory.knots()[0].position_m;
    assert!((first.coords - here).norm() < 1e-9, "{first} vs {here}");
    let stopped_x = stop.trajectory.knots().last().unwrap().position_m.x;
    let planned_x = plans[0].trajectory.knots().last().unwrap().position_m.x;
    assert!(stopped_x < planned_x, "{stopped_x} vs {planned_x}");
    let reference = stop.reference.as_ref().unwrap();
    let end = reference.state_at(stop.trajectory.end_time());
    assert!(end.velocity_mps().norm() < 1e-6);
}

#[test]
fn a_robot_keeps_its_plan_for_peers_out_of_the_way_or_of_lower_priority() {
    // The same peer flight, but the peer must yield to us (same priority, higher id).
    // (The round at 2 s continues the forward flight: committed.)
    let (plans, braked, stale) = fly_with_peer(3, 0, [6.0, 0.0, 1.0], [0.0, 0.0, 1.0]);
    assert_eq!((plans.len(), braked, stale), (2, 0, 0));
    // A peer of higher priority flying elsewhere.
    let (plans, braked, stale) = fly_with_peer(1, 5, [6.0, 8.0, 1.0], [0.0, 8.0, 1.0]);
    assert_eq!((plans.len(), braked, stale), (2, 0, 0));
}

#[test]
fn a_robot_brakes_for_a_peer_it_must_yield_to_whatever_other_peers_do() {
    // Robot 1 (same priority as ours: it yields to us) flies at us head-on from 3 m and
    // is announced first; then robot 2, of higher priority, from 6 m, 0.4 m beside that
    // path. Robot 1 is in the way too, but the check of robot 2's plan is about robot 2
    // (it failed while the first conflict of all peers was taken: robot 1's).
    let (plans, braked, _) = fly_with_peers(&[
        (1, 0, [3.0, 0.0, 1.0], [-3.0, 0.0, 1.0]),
        (2, 5, [6.0, 0.4, 1.0], [0.0, 0.4, 1.0]),
    ]);
    assert_eq!(braked, 1, "{plans:?}");
    assert!(plans[1].stopping);
}
