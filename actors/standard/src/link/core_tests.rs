//! [`LinkCore`] without an executor (DESIGN §5): shaping to the configured rate,
//! strict priority between classes, store-and-forward until acknowledged and across
//! a new core built from the journal, the silence of recipients and restarted
//! peers, and the rejections of what the network brings. A [`Team`] of cores stands
//! in for the executor: it fires each core's timers in time order and hands the
//! frames one core transmits to the others at once.

use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;
use std::time::Duration;

use nalgebra::Point3;
use troupe_algorithms::frame::Odometry;
use troupe_algorithms::keyframe::Keyframe;
use troupe_algorithms::plan::Plan;
use troupe_algorithms::team::PeerOdometry;
use troupe_algorithms::trajectory::{Knot, Trajectory};
use troupe_comms::shaping::ClassConfig;
use troupe_comms::shaping::frame::{self, ParsedFrame};
use troupe_comms::wire::{self, Class, Envelope, Payload};
use troupe_runtime::{Destination, LinkTx, RobotId, TeamClock, Time};

use super::{
    LinkConfig, LinkCore, LinkIdentity, LinkInput, LinkJournal, LinkOutput, LinkStatus, LinkTimer,
};

/// A 40-component keyframe (about 1.9 kB on the wire, compact), numbered `id`.
pub(super) fn test_keyframe(id: u32, stamp: Time) -> Keyframe {
    use nalgebra::{Matrix4, Vector4};
    let n = 40;
    let gmm = troupe_algorithms::sogmm::Gmm4::new(
        vec![1.0 / n as f64; n],
        (0..n)
            .map(|i| Vector4::new(i as f64 * 0.1, f64::from(id), 1.0, 0.5))
            .collect(),
        vec![Matrix4::from_diagonal(&Vector4::new(0.01, 0.02, 0.01, 0.005)); n],
    )
    .unwrap();
    Keyframe {
        id,
        stamp,
        pose: nalgebra::Isometry3::translation(f64::from(id), 0.0, 1.0),
        support_size: 1000,
        gmm,
    }
}

/// A straight 2 s line whose offset grows with `index`, so every plan is
/// distinguishable.
pub(super) fn test_plan(index: u32, now: Time) -> Plan {
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
    Plan::new(now, Trajectory::new(knots).unwrap())
}

/// One member of a [`Team`]: its core, the timers it armed and what it published.
struct Member {
    robot: u32,
    core: LinkCore,
    /// Armed timers: next tick and period.
    timers: BTreeMap<LinkTimer, (Time, Duration)>,
    /// Everything but the timers, in order, with the time.
    published: Vec<(Time, LinkOutput)>,
}

impl Member {
    /// The frames it transmitted, with their times.
    fn frames(&self) -> impl Iterator<Item = (Time, &LinkTx)> {
        self.published.iter().filter_map(|(t, o)| match o {
            LinkOutput::Transmit(tx) => Some((*t, tx)),
            _ => None,
        })
    }

    /// The ids of the peers' keyframes it published, in order.
    fn keyframes_heard(&self) -> Vec<(RobotId, u32)> {
        self.published
            .iter()
            .filter_map(|(_, o)| match o {
                LinkOutput::PeerKeyframe(k) => Some((k.robot, k.keyframe.id)),
                _ => None,
            })
            .collect()
    }

    /// The peers' odometry it published, in order.
    fn odometry_heard(&self) -> Vec<&PeerOdometry> {
        self.published
            .iter()
            .filter_map(|(_, o)| match o {
                LinkOutput::PeerOdometry(p) => Some(p),
                _ => None,
            })
            .collect()
    }

    /// The x of each peer odometry it published, in order.
    fn positions_heard(&self) -> Vec<f64> {
        self.odometry_heard()
            .iter()
            .map(|o| o.odometry.pose.translation.x)
            .collect()
    }

    /// The last status it published.
    fn last_status(&self) -> &LinkStatus {
        self.published
            .iter()
            .rev()
            .find_map(|(_, o)| match o {
                LinkOutput::Status(s) => Some(&**s),
                _ => None,
            })
            .expect("a status")
    }
}

