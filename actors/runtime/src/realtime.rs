//! The real-time executor: one tokio task per actor, against the wall clock.
//!
//! Publishers push into the subscriber's bounded queues (behind a mutex) and wake its
//! task; each topic's subscriber list is a snapshot they read without locking, which
//! a subscription (in `start` or any later hook) replaces. Timers are tokio timers.
//! Actors marked [`blocking`](crate::ActorOptions::blocking) run their handlers
//! under `block_in_place`, so heavy compute does not stall the async workers (this
//! needs the multi-threaded runtime; on a current-thread runtime they run inline and
//! a warning says so). Packets on [`LINK_TX`] are delivered to the peers'
//! [`LINK_RX`] at once, inside the process.
//!
//! **Transport hook**: a process may run some robots of a larger team
//! ([`RealtimeExecutor::with_robot_ids`]: the process for robot 2 of a 3-robot
//! team has `RobotId(2)`) and exchange packets with the others through a
//! [`PacketTransport`] ([`RealtimeExecutor::spawn_with_transport`]): packets on
//! [`LINK_TX`] for robots not in this process go to the transport, and packets
//! it receives are published on the addressed local robots' [`LINK_RX`]. The
//! trait is `troupe_comms::transport::PacketTransport` (comms implements it over
//! zenoh); this crate never names zenoh.

use std::any::TypeId;
use std::sync::Weak;

use std::collections::{BTreeMap, HashMap};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, RwLock};

use arc_swap::ArcSwap;
use tokio::runtime::RuntimeFlavor;
use tokio::sync::{Notify, watch};
use tokio::task::JoinHandle;
use tokio::time::Instant;
use troupe_comms::transport::{PacketTransport, ReceivedPacket, TransportError};

use crate::context::Outgoing;
use crate::inputs::Inputs;
use crate::network::{Destination, LINK_RX, LINK_TRANSPORT, LINK_TX, LinkRx, LinkTx};
use crate::registry::{SubscriberRef, TopicRegistry, TypeMismatch, apply_command};
use crate::slot::{Hook, HookOutcome, Slot};
use crate::spec::RobotSpec;
use crate::stats::{RobotReport, TopicStats};
use crate::tap::{Publication, Tap};
use crate::topic::Received;
use troupe_core::Time;
use troupe_core::{RobotId, TeamClock, TimeSource};

/// How often the transport's counters go out on [`LINK_TRANSPORT`], milliseconds.
const TRANSPORT_STATS_PERIOD_MS: u64 = 1000;

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // A panic while holding an input lock cannot leave the queues inconsistent
    // (handlers never run under it), so a poisoned lock is still usable.
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

struct RtTopic {
    name: Arc<str>,
    type_id: TypeId,
    type_name: &'static str,
    /// Who receives its messages. Publishers read a snapshot without locking; a
    /// subscription (in `start` or any later hook) swaps in a new list.
    subscribers: ArcSwap<Vec<SubscriberRef>>,
    messages: AtomicU64,
    bytes: AtomicU64,
    type_mismatches: AtomicU64,
}

impl RtTopic {
    fn new(
        name: Arc<str>,
        type_id: TypeId,
        type_name: &'static str,
        subscribers: Vec<SubscriberRef>,
    ) -> Self {
        RtTopic {
            name,
            type_id,
            type_name,
            subscribers: ArcSwap::from_pointee(subscribers),
            messages: AtomicU64::new(0),
            bytes: AtomicU64::new(0),
            type_mismatches: AtomicU64::new(0),
        }
    }
}

struct Inbox {
    inputs: Mutex<Inputs>,
    notify: Notify,
}

struct RtRobot {
    id: RobotId,
    name: Arc<str>,
    topics: RwLock<HashMap<Arc<str>, Arc<RtTopic>>>,
    inboxes: Vec<Arc<Inbox>>,
}

struct Shared {
    robots: Vec<RtRobot>,
    epoch: Instant,
    arrival: AtomicU64,
    taps: Mutex<Vec<Box<dyn Tap>>>,
    has_taps: bool,
    transport: Option<Arc<dyn PacketTransport>>,
    /// Packets the transport refused (queue full, closed).
    transport_errors: AtomicU64,
    /// Per robot: when its transport counters were last published, ms since epoch
    /// plus one (0: never).
    transport_published_ms: Vec<AtomicU64>,
}

