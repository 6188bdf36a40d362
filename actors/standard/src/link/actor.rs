//! The link actor (module docs of [`crate::link`]).

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;
use std::time::Duration;

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use serde::Serialize;
use troupe_comms::journal::{JournalError, ReceivedMessage};
use troupe_comms::shaping::{
    AckOutcome, ClassStats, Incoming, LaneId, LinkShaper, MessageId, Reassembler, ReassemblyStats,
    ShaperStats,
};
use troupe_comms::transport::TransportStats;
use troupe_comms::wire::{self, Class, Envelope, Payload, UserMessage, valid_user_name};

use crate::msgs::{
    GRID_CHANGES, KEYFRAME, ODOMETRY, PEER_GRID_CHANGES, PEER_KEYFRAME, PEER_ODOMETRY, PEER_PLAN,
    PLAN, PeerGridChanges,
};
use troupe_algorithms::frame::Odometry;
use troupe_algorithms::plan::Plan;
use troupe_algorithms::team::{PeerKeyframe, PeerOdometry, PeerPlan};

use troupe_runtime::{
    Actor, ActorError, ActorResult, Context, Destination, ErrorChain, Event, LINK_RX,
    LINK_TRANSPORT, LINK_TX, LinkTx, Message, QueuePolicy, Received, RobotId, Time, TimerId, Topic,
};

use super::config::{KeyframeEncoding, LinkConfig};
use super::convert::{keyframe_from_wire, keyframe_to_wire, plan_from_wire, plan_to_wire};
use super::frames::{PeerFrame, transform_keyframe, transform_plan};
use super::journal::{JournaledLane, LinkJournal};
use super::rejections::{RateLimitedLog, Rejection, RejectionCounts};
use super::replay::{ReplayWindow, Verdict};
use super::shared::{SHARE_REQUESTS, ShareFrom, ShareRequest, ShareTo, SharedCodec};
/// The link's counters, published every second.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LinkStatus {
    /// When.
    #[serde(skip)]
    pub stamp: Time,
    /// Outgoing: per class offered, sent, dropped by reason, queue delay, age of information.
    pub shaper: ShaperStats,
    /// Incoming: frames, completed messages, duplicates, timeouts, evictions.
    pub reassembly: ReassemblyStats,
    /// Messages rejected after reassembly (decode errors, wrong team or sender,
    /// invalid payloads).
    pub rejected_messages: u64,
    /// Frames and messages rejected, per reason (roster, own id, malformed frames,
    /// envelopes, payloads, acknowledgements of messages not held).
    pub rejections: RejectionCounts,
    /// Store-and-forward recipients suspended now: silent for longer than
    /// `peer_timeout_s` (what they miss is kept for them, within their bounds).
    pub silent_peers: Vec<u32>,
    /// How many times a recipient was suspended for its silence.
    pub peer_timeouts: u64,
    /// Received messages the journal on disk dropped for room: the sender holding
    /// the most bytes loses its oldest first, so one member cannot push out what the
    /// others sent (robot processes; 0 in simulation).
    pub journal_evicted: u64,
    /// The process's network transport counters, when it has one (robot processes
    /// over zenoh; `None` in simulation), as last published on `link/transport`.
    pub transport: Option<TransportStats>,
    /// Per shared topic (by name): what went out in its lane and what came in,
    /// including names this robot does not share (`registered = false`).
    pub shared: BTreeMap<String, SharedStats>,
}
impl Message for LinkStatus {}

/// Counters of one shared topic ([`SharedTopic`](super::SharedTopic)).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SharedStats {
    /// Whether this robot shares the topic (else every message of it that
    /// arrives is rejected as `unknown_name`).
    pub registered: bool,
    /// Its traffic class and schema version here.
    pub class: Option<Class>,
    /// The schema version of the topic's type here.
    pub version: u16,
    /// Outgoing: its lane's counters (offered, sent, drops, queue delay, age).
    pub sent: ClassStats,
    /// Local messages that could not be serialised.
    pub unencodable: u64,
    /// Messages received, decoded and published on the peer topic.
    pub received: u64,
    /// Rejected: this robot does not share the name.
    pub unknown_name: u64,
    /// Rejected: the sender's schema version is older than ours.
    pub older_version: u64,
    /// Rejected: the sender's schema version is newer than ours.
    pub newer_version: u64,
    /// Rejected: the bytes are not a valid message of our type.
    pub undecodable: u64,
    /// Dropped: addressed to another robot.
    pub not_addressed: u64,
}

/// Most distinct unknown names counted one by one; more are counted under
/// [`OTHER_UNKNOWN_NAMES`] (a hostile peer cannot grow the table without bound).
pub const MAX_UNKNOWN_NAMES: usize = 32;
/// The counter name for unknown names beyond [`MAX_UNKNOWN_NAMES`].
pub const OTHER_UNKNOWN_NAMES: &str = "(other unknown names)";

/// A shared topic as the link keeps it.
struct SharedEntry {
    /// `None` while known only from the journal (not yet asked for again).
    codec: Option<Arc<dyn SharedCodec>>,
    class: Class,
    lane: Option<LaneId>,
    to: ShareTo,
    stats: SharedStats,
}

/// Most received frames waiting for the link ([`LINK_RX`]); more are dropped and
/// counted by the runtime (the sender's store-and-forward resends what mattered).
pub const LINK_RX_MAX_FRAMES: usize = 4096;
/// Most bytes of received frames waiting for the link: a flood of large junk
/// frames cannot hold more memory than this (4096 frames of the largest MTU would
/// be 256 MiB).
pub const LINK_RX_MAX_BYTES: usize = 8 * 1024 * 1024;