/// Cores that talk to each other with no latency, while `up` says the network
/// carries frames sent at that time.
struct Team {
    members: Vec<Member>,
    now: Time,
    up: fn(Time) -> bool,
    in_flight: VecDeque<(u32, LinkTx)>,
}

impl Team {
    fn new(up: fn(Time) -> bool) -> Self {
        Team {
            members: Vec::new(),
            now: Time::ZERO,
            up,
            in_flight: VecDeque::new(),
        }
    }

    /// Starts `core` as robot `robot` now, in place of an earlier core of that robot.
    fn join(&mut self, robot: u32, mut core: LinkCore) {
        let identity = LinkIdentity {
            robot: RobotId(robot),
            name: format!("r{robot}"),
            clock: TeamClock::SHARED,
        };
        let mut out = Vec::new();
        core.start(identity, self.now, &mut out).unwrap();
        let member = Member {
            robot,
            core,
            timers: BTreeMap::new(),
            published: Vec::new(),
        };
        self.members.retain(|m| m.robot != robot);
        self.members.push(member);
        let index = self.members.len() - 1;
        self.apply(index, out);
        self.deliver();
    }

    fn index(&self, robot: u32) -> usize {
        self.members
            .iter()
            .position(|m| m.robot == robot)
            .expect("a member")
    }

    fn member(&self, robot: u32) -> &Member {
        &self.members[self.index(robot)]
    }

    /// Hands `input` to robot `robot`'s core now (after the timers due by now).
    fn input(&mut self, robot: u32, input: LinkInput<'_>) {
        let index = self.index(robot);
        self.handle(index, input).unwrap();
        self.deliver();
    }

    fn handle(
        &mut self,
        index: usize,
        input: LinkInput<'_>,
    ) -> Result<(), troupe_runtime::ActorError> {
        let mut out = Vec::new();
        let result = self.members[index].core.handle(self.now, input, &mut out);
        self.apply(index, out);
        result
    }

    /// Records a core's outputs: timers armed or cancelled, frames put in flight.
    fn apply(&mut self, index: usize, outputs: Vec<LinkOutput>) {
        let now = self.now;
        let member = &mut self.members[index];
        for output in outputs {
            match output {
                LinkOutput::SetTimer(timer, period) => {
                    member.timers.insert(timer, (now + period, period));
                }
                LinkOutput::CancelTimer(timer) => {
                    member.timers.remove(&timer);
                }
                LinkOutput::Transmit(tx) => {
                    self.in_flight.push_back((member.robot, tx.clone()));
                    member.published.push((now, LinkOutput::Transmit(tx)));
                }
                other => member.published.push((now, other)),
            }
        }
    }

    /// Hands the frames in flight to their recipients (whose answers follow).
    fn deliver(&mut self) {
        while let Some((from, tx)) = self.in_flight.pop_front() {
            if !(self.up)(self.now) {
                continue;
            }
            for index in 0..self.members.len() {
                let to = self.members[index].robot;
                let addressed = match tx.to {
                    Destination::Broadcast => to != from,
                    Destination::Robot(r) => r.0 == to,
                };
                if addressed {
                    let input = LinkInput::Frame {
                        from: RobotId(from),
                        bytes: &tx.bytes,
                    };
                    self.handle(index, input).unwrap();
                }
            }
        }
    }

    /// Fires every timer due by `until`, in time order, and moves the clock there.
    fn run_until(&mut self, until: Time) {
        loop {
            let next = self
                .members
                .iter()
                .enumerate()
                .flat_map(|(i, m)| m.timers.iter().map(move |(t, (at, _))| (*at, i, *t)))
                .min();
            let Some((at, index, timer)) = next.filter(|(at, ..)| *at <= until) else {
                break;
            };
            self.now = at;
            let timers = &mut self.members[index].timers;
            if let Some((next, period)) = timers.get_mut(&timer) {
                *next = at + *period;
            }
            self.handle(index, LinkInput::Tick(timer)).unwrap();
            self.deliver();
        }
        self.now = until;
    }
}