impl Shared {
    fn now(&self) -> Time {
        Time::from_nanos(u64::try_from(self.epoch.elapsed().as_nanos()).unwrap_or(u64::MAX))
    }

    fn topic(
        &self,
        robot: usize,
        name: &str,
        type_id: TypeId,
        type_name: &'static str,
    ) -> Arc<RtTopic> {
        let r = &self.robots[robot];
        if let Some(t) = r
            .topics
            .read()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .get(name)
        {
            return t.clone();
        }
        let mut topics = r
            .topics
            .write()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        topics
            .entry(Arc::from(name))
            .or_insert_with(|| {
                Arc::new(RtTopic::new(
                    Arc::from(name),
                    type_id,
                    type_name,
                    Vec::new(),
                ))
            })
            .clone()
    }

    /// Adds a subscriber to a topic of robot `robot` (idempotent), as the sim-time
    /// executor's registry does: a topic that carries another type refuses it
    /// (counted and logged).
    fn add_subscriber(
        &self,
        robot: usize,
        name: &str,
        type_id: TypeId,
        type_name: &'static str,
        who: SubscriberRef,
    ) -> Result<(), TypeMismatch> {
        let topic = self.topic(robot, name, type_id, type_name);
        if topic.type_id != type_id {
            topic.type_mismatches.fetch_add(1, Ordering::Relaxed);
            return Err(TypeMismatch {
                topic: topic.name.clone(),
                declared: topic.type_name,
                used: type_name,
            });
        }
        topic.subscribers.rcu(|list| {
            let mut list = Vec::clone(list);
            if !list.contains(&who) {
                list.push(who);
            }
            list
        });
        Ok(())
    }

    fn route(&self, robot: usize, outputs: &mut Vec<Outgoing>) {
        for out in outputs.drain(..) {
            let topic = self.topic(robot, &out.topic, out.type_id, out.type_name);
            if topic.type_id != out.type_id {
                topic.type_mismatches.fetch_add(1, Ordering::Relaxed);
                tracing::error!(robot = %self.robots[robot].name, topic = %topic.name,
                    "dropped a publication of type {}: the topic carries {}", out.type_name, topic.type_name);
                continue;
            }
            topic.messages.fetch_add(1, Ordering::Relaxed);
            topic.bytes.fetch_add(out.bytes as u64, Ordering::Relaxed);
            let now = self.now();
            if self.has_taps {
                for tap in lock(&self.taps).iter_mut() {
                    tap.on_publish(&Publication {
                        time: now,
                        robot: self.robots[robot].id,
                        topic: &topic.name,
                        payload: &out.payload,
                        bytes: out.bytes,
                    });
                }
            }
            for &(slot, sub) in topic.subscribers.load().iter() {
                let inbox = &self.robots[robot].inboxes[slot];
                let arrival = self.arrival.fetch_add(1, Ordering::Relaxed);
                let message = Received {
                    topic: topic.name.clone(),
                    payload: out.payload.clone(),
                    published_at: now,
                    bytes: out.bytes,
                };
                if lock(&inbox.inputs).offer(sub, arrival, message) {
                    inbox.notify.notify_one();
                }
            }
            if out.type_id == TypeId::of::<LinkTx>()
                && *out.topic == *LINK_TX.name()
                && let Some(packet) = out.payload.downcast_ref::<LinkTx>()
            {
                self.transmit(robot, packet);
            }
        }
    }

    /// Delivers a packet to the local robots it is for (never back to `from`).
    fn deliver_locally(&self, from: RobotId, to: Destination, bytes: &Arc<[u8]>) {
        for (index, robot) in self.robots.iter().enumerate() {
            let addressed = match to {
                Destination::Broadcast => true,
                Destination::Robot(r) => r == robot.id,
            };
            if addressed && robot.id != from {
                let message = Arc::new(LinkRx {
                    from,
                    bytes: bytes.clone(),
                });
                let mut outputs = vec![Outgoing::new(&LINK_RX, message)];
                self.route(index, &mut outputs);
            }
        }
    }