/// Link counters.
pub const LINK_STATUS: Topic<LinkStatus> = Topic::new("link/status");

const SEND_ODOMETRY: TimerId = TimerId(0);
const PUMP: TimerId = TimerId(1);
const STATUS: TimerId = TimerId(2);
const SEND_PLAN: TimerId = TimerId(3);
const REPLAY: TimerId = TimerId(4);

/// A link that has sent nothing for this long sends a [`wire::Heartbeat`] (checked
/// on the one-second status timer): a member with nothing else to say (the base
/// station, a robot whose odometry stopped) stays a store-and-forward recipient of
/// its peers instead of being suspended as silent after `peer_timeout_s`.
pub const HEARTBEAT_AFTER: Duration = Duration::from_secs(1);

/// See the [module docs](crate::link).
pub struct LinkActor {
    config: LinkConfig,
    shaper: LinkShaper,
    reassembler: Reassembler,
    sequence: u64,
    latest: Option<Arc<Odometry>>,
    sent_stamp: Option<Time>,
    /// The latest committed plan not yet sent.
    unsent_plan: Option<Arc<Plan>>,
    /// When the last plan went out (for the rate limit).
    plan_sent_at: Option<Time>,
    plans_sent: u32,
    /// When each store-and-forward recipient was last heard.
    last_heard: BTreeMap<u32, Time>,
    rejected: u64,
    /// Suspensions of silent recipients so far.
    peer_timeouts: u64,
    /// Who may talk to us (empty: anyone but ourselves).
    roster: BTreeSet<u32>,
    /// Rejections per reason, and their rate-limited log.
    rejections: RejectionCounts,
    rejection_log: RateLimitedLog<Rejection>,
    /// The latest transport counters from the executor (`link/transport`).
    transport: Option<TransportStats>,
    /// Whether this robot's keyframes go to peers ([`LinkActor::without_keyframes`]).
    share_keyframes: bool,
    /// Where the durable part of the link is kept ([`LinkJournal`]).
    journal: LinkJournal,
    /// Shared topics by name, and unknown names that arrived.
    shared: BTreeMap<String, SharedEntry>,
    /// Lanes added so far, in order (what the journal keeps).
    lanes: Vec<JournaledLane>,
    /// Whether `lanes` changed since the journal was written.
    lanes_changed: bool,
    /// The shaper's store generation last written to the journal.
    journaled_generation: Option<u64>,
    /// Messages received before a process restart, to publish again at start.
    replay: Vec<ReceivedMessage>,
    /// Per peer, the latest of its runs heard (its start on the team clock).
    peer_runs: BTreeMap<u32, u64>,
    /// When this link last offered a message of its own (for the heartbeat).
    last_offered: Option<Time>,
    /// Per peer, the envelope sequence numbers its latest run has used.
    replay_windows: BTreeMap<u32, ReplayWindow>,
}

impl LinkActor {
    /// A link actor; fails if the shaper or reassembly settings are invalid.
    pub fn new(config: LinkConfig) -> Result<Self, ActorError> {
        let shaper = LinkShaper::new(config.shaper)
            .map_err(|e| ActorError::msg(format!("link shaper: {e}")))?;
        let reassembler = Reassembler::new(config.reassembly)
            .map_err(|e| ActorError::msg(format!("link reassembly: {e}")))?;
        let roster = config.roster.iter().copied().collect();
        Ok(LinkActor {
            config,
            shaper,
            reassembler,
            sequence: 0,
            latest: None,
            sent_stamp: None,
            unsent_plan: None,
            plan_sent_at: None,
            plans_sent: 0,
            last_heard: BTreeMap::new(),
            rejected: 0,
            peer_timeouts: 0,
            roster,
            rejections: RejectionCounts::default(),
            rejection_log: RateLimitedLog::new(Duration::from_secs(1)),
            transport: None,
            share_keyframes: true,
            journal: LinkJournal::default(),
            journaled_generation: None,
            shared: BTreeMap::new(),
            lanes: Vec::new(),
            lanes_changed: false,
            replay: Vec::new(),
            peer_runs: BTreeMap::new(),
            last_offered: None,
            replay_windows: BTreeMap::new(),
        })
    }

    /// Keeps the link's durable state in `journal` and resumes from what it holds
    /// (see [`LinkJournal`]); fails if the stored state does not fit the settings.
    pub fn journaled(mut self, journal: LinkJournal) -> Result<Self, ActorError> {
        let (shaper, lanes, sequence) = {
            let entry = journal.entry();
            (entry.shaper.clone(), entry.lanes.clone(), entry.sequence)
        };
        self.replay = journal.take_received();
        if let Some(state) = &shaper {
            self.shaper = LinkShaper::new(self.config.shaper)
                .map_err(|e| ActorError::msg(format!("link shaper: {e}")))?;
            // The shared topics' lanes come back first, in their order, so that
            // their stored messages return to them.
            for journaled in &lanes {
                let name = &journaled.name;
                let lane = self
                    .shaper
                    .add_lane(journaled.class, journaled.config)
                    .map_err(|e| ActorError::msg(format!("link lane {name}: {e}")))?;
                let codec = journaled.request.as_ref().map(|r| r.0.clone());
                let to = self
                    .config
                    .shared
                    .get(name)
                    .and_then(|c| c.to)
                    .unwrap_or(ShareTo::Peers);
                let stats = SharedStats {
                    registered: codec.is_some(),
                    class: Some(journaled.class),
                    version: codec.as_ref().map_or(0, |c| c.version()),
                    ..SharedStats::default()
                };
                self.shared.insert(
                    name.clone(),
                    SharedEntry {
                        codec,
                        class: journaled.class,
                        lane: Some(lane),
                        to,
                        stats,
                    },
                );
            }
            self.lanes = lanes;
            self.shaper.resume(state);
            if !state.stored.is_empty() {
                tracing::info!(
                    stored = state.stored.len(),
                    next_id = state.next_id,
                    "link resumed its store-and-forward messages from the journal"
                );
            }
        }
        self.sequence = sequence;
        self.journal = journal;
        self.journaled_generation = None;
        Ok(self)
    }