fn secs(s: f64) -> Time {
    Time::from_secs_f64(s)
}

/// A data frame of one fragment carrying `body` (`troupe_comms::shaping::frame`'s
/// layout), message `message_id` of `class`.
pub(super) fn one_fragment_frame(message_id: u32, class: Class, body: &[u8]) -> Vec<u8> {
    let mut frame = vec![0, class.index() as u8, 0];
    frame.extend_from_slice(&message_id.to_le_bytes());
    frame.extend_from_slice(&0u16.to_le_bytes());
    frame.extend_from_slice(&1u16.to_le_bytes());
    frame.extend_from_slice(body);
    frame
}

/// An envelope as a frame of one fragment.
fn envelope_frame(message_id: u32, envelope: &Envelope) -> Vec<u8> {
    let body = wire::encode(envelope).expect("a valid envelope");
    one_fragment_frame(message_id, envelope.class, &body)
}

/// Robot `sender`'s odometry at `x`, numbered `sequence`, stamped `stamp_ms` in the
/// run that started at `run_start_ms` (team clock, ms).
pub(super) fn odometry_envelope(
    sender: u32,
    run_start_ms: u64,
    sequence: u64,
    stamp_ms: u64,
    x: f64,
) -> Envelope {
    Envelope::new(
        0,
        sender,
        sequence,
        stamp_ms * 1_000_000,
        Payload::Odometry(wire::Odometry {
            position_m: [x, 0.0, 1.0],
            orientation_xyzw: [0.0, 0.0, 0.0, 1.0],
            velocity_mps: [0.0; 3],
        }),
    )
    .from_run(run_start_ms * 1_000_000)
}

/// Plays `frames` (at seconds, from robot, bytes) on robot 1's core (`config`)
/// until `until_s`: robot 1's member, with what it published.
fn forged(config: LinkConfig, frames: Vec<(f64, u32, Vec<u8>)>, until_s: f64) -> Team {
    let mut team = Team::new(|_| true);
    team.join(1, LinkCore::new(config).unwrap());
    for (at_s, from, bytes) in frames {
        team.run_until(secs(at_s));
        let input = LinkInput::Frame {
            from: RobotId(from),
            bytes: &bytes,
        };
        team.input(1, input);
    }
    team.run_until(secs(until_s));
    team
}

/// Forged odometry frames from robot 0: (at seconds, envelope), numbered in order.
fn forged_odometry(envelopes: Vec<(f64, Envelope)>) -> Vec<(f64, u32, Vec<u8>)> {
    (0u32..)
        .zip(envelopes)
        .map(|(id, (at, e))| (at, e.sender, envelope_frame(id, &e)))
        .collect()
}

/// A link at 10 kB/s with a 4 kB bucket, keyframes waiting in a deep queue.
fn saturated() -> LinkConfig {
    let mut config = LinkConfig::default();
    config.shaper.rate_bps = Some(80_000);
    config.shaper.burst_bytes = 4_096;
    config.shaper.keyframe.capacity_messages = 256;
    config.peers = vec![1];
    config
}

/// Robot 0 on a [`saturated`] link with `count` keyframes offered at 0 s.
fn keyframe_backlog(count: u32) -> Team {
    let mut team = Team::new(|_| true);
    team.join(0, LinkCore::new(saturated()).unwrap());
    for id in 0..count {
        team.input(0, LinkInput::Keyframe(&test_keyframe(id, Time::ZERO)));
    }
    team
}

/// Bytes sent by time `t` never exceed rate × t + burst, and a backlog keeps the
/// link at its rate.
#[test]
fn the_link_sends_no_more_than_its_rate_and_burst() {
    let mut team = keyframe_backlog(60);
    team.run_until(secs(8.0));
    let (rate, burst) = (10_000.0, 4_096.0);
    let mut total = 0.0;
    for (at, tx) in team.member(0).frames() {
        total += tx.bytes.len() as f64;
        let allowed = rate * at.as_secs_f64() + burst;
        assert!(total <= allowed, "{total} B by {at:?}, allowed {allowed}");
    }
    // 60 keyframes of about 1.9 kB are more than 8 s of the link: it stays busy.
    let full = rate * 8.0 + burst;
    assert!(total >= full - 1_200.0, "{total} B sent, {full} B allowed");
    let status = team.member(0).core.status();
    assert_eq!(status.shaper.total_sent_bytes() as f64, total);
}