    fn transmit(&self, from: usize, packet: &LinkTx) {
        let from_id = self.robots[from].id;
        self.deliver_locally(from_id, packet.to, &packet.bytes);
        let Some(transport) = &self.transport else {
            return;
        };
        let to = match packet.to {
            Destination::Broadcast => None,
            Destination::Robot(r) if self.robots.iter().any(|l| l.id == r) => return,
            Destination::Robot(r) => Some(r.0),
        };
        if let Err(e) = transport.send(from_id.0, to, &packet.bytes) {
            let n = self.transport_errors.fetch_add(1, Ordering::Relaxed);
            if n.is_power_of_two() || n == 0 {
                tracing::warn!(robot = %self.robots[from].name, "transport refused a packet ({} so far): {e}", n + 1);
            }
        }
        self.publish_transport_stats(from, transport.as_ref());
    }

    /// Publishes the transport's counters on robot `from`'s [`LINK_TRANSPORT`] if
    /// a second has passed since the last time (checked as it sends, so a robot
    /// that sends nothing publishes nothing new).
    fn publish_transport_stats(&self, from: usize, transport: &dyn PacketTransport) {
        let Some(last) = self.transport_published_ms.get(from) else {
            return;
        };
        let now_ms = u64::try_from(self.epoch.elapsed().as_millis()).unwrap_or(u64::MAX - 1) + 1;
        let previous = last.load(Ordering::Relaxed);
        if previous != 0 && now_ms < previous + TRANSPORT_STATS_PERIOD_MS {
            return;
        }
        if last
            .compare_exchange(previous, now_ms, Ordering::Relaxed, Ordering::Relaxed)
            .is_err()
        {
            return;
        }
        let mut stats = transport.stats();
        stats.send_failures = stats
            .send_failures
            .max(self.transport_errors.load(Ordering::Relaxed));
        let mut outputs = vec![Outgoing::new(&LINK_TRANSPORT, Arc::new(stats))];
        self.route(from, &mut outputs);
    }

    /// A packet from the transport: published on the addressed local robots' LINK_RX.
    fn inject(&self, packet: ReceivedPacket<'_>) {
        let to = packet
            .to
            .map_or(Destination::Broadcast, |r| Destination::Robot(RobotId(r)));
        self.deliver_locally(RobotId(packet.from), to, &Arc::from(packet.bytes));
    }
}

/// Runs a team of robots on tokio against the wall clock.
///
/// Publishers push into the subscriber's bounded queues (behind a mutex) and wake its
/// task; timers are tokio timers. Actors marked [`blocking`](crate::ActorOptions::blocking)
/// run their handlers under `block_in_place`, so heavy compute does not stall the
/// async workers (this needs the multi-threaded runtime; on a current-thread runtime
/// they run inline and a warning says so). Packets on [`LINK_TX`] are delivered to
/// the peers' [`LINK_RX`] at once, inside the process.
pub struct RealtimeExecutor {
    team: Vec<RobotSpec>,
    seed: u64,
    taps: Vec<Box<dyn Tap>>,
    ids: Vec<RobotId>,
}

/// Why robot ids were not accepted.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum RobotIdsError {
    /// One id per robot spec is needed.
    #[error("{ids} robot ids for {robots} robots")]
    CountMismatch {
        /// Ids given.
        ids: usize,
        /// Robots in the executor.
        robots: usize,
    },
    /// Ids must be distinct.
    #[error("robot id {0} given twice")]
    Duplicate(RobotId),
}

/// A running team; [`RealtimeHandle::shutdown`] stops it and returns the reports.
pub struct RealtimeHandle {
    shared: Arc<Shared>,
    stop: watch::Sender<bool>,
    tasks: Vec<(usize, JoinHandle<Slot>)>,
    names: Vec<Vec<Arc<str>>>,
}

impl RealtimeExecutor {
    /// A team of robots; `seed` seeds every actor's generator.
    #[must_use]
    pub fn new(team: Vec<RobotSpec>, seed: u64) -> Self {
        let ids = (0..team.len() as u32).map(RobotId).collect();
        RealtimeExecutor {
            team,
            seed,
            taps: Vec::new(),
            ids,
        }
    }