    /// Writes the durable state to the journal: the stored messages when they
    /// changed (bytes are shared, not copied), the counters always; a journal on
    /// disk gets what changed, fsync'd.
    fn save(&mut self) -> Result<(), JournalError> {
        let generation = self.shaper.store_generation();
        let mut entry = self.journal.entry();
        let entry = &mut *entry;
        let changed = match &mut entry.shaper {
            Some(state) if self.journaled_generation == Some(generation) => {
                state.next_id = self.shaper.next_id().0;
                false
            }
            slot => {
                *slot = Some(self.shaper.durable_state());
                self.journaled_generation = Some(generation);
                true
            }
        };
        entry.sequence = self.sequence;
        if self.lanes_changed {
            // Before the stored messages that name them.
            entry.lanes = self.lanes.clone();
            entry.sync_lanes()?;
            self.lanes_changed = false;
        }
        if let (Some(disk), Some(state)) = (&mut entry.disk, &entry.shaper)
            && (changed || disk.ceiling_reached(state.next_id, entry.sequence))
        {
            disk.sync(state, entry.sequence)?;
        }
        Ok(())
    }

    /// Keeps this robot's keyframes local (when the team shares occupancy-grid change
    /// sets instead, §8.2.5; change sets on `grid/changes` are always sent).
    #[must_use]
    pub fn without_keyframes(mut self) -> Self {
        self.share_keyframes = false;
        self
    }

    /// The transform from a peer's world frame into ours, if it differs.
    fn frame_of(&self, peer: RobotId) -> Option<Isometry3<f64>> {
        self.config
            .peer_frames
            .iter()
            .find(|f| f.robot == peer.0)
            .map(PeerFrame::transform)
    }

    /// Encodes and offers one payload to the shaper (its class's queue).
    fn send(&mut self, payload: Payload, stamp: Time, ctx: &mut Context<'_>) -> ActorResult {
        self.send_in(payload, stamp, None, ctx)
    }

    /// Encodes and offers one payload to its class's queue or to a shared
    /// topic's lane (with its addressee).
    fn send_in(
        &mut self,
        payload: Payload,
        stamp: Time,
        lane: Option<(LaneId, Option<u32>)>,
        ctx: &mut Context<'_>,
    ) -> ActorResult {
        let class = payload.class();
        let clock = ctx.team_clock();
        let envelope = Envelope::new(
            self.config.team,
            ctx.robot().0,
            self.sequence,
            clock.to_team_ns(stamp),
            payload,
        )
        .from_run(clock.origin_ns());
        let bytes = wire::encode(&envelope)
            .map_err(|e| ActorError::with_source("encoding a message", e))?;
        self.sequence += 1;
        self.last_offered = Some(ctx.now());
        let now = ctx.now().as_nanos();
        let offered = match lane {
            None => self.shaper.offer(now, class, bytes),
            Some((lane, to)) => self.shaper.offer_to_lane(now, lane, to, bytes),
        };
        if let Err(refused) = offered {
            tracing::debug!(
                robot = ctx.robot_name(),
                ?class,
                "link refused a message: {refused}"
            );
        }
        self.pump(ctx);
        Ok(())
    }

    /// Sends every frame the bucket allows now and arms the pump for the next one.
    fn pump(&mut self, ctx: &mut Context<'_>) {
        let now = ctx.now().as_nanos();
        while let Some(frame) = self.shaper.poll(now) {
            ctx.publish(
                &LINK_TX,
                LinkTx {
                    to: frame
                        .to
                        .map_or(Destination::Broadcast, |p| Destination::Robot(RobotId(p))),
                    bytes: Arc::from(frame.bytes),
                },
            );
        }
        match self.shaper.next_send_time(now) {
            Some(next) => {
                ctx.set_timer(PUMP, Duration::from_nanos(next.saturating_sub(now).max(1)))
            }
            None => ctx.cancel_timer(PUMP),
        }
    }

    fn send_odometry(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        let Some(odometry) = self.latest.clone() else {
            return Ok(());
        };
        if self.sent_stamp == Some(odometry.stamp) {
            return Ok(());
        }
        let q = odometry.pose.rotation.quaternion();
        let payload = Payload::Odometry(wire::Odometry {
            position_m: odometry.pose.translation.vector.into(),
            orientation_xyzw: [q.i, q.j, q.k, q.w],
            velocity_mps: odometry.velocity_mps.into(),
        });
        self.sent_stamp = Some(odometry.stamp);
        self.send(payload, odometry.stamp, ctx)
    }

