//! Link actor tests under the sim-time executor: the actor's wiring — plans over
//! the link (§8.2.3), per-peer store-and-forward, restarts, journals on disk,
//! transports, the roster and heartbeats between real links. The link's logic
//! alone is tested without an executor in `core_tests.rs`.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use super::*;
use crate::link::core_tests::{test_keyframe, test_plan};
use crate::link::{KeyframeEncoding, LinkConfig, LinkJournal, PeerFrame, transform_plan};
use crate::msgs::{PEER_KEYFRAME, PEER_PLAN};
use troupe_algorithms::keyframe::Keyframe;
use troupe_algorithms::plan::Plan;
use troupe_algorithms::team::PeerPlan;
use troupe_comms::shaping::{Incoming, Reassembler, ReassemblyConfig};
use troupe_comms::wire::{self, Payload};
use troupe_runtime::{ActorSpec, Publication, RobotSpec, SimExecutor};
use troupe_runtime::{Destination, Message, RobotId, Time};

const TICK: TimerId = TimerId(0);

/// Publishes a new committed plan every `period`: a straight 2 s line whose
/// offset grows with each plan, so every plan is distinguishable.
struct PlanSource {
    period: Duration,
    count: u32,
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

/// Publishes keyframe `n` (a 40-component mixture, about 2.4 kB on the wire) at
/// `n + 1` seconds, `count` of them.
struct KeyframeSource {
    next: u32,
    count: u32,
}

/// A `keyframes` actor publishing `count` keyframes (see [`KeyframeSource`]).
fn keyframes(count: u32) -> ActorSpec {
    ActorSpec::new("keyframes", move || KeyframeSource { next: 0, count })
}

impl Actor for KeyframeSource {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.set_timer(TICK, Duration::from_secs(1));
        Ok(())
    }
    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        if matches!(event, Event::Timer(TICK)) && self.next < self.count {
            ctx.publish(&KEYFRAME, test_keyframe(self.next, ctx.now()));
            self.next += 1;
        }
        Ok(())
    }
}

/// The ids that `robot` received, in the order it received them, from a log of
/// `(receiving robot, id, when)` entries.
fn ids_received_by<T>(log: &[(RobotId, u32, T)], robot: RobotId) -> Vec<u32> {
    log.iter()
        .filter(|(r, ..)| *r == robot)
        .map(|(_, id, _)| *id)
        .collect()
}

/// 20 ms latency; everything between robots 0 and 1 is lost from 10 s to 40 s.
struct OnePairPartition;

impl troupe_runtime::SimNetwork for OnePairPartition {
    fn route(
        &mut self,
        now: Time,
        from: RobotId,
        to: Destination,
        _bytes: &[u8],
        team_size: usize,
        deliveries: &mut Vec<(RobotId, Time)>,
    ) {
        let cut = (10.0..40.0).contains(&now.as_secs_f64());
        for r in to.recipients(from, team_size) {
            let pair = [from.0.min(r.0), from.0.max(r.0)];
            if !(cut && pair == [0, 1]) {
                deliveries.push((r, now + Duration::from_millis(20)));
            }
        }
    }
}