    /// The team indices of this executor's robots, in spec order (default
    /// `0, 1, …`). A process running robot 2 of a 3-robot team passes
    /// `[RobotId(2)]`; the id is what actors see as [`Context::robot`](crate::Context::robot)
    /// and what the link writes as the envelope's sender.
    pub fn with_robot_ids(mut self, ids: Vec<RobotId>) -> Result<Self, RobotIdsError> {
        if ids.len() != self.team.len() {
            return Err(RobotIdsError::CountMismatch {
                ids: ids.len(),
                robots: self.team.len(),
            });
        }
        for (i, id) in ids.iter().enumerate() {
            if ids[..i].contains(id) {
                return Err(RobotIdsError::Duplicate(*id));
            }
        }
        self.ids = ids;
        Ok(self)
    }

    /// Adds an observer of every publication (called from the actor tasks, under a lock).
    pub fn add_tap(&mut self, tap: impl Tap + 'static) {
        self.taps.push(Box::new(tap));
    }

    /// Starts every actor and spawns one task per actor on the current tokio runtime.
    ///
    /// All `start` hooks run before any task is spawned, so every subscription made
    /// in `start` exists before the first message flows; one made later takes effect
    /// when its hook returns.
    ///
    /// # Panics
    ///
    /// If called outside a tokio runtime.
    #[must_use]
    pub fn spawn(self) -> RealtimeHandle {
        self.prepare(None).launch()
    }

    /// Like [`spawn`](Self::spawn), with packets for robots outside this process
    /// handed to `transport` and packets it receives injected on the local
    /// robots' [`LINK_RX`] (see [`RealtimeExecutor`]). Fails, before any actor
    /// task runs, if the transport cannot start receiving.
    ///
    /// # Panics
    ///
    /// If called outside a tokio runtime.
    pub fn spawn_with_transport(
        self,
        transport: Arc<dyn PacketTransport>,
    ) -> Result<RealtimeHandle, TransportError> {
        let prepared = self.prepare(Some(transport.clone()));
        let weak: Weak<Shared> = Arc::downgrade(&prepared.shared);
        transport.start(Arc::new(move |packet: ReceivedPacket<'_>| {
            if let Some(shared) = weak.upgrade() {
                shared.inject(packet);
            }
        }))?;
        Ok(prepared.launch())
    }

    /// Instantiates and starts every actor; nothing runs yet.
    fn prepare(self, transport: Option<Arc<dyn PacketTransport>>) -> Prepared {
        let epoch = Instant::now();
        let clock = TeamClock::starting_now();
        let mut robots = Vec::new();
        let mut slots_per_robot = Vec::new();
        let mut pending_outputs = Vec::new();
        let mut names = Vec::new();
        for (r, (spec, id)) in self.team.into_iter().zip(self.ids).enumerate() {
            let mut registry = TopicRegistry::default();
            let mut slots = Vec::new();
            let mut inboxes = Vec::new();
            for (s, actor) in spec.actors.into_iter().enumerate() {
                let mut slot = Slot::new(actor, self.seed, id, (clock, TimeSource::WallClock));
                let mut inputs = Inputs::default();
                if !slot.instantiate(Time::ZERO)
                    || slot.run_hook(Hook::Start, Time::ZERO, id, &spec.name)
                        == HookOutcome::Stopped
                {
                    inputs.stop();
                }
                for command in std::mem::take(&mut slot.commands) {
                    // Timers need no scheduling here: each task arms its own.
                    let _ = apply_command(
                        command,
                        s,
                        &mut inputs,
                        &mut |topic, type_id, type_name, who| {
                            registry.add_subscriber(topic, type_id, type_name, who)
                        },
                        &spec.name,
                        &slot.name,
                    );
                }
                let outputs = std::mem::take(&mut slot.outbox);
                if !outputs.is_empty() {
                    pending_outputs.push((r, outputs));
                }
                inboxes.push(Arc::new(Inbox {
                    inputs: Mutex::new(inputs),
                    notify: Notify::new(),
                }));
                slots.push(slot);
            }
            names.push(slots.iter().map(|s: &Slot| s.name.clone()).collect());
            robots.push(RtRobot {
                id,
                name: spec.name,
                topics: RwLock::new(
                    registry
                        .into_entries()
                        .map(|e| {
                            let topic =
                                RtTopic::new(e.name.clone(), e.type_id, e.type_name, e.subscribers);
                            (e.name, Arc::new(topic))
                        })
                        .collect(),
                ),
                inboxes,
            });
            slots_per_robot.push(slots);
        }
        let has_taps = !self.taps.is_empty();
        let transport_published_ms = (0..robots.len()).map(|_| AtomicU64::new(0)).collect();
        let shared = Arc::new(Shared {
            robots,
            epoch,
            arrival: AtomicU64::new(0),
            taps: Mutex::new(self.taps),
            has_taps,
            transport,
            transport_errors: AtomicU64::new(0),
            transport_published_ms,
        });
        Prepared {
            shared,
            slots_per_robot,
            pending_outputs,
            names,
        }
    }
}