    /// Sends a heartbeat when this link has offered nothing for [`HEARTBEAT_AFTER`]
    /// and has a team to tell.
    fn send_heartbeat_if_idle(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        let now = ctx.now();
        let idle = self
            .last_offered
            .is_none_or(|at| now.saturating_since(at) >= HEARTBEAT_AFTER);
        if !idle || (self.roster.is_empty() && self.config.peers.is_empty()) {
            return Ok(());
        }
        let uptime_s = now.as_secs_f64();
        self.send(Payload::Heartbeat(wire::Heartbeat { uptime_s }), now, ctx)
    }

    /// Minimum time between two plans; `None` when plans are not shared.
    fn plan_period(&self) -> Option<Duration> {
        (self.config.plan_rate_hz > 0.0)
            .then(|| Duration::from_secs_f64(1.0 / self.config.plan_rate_hz))
    }

    /// Sends the latest unsent plan now if the rate allows, else arms the timer
    /// for when it will.
    fn send_plan(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        let Some(period) = self.plan_period() else {
            self.unsent_plan = None;
            return Ok(());
        };
        if self.unsent_plan.is_none() {
            ctx.cancel_timer(SEND_PLAN);
            return Ok(());
        }
        let now = ctx.now();
        if let Some(last) = self.plan_sent_at {
            let since = now.saturating_since(last);
            if since < period {
                ctx.set_timer(SEND_PLAN, period - since);
                return Ok(());
            }
        }
        ctx.cancel_timer(SEND_PLAN);
        let Some(plan) = self.unsent_plan.take() else {
            return Ok(());
        };
        let Some(wire_plan) = plan_to_wire(
            &plan,
            self.plans_sent,
            self.config.priority,
            ctx.team_clock(),
        ) else {
            return Ok(()); // an empty trajectory: nothing to share
        };
        self.plans_sent = self.plans_sent.wrapping_add(1);
        self.plan_sent_at = Some(now);
        self.send(Payload::Plan(wire_plan), plan.stamp, ctx)
    }

    /// A peer proved it is a team member (a valid message or an ack): it becomes a
    /// recipient of store-and-forward messages (with the stored backlog) and its
    /// silence clock restarts.
    fn heard(&mut self, peer: RobotId, ctx: &mut Context<'_>) {
        let silent = !self.last_heard.contains_key(&peer.0);
        self.last_heard.insert(peer.0, ctx.now());
        let suspended = silent && self.shaper.suspended_peers().contains(&peer.0);
        if self.shaper.add_peer(peer.0) {
            if suspended {
                tracing::info!(
                    robot = ctx.robot_name(),
                    %peer,
                    "store-and-forward peer heard again: it rejoins and gets what it missed"
                );
            } else {
                tracing::debug!(robot = ctx.robot_name(), %peer, "store-and-forward peer added");
            }
            self.pump(ctx);
        }
    }

    /// Suspends peers silent for longer than `peer_timeout_s`: nothing more is sent
    /// to them and they no longer hold back the others; what they miss is kept for
    /// them (within their own bounds) until they are heard again.
    fn expire_peers(&mut self, ctx: &mut Context<'_>) {
        if self.config.peer_timeout_s <= 0.0 {
            return;
        }
        let timeout = Duration::from_secs_f64(self.config.peer_timeout_s);
        let now = ctx.now();
        let silent: Vec<u32> = self
            .last_heard
            .iter()
            .filter(|(_, at)| now.saturating_since(**at) > timeout)
            .map(|(p, _)| *p)
            .collect();
        for peer in silent {
            self.last_heard.remove(&peer);
            if self.shaper.suspend_peer(peer) {
                self.peer_timeouts += 1;
                let (pending, pending_bytes) = self.shaper.pending_for(Class::Keyframe, peer);
                if self.config.base_id == Some(peer) {
                    // A team may fly without its base (or before it starts): one
                    // line per silence, not a warning.
                    tracing::info!(
                        robot = ctx.robot_name(),
                        base = peer,
                        pending,
                        pending_bytes,
                        "base station not heard for {} s: what it misses is kept for it \
                         and sent when it is heard",
                        self.config.peer_timeout_s
                    );
                } else {
                    tracing::warn!(
                        robot = ctx.robot_name(),
                        peer,
                        pending,
                        pending_bytes,
                        "peer silent for more than {} s: suspended as a store-and-forward \
                         recipient until heard again",
                        self.config.peer_timeout_s
                    );
                }
            }
        }
        self.pump(ctx);
    }

    /// Counts a rejection and logs it, at most one line per reason per second
    /// (with the count since the last line).
    fn reject(
        &mut self,
        reason: Rejection,
        from: RobotId,
        detail: impl std::fmt::Display,
        ctx: &mut Context<'_>,
    ) {
        self.rejections.count(reason);
        if let Some(count) = self.rejection_log.note(reason, ctx.now()) {
            tracing::warn!(
                robot = ctx.robot_name(),
                reason = reason.name(),
                count,
                "link rejected {count} since the last line; latest from {from}: {detail}"
            );
        }
    }

    /// Logs the rejections held back by the rate limit (on the status timer).
    fn flush_rejection_log(&mut self, ctx: &mut Context<'_>) {
        for (reason, count) in self.rejection_log.flush(ctx.now()) {
            tracing::warn!(
                robot = ctx.robot_name(),
                reason = reason.name(),
                count,
                "link rejected {count} since the last line"
            );
        }
    }

