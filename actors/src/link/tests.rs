//! Link actor tests under the sim-time executor: plans over the link (§8.2.3) and
//! per-peer store-and-forward.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use nalgebra::Point3;

use super::*;
use crate::runtime::{ActorSpec, Publication, RobotSpec, SimExecutor};
use crate::trajectory::{Knot, Trajectory};

const TICK: TimerId = TimerId(0);

/// Publishes a new committed plan every `period`: a straight 2 s line whose
/// offset grows with each plan, so every plan is distinguishable.
struct PlanSource {
    period: Duration,
    count: u32,
}

fn test_plan(index: u32, now: Time) -> Plan {
    let knots = (0..=20)
        .map(|k| Knot {
            time: now + Duration::from_millis(100 * k),
            position_m: Point3::new(
                f64::from(index) + 0.1 * k as f64,
                -0.5 * f64::from(index),
                1.0,
            ),
            yaw_rad: 0.05 * f64::from(index),
        })
        .collect();
    Plan {
        stamp: now,
        trajectory: Trajectory::new(knots).unwrap(),
    }
}

impl Actor for PlanSource {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.set_timer(TICK, self.period);
        Ok(())
    }
    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        if matches!(event, Event::Timer(TICK)) {
            ctx.publish(&PLAN, test_plan(self.count, ctx.now()));
            self.count += 1;
        }
        Ok(())
    }
}

fn link(config: &LinkConfig) -> ActorSpec {
    let config = config.clone();
    ActorSpec::new("link", move || LinkActor::new(config.clone()))
}

/// Records sent plans and received peer plans.
#[derive(Default)]
struct PlanLog {
    sent: Vec<Plan>,
    received: Vec<PeerPlan>,
}

#[test]
fn plans_reach_the_peer_at_the_plan_rate_in_its_frame() {
    let sender = LinkConfig {
        priority: 7,
        ..LinkConfig::default()
    };
    let frame = PeerFrame {
        robot: 0,
        translation_m: [4.0, -1.0, 0.5],
        rotation_rpy_deg: [0.0, 0.0, 120.0],
    };
    let receiver = LinkConfig {
        peer_frames: vec![frame],
        ..LinkConfig::default()
    };
    let team = vec![
        RobotSpec::new("r0")
            .with(link(&sender))
            .with(ActorSpec::new("plans", || PlanSource {
                period: Duration::from_millis(250),
                count: 0,
            })),
        RobotSpec::new("r1").with(link(&receiver)),
    ];
    let log = Arc::new(Mutex::new(PlanLog::default()));
    let mut exec = SimExecutor::new(team, 1);
    let tap_log = log.clone();
    exec.add_tap(move |p: &Publication<'_>| {
        let mut log = tap_log.lock().unwrap();
        if let Some(plan) = p.get(&PLAN) {
            log.sent.push(plan.clone());
        }
        if let Some(peer) = p.get(&PEER_PLAN) {
            assert_eq!(p.robot, RobotId(1));
            log.received.push(peer.clone());
        }
    });
    exec.run_until(Time::from_secs_f64(6.0));
    let reports = exec.finish();
    let log = log.lock().unwrap();
    assert!(log.sent.len() >= 20, "{} plans published", log.sent.len());
    // At most 1 Hz: 6 s of plans give at most 7, and the link keeps up.
    let n = log.received.len();
    assert!((5..=7).contains(&n), "{n} plans received");
    for pair in log.received.windows(2) {
        let gap = pair[1].received_at.saturating_since(pair[0].received_at);
        assert!(gap >= Duration::from_millis(999), "plans {gap:?} apart");
    }
    let t = frame.transform();
    for peer in log.received.iter() {
        assert_eq!(peer.robot, RobotId(0));
        assert_eq!(peer.priority, 7);
        // The plan received is one that was sent, moved by Eq. 8.1.
        let sent = log
            .sent
            .iter()
            .find(|s| s.stamp == peer.plan.stamp)
            .expect("a received plan was sent");
        let expected = transform_plan(sent, &t).unwrap();
        let (a, b) = (expected.trajectory.knots(), peer.plan.trajectory.knots());
        assert_eq!(a.len(), b.len());
        for (a, b) in a.iter().zip(b) {
            assert!(a.time.as_nanos().abs_diff(b.time.as_nanos()) < 1_000);
            assert!((a.position_m - b.position_m).norm() < 1e-4);
            let dyaw = (a.yaw_rad - b.yaw_rad).sin().abs();
            assert!(dyaw < 1e-5, "{} vs {}", a.yaw_rad, b.yaw_rad);
        }
        // 120° about z: the heading turns by 120°.
        let original = sent.trajectory.knots()[0].yaw_rad;
        let turned = b[0].yaw_rad - original - 120f64.to_radians();
        assert!(turned.sin().abs() < 1e-5);
    }
    // The newest plan is not held back longer than one period.
    let last_sent = log.sent.last().unwrap().stamp;
    let last_received = log.received.last().unwrap().plan.stamp;
    assert!(last_sent.saturating_since(last_received) <= Duration::from_secs(1));
    for report in &reports {
        assert!(
            report
                .actors
                .iter()
                .all(|a| a.stats.errors == 0 && a.stats.panics == 0)
        );
    }
}

#[test]
fn a_zero_plan_rate_shares_no_plans() {
    let quiet = LinkConfig {
        plan_rate_hz: 0.0,
        ..LinkConfig::default()
    };
    let team = vec![
        RobotSpec::new("r0")
            .with(link(&quiet))
            .with(ActorSpec::new("plans", || PlanSource {
                period: Duration::from_millis(250),
                count: 0,
            })),
        RobotSpec::new("r1").with(link(&LinkConfig::default())),
    ];
    let received = Arc::new(Mutex::new(0usize));
    let mut exec = SimExecutor::new(team, 1);
    let counter = received.clone();
    exec.add_tap(move |p: &Publication<'_>| {
        if p.get(&PEER_PLAN).is_some() {
            *counter.lock().unwrap() += 1;
        }
    });
    exec.run_until(Time::from_secs_f64(3.0));
    assert_eq!(*received.lock().unwrap(), 0);
}