/// Odometry goes before plans and plans before keyframes: offered behind a backlog
/// of keyframes, they are the next frames out.
#[test]
fn odometry_goes_before_plans_and_plans_before_keyframes() {
    let mut team = keyframe_backlog(20);
    team.run_until(secs(2.0));
    // Right after a keyframe frame went out: the bucket is empty, so what is
    // offered now waits for the next frame's tokens.
    let (pump, _) = team.member(0).timers[&LinkTimer::Pump];
    team.run_until(pump);
    let before = team.member(0).frames().count();
    let odometry = Odometry {
        stamp: pump,
        pose: nalgebra::Isometry3::translation(1.0, 2.0, 1.0),
        velocity_mps: nalgebra::Vector3::zeros(),
    };
    team.input(0, LinkInput::Plan(Arc::new(test_plan(0, pump))));
    team.input(0, LinkInput::Odometry(Arc::new(odometry)));
    team.input(0, LinkInput::Tick(LinkTimer::Odometry));
    team.run_until(secs(3.0));
    let classes: Vec<Class> = team
        .member(0)
        .frames()
        .skip(before)
        .map(|(_, tx)| frame::class_of(&tx.bytes).unwrap())
        .collect();
    let first_keyframe = classes.iter().position(|c| *c == Class::Keyframe);
    let odometry_at = classes.iter().position(|c| *c == Class::Odometry);
    let plans: Vec<usize> = (0..classes.len())
        .filter(|i| classes[*i] == Class::Plan)
        .collect();
    assert!(first_keyframe.is_some(), "{classes:?}");
    assert_eq!(odometry_at, Some(0), "{classes:?}");
    assert!(!plans.is_empty(), "{classes:?}");
    assert!(
        plans.iter().all(|p| Some(*p) < first_keyframe),
        "{classes:?}"
    );
}

/// Store-and-forward keyframes, both robots knowing each other from the start.
fn store_and_forward() -> LinkConfig {
    let mut config = LinkConfig::default();
    config.shaper.keyframe = ClassConfig::store_and_forward();
    config.peers = vec![0, 1];
    config
}

/// Robot 0 (journaled) offers three store-and-forward keyframes to robot 1 at
/// 0.5 s, over a network that is `up` when it says.
fn three_keyframes_stored(up: fn(Time) -> bool) -> (LinkJournal, Team) {
    let journal = LinkJournal::default();
    let mut team = Team::new(up);
    let sender = LinkCore::new(store_and_forward()).unwrap();
    team.join(0, sender.journaled(journal.clone()).unwrap());
    team.join(1, LinkCore::new(store_and_forward()).unwrap());
    team.run_until(secs(0.5));
    for id in 0..3 {
        team.input(0, LinkInput::Keyframe(&test_keyframe(id, secs(0.5))));
    }
    (journal, team)
}

/// A peer that hears nothing for 5 s gets every keyframe once, in order, after the
/// sender went back to it again and again; once acknowledged, nothing is stored
/// and nothing more is sent.
#[test]
fn store_and_forward_retransmits_until_acknowledged() {
    let (journal, mut team) = three_keyframes_stored(|t| t >= secs(5.0));
    team.run_until(secs(4.9));
    assert!(team.member(1).keyframes_heard().is_empty());
    assert_eq!(journal.stored_messages(), 3);
    let status = team.member(0).core.status();
    assert!(status.shaper.class(Class::Keyframe).retransmitted_messages > 0);
    team.run_until(secs(20.0));
    let heard = team.member(1).keyframes_heard();
    assert_eq!(
        heard,
        vec![(RobotId(0), 0), (RobotId(0), 1), (RobotId(0), 2)]
    );
    assert_eq!(journal.stored_messages(), 0);
    let status = team.member(0).core.status();
    assert_eq!(
        status.shaper.class(Class::Keyframe).acknowledged_messages,
        3
    );
    let late = team.member(0).frames().filter(|(at, tx)| {
        *at >= secs(15.0) && frame::class_of(&tx.bytes).unwrap() == Class::Keyframe
    });
    assert_eq!(late.count(), 0, "nothing left to send");
}