    /// Whether `from` may talk to us: in the roster and not our own id. Nothing of
    /// a frame that fails is kept (no reassembly, no recipient, no silence clock).
    fn admits(&mut self, from: RobotId, ctx: &mut Context<'_>) -> bool {
        if from == ctx.robot() {
            self.reject(
                Rejection::OwnId,
                from,
                "a frame claims this robot's id",
                ctx,
            );
            false
        } else if !self.roster.is_empty() && !self.roster.contains(&from.0) {
            self.reject(Rejection::NotInRoster, from, "not in the team roster", ctx);
            false
        } else {
            true
        }
    }

    fn receive_frame(&mut self, from: RobotId, bytes: &[u8], ctx: &mut Context<'_>) -> ActorResult {
        if !self.admits(from, ctx) {
            return Ok(());
        }
        let now = ctx.now().as_nanos();
        let incoming = match self.reassembler.push(now, from.0, bytes) {
            Ok(incoming) => incoming,
            Err(e) => {
                self.reject(Rejection::MalformedFrame, from, ErrorChain(&e), ctx);
                return Ok(());
            }
        };
        match incoming {
            None => Ok(()),
            Some(Incoming::Message(message)) => {
                let opened = self
                    .open_envelope(from, &message.bytes)
                    .and_then(|envelope| self.not_ahead(from, envelope, ctx))
                    .and_then(|envelope| self.in_role(from, envelope))
                    .and_then(|envelope| self.fresh(from, envelope));
                let envelope = match opened {
                    Ok(envelope) => envelope,
                    Err((reason, e)) => {
                        // Not a valid envelope of our team from this sender: it proves
                        // nothing, so it is neither acknowledged nor remembered as
                        // received (junk carrying a peer's next message ids must not
                        // make us drop that peer's real messages as repeats, nor
                        // acknowledge them in its name).
                        self.reassembler.forget(from.0, message.message_id);
                        self.rejected += 1;
                        self.reject(reason, from, ErrorChain(&e), ctx);
                        return Ok(());
                    }
                };
                // A valid envelope is acknowledged even when its payload is unusable
                // (a retransmission would not make it usable); on disk, only once
                // it is journaled (an ack promises the message survives a crash).
                if message.ack_requested {
                    if let Err(e) =
                        self.journal
                            .record_received(from.0, message.message_id, &message.bytes)
                    {
                        self.reassembler.forget(from.0, message.message_id);
                        return Err(ActorError::with_source("writing the link journal", e));
                    }
                    self.shaper.queue_ack(from.0, message.message_id);
                    self.pump(ctx);
                }
                if let Err(e) = self.deliver(from, envelope, ctx) {
                    self.rejected += 1;
                    self.reject(Rejection::InvalidPayload, from, ErrorChain(&e), ctx);
                }
                self.heard(from, ctx);
                Ok(())
            }
            Some(Incoming::Duplicate {
                message_id,
                ack_requested,
                ..
            }) => {
                if ack_requested {
                    self.shaper.queue_ack(from.0, message_id);
                    self.pump(ctx);
                }
                Ok(())
            }
            Some(Incoming::Ack { ids, .. }) => {
                // Acks are addressed to us; each releases our stored message for
                // that peer only (the store keeps it until every peer has it).
                self.heard(from, ctx);
                for id in ids {
                    if self.shaper.acknowledge(now, from.0, MessageId(id)) == AckOutcome::NotSent {
                        self.reject(
                            Rejection::UnheldAck,
                            from,
                            format_args!("acknowledges message {id}, not yet sent to it"),
                            ctx,
                        );
                    }
                }
                self.pump(ctx);
                Ok(())
            }
        }
    }

    /// An actor asked to share a topic ([`SharedTopic::share`](super::SharedTopic::share)):
    /// the topic gets its lane (the declared policy with the robot file's
    /// overrides, or the lane the journal kept) and the link subscribes to it.
    fn register(&mut self, request: &ShareRequest, ctx: &mut Context<'_>) -> ActorResult {
        let codec = request.0.clone();
        let name = codec.name().to_owned();
        if !valid_user_name(&name) {
            return Err(ActorError::msg(format!(
                "cannot share topic {name:?}: a name is 1 to 64 ASCII letters, digits and / _ - ."
            )));
        }
        let (class, lane_config, to) = self
            .config
            .shared
            .get(&name)
            .copied()
            .unwrap_or_default()
            .apply(codec.policy());
        let class = Class::from(class);
        let entry = self
            .shared
            .entry(name.clone())
            .or_insert_with(|| SharedEntry {
                codec: None,
                class,
                lane: None,
                to,
                stats: SharedStats::default(),
            });
        if let Some(known) = &entry.codec
            && known.version() != codec.version()
        {
            tracing::warn!(
                robot = ctx.robot_name(),
                topic = name,
                "shared topic asked for again with version {} (was {}); the new one counts",
                codec.version(),
                known.version()
            );
        }
        if entry.lane.is_none() {
            let lane = self
                .shaper
                .add_lane(class, lane_config)
                .map_err(|e| ActorError::with_source(format!("cannot share topic {name}"), e))?;
            entry.lane = Some(lane);
            entry.class = class;
            self.lanes.push(JournaledLane {
                name: name.clone(),
                class,
                config: lane_config,
                request: None,
            });
        }
        if let Some(journaled) = self.lanes.iter_mut().find(|l| l.name == name) {
            journaled.request = Some(request.clone());
            self.lanes_changed = true;
        }
        entry.stats.registered = true;
        entry.stats.class = Some(entry.class);
        entry.stats.version = codec.version();
        codec.subscribe(ctx);
        entry.codec = Some(codec);
        tracing::debug!(robot = ctx.robot_name(), topic = name, "sharing a topic");
        Ok(())
    }