/// Issue 3, item 2 through the actor: with keyframes in store-and-forward, a
/// partition of one pair loses nothing for that peer, which gets every keyframe
/// once and in order after healing, while the third robot keeps receiving.
#[test]
fn store_and_forward_per_peer_through_the_link_actor() {
    let mut config = LinkConfig::default();
    config.shaper.rate_bps = Some(250_000);
    config.shaper.burst_bytes = 4_096;
    config.shaper.keyframe = troupe_comms::shaping::ClassConfig {
        capacity_messages: 64,
        ..troupe_comms::shaping::ClassConfig::store_and_forward()
    };
    config.peers = vec![0, 1, 2];
    let team = vec![
        RobotSpec::new("r0").with(link(&config)).with(keyframes(50)),
        RobotSpec::new("r1").with(link(&config)),
        RobotSpec::new("r2").with(link(&config)),
    ];
    type Log = Vec<(RobotId, u32, Time)>;
    let log: Arc<Mutex<Log>> = Arc::default();
    let mut exec = SimExecutor::new(team, 3).with_network(OnePairPartition);
    let tap_log = log.clone();
    exec.add_tap(move |p: &Publication<'_>| {
        if let Some(k) = p.get(&PEER_KEYFRAME) {
            assert_eq!(k.robot, RobotId(0));
            tap_log
                .lock()
                .unwrap()
                .push((p.robot, k.keyframe.id, p.time));
        }
    });
    exec.run_until(Time::from_secs_f64(90.0));
    let reports = exec.finish();
    let log = log.lock().unwrap();
    let expected: Vec<u32> = (0..50).collect();
    for robot in [RobotId(1), RobotId(2)] {
        let ids = ids_received_by(&log, robot);
        assert_eq!(ids, expected, "{robot}: every keyframe, once, in order");
    }
    // Robot 2 was not held back by robot 1's partition.
    for (_, id, at) in log.iter().filter(|(r, ..)| *r == RobotId(2)) {
        let offered = Time::from_secs_f64(f64::from(*id + 1));
        assert!(
            at.saturating_since(offered) < Duration::from_secs(1),
            "keyframe {id} at {at:?}"
        );
    }
    // Robot 1 got the partition's keyframes only after it healed.
    let held = log
        .iter()
        .filter(|(r, id, at)| *r == RobotId(1) && (10..39).contains(id) && at.as_secs_f64() >= 40.0)
        .count();
    assert_eq!(held, 29);
    for report in &reports {
        assert!(
            report
                .actors
                .iter()
                .all(|a| a.stats.errors == 0 && a.stats.panics == 0),
            "{report:?}"
        );
    }
}

/// Keyframes go out compact by default (44 instead of 60 bytes per component) and
/// arrive with the same density up to the encoding's rounding.
#[test]
fn compact_keyframes_are_smaller_and_keep_the_density() {
    let offered_bytes = |encoding: KeyframeEncoding| {
        let config = LinkConfig {
            keyframe_encoding: encoding,
            ..LinkConfig::default()
        };
        let team = vec![
            RobotSpec::new("r0").with(link(&config)).with(keyframes(3)),
            RobotSpec::new("r1").with(link(&config)),
        ];
        let received: Arc<Mutex<Vec<Keyframe>>> = Arc::default();
        let status: Arc<Mutex<Option<LinkStatus>>> = Arc::default();
        let mut exec = SimExecutor::new(team, 1);
        let (tap_received, tap_status) = (received.clone(), status.clone());
        exec.add_tap(move |p: &Publication<'_>| {
            if let Some(k) = p.get(&PEER_KEYFRAME) {
                tap_received.lock().unwrap().push(k.keyframe.clone());
            } else if let Some(s) = p.get(&LINK_STATUS)
                && p.robot == RobotId(0)
            {
                *tap_status.lock().unwrap() = Some(s.clone());
            }
        });
        exec.run_until(Time::from_secs_f64(5.0));
        let received = received.lock().unwrap().clone();
        assert_eq!(received.len(), 3);
        for k in &received {
            let sent = test_keyframe(k.id, k.stamp);
            for i in 0..sent.gmm.len() {
                let x = sent.gmm.means()[i] + nalgebra::Vector4::new(0.02, -0.01, 0.03, 0.01);
                let (a, b) = (sent.gmm.log_likelihood(&x), k.gmm.log_likelihood(&x));
                assert!((a - b).abs() < 1e-3, "{encoding:?}: {a} vs {b}");
            }
        }
        let status = status.lock().unwrap().clone().unwrap();
        status
            .shaper
            .class(troupe_comms::wire::Class::Keyframe)
            .offered_bytes
    };
    let exact = offered_bytes(KeyframeEncoding::Exact);
    let compact = offered_bytes(KeyframeEncoding::Compact);
    // 3 keyframes of 40 components: 16 bytes per component saved.
    assert!(
        exact - compact >= 3 * 40 * 15,
        "exact {exact} B, compact {compact} B"
    );
    assert_eq!(KeyframeEncoding::default(), KeyframeEncoding::Compact);
}

/// Wraps the first link actor a factory builds: it panics on the first event at or
/// after `at` (later incarnations do not).
struct PanicsOnceAt {
    inner: LinkActor,
    at: Time,
    armed: Arc<std::sync::atomic::AtomicBool>,
}