/// A core that stored keyframes nobody acknowledged is replaced by a new one from
/// the same journal: the new core sends what the old one stored, once each, and
/// numbers its own messages after them (a reused id would be dropped as a repeat).
#[test]
fn a_new_core_from_the_journal_sends_what_the_old_one_stored() {
    let (journal, mut team) = three_keyframes_stored(|t| t >= secs(3.0));
    team.run_until(secs(3.0));
    assert_eq!(journal.stored_messages(), 3);
    let restarted = LinkCore::new(store_and_forward()).unwrap();
    team.join(0, restarted.journaled(journal.clone()).unwrap());
    team.input(0, LinkInput::Keyframe(&test_keyframe(3, secs(3.0))));
    team.run_until(secs(10.0));
    let heard: Vec<u32> = team
        .member(1)
        .keyframes_heard()
        .into_iter()
        .map(|(_, id)| id)
        .collect();
    assert_eq!(heard, vec![0, 1, 2, 3]);
    assert_eq!(journal.stored_messages(), 0);
    let status = team.member(1).core.status();
    assert_eq!(status.rejections.total(), 0, "{:?}", status.rejections);
}

/// A recipient silent for longer than `peer_timeout_s` is suspended (once), and
/// heard again at once when it comes back from a restart (a new run start, whose
/// sequence numbers start again).
#[test]
fn a_silent_peer_is_suspended_and_a_restarted_one_heard_again() {
    let config = store_and_forward();
    assert_eq!(config.peer_timeout_s, 10.0);
    let frames = forged_odometry(vec![
        (0.5, odometry_envelope(0, 0, 0, 450, 1.0)),
        // Robot 0 restarted at 11.5 s without its journal: numbered from 0 again.
        (12.2, odometry_envelope(0, 11_500, 0, 12_000, 2.0)),
    ]);
    let mut team = forged(config, frames[..1].to_vec(), 10.9);
    let status = team.member(1).last_status();
    assert!(status.silent_peers.is_empty(), "{status:?}");
    team.run_until(secs(11.9));
    let status = team.member(1).last_status();
    assert_eq!(status.silent_peers, vec![0]);
    assert_eq!(status.peer_timeouts, 1);
    team.run_until(secs(12.2));
    let input = LinkInput::Frame {
        from: RobotId(0),
        bytes: &frames[1].2,
    };
    team.input(1, input);
    team.run_until(secs(13.5));
    let member = team.member(1);
    let status = member.last_status();
    assert!(status.silent_peers.is_empty(), "{status:?}");
    assert_eq!(status.peer_timeouts, 1);
    assert_eq!(status.rejections.total(), 0);
    let runs: Vec<(u64, f64)> = member
        .odometry_heard()
        .iter()
        .map(|o| (o.run_start_ns, o.odometry.pose.translation.x))
        .collect();
    assert_eq!(runs, vec![(0, 1.0), (11_500_000_000, 2.0)]);
}

