//! The link's state and logic as a plain type ([`LinkCore`]): no runtime context,
//! no executor. The [`LinkActor`](super::LinkActor) forwards its events to it and
//! publishes what it returns.

mod receive;
mod send;
mod sharing;

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;
use std::time::Duration;

use troupe_algorithms::frame::Odometry;
use troupe_algorithms::keyframe::Keyframe;
use troupe_algorithms::plan::Plan;
use troupe_algorithms::team::{PeerKeyframe, PeerOdometry, PeerPlan};
use troupe_comms::journal::{JournalError, ReceivedMessage};
use troupe_comms::shaping::{LinkShaper, Reassembler};
use troupe_comms::transport::TransportStats;
use troupe_runtime::{ActorError, LinkTx, Received, RobotId, TeamClock, Time};

use super::config::LinkConfig;
use super::journal::{JournaledLane, LinkJournal};
use super::rejections::{RateLimitedLog, Rejection, RejectionCounts};
use super::replay::ReplayWindow;
use super::shared::{ShareRequest, ShareTo, SharedDelivery};
use super::status::{LinkStatus, SharedStats};
use crate::msgs::{GridChanges, PeerGridChanges};
use sharing::SharedEntry;

/// A link that has sent nothing for this long sends a
/// [`Heartbeat`](troupe_comms::wire::Heartbeat) (checked on the one-second status
/// tick): a member with nothing else to say (the base station, a robot whose
/// odometry stopped) stays a store-and-forward recipient of its peers instead of
/// being suspended as silent after `peer_timeout_s`.
pub const HEARTBEAT_AFTER: Duration = Duration::from_secs(1);

/// The robot a [`LinkCore`] runs on, given when it starts.
#[derive(Clone, Debug)]
pub struct LinkIdentity {
    /// This robot's index in the team (its envelopes' sender).
    pub robot: RobotId,
    /// Its name, for the log.
    pub name: String,
    /// Where this run sits on the team clock: envelopes are stamped on it.
    pub clock: TeamClock,
}

/// The link's timers: each [`LinkOutput::SetTimer`] arms one, periodic from then
/// on until set again or cancelled, and each tick goes back to the core as
/// [`LinkInput::Tick`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum LinkTimer {
    /// Send the latest odometry (at `odometry_rate_hz`).
    Odometry,
    /// The token bucket allows the next frame.
    Pump,
    /// Once a second: heartbeat if idle, suspend silent peers, flush the rejection
    /// log, publish the status.
    Status,
    /// The plan rate allows the latest unsent plan.
    Plan,
    /// Publish again what the journal received before a restart (then cancelled).
    Replay,
}