impl Actor for PanicsOnceAt {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        self.inner.start(ctx)
    }
    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        if ctx.now() >= self.at && self.armed.swap(false, std::sync::atomic::Ordering::SeqCst) {
            panic!("injected link panic");
        }
        self.inner.handle(event, ctx)
    }
}

/// The link actor panics (and is rebuilt by its supervisor) at 25 s, in the middle
/// of robot 1's partition (10–40 s) while ~15 keyframes wait for it. Journaled, the
/// new link resumes them: robots 1 and 2 still get every keyframe once, in order,
/// and robot 2 keeps hearing odometry (the ids continue, so its duplicate filter
/// passes them). Without the journal robot 1 never gets the stored keyframes.
#[test]
fn a_journaled_link_restarted_after_a_panic_loses_nothing_it_stored() {
    let mut config = LinkConfig::default();
    config.shaper.rate_bps = Some(250_000);
    config.shaper.burst_bytes = 4_096;
    config.shaper.keyframe = troupe_comms::shaping::ClassConfig::store_and_forward();
    config.peers = vec![0, 1, 2];
    let run = |journaled: bool| {
        let armed = Arc::new(std::sync::atomic::AtomicBool::new(true));
        let journal = LinkJournal::default();
        let sender_config = config.clone();
        let sender = ActorSpec::new("link", move || {
            let link = LinkActor::new(sender_config.clone())?;
            let inner = if journaled {
                link.journaled(journal.clone())?
            } else {
                link
            };
            Ok(PanicsOnceAt {
                inner,
                at: Time::from_secs_f64(25.0),
                armed: armed.clone(),
            })
        });
        let team = vec![
            RobotSpec::new("r0").with(sender).with(keyframes(50)),
            RobotSpec::new("r1").with(link(&config)),
            RobotSpec::new("r2").with(link(&config)),
        ];
        let log: Arc<Mutex<Vec<(RobotId, u32)>>> = Arc::default();
        let mut exec = SimExecutor::new(team, 3).with_network(OnePairPartition);
        let tap_log = log.clone();
        exec.add_tap(move |p: &Publication<'_>| {
            if let Some(k) = p.get(&PEER_KEYFRAME) {
                tap_log.lock().unwrap().push((p.robot, k.keyframe.id));
            }
        });
        exec.run_until(Time::from_secs_f64(90.0));
        let reports = exec.finish();
        let restarts: u64 = reports[0].actors.iter().map(|a| a.stats.restarts).sum();
        assert_eq!(restarts, 1, "the link was rebuilt once");
        let log = log.lock().unwrap();
        let ids_at = |robot: RobotId| -> Vec<u32> {
            log.iter()
                .filter(|(r, _)| *r == robot)
                .map(|(_, id)| *id)
                .collect()
        };
        (ids_at(RobotId(1)), ids_at(RobotId(2)))
    };
    let expected: Vec<u32> = (0..50).collect();
    let (one, two) = run(true);
    assert_eq!(one, expected, "robot 1: every keyframe, once, in order");
    assert_eq!(two, expected, "robot 2: every keyframe, once, in order");
    let (one, two) = run(false);
    assert!(
        one.len() < 50 && two.len() < 50,
        "without the journal keyframes are lost: robot 1 got {}, robot 2 got {}",
        one.len(),
        two.len()
    );
}

/// An in-memory "network" between executors, through the transport hook.
#[derive(Default)]
struct MemWire {
    endpoints: Mutex<Vec<(Vec<u32>, troupe_comms::transport::PacketSink)>>,
    packets: std::sync::atomic::AtomicU64,
}

struct MemTransport {
    wire: Arc<MemWire>,
    local: Vec<u32>,
}

impl troupe_comms::transport::PacketTransport for MemTransport {
    fn start(
        &self,
        sink: troupe_comms::transport::PacketSink,
    ) -> Result<(), troupe_comms::transport::TransportError> {
        self.wire
            .endpoints
            .lock()
            .unwrap()
            .push((self.local.clone(), sink));
        Ok(())
    }