/// Issue 45, item 1: stamps are on the team clock and every message names its
/// sender's run, so a restarted peer is heard at once, while a stamp too far ahead
/// of this robot's clock is rejected and counted.
#[test]
fn a_restarted_peer_is_heard_at_once_and_a_future_stamp_is_rejected() {
    let odometry = |run_start_ms: u64, stamp_ms: u64, x: f64| {
        odometry_envelope(0, run_start_ms, stamp_ms, stamp_ms, x)
    };
    let frames = forged_odometry(vec![
        (0.5, odometry(0, 450, 1.0)),
        // An hour ahead: would hold robot 1's view of robot 0 for an hour.
        (1.0, odometry(0, 3_600_000, 2.0)),
        // Robot 0 restarted at 1.2 s: its new run is heard at once.
        (1.5, odometry(1_200, 1_450, 3.0)),
        // 0.4 s ahead is within the bound (clocks a little apart).
        (2.0, odometry(1_200, 2_400, 4.0)),
    ]);
    let team = forged(LinkConfig::default(), frames, 3.5);
    let member = team.member(1);
    let heard: Vec<(u64, u64, f64)> = member
        .odometry_heard()
        .iter()
        .map(|o| {
            (
                o.run_start_ns,
                o.odometry.stamp.as_nanos() / 1_000_000,
                o.odometry.pose.translation.x,
            )
        })
        .collect();
    assert_eq!(
        heard,
        vec![
            (0, 450, 1.0),
            (1_200_000_000, 1_450, 3.0),
            (1_200_000_000, 2_400, 4.0)
        ]
    );
    let status = member.last_status();
    assert_eq!(status.rejections.from_the_future, 1);
    assert_eq!(status.rejections.total(), 1);
}

/// Issue 45, item 2: the base station's id may send commands, acknowledgements and
/// heartbeats, never a robot's messages: odometry under the base's id is rejected
/// and counted (`base_as_robot`), while robot 0's odometry is delivered.
#[test]
fn the_base_station_cannot_send_a_robots_messages() {
    let heartbeat = Envelope::new(
        0,
        2,
        9,
        900_000_000,
        Payload::Heartbeat(wire::Heartbeat { uptime_s: 0.9 }),
    );
    let frames = forged_odometry(vec![
        (0.5, odometry_envelope(2, 0, 450, 450, 1.0)),
        (1.0, heartbeat),
        (1.5, odometry_envelope(0, 0, 1_450, 1_450, 1.0)),
    ]);
    let config = LinkConfig::default().with_team(2);
    assert_eq!(config.base_id, Some(2));
    let team = forged(config, frames, 2.5);
    let member = team.member(1);
    let senders: Vec<RobotId> = member.odometry_heard().iter().map(|o| o.robot).collect();
    assert_eq!(senders, vec![RobotId(0)]);
    let status = member.last_status();
    assert_eq!(status.rejections.base_as_robot, 1);
    assert_eq!(status.rejections.total(), 1);
}

/// Issue 45, item 5: a captured message sent again under a fresh message id passes
/// the reassembler's duplicate filter but not the envelope's sequence check: it is
/// rejected and counted (`replayed`); a number not seen yet (sent out of order) is
/// accepted, and a restarted peer's new run numbers afresh.
#[test]
fn a_message_replayed_under_a_fresh_id_is_rejected() {
    let odometry = |run_start_ms: u64, sequence: u64, stamp_ms: u64, x: f64| {
        odometry_envelope(0, run_start_ms, sequence, stamp_ms, x)
    };
    let frames = forged_odometry(vec![
        (0.5, odometry(0, 10, 450, 1.0)),
        // The same envelope again (every forged frame has a fresh id).
        (1.0, odometry(0, 10, 450, 1.0)),
        // An earlier number not seen yet: sent out of order, accepted.
        (1.5, odometry(0, 9, 1_400, 2.0)),
        // Robot 0 restarted without its journal: its new run numbers from 0.
        (2.0, odometry(1_800, 0, 1_900, 3.0)),
        (2.5, odometry(1_800, 0, 1_900, 3.0)),
    ]);
    let team = forged(LinkConfig::default(), frames, 3.5);
    let member = team.member(1);
    let xs = member.positions_heard();
    assert_eq!(xs, vec![1.0, 2.0, 3.0]);
    let status = member.last_status();
    assert_eq!(status.rejections.replayed, 2);
    assert_eq!(status.rejections.total(), 2);
}