    /// A local message on a shared topic goes out in its lane; `None` when the
    /// message is not on a shared topic.
    fn send_shared(&mut self, received: &Received, ctx: &mut Context<'_>) -> Option<ActorResult> {
        let entry = self.shared.get_mut(received.topic())?;
        let codec = entry.codec.as_ref()?;
        let body = match codec.encode(received)? {
            Ok(body) => body,
            Err(e) => {
                entry.stats.unencodable += 1;
                return Some(Err(ActorError::with_source(
                    format!("cannot serialise a message of {}", received.topic()),
                    e,
                )));
            }
        };
        let to = match entry.to {
            ShareTo::Peers => None,
            ShareTo::Robot(r) => Some(r),
        };
        let payload = Payload::User(UserMessage {
            class: entry.class,
            name: received.topic().to_owned(),
            version: codec.version(),
            to,
            body,
        });
        let lane = entry.lane.map(|l| (l, to));
        Some(self.send_in(payload, received.published_at(), lane, ctx))
    }

    /// A peer's message on a shared topic: checked against this robot's
    /// registration, decoded and published as `Peer<T>`, or counted and dropped.
    fn receive_shared(
        &mut self,
        from: RobotId,
        stamp: Time,
        message: &UserMessage,
        ctx: &mut Context<'_>,
    ) -> ActorResult {
        let me = ctx.robot().0;
        let name = if self.shared.contains_key(&message.name)
            || self.shared.len() < MAX_UNKNOWN_NAMES + self.lanes.len()
        {
            message.name.as_str()
        } else {
            OTHER_UNKNOWN_NAMES
        };
        let entry = self
            .shared
            .entry(name.to_owned())
            .or_insert_with(|| SharedEntry {
                codec: None,
                class: message.class,
                lane: None,
                to: ShareTo::Peers,
                stats: SharedStats::default(),
            });
        let stats = &mut entry.stats;
        let Some(codec) = &entry.codec else {
            stats.unknown_name += 1;
            return Ok(());
        };
        if message.to.is_some_and(|to| to != me) {
            stats.not_addressed += 1;
            return Ok(());
        }
        if codec.policy().from == ShareFrom::Base && self.config.base_id != Some(from.0) {
            self.reject(
                Rejection::NotFromBase,
                from,
                format_args!("{} may come from the base station only", message.name),
                ctx,
            );
            return Ok(());
        }
        if message.version != codec.version() {
            if message.version < codec.version() {
                stats.older_version += 1;
            } else {
                stats.newer_version += 1;
            }
            return Err(ActorError::msg(format!(
                "rejected {} from {from}: version {}, this robot speaks {}",
                message.name,
                message.version,
                codec.version()
            )));
        }
        match codec.clone().publish(from, stamp, &message.body, ctx) {
            Ok(()) => {
                entry.stats.received += 1;
                Ok(())
            }
            Err(e) => {
                entry.stats.undecodable += 1;
                Err(ActorError::with_source(
                    format!("rejected {} from {from}", message.name),
                    e,
                ))
            }
        }
    }

    /// Per shared topic counters, with each lane's current stats.
    fn shared_stats(&self) -> BTreeMap<String, SharedStats> {
        self.shared
            .iter()
            .map(|(name, entry)| {
                let mut stats = entry.stats.clone();
                if let Some(lane) = entry.lane.and_then(|l| self.shaper.lane_stats(l)) {
                    stats.sent = *lane;
                }
                (name.clone(), stats)
            })
            .collect()
    }

    /// Publishes again what the journal received before the process restarted
    /// (the team map of a restarted robot is whole again).
    fn replay_received(&mut self, ctx: &mut Context<'_>) {
        let replay = std::mem::take(&mut self.replay);
        let count = replay.len();
        for m in replay {
            let from = RobotId(m.source);
            let result = self
                .open_envelope(from, &m.bytes)
                .map_err(|(_, e)| e)
                .and_then(|envelope| self.deliver(from, envelope, ctx));
            if let Err(e) = result {
                tracing::debug!(
                    robot = ctx.robot_name(),
                    "journaled message not replayed: {}",
                    ErrorChain(&e)
                );
            }
        }
        tracing::info!(
            robot = ctx.robot_name(),
            count,
            "replayed the messages received before the restart"
        );
    }

    /// Decodes a reassembled message and checks its team and sender.
    fn open_envelope(
        &self,
        from: RobotId,
        bytes: &[u8],
    ) -> Result<Envelope, (Rejection, ActorError)> {
        let envelope = wire::decode(bytes).map_err(|e| {
            (
                Rejection::Undecodable,
                ActorError::with_source(format!("rejected a message from {from}"), e),
            )
        })?;
        if envelope.team != self.config.team {
            return Err((
                Rejection::WrongTeam,
                ActorError::msg(format!(
                    "rejected a message from {from}: team {} is not ours ({})",
                    envelope.team, self.config.team
                )),
            ));
        }
        if envelope.sender != from.0 {
            return Err((
                Rejection::WrongSender,
                ActorError::msg(format!(
                    "rejected a message from {from}: envelope names robot{} as its sender",
                    envelope.sender
                )),
            ));
        }
        Ok(envelope)
    }