/// An event for the link.
#[derive(Clone, Debug)]
pub enum LinkInput<'a> {
    /// A timer the core asked for went off.
    Tick(LinkTimer),
    /// This robot's latest odometry (sent on the next [`LinkTimer::Odometry`]).
    Odometry(Arc<Odometry>),
    /// A committed plan (sent at most at `plan_rate_hz`, thesis §8.2.3).
    Plan(Arc<Plan>),
    /// A keyframe of this robot's mapper.
    Keyframe(&'a Keyframe),
    /// An occupancy-grid change set of this robot (§8.2.5).
    GridChanges(&'a GridChanges),
    /// A frame from the network, with the sender the network names.
    Frame {
        /// The sender.
        from: RobotId,
        /// The frame's bytes.
        bytes: &'a [u8],
    },
    /// The network transport's latest counters.
    Transport(TransportStats),
    /// An actor asks to share a topic.
    Share(&'a ShareRequest),
    /// Any other local message: sent if it is on a shared topic.
    Local(&'a Received),
}

/// What the link does in answer to an event, in order: what it publishes, which
/// local topics it starts listening to, and which timers it arms or cancels.
#[derive(Debug)]
pub enum LinkOutput {
    /// A frame for the network ([`LINK_TX`](troupe_runtime::LINK_TX)).
    Transmit(LinkTx),
    /// A peer's odometry ([`PEER_ODOMETRY`](crate::msgs::PEER_ODOMETRY)).
    PeerOdometry(PeerOdometry),
    /// A peer's keyframe ([`PEER_KEYFRAME`](crate::msgs::PEER_KEYFRAME)).
    PeerKeyframe(PeerKeyframe),
    /// A peer's committed plan ([`PEER_PLAN`](crate::msgs::PEER_PLAN)).
    PeerPlan(PeerPlan),
    /// A peer's grid change set ([`PEER_GRID_CHANGES`](crate::msgs::PEER_GRID_CHANGES)).
    PeerGridChanges(PeerGridChanges),
    /// A peer's message on a shared topic (`peer/<name>`).
    PeerShared(SharedDelivery),
    /// The counters ([`LINK_STATUS`](super::LINK_STATUS)).
    Status(Box<LinkStatus>),
    /// Listen to a shared topic's local messages (and give them as
    /// [`LinkInput::Local`]).
    Subscribe(ShareRequest),
    /// Arm a periodic timer, the first tick after `period`.
    SetTimer(LinkTimer, Duration),
    /// Cancel a timer.
    CancelTimer(LinkTimer),
}

/// The link's state and logic (DESIGN §5), driven by its caller's clock: shaping
/// (token bucket, strict priority classes, fragmentation, per-class policies),
/// the team roster and the silence of store-and-forward recipients, the
/// acknowledgement state machine and its journal, envelope checks (team, sender,
/// role, stamp, replay window) with rejections counted per reason, plans at a
/// bounded rate (thesis §8.2.3), shared topics, and delivery of what peers sent
/// in this robot's world frame (Eq. 8.1).
///
/// Each event goes in through [`handle`](Self::handle) with the time it happens;
/// what the link then publishes, and the timers it needs, come out as
/// [`LinkOutput`]s in order. After every event the durable state is written to the
/// [`LinkJournal`]. Call [`start`](Self::start) first: it says which robot the
/// link runs on.
///
/// ```
/// use troupe_actors::link::{LinkConfig, LinkCore, LinkIdentity, LinkInput, LinkOutput, LinkTimer};
/// use troupe_runtime::{RobotId, TeamClock, Time};
///
/// let mut core = LinkCore::new(LinkConfig::default()).unwrap();
/// let me = LinkIdentity { robot: RobotId(0), name: "r0".into(), clock: TeamClock::SHARED };
/// let mut out = Vec::new();
/// core.start(me, Time::ZERO, &mut out).unwrap();
/// // It asks for its status tick, once a second.
/// assert!(out.iter().any(|o| matches!(o, LinkOutput::SetTimer(LinkTimer::Status, _))));
/// out.clear();
/// let tick = LinkInput::Tick(LinkTimer::Status);
/// core.handle(Time::from_secs_f64(1.0), tick, &mut out).unwrap();
/// assert!(matches!(out.last(), Some(LinkOutput::Status(_))));
/// ```
pub struct LinkCore {
    config: LinkConfig,
    /// Who this link runs on (set at [`start`](Self::start)).
    identity: LinkIdentity,
    /// The time of the event being handled.
    now: Time,
    /// What the event being handled produced so far.
    outbox: Vec<LinkOutput>,
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
    /// The latest transport counters.
    transport: Option<TransportStats>,
    /// Where the durable part of the link is kept ([`LinkJournal`]).
    journal: LinkJournal,
    /// The journal's evictions of received messages already logged.
    journal_evicted_logged: u64,
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

impl LinkCore {
    /// A link core; fails if the shaper or reassembly settings are invalid.
    pub fn new(config: LinkConfig) -> Result<Self, ActorError> {
        let shaper = LinkShaper::new(config.shaper)
            .map_err(|e| ActorError::msg(format!("link shaper: {e}")))?;
        let reassembler = Reassembler::new(config.reassembly)
            .map_err(|e| ActorError::msg(format!("link reassembly: {e}")))?;
        let roster = config.roster.iter().copied().collect();
        Ok(LinkCore {
            config,
            identity: LinkIdentity {
                robot: RobotId(0),
                name: String::new(),
                clock: TeamClock::SHARED,
            },
            now: Time::ZERO,
            outbox: Vec::new(),
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
            journal: LinkJournal::default(),
            journal_evicted_logged: 0,
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
                self.resume_lane(journaled)?;
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
        // Evictions replayed while reading the journal back happened before the restart.
        self.journal_evicted_logged = journal.received_evicted();
        self.journal = journal;
        self.journaled_generation = None;
        Ok(self)
    }

    /// Adds a shared topic's lane kept by the journal back to the shaper.
    fn resume_lane(&mut self, journaled: &JournaledLane) -> Result<(), ActorError> {
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
        Ok(())
    }

    /// Starts the link at `now` on robot `identity`: the configured peers become
    /// store-and-forward recipients, the local topics of shared topics the journal
    /// kept are subscribed again, the periodic timers are armed and what the
    /// journal received before a restart is scheduled for publication.
    pub fn start(
        &mut self,
        identity: LinkIdentity,
        now: Time,
        out: &mut Vec<LinkOutput>,
    ) -> Result<(), ActorError> {
        self.identity = identity;
        self.now = now;
        for entry in self.shared.values() {
            if let Some(codec) = &entry.codec {
                self.outbox
                    .push(LinkOutput::Subscribe(ShareRequest(codec.clone())));
            }
        }
        let me = self.identity.robot.0;
        for &peer in self.config.peers.iter().filter(|p| **p != me) {
            self.shaper.add_peer(peer);
            self.last_heard.insert(peer, now);
        }
        if self.config.odometry_rate_hz > 0.0 {
            let period = Duration::from_secs_f64(1.0 / self.config.odometry_rate_hz);
            self.outbox
                .push(LinkOutput::SetTimer(LinkTimer::Odometry, period));
        }
        self.outbox.push(LinkOutput::SetTimer(
            LinkTimer::Status,
            Duration::from_secs(1),
        ));
        if !self.replay.is_empty() {
            // What this robot held before its process restarted: known (resends
            // are duplicates), and published again once the other actors listen.
            for m in &self.replay {
                self.reassembler.remember(m.source, m.id);
            }
            self.outbox.push(LinkOutput::SetTimer(
                LinkTimer::Replay,
                Duration::from_millis(100),
            ));
        }
        out.append(&mut self.outbox);
        self.save()
            .map_err(|e| ActorError::with_source("writing the link journal", e))
    }

    /// Handles one event at `now`: what the link publishes and the timers it needs
    /// go to `out`, in order; then the durable state is written to the journal (also
    /// when handling failed).
    pub fn handle(
        &mut self,
        now: Time,
        input: LinkInput<'_>,
        out: &mut Vec<LinkOutput>,
    ) -> Result<(), ActorError> {
        self.now = now;
        let result = self.dispatch(input);
        out.append(&mut self.outbox);
        let saved = self
            .save()
            .map_err(|e| ActorError::with_source("writing the link journal", e));
        result.and(saved)
    }

    fn dispatch(&mut self, input: LinkInput<'_>) -> Result<(), ActorError> {
        match input {
            LinkInput::Tick(timer) => self.tick(timer),
            LinkInput::Odometry(odometry) => {
                self.latest = Some(odometry);
                Ok(())
            }
            LinkInput::Transport(stats) => {
                self.transport = Some(stats);
                Ok(())
            }
            LinkInput::Plan(plan) => {
                self.unsent_plan = Some(plan);
                self.send_plan()
            }
            LinkInput::Keyframe(keyframe) => self.send_keyframe(keyframe),
            LinkInput::GridChanges(changes) => self.send_grid_changes(changes),
            LinkInput::Frame { from, bytes } => self.receive_frame(from, bytes),
            LinkInput::Share(request) => self.register(request),
            LinkInput::Local(received) => self.send_shared(received).unwrap_or(Ok(())),
        }
    }

    fn tick(&mut self, timer: LinkTimer) -> Result<(), ActorError> {
        match timer {
            LinkTimer::Odometry => self.send_odometry(),
            LinkTimer::Plan => self.send_plan(),
            LinkTimer::Pump => {
                self.pump();
                Ok(())
            }
            LinkTimer::Replay => {
                // Once: the timer is periodic, and nothing is left to replay.
                self.outbox.push(LinkOutput::CancelTimer(LinkTimer::Replay));
                self.replay_received();
                Ok(())
            }
            LinkTimer::Status => {
                self.send_heartbeat_if_idle()?;
                self.expire_peers();
                self.flush_rejection_log();
                self.log_journal_evictions();
                let status = self.status();
                self.outbox.push(LinkOutput::Status(Box::new(status)));
                Ok(())
            }
        }
    }

    /// Says once per status tick how many received messages the journal dropped for
    /// room since the last line (each from the sender holding the most bytes): a
    /// restart would not publish them again.
    fn log_journal_evictions(&mut self) {
        let evicted = self.journal.received_evicted();
        if evicted > self.journal_evicted_logged {
            tracing::warn!(
                robot = self.robot_name(),
                evicted = evicted - self.journal_evicted_logged,
                total = evicted,
                "link journal full: dropped received messages of the sender holding the most \
                 bytes; a restart will not publish them again"
            );
            self.journal_evicted_logged = evicted;
        }
    }

    /// The counters now.
    #[must_use]
    pub fn status(&self) -> LinkStatus {
        LinkStatus {
            stamp: self.now,
            shaper: *self.shaper.stats(),
            reassembly: *self.reassembler.stats(),
            rejected_messages: self.rejected,
            rejections: self.rejections,
            silent_peers: self.shaper.suspended_peers(),
            peer_timeouts: self.peer_timeouts,
            journal_evicted: self.journal.received_evicted(),
            transport: self.transport,
            shared: self.shared_stats(),
        }
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

    /// This robot's name, for the log.
    fn robot_name(&self) -> &str {
        &self.identity.name
    }
}