/// A team whose actors are started but whose tasks are not spawned yet.
struct Prepared {
    shared: Arc<Shared>,
    slots_per_robot: Vec<Vec<Slot>>,
    pending_outputs: Vec<(usize, Vec<Outgoing>)>,
    names: Vec<Vec<Arc<str>>>,
}

impl Prepared {
    /// Routes what the start hooks published and spawns one task per actor.
    fn launch(self) -> RealtimeHandle {
        let Prepared {
            shared,
            slots_per_robot,
            pending_outputs,
            names,
        } = self;
        for (r, mut outputs) in pending_outputs {
            shared.route(r, &mut outputs);
        }
        let (stop, stop_rx) = watch::channel(false);
        let can_block =
            tokio::runtime::Handle::current().runtime_flavor() == RuntimeFlavor::MultiThread;
        let mut tasks = Vec::new();
        for (r, slots) in slots_per_robot.into_iter().enumerate() {
            for (s, slot) in slots.into_iter().enumerate() {
                if slot.options.blocking && !can_block {
                    tracing::warn!(actor = %slot.name, "blocking actor runs inline: the tokio runtime is not multi-threaded");
                }
                let task = ActorTask {
                    shared: shared.clone(),
                    robot: r,
                    index: s,
                    slot,
                    block: can_block,
                };
                tasks.push((r, tokio::spawn(task.run(stop_rx.clone()))));
            }
        }
        RealtimeHandle {
            shared,
            stop,
            tasks,
            names,
        }
    }
}

struct ActorTask {
    shared: Arc<Shared>,
    robot: usize,
    index: usize,
    slot: Slot,
    block: bool,
}

impl ActorTask {
    fn inbox(&self) -> &Inbox {
        &self.shared.robots[self.robot].inboxes[self.index]
    }

    /// Marks due timers as pending; returns the next deadline.
    fn fire_timers(&self, deadlines: &mut Vec<Option<Instant>>) -> Option<Instant> {
        let now = Instant::now();
        let mut inputs = lock(&self.inbox().inputs);
        deadlines.resize(inputs.timers.len(), None);
        let mut next: Option<Instant> = None;
        for (i, slot) in deadlines.iter_mut().enumerate() {
            let (active, period) = (inputs.timers[i].active, inputs.timers[i].period);
            if !active {
                *slot = None;
                continue;
            }
            let deadline = slot.get_or_insert(now + period);
            if *deadline <= now {
                let arrival = self.shared.arrival.fetch_add(1, Ordering::Relaxed);
                inputs.tick(i, arrival);
                while *deadline <= now {
                    *deadline += period;
                }
            }
            next = Some(next.map_or(*deadline, |n: Instant| n.min(*deadline)));
        }
        next
    }

    fn apply_commands(&mut self, deadlines: &mut [Option<Instant>]) {
        let commands = std::mem::take(&mut self.slot.commands);
        if commands.is_empty() {
            return;
        }
        let robot = &self.shared.robots[self.robot];
        let mut inputs = lock(&robot.inboxes[self.index].inputs);
        let mut add_subscriber = |topic: &str, type_id, type_name, who| {
            self.shared
                .add_subscriber(self.robot, topic, type_id, type_name, who)
        };
        for command in commands {
            // It makes a subscriber's queue before the shared table lists it, so
            // the queue exists before any publisher can see the subscriber.
            let started = apply_command(
                command,
                self.index,
                &mut inputs,
                &mut add_subscriber,
                &robot.name,
                &self.slot.name,
            );
            if let Some(d) = started.and_then(|t| deadlines.get_mut(t.index)) {
                *d = None;
            }
        }
    }