    fn send(
        &self,
        from: u32,
        to: Option<u32>,
        frame: &[u8],
    ) -> Result<(), troupe_comms::transport::TransportError> {
        self.wire
            .packets
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let endpoints = self.wire.endpoints.lock().unwrap().clone();
        for (local, sink) in endpoints {
            let addressed = to.is_none_or(|to| local.contains(&to));
            if addressed && !local.contains(&from) {
                sink(troupe_comms::transport::ReceivedPacket {
                    from,
                    to,
                    bytes: frame,
                });
            }
        }
        Ok(())
    }
}

/// Issue 3, item 4: three executors in one process, each running one robot of a
/// 3-robot team with its team id (0, 1, 2), connected only through the
/// transport hook; every robot receives the other two's plans and keyframes.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn realtime_executors_of_one_robot_each_talk_through_a_transport() {
    use troupe_runtime::RealtimeExecutor;
    let wire = Arc::new(MemWire::default());
    type Log = Vec<(RobotId, RobotId, &'static str)>;
    let log: Arc<Mutex<Log>> = Arc::default();
    let mut handles = Vec::new();
    for id in 0..3u32 {
        let config = LinkConfig {
            plan_rate_hz: 5.0,
            ..LinkConfig::default()
        };
        let robot = RobotSpec::new(format!("robot{id}"))
            .with(link(&config))
            .with(ActorSpec::new("plans", || PlanSource {
                period: Duration::from_millis(100),
                count: 0,
            }))
            .with(keyframes(3));
        let mut exec = RealtimeExecutor::new(vec![robot], u64::from(id))
            .with_robot_ids(vec![RobotId(id)])
            .unwrap();
        let tap_log = log.clone();
        exec.add_tap(move |p: &Publication<'_>| {
            if let Some(k) = p.get(&PEER_KEYFRAME) {
                tap_log.lock().unwrap().push((p.robot, k.robot, "keyframe"));
            }
            if let Some(plan) = p.get(&PEER_PLAN) {
                tap_log.lock().unwrap().push((p.robot, plan.robot, "plan"));
            }
        });
        let transport = Arc::new(MemTransport {
            wire: wire.clone(),
            local: vec![id],
        });
        handles.push(exec.spawn_with_transport(transport).unwrap());
    }
    let complete = |log: &Log| {
        (0..3).all(|me| {
            (0..3).filter(|peer| *peer != me).all(|peer| {
                ["plan", "keyframe"]
                    .iter()
                    .all(|kind| log.contains(&(RobotId(me), RobotId(peer), *kind)))
            })
        })
    };
    let start = std::time::Instant::now();
    while !complete(&log.lock().unwrap()) {
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "not every robot heard both peers: {:?}",
            log.lock().unwrap()
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    for handle in handles {
        assert_eq!(handle.transport_errors(), 0);
        for report in handle.shutdown().await {
            for a in &report.actors {
                assert_eq!(a.stats.errors, 0, "{} {}", report.name, a.name);
            }
        }
    }
    assert!(wire.packets.load(std::sync::atomic::Ordering::Relaxed) > 0);
    // A robot never hears itself.
    assert!(log.lock().unwrap().iter().all(|(me, peer, _)| me != peer));
}

#[test]
fn robot_ids_must_match_the_robots_and_be_distinct() {
    use troupe_runtime::{RealtimeExecutor, RobotIdsError};
    let team = || vec![RobotSpec::new("a"), RobotSpec::new("b")];
    assert!(matches!(
        RealtimeExecutor::new(team(), 0).with_robot_ids(vec![RobotId(2)]),
        Err(RobotIdsError::CountMismatch { ids: 1, robots: 2 })
    ));
    assert!(matches!(
        RealtimeExecutor::new(team(), 0).with_robot_ids(vec![RobotId(4), RobotId(4)]),
        Err(RobotIdsError::Duplicate(RobotId(4)))
    ));
    assert!(
        RealtimeExecutor::new(team(), 0)
            .with_robot_ids(vec![RobotId(7), RobotId(3)])
            .is_ok()
    );
}

#[path = "shared_tests.rs"]
mod shared_tests;