    /// Passes an envelope its sender's role may send: the base station sends no
    /// odometry, plans, keyframes or grid changes (its certificate may publish under
    /// its own id only, so this is what keeps it from acting as a robot).
    fn in_role(
        &self,
        from: RobotId,
        envelope: Envelope,
    ) -> Result<Envelope, (Rejection, ActorError)> {
        let robot_payload = matches!(
            envelope.payload,
            Payload::Odometry(_)
                | Payload::Plan(_)
                | Payload::Keyframe(_)
                | Payload::GridChanges(_)
        );
        if robot_payload && self.config.base_id == Some(from.0) {
            return Err((
                Rejection::BaseAsRobot,
                ActorError::msg(format!(
                    "rejected a robot's message ({:?}) from the base station's id {from}",
                    envelope.payload.class()
                )),
            ));
        }
        Ok(envelope)
    }

    /// Passes an envelope whose sequence number its sender's run has not used
    /// before ([`ReplayWindow`]); the last check, so that only a message otherwise
    /// accepted takes its number.
    fn fresh(
        &mut self,
        from: RobotId,
        envelope: Envelope,
    ) -> Result<Envelope, (Rejection, ActorError)> {
        let (run, sequence) = (envelope.run_start_ns, envelope.sequence);
        let verdict = match self.replay_windows.get_mut(&from.0) {
            Some(window) => window.check(run, sequence),
            None => {
                self.replay_windows
                    .insert(from.0, ReplayWindow::new(run, sequence));
                Verdict::Fresh
            }
        };
        if verdict == Verdict::Replayed {
            return Err((
                Rejection::Replayed,
                ActorError::msg(format!(
                    "rejected a message from {from}: its sequence number {sequence} was \
                     used before (a replay under a fresh message id)"
                )),
            ));
        }
        Ok(envelope)
    }

    /// Passes an envelope made no later than `max_clock_ahead_s` from now on the team
    /// clock. (Messages replayed from the journal were checked when they arrived.)
    fn not_ahead(
        &self,
        from: RobotId,
        envelope: Envelope,
        ctx: &Context<'_>,
    ) -> Result<Envelope, (Rejection, ActorError)> {
        let now_ns = ctx.team_clock().to_team_ns(ctx.now());
        let ahead_s = envelope.stamp_ns.saturating_sub(now_ns) as f64 * 1e-9;
        if ahead_s > self.config.max_clock_ahead_s {
            return Err((
                Rejection::FromTheFuture,
                ActorError::msg(format!(
                    "rejected a message from {from}: stamped {ahead_s:.3} s ahead of this \
                     robot's clock (at most {} s; are the hosts' clocks synchronised?)",
                    self.config.max_clock_ahead_s
                )),
            ));
        }
        Ok(envelope)
    }

    /// Keeps the latest run heard of each peer and says once when a peer restarted
    /// (a message of a later run than before).
    fn note_run(&mut self, from: RobotId, run_start_ns: u64, ctx: &Context<'_>) {
        let known = self.peer_runs.entry(from.0).or_insert(run_start_ns);
        if run_start_ns > *known {
            let earlier = *known;
            *known = run_start_ns;
            tracing::info!(
                robot = ctx.robot_name(),
                peer = %from,
                "{from} restarted ({:.3} s after its previous start): what it said before no \
                 longer holds",
                (run_start_ns - earlier) as f64 * 1e-9
            );
        }
    }

    /// Publishes a checked envelope's payload on the peer topics; an invalid
    /// payload is an error.
    fn deliver(&mut self, from: RobotId, envelope: Envelope, ctx: &mut Context<'_>) -> ActorResult {
        let clock = ctx.team_clock();
        let stamp = clock.from_team_ns(envelope.stamp_ns);
        let run_start_ns = envelope.run_start_ns;
        self.note_run(from, run_start_ns, ctx);
        if let Payload::User(message) = &envelope.payload {
            return self.receive_shared(from, stamp, message, ctx);
        }
        let frame = self.frame_of(from);
        if let Payload::Keyframe(keyframe) = &envelope.payload {
            let reject = |e| ActorError::with_source(format!("rejected a keyframe from {from}"), e);
            let mut keyframe = keyframe_from_wire(keyframe, stamp).map_err(reject)?;
            if let Some(t) = frame {
                keyframe = transform_keyframe(&keyframe, &t).map_err(|e| {
                    ActorError::with_source(format!("rejected a keyframe from {from}"), e)
                })?;
            }
            ctx.publish(
                &PEER_KEYFRAME,
                PeerKeyframe {
                    robot: from,
                    keyframe,
                    made_ns: envelope.stamp_ns,
                    received_at: ctx.now(),
                },
            );
            return Ok(());
        }
        if let Payload::Plan(p) = &envelope.payload {
            let reject = |e| ActorError::with_source(format!("rejected a plan from {from}"), e);
            let mut plan = plan_from_wire(p, stamp, clock)?;
            if let Some(t) = frame {
                plan = transform_plan(&plan, &t).map_err(reject)?;
            }
            ctx.publish(
                &PEER_PLAN,
                PeerPlan {
                    robot: from,
                    priority: p.priority,
                    plan,
                    run_start_ns,
                    received_at: ctx.now(),
                },
            );
            return Ok(());
        }
        if let Payload::GridChanges(set) = envelope.payload {
            ctx.publish(
                &PEER_GRID_CHANGES,
                PeerGridChanges {
                    robot: from,
                    set,
                    frame,
                    received_at: ctx.now(),
                },
            );
            return Ok(());
        }
        // Heartbeats only prove liveness.
        if let Payload::Odometry(o) = envelope.payload {
            let [x, y, z, w] = o.orientation_xyzw;
            let pose = Isometry3::from_parts(
                Translation3::from(Vector3::from(o.position_m)),
                UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z)),
            );
            ctx.publish(
                &PEER_ODOMETRY,
                PeerOdometry {
                    robot: from,
                    odometry: Odometry {
                        stamp,
                        pose: frame.map_or(pose, |t| t * pose),
                        velocity_mps: frame.map_or(Vector3::from(o.velocity_mps), |t| {
                            t.rotation * Vector3::from(o.velocity_mps)
                        }),
                    },
                    run_start_ns,
                    received_at: ctx.now(),
                },
            );
        }
        Ok(())
    }
}