    async fn run(mut self, mut stop: watch::Receiver<bool>) -> Slot {
        let robot_id = self.shared.robots[self.robot].id;
        let robot_name = self.shared.robots[self.robot].name.clone();
        let mut deadlines = Vec::new();
        let mut outputs = Vec::new();
        loop {
            if *stop.borrow() {
                break;
            }
            let next_deadline = self.fire_timers(&mut deadlines);
            let event = lock(&self.inbox().inputs).next_event();
            if let Some(event) = event {
                let now = self.shared.now();
                let outcome = if self.slot.options.blocking && self.block {
                    tokio::task::block_in_place(|| {
                        self.slot
                            .run_hook(Hook::Handle(&event), now, robot_id, &robot_name)
                    })
                } else {
                    self.slot
                        .run_hook(Hook::Handle(&event), now, robot_id, &robot_name)
                };
                drop(event);
                if outcome == HookOutcome::Stopped {
                    lock(&self.inbox().inputs).stop();
                }
                self.apply_commands(&mut deadlines);
                std::mem::swap(&mut outputs, &mut self.slot.outbox);
                self.shared.route(self.robot, &mut outputs);
                continue;
            }
            let inbox = &self.shared.robots[self.robot].inboxes[self.index];
            tokio::select! {
                _ = inbox.notify.notified() => {}
                _ = sleep_until_opt(next_deadline) => {}
                _ = stop.changed() => {}
            }
        }
        if self.slot.is_running() {
            let now = self.shared.now();
            self.slot.run_hook(Hook::Stop, now, robot_id, &robot_name);
        }
        self.slot
    }
}

async fn sleep_until_opt(deadline: Option<Instant>) {
    match deadline {
        Some(d) => tokio::time::sleep_until(d).await,
        None => std::future::pending().await,
    }
}

impl RealtimeHandle {
    /// Elapsed wall time since the team started.
    #[must_use]
    pub fn now(&self) -> Time {
        self.shared.now()
    }

    /// Packets the transport refused so far (queue full or closed).
    #[must_use]
    pub fn transport_errors(&self) -> u64 {
        self.shared.transport_errors.load(Ordering::Relaxed)
    }

    /// Stops every actor (each finishes its current handler, then runs its stop hook)
    /// and returns the per-robot reports.
    pub async fn shutdown(self) -> Vec<RobotReport> {
        let _ = self.stop.send(true);
        let mut slots: Vec<Vec<Option<Slot>>> = self
            .names
            .iter()
            .map(|n| n.iter().map(|_| None).collect())
            .collect();
        let mut index = vec![0usize; self.names.len()];
        for (r, task) in self.tasks {
            let s = index[r];
            index[r] += 1;
            match task.await {
                Ok(slot) => slots[r][s] = Some(slot),
                Err(e) => {
                    tracing::error!(robot = r, actor = %self.names[r][s], "actor task failed: {e}")
                }
            }
        }
        self.shared
            .robots
            .iter()
            .zip(slots)
            .map(|(robot, slots)| {
                let topics: BTreeMap<String, TopicStats> = robot
                    .topics
                    .read()
                    .unwrap_or_else(std::sync::PoisonError::into_inner)
                    .values()
                    .map(|t| {
                        (
                            t.name.to_string(),
                            TopicStats {
                                messages: t.messages.load(Ordering::Relaxed),
                                bytes: t.bytes.load(Ordering::Relaxed),
                                type_mismatches: t.type_mismatches.load(Ordering::Relaxed),
                            },
                        )
                    })
                    .collect();
                let actors = slots
                    .iter()
                    .zip(&robot.inboxes)
                    .filter_map(|(slot, inbox)| {
                        slot.as_ref().map(|s| s.report(&lock(&inbox.inputs)))
                    })
                    .collect();
                RobotReport {
                    name: robot.name.to_string(),
                    actors,
                    topics,
                }
            })
            .collect()
    }
}