/// Issue 23: a robot outside the roster (robot 3, a real link sending keyframes and
/// acknowledging ours) is rejected and counted before anything else looks at its
/// frames: nothing of it is published, it never becomes a recipient, and the team's
/// own keyframe delivery is unchanged.
#[test]
fn a_robot_outside_the_roster_is_rejected_and_counted() {
    let mut config = LinkConfig::default();
    config.shaper.keyframe = troupe_comms::shaping::ClassConfig::store_and_forward();
    config.roster = vec![0, 1, 2];
    config.peers = vec![0, 1, 2];
    let stranger = LinkConfig {
        roster: Vec::new(),
        peers: vec![0, 1, 2, 3],
        ..config.clone()
    };
    let team = vec![
        RobotSpec::new("r0").with(link(&config)).with(keyframes(20)),
        RobotSpec::new("r1").with(link(&config)),
        RobotSpec::new("r2").with(link(&config)),
        RobotSpec::new("r3")
            .with(link(&stranger))
            .with(keyframes(20)),
    ];
    type Log = Vec<(RobotId, RobotId, u32)>;
    let log: Arc<Mutex<Log>> = Arc::default();
    let status: Arc<Mutex<BTreeMap<RobotId, LinkStatus>>> = Arc::default();
    let mut exec = SimExecutor::new(team, 4);
    let (tap_log, tap_status) = (log.clone(), status.clone());
    exec.add_tap(move |p: &Publication<'_>| {
        if let Some(k) = p.get(&PEER_KEYFRAME) {
            tap_log
                .lock()
                .unwrap()
                .push((p.robot, k.robot, k.keyframe.id));
        } else if let Some(s) = p.get(&LINK_STATUS) {
            tap_status.lock().unwrap().insert(p.robot, s.clone());
        }
    });
    exec.run_until(Time::from_secs_f64(30.0));
    exec.finish();
    let log = log.lock().unwrap();
    for robot in [RobotId(0), RobotId(1), RobotId(2)] {
        assert!(
            !log.iter()
                .any(|(r, from, _)| *r == robot && *from == RobotId(3)),
            "{robot} published something of robot 3"
        );
    }
    for robot in [RobotId(1), RobotId(2)] {
        let ids: Vec<u32> = log
            .iter()
            .filter(|(r, from, _)| *r == robot && *from == RobotId(0))
            .map(|(_, _, id)| *id)
            .collect();
        assert_eq!(ids, (0..20).collect::<Vec<_>>(), "{robot}");
    }
    let status = status.lock().unwrap();
    for robot in [RobotId(0), RobotId(1), RobotId(2)] {
        let r = status[&robot].rejections;
        assert!(r.not_in_roster > 0, "{robot}: {r:?}");
        assert_eq!(r.total(), r.not_in_roster, "{robot}: {r:?}");
        // Its frames never reached the reassembler.
        assert_eq!(status[&robot].reassembly.malformed_frames, 0);
    }
    // Robot 0 stored nothing for robot 3: every keyframe was released once robots
    // 1 and 2 had it (the stranger's acks did not make it a recipient).
    assert_eq!(status[&RobotId(0)].shaper.classes[2].drops.total(), 0);
}

/// Issue 23, item 4: robots whose links keep their journal on disk, "killed" (the
/// executor dropped mid-run) and started again from the files: the restarted
/// receiver publishes the peer's keyframes it had before (its team map is whole),
/// once each, and takes the sender's resends for duplicates.
#[test]
fn a_link_journal_on_disk_gives_a_restarted_robot_its_team_map_back() {
    let dirs = [tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap()];
    let mut config = LinkConfig::default();
    config.shaper.keyframe = troupe_comms::shaping::ClassConfig::store_and_forward();
    config.peers = vec![0, 1];
    let journaled = |robot: usize| {
        let config = config.clone();
        let journal = LinkJournal::on_disk(dirs[robot].path(), 1_000).unwrap();
        ActorSpec::new("link", move || {
            LinkActor::new(config.clone())?.journaled(journal.clone())
        })
    };
    let run = |with_source: bool, until_s: f64| {
        let mut r0 = RobotSpec::new("r0").with(journaled(0));
        if with_source {
            r0 = r0.with(keyframes(8));
        }
        let team = vec![r0, RobotSpec::new("r1").with(journaled(1))];
        let log: Arc<Mutex<Vec<(RobotId, u32)>>> = Arc::default();
        let mut exec = SimExecutor::new(team, 2);
        let tap_log = log.clone();
        exec.add_tap(move |p: &Publication<'_>| {
            if let Some(k) = p.get(&PEER_KEYFRAME) {
                tap_log.lock().unwrap().push((p.robot, k.keyframe.id));
            }
        });
        exec.run_until(Time::from_secs_f64(until_s));
        drop(exec); // no clean shutdown: what is on disk is what survives
        log.lock().unwrap().clone()
    };
    let first = run(true, 12.0);
    let expected: Vec<(RobotId, u32)> = (0..8).map(|id| (RobotId(1), id)).collect();
    assert_eq!(first, expected);
    let second = run(false, 5.0);
    assert_eq!(
        second, expected,
        "replayed from robot 1's journal, once each"
    );
    assert!(
        std::fs::metadata(dirs[1].path().join("link.journal"))
            .unwrap()
            .len()
            > 8 * 1_000,
        "the received keyframes are on disk"
    );
}