impl Actor for LinkActor {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&ODOMETRY, QueuePolicy::LATEST);
        ctx.subscribe(
            &LINK_RX,
            QueuePolicy::fifo_bytes(LINK_RX_MAX_FRAMES, LINK_RX_MAX_BYTES),
        );
        ctx.subscribe(&LINK_TRANSPORT, QueuePolicy::LATEST);
        if self.share_keyframes {
            ctx.subscribe(&KEYFRAME, QueuePolicy::fifo(64));
        }
        ctx.subscribe(&GRID_CHANGES, QueuePolicy::fifo(64));
        ctx.subscribe(&PLAN, QueuePolicy::LATEST);
        ctx.subscribe(&SHARE_REQUESTS, QueuePolicy::fifo(64));
        for entry in self.shared.values() {
            if let Some(codec) = &entry.codec {
                codec.subscribe(ctx);
            }
        }
        let me = ctx.robot().0;
        for &peer in self.config.peers.iter().filter(|p| **p != me) {
            self.shaper.add_peer(peer);
            self.last_heard.insert(peer, ctx.now());
        }
        if self.config.odometry_rate_hz > 0.0 {
            ctx.set_timer(
                SEND_ODOMETRY,
                Duration::from_secs_f64(1.0 / self.config.odometry_rate_hz),
            );
        }
        ctx.set_timer(STATUS, Duration::from_secs(1));
        if !self.replay.is_empty() {
            // What this robot held before its process restarted: known (resends
            // are duplicates), and published again once the other actors listen.
            for m in &self.replay {
                self.reassembler.remember(m.source, m.id);
            }
            ctx.set_timer(REPLAY, Duration::from_millis(100));
        }
        self.save()
            .map_err(|e| ActorError::with_source("writing the link journal", e))
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        let result = self.handle_event(event, ctx);
        let saved = self
            .save()
            .map_err(|e| ActorError::with_source("writing the link journal", e));
        result.and(saved)
    }
}

impl LinkActor {
    fn handle_event(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        match event {
            Event::Timer(SEND_ODOMETRY) => self.send_odometry(ctx),
            Event::Timer(SEND_PLAN) => self.send_plan(ctx),
            Event::Timer(PUMP) => {
                self.pump(ctx);
                Ok(())
            }
            Event::Timer(REPLAY) => {
                // Once: the timer is periodic, and nothing is left to replay.
                ctx.cancel_timer(REPLAY);
                self.replay_received(ctx);
                Ok(())
            }
            Event::Timer(_) => {
                self.send_heartbeat_if_idle(ctx)?;
                self.expire_peers(ctx);
                self.flush_rejection_log(ctx);
                ctx.publish(
                    &LINK_STATUS,
                    LinkStatus {
                        stamp: ctx.now(),
                        shaper: *self.shaper.stats(),
                        reassembly: *self.reassembler.stats(),
                        rejected_messages: self.rejected,
                        rejections: self.rejections,
                        silent_peers: self.shaper.suspended_peers(),
                        peer_timeouts: self.peer_timeouts,
                        journal_evicted: self.journal.received_evicted(),
                        transport: self.transport,
                        shared: self.shared_stats(),
                    },
                );
                Ok(())
            }
            Event::Message(m) => {
                if let Some(odometry) = m.get_arc(&ODOMETRY) {
                    self.latest = Some(odometry);
                    Ok(())
                } else if let Some(stats) = m.get(&LINK_TRANSPORT) {
                    self.transport = Some(*stats);
                    Ok(())
                } else if let Some(plan) = m.get_arc(&PLAN) {
                    self.unsent_plan = Some(plan);
                    self.send_plan(ctx)
                } else if let Some(keyframe) = m.get(&KEYFRAME) {
                    let mut wire = keyframe_to_wire(keyframe);
                    if self.config.keyframe_encoding == KeyframeEncoding::Compact {
                        match wire.mixture.compact() {
                            Ok(compact) => wire.mixture = compact,
                            Err(e) => tracing::debug!(
                                robot = ctx.robot_name(),
                                "keyframe {} goes exact: {e}",
                                keyframe.id
                            ),
                        }
                    }
                    self.send(Payload::Keyframe(wire), keyframe.stamp, ctx)
                } else if let Some(changes) = m.get(&GRID_CHANGES) {
                    self.send(
                        Payload::GridChanges(changes.set.clone()),
                        changes.stamp,
                        ctx,
                    )
                } else if let Some(rx) = m.get(&LINK_RX) {
                    self.receive_frame(rx.from, &rx.bytes, ctx)
                } else if let Some(request) = m.get(&SHARE_REQUESTS) {
                    self.register(request, ctx)
                } else {
                    self.send_shared(m, ctx).unwrap_or(Ok(()))
                }
            }
        }
    }
}

#[cfg(test)]
#[path = "tests.rs"]
mod tests;