/// What the network brings is checked before anything else looks at it: a corrupt
/// frame, bytes that are no envelope, another team's envelope, an envelope naming
/// another sender than the network does, a stranger, this robot's own id, a replay
/// and a far-future stamp are each counted under their reason, and only the one
/// valid message is delivered.
#[test]
fn each_bad_frame_is_rejected_and_counted_under_its_reason() {
    let config = LinkConfig {
        roster: vec![0, 1, 2],
        ..LinkConfig::default()
    };
    let valid = odometry_envelope(0, 0, 4, 400, 1.0);
    let mut other_team = odometry_envelope(0, 0, 5, 400, 2.0);
    other_team.team = 7;
    let named_2 = odometry_envelope(2, 0, 6, 400, 3.0);
    let future = odometry_envelope(0, 0, 7, 3_600_000, 4.0);
    let junk = one_fragment_frame(1, Class::Odometry, &[0xff; 16]);
    let frames = vec![
        (0.5, 0, vec![7, 1, 2]),
        (0.5, 0, junk),
        (0.5, 0, envelope_frame(2, &other_team)),
        (0.5, 0, envelope_frame(3, &named_2)),
        (0.5, 3, envelope_frame(4, &valid)),
        (0.5, 1, envelope_frame(5, &valid)),
        (0.5, 0, envelope_frame(6, &valid)),
        (0.6, 0, envelope_frame(7, &valid)),
        (0.7, 0, envelope_frame(8, &future)),
    ];
    let team = forged(config, frames, 1.5);
    let member = team.member(1);
    let xs = member.positions_heard();
    assert_eq!(xs, vec![1.0]);
    let status = member.last_status();
    let r = status.rejections;
    let counted = [
        r.malformed_frame,
        r.undecodable,
        r.wrong_team,
        r.wrong_sender,
        r.not_in_roster,
        r.own_id,
        r.replayed,
        r.from_the_future,
    ];
    assert_eq!(counted, [1; 8], "{r:?}");
    assert_eq!(r.total(), 8);
    // After reassembly: no envelope, wrong team or sender, replayed, from the future.
    assert_eq!(status.rejected_messages, 5);
    assert_eq!(status.reassembly.malformed_frames, 1);
}

/// The outputs of one event keep their order, and a frame from the network is
/// journaled and acknowledged before it is delivered (an acknowledgement promises
/// the message survives a crash).
#[test]
fn a_store_and_forward_message_is_acknowledged_once_journaled() {
    let dir = tempfile::tempdir().unwrap();
    let journal = LinkJournal::on_disk(dir.path(), 1_000).unwrap();
    let core = LinkCore::new(store_and_forward()).unwrap();
    let mut team = Team::new(|_| true);
    team.join(1, core.journaled(journal).unwrap());
    let mut sender = LinkCore::new(store_and_forward()).unwrap();
    let identity = LinkIdentity {
        robot: RobotId(0),
        name: "r0".into(),
        clock: TeamClock::SHARED,
    };
    let mut out = Vec::new();
    sender.start(identity, Time::ZERO, &mut out).unwrap();
    out.clear();
    let keyframe = test_keyframe(0, Time::ZERO);
    sender
        .handle(Time::ZERO, LinkInput::Keyframe(&keyframe), &mut out)
        .unwrap();
    let frames: Vec<Vec<u8>> = out
        .iter()
        .filter_map(|o| match o {
            LinkOutput::Transmit(tx) => Some(tx.bytes.to_vec()),
            _ => None,
        })
        .collect();
    assert!(frames.len() > 1, "a keyframe takes several frames");
    for bytes in &frames {
        let input = LinkInput::Frame {
            from: RobotId(0),
            bytes,
        };
        team.input(1, input);
    }
    let kinds: Vec<&str> = team
        .member(1)
        .published
        .iter()
        .map(|(_, o)| match o {
            LinkOutput::Transmit(tx) => match frame::parse(&tx.bytes).unwrap() {
                ParsedFrame::Ack(_) => "ack",
                ParsedFrame::Data(..) => "data",
            },
            LinkOutput::PeerKeyframe(_) => "keyframe",
            _ => "other",
        })
        .collect();
    assert_eq!(kinds, vec!["ack", "keyframe"]);
    drop(team);
    let reopened = LinkJournal::on_disk(dir.path(), 1_000).unwrap();
    assert_eq!(reopened.take_received().len(), 1, "journaled as received");
}