/// Issue 40, item 4: members with nothing of their own to say (no odometry: a
/// base station, a robot whose odometry stopped) send heartbeats, so the robot
/// storing keyframes for them never suspends them as silent once its keyframes
/// stop coming (acknowledgements alone would have kept them only while there
/// were keyframes to acknowledge), and every keyframe reaches each of them.
#[test]
fn members_with_nothing_to_say_send_heartbeats_and_stay_recipients() {
    let mut config = LinkConfig::default().with_team(2).with_roster_as_peers();
    config.shaper.keyframe = troupe_comms::shaping::ClassConfig::store_and_forward();
    assert_eq!(config.peer_timeout_s, 10.0);
    let team = vec![
        RobotSpec::new("r0").with(link(&config)).with(keyframes(5)),
        RobotSpec::new("r1").with(link(&config)),
        RobotSpec::new("base").with(link(&config)),
    ];
    type Log = Vec<(RobotId, u32)>;
    let log: Arc<Mutex<Log>> = Arc::default();
    let heartbeats = Arc::new(Mutex::new([0u32; 3]));
    let status: Arc<Mutex<BTreeMap<RobotId, LinkStatus>>> = Arc::default();
    let mut exec = SimExecutor::new(team, 5);
    let (tap_log, tap_beats, tap_status) = (log.clone(), heartbeats.clone(), status.clone());
    exec.add_tap(move |p: &Publication<'_>| {
        if let Some(k) = p.get(&PEER_KEYFRAME) {
            tap_log.lock().unwrap().push((p.robot, k.keyframe.id));
        } else if let Some(s) = p.get(&LINK_STATUS) {
            tap_status.lock().unwrap().insert(p.robot, s.clone());
        } else if let Some(tx) = p.get(&LINK_TX)
            && let Ok(Some(Incoming::Message(m))) = Reassembler::new(ReassemblyConfig::default())
                .unwrap()
                .push(0, p.robot.0, &tx.bytes)
            && let Ok(envelope) = wire::decode(&m.bytes)
            && matches!(envelope.payload, Payload::Heartbeat(_))
        {
            tap_beats.lock().unwrap()[p.robot.0 as usize] += 1;
        }
    });
    exec.run_until(Time::from_secs_f64(40.0));
    exec.finish();
    let status = status.lock().unwrap();
    for robot in [RobotId(0), RobotId(1), RobotId(2)] {
        assert_eq!(
            status[&robot].peer_timeouts, 0,
            "{robot}: {:?}",
            status[&robot]
        );
        assert!(status[&robot].silent_peers.is_empty(), "{robot}");
    }
    let log = log.lock().unwrap();
    for robot in [RobotId(1), RobotId(2)] {
        let ids: Vec<u32> = log
            .iter()
            .filter(|(r, _)| *r == robot)
            .map(|(_, id)| *id)
            .collect();
        assert_eq!(ids, (0..5).collect::<Vec<_>>(), "{robot}");
    }
    // About one a second each once idle (none of them has odometry to send).
    let beats = *heartbeats.lock().unwrap();
    for (robot, n) in beats.iter().enumerate() {
        assert!((30..=41).contains(n), "robot {robot} sent {n} heartbeats");
    }
}
