//! The deterministic sim-time executor: every robot of a team in one discrete-event
//! simulation, the robots side by side on the available cores.
//!
//! Each robot has its own event queue, ordered by `(time, sequence)`, where the
//! sequence number is the robot's own count of scheduled events. The robots advance
//! together through windows as long as the network's least delay
//! ([`SimNetwork::min_delay`]): nothing a robot sends within a window can reach
//! another before the window ends, so within it each robot's events depend only on
//! its own state, and the robots may run on any threads in any order. Between windows
//! what the robots published goes to the [taps](crate::Tap) and the network in
//! `(time, robot, order of publication)` order. Nothing depends on wall-clock time or
//! thread timing, so the same team, seed and inputs give bit-identical results on any
//! number of threads. Each handler call is charged the compute latency of its actor's
//! [`LatencyModel`](crate::LatencyModel): its outputs appear after that latency and the
//! actor is busy until then. A call that only stored what arrived
//! ([`Context::bookkeeping_only`](crate::Context::bookkeeping_only)) is charged nothing.
//!
//! A call whose actor lets it overlap ([`Actor::overlaps`](crate::Actor::overlaps): a
//! keyframe fit) runs on a pool of its own while the robot's later events go on; its
//! outcome is applied, and its outputs delivered, when its latency has passed, exactly
//! where the call run in place would have delivered them. The run is the same, bit for
//! bit; the cores are busier.

use std::any::TypeId;
use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::sync::{Arc, OnceLock, mpsc};

use rayon::prelude::*;

use crate::context::Outgoing;
use crate::inputs::Inputs;
use crate::network::{IdealNetwork, LINK_RX, LINK_TX, LinkRx, LinkTx, SimNetwork};
use crate::registry::{TopicRegistry, apply_command};
use crate::slot::{Hook, HookOutcome, Slot};
use crate::spec::RobotSpec;
use crate::stats::RobotReport;
use crate::tap::{Publication, Tap};
use crate::topic::{Payload, Received};
use troupe_core::Time;
use troupe_core::{RobotId, TeamClock, TimeSource};

/// An event of one robot.
enum Kind {
    Activate {
        slot: u32,
    },
    Timer {
        slot: u32,
        timer: u32,
        generation: u64,
    },
    Deliver {
        outputs: Vec<Outgoing>,
    },
    Network {
        from: RobotId,
        bytes: Arc<[u8]>,
    },
    /// The latency of a call run beside the robot's events has passed (see
    /// [`InFlight`]).
    Complete {
        slot: u32,
    },
}

/// A handler call the actor let run beside its robot's later events
/// ([`Actor::overlaps`](crate::Actor::overlaps)), on the offload pool: its slot is there
/// until the call is joined, and its outcome is applied when its latency has passed
/// (the [`Kind::Complete`] event, where the synchronous path would deliver its outputs).
enum InFlight {
    Idle,
    Running(mpsc::Receiver<(Slot, HookOutcome)>),
    /// Joined (the slot is back), its latency not yet passed.
    Joined(HookOutcome),
}

struct Scheduled {
    time: Time,
    seq: u64,
    kind: Kind,
}

impl PartialEq for Scheduled {
    fn eq(&self, other: &Self) -> bool {
        (self.time, self.seq) == (other.time, other.seq)
    }
}
impl Eq for Scheduled {}
impl PartialOrd for Scheduled {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Scheduled {
    /// Reversed, so that `BinaryHeap` (a max-heap) pops the earliest event first.
    fn cmp(&self, other: &Self) -> Ordering {
        (other.time, other.seq).cmp(&(self.time, self.seq))
    }
}

/// One robot's event queue and clock.
struct Clock {
    heap: BinaryHeap<Scheduled>,
    now: Time,
    seq: u64,
}

impl Clock {
    fn next_seq(&mut self) -> u64 {
        self.seq += 1;
        self.seq
    }

    fn schedule(&mut self, time: Time, kind: Kind) {
        let seq = self.next_seq();
        self.heap.push(Scheduled { time, seq, kind });
    }

    /// When the next event is due, if any.
    fn next_time(&self) -> Option<Time> {
        self.heap.peek().map(|e| e.time)
    }
}

#[derive(Clone, Copy, Default)]
struct SlotSchedule {
    busy_until: Time,
    activation_pending: bool,
}

/// A publication that leaves its robot: for the taps and, a packet, the network.
struct Outside {
    time: Time,
    topic: Arc<str>,
    payload: Payload,
    bytes: usize,
    packet: bool,
}

struct SimRobot {
    id: RobotId,
    name: Arc<str>,
    slots: Vec<Slot>,
    in_flight: Vec<InFlight>,
    inputs: Vec<Inputs>,
    schedule: Vec<SlotSchedule>,
    registry: TopicRegistry,
    clock: Clock,
    /// What left the robot in the current window, in order.
    outside: Vec<Outside>,
    /// Publications go to `outside` for the taps too (not only packets).
    observed: bool,
    events: u64,
}

impl SimRobot {
    /// Schedules an activation of `slot` if it has input and none is pending.
    fn wake(&mut self, slot: usize) {
        let state = &mut self.schedule[slot];
        if !state.activation_pending && self.inputs[slot].has_input() {
            state.activation_pending = true;
            let at = state.busy_until.max(self.clock.now);
            self.clock
                .schedule(at, Kind::Activate { slot: slot as u32 });
        }
    }

    /// Applies the subscribe / timer commands a hook left behind.
    fn apply_commands(&mut self, slot: usize) {
        let commands = std::mem::take(&mut self.slots[slot].commands);
        for command in commands {
            let started = apply_command(
                command,
                slot,
                &mut self.inputs[slot],
                &mut |topic, type_id, type_name, who| {
                    self.registry.add_subscriber(topic, type_id, type_name, who)
                },
                &self.name,
                &self.slots[slot].name,
            );
            if let Some(timer) = started {
                self.clock.schedule(
                    self.clock.now + timer.period,
                    Kind::Timer {
                        slot: slot as u32,
                        timer: timer.index as u32,
                        generation: timer.generation,
                    },
                );
            }
        }
    }

    /// Delivers publications to this robot's subscribers; what must leave the robot
    /// (for the taps, the network) is kept for the end of the window.
    fn route(&mut self, outputs: &mut Vec<Outgoing>) {
        for out in outputs.drain(..) {
            let entry = match self.registry.entry(&out.topic, out.type_id, out.type_name) {
                Ok(entry) => entry,
                Err(e) => {
                    tracing::error!(robot = %self.name, topic = %e.topic,
                        "dropped a publication of type {}: the topic carries {}", e.used, e.declared);
                    continue;
                }
            };
            entry.stats.messages += 1;
            entry.stats.bytes += out.bytes as u64;
            for &(slot, sub) in &entry.subscribers {
                let arrival = self.clock.next_seq();
                let message = Received {
                    topic: entry.name.clone(),
                    payload: out.payload.clone(),
                    published_at: self.clock.now,
                    bytes: out.bytes,
                };
                if self.inputs[slot].offer(sub, arrival, message) {
                    let state = &mut self.schedule[slot];
                    if !state.activation_pending {
                        state.activation_pending = true;
                        let at = state.busy_until.max(self.clock.now);
                        self.clock
                            .schedule(at, Kind::Activate { slot: slot as u32 });
                    }
                }
            }
            let packet = out.type_id == TypeId::of::<LinkTx>() && *out.topic == *LINK_TX.name();
            if packet || self.observed {
                self.outside.push(Outside {
                    time: self.clock.now,
                    topic: entry.name.clone(),
                    payload: out.payload,
                    bytes: out.bytes,
                    packet,
                });
            }
        }
    }

    /// Processes every event of this robot due at or before `limit`.
    fn run_window(&mut self, limit: Time) {
        while self.clock.next_time().is_some_and(|t| t <= limit) {
            if let Some(event) = self.clock.heap.pop() {
                self.clock.now = event.time;
                // A completion counts only where the synchronous path has an event
                // (its delivery), so that the count is the same either way.
                self.events += u64::from(!matches!(event.kind, Kind::Complete { .. }));
                self.dispatch(event.kind);
            }
        }
    }

    fn dispatch(&mut self, kind: Kind) {
        match kind {
            Kind::Activate { slot } => self.activate(slot as usize),
            Kind::Timer {
                slot,
                timer,
                generation,
            } => {
                let s = &mut self.inputs[slot as usize];
                let t = &s.timers[timer as usize];
                if t.generation != generation || !t.active || s.stopped {
                    return;
                }
                let period = t.period;
                let arrival = self.clock.next_seq();
                s.tick(timer as usize, arrival);
                self.clock.schedule(
                    self.clock.now + period,
                    Kind::Timer {
                        slot,
                        timer,
                        generation,
                    },
                );
                self.wake(slot as usize);
            }
            Kind::Deliver { mut outputs } => self.route(&mut outputs),
            Kind::Complete { slot } => self.complete(slot as usize),
            Kind::Network { from, bytes } => {
                let message = Arc::new(LinkRx { from, bytes });
                self.route(&mut vec![Outgoing::new(&LINK_RX, message)]);
            }
        }
    }

    fn activate(&mut self, s: usize) {
        self.schedule[s].activation_pending = false;
        let Some(event) = self.inputs[s].next_event() else {
            return;
        };
        let slot = &mut self.slots[s];
        let now = self.clock.now;
        let latency = slot.options.latency.sample(&mut slot.latency_rng);
        if !latency.is_zero()
            && slot.overlaps(&event)
            && let Some(pool) = offload_pool()
        {
            let mut slot = slot.take();
            let (id, name) = (self.id, self.name.clone());
            let (done_tx, done_rx) = mpsc::channel();
            pool.spawn(move || {
                let outcome = slot.run_hook(Hook::Handle(&event), now, id, &name);
                drop(event);
                // The executor waits for this; if it is gone, so is the run.
                let _ = done_tx.send((slot, outcome));
            });
            self.in_flight[s] = InFlight::Running(done_rx);
            let done = now + latency;
            self.clock.schedule(done, Kind::Complete { slot: s as u32 });
            self.schedule[s].busy_until = done;
            self.wake(s);
            return;
        }
        let outcome = slot.run_hook(Hook::Handle(&event), now, self.id, &self.name);
        let latency = if slot.bookkeeping {
            std::time::Duration::ZERO
        } else {
            latency
        };
        drop(event);
        if outcome == HookOutcome::Stopped {
            self.inputs[s].stop();
        }
        self.apply_commands(s);
        let done = now + latency;
        if outcome != HookOutcome::Stopped && !self.slots[s].outbox.is_empty() {
            if latency.is_zero() {
                self.route_outbox(s);
            } else {
                let outputs = std::mem::take(&mut self.slots[s].outbox);
                self.clock.schedule(done, Kind::Deliver { outputs });
            }
        }
        self.schedule[s].busy_until = done;
        self.wake(s);
    }

    /// Waits for the call in flight in slot `s`, if any, and puts its slot back.
    fn join(&mut self, s: usize) {
        let done = match std::mem::replace(&mut self.in_flight[s], InFlight::Idle) {
            InFlight::Running(done) => done,
            other => {
                self.in_flight[s] = other;
                return;
            }
        };
        let Ok((slot, outcome)) = done.recv() else {
            tracing::error!(robot = %self.name, actor = %self.slots[s].name,
                "a handler call run beside the robot's events was lost; the actor stops");
            self.slots[s].stats.stopped = true;
            self.in_flight[s] = InFlight::Joined(HookOutcome::Stopped);
            return;
        };
        self.slots[s] = slot;
        let slot = &self.slots[s];
        if slot.bookkeeping || !slot.commands.is_empty() {
            tracing::error!(robot = %self.name, actor = %slot.name,
                "a handler call the actor let run beside the robot's events subscribed, set \
                 timers or stored only what arrived (see Actor::overlaps); its commands \
                 take effect late");
        }
        self.in_flight[s] = InFlight::Joined(outcome);
    }

    /// Waits for every call in flight (their outcomes still wait for their latency).
    fn join_all(&mut self) {
        for s in 0..self.in_flight.len() {
            self.join(s);
        }
    }

    /// The latency of slot `s`'s call in flight has passed: what the synchronous path
    /// did at the call (stop, commands) and at its delivery (outputs), now.
    fn complete(&mut self, s: usize) {
        self.join(s);
        let InFlight::Joined(outcome) = std::mem::replace(&mut self.in_flight[s], InFlight::Idle)
        else {
            return;
        };
        if outcome == HookOutcome::Stopped {
            self.inputs[s].stop();
        }
        self.apply_commands(s);
        if outcome != HookOutcome::Stopped && !self.slots[s].outbox.is_empty() {
            self.events += 1;
            self.route_outbox(s);
        }
    }

    /// Routes what slot `s` published, now (its buffer kept for the next call).
    fn route_outbox(&mut self, s: usize) {
        let mut outputs = std::mem::take(&mut self.slots[s].outbox);
        self.route(&mut outputs);
        self.slots[s].outbox = outputs;
    }
}

/// The threads that run the calls in flight, as many as the cores: a pool of their
/// own, so that what such a call runs on rayon (a frame's tiles, a fit's chunks) never
/// waits behind a robot's window on a thread that waits for the call (a thread of the
/// robots' pool blocks while it waits).
fn offload_pool() -> Option<&'static rayon::ThreadPool> {
    static POOL: OnceLock<Option<rayon::ThreadPool>> = OnceLock::new();
    POOL.get_or_init(|| {
        rayon::ThreadPoolBuilder::new()
            .thread_name(|i| format!("troupe-offload-{i}"))
            .build()
            .map_err(|e| {
                tracing::warn!("no threads for handler calls in flight ({e}); they run in turn")
            })
            .ok()
    })
    .as_ref()
}

/// The taps and the network, which see the robots' publications between windows.
struct World {
    network: Box<dyn SimNetwork>,
    taps: Vec<Box<dyn Tap>>,
    deliveries: Vec<(RobotId, Time)>,
}

impl World {
    /// Hands what the robots published in the last window to the taps and sends the
    /// packets, in `(time, robot, order)` order, scheduling their arrivals.
    fn exchange(&mut self, robots: &mut [SimRobot]) {
        let outside: Vec<Vec<Outside>> = robots
            .iter_mut()
            .map(|r| std::mem::take(&mut r.outside))
            .collect();
        let mut order: Vec<(Time, usize, usize)> = outside
            .iter()
            .enumerate()
            .flat_map(|(r, items)| items.iter().enumerate().map(move |(i, o)| (o.time, r, i)))
            .collect();
        order.sort_unstable();
        let team_size = robots.len();
        for (time, r, i) in order {
            let o = &outside[r][i];
            let robot = RobotId(r as u32);
            for tap in &mut self.taps {
                tap.on_publish(&Publication {
                    time,
                    robot,
                    topic: &o.topic,
                    payload: &o.payload,
                    bytes: o.bytes,
                });
            }
            let Some(packet) = o
                .packet
                .then(|| o.payload.downcast_ref::<LinkTx>())
                .flatten()
            else {
                continue;
            };
            self.deliveries.clear();
            self.network.route(
                time,
                robot,
                packet.to,
                &packet.bytes,
                team_size,
                &mut self.deliveries,
            );
            for &(to, at) in &self.deliveries {
                let Some(target) = robots.get_mut(to.0 as usize) else {
                    continue;
                };
                // Never in a robot's past (a network faster than its `min_delay`).
                let at = at.max(time).max(target.clock.now);
                target.clock.schedule(
                    at,
                    Kind::Network {
                        from: robot,
                        bytes: packet.bytes.clone(),
                    },
                );
            }
        }
        for (robot, mut items) in robots.iter_mut().zip(outside) {
            items.clear();
            robot.outside = items;
        }
    }
}

/// Runs a team of robots in simulated time, side by side on the rayon pool: through
/// windows as long as the network's [`min_delay`](SimNetwork::min_delay), in which no
/// robot can hear from another; between windows the [taps](Tap) and the network see
/// what was published, in `(time, robot, order of publication)` order. Actors of
/// different robots must share nothing mutable outside topics and the link.
///
/// Each robot's events are ordered by `(time, sequence)`, where the sequence number is
/// assigned when an event is scheduled; nothing depends on wall-clock time or thread
/// timing, so the same team, seed and inputs give bit-identical results on any number
/// of threads. Each handler call is charged the compute latency of its actor's
/// [`LatencyModel`](crate::LatencyModel): its outputs appear after that latency and the
/// actor is busy until then.
///
/// ```
/// use std::time::Duration;
/// use troupe_runtime::*;
///
/// struct Counter(u32);
/// impl Actor for Counter {
///     fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
///         ctx.set_timer(TimerId(0), Duration::from_millis(100));
///         Ok(())
///     }
///     fn handle(&mut self, _event: &Event, _ctx: &mut Context<'_>) -> ActorResult {
///         self.0 += 1;
///         Ok(())
///     }
/// }
///
/// let robot = RobotSpec::new("r0").with(ActorSpec::new("counter", || Counter(0)));
/// let mut team = SimExecutor::new(vec![robot], 7);
/// team.run_until(Time::from_secs_f64(1.0));
/// let report = team.finish();
/// assert_eq!(report[0].actors[0].stats.handled, 10);
/// ```
pub struct SimExecutor {
    robots: Vec<SimRobot>,
    now: Time,
    world: World,
    started: bool,
}

impl SimExecutor {
    /// A team of robots; `seed` seeds every actor's generator. The network defaults
    /// to an [`IdealNetwork`] with zero latency.
    #[must_use]
    pub fn new(team: Vec<RobotSpec>, seed: u64) -> Self {
        let robots = team
            .into_iter()
            .enumerate()
            .map(|(i, spec)| {
                let id = RobotId(i as u32);
                let slots: Vec<Slot> = spec
                    .actors
                    .into_iter()
                    .map(|a| Slot::new(a, seed, id, (TeamClock::SHARED, TimeSource::Simulated)))
                    .collect();
                SimRobot {
                    id,
                    name: spec.name,
                    schedule: vec![SlotSchedule::default(); slots.len()],
                    in_flight: slots.iter().map(|_| InFlight::Idle).collect(),
                    inputs: slots.iter().map(|_| Inputs::default()).collect(),
                    slots,
                    registry: TopicRegistry::default(),
                    clock: Clock {
                        heap: BinaryHeap::new(),
                        now: Time::ZERO,
                        seq: 0,
                    },
                    outside: Vec::new(),
                    observed: false,
                    events: 0,
                }
            })
            .collect();
        SimExecutor {
            robots,
            now: Time::ZERO,
            world: World {
                network: Box::new(IdealNetwork::default()),
                taps: Vec::new(),
                deliveries: Vec::new(),
            },
            started: false,
        }
    }

    /// Replaces the network model.
    #[must_use]
    pub fn with_network(mut self, network: impl SimNetwork + 'static) -> Self {
        self.world.network = Box::new(network);
        self
    }

    /// Adds an observer of every publication.
    pub fn add_tap(&mut self, tap: impl Tap + 'static) {
        self.world.taps.push(Box::new(tap));
        for robot in &mut self.robots {
            robot.observed = true;
        }
    }

    /// Current simulated time.
    #[must_use]
    pub fn now(&self) -> Time {
        self.now
    }

    /// Events processed so far.
    #[must_use]
    pub fn events_processed(&self) -> u64 {
        self.robots.iter().map(|r| r.events).sum()
    }

    /// Starts every actor (called by [`SimExecutor::run_until`] if needed).
    pub fn start(&mut self) {
        if self.started {
            return;
        }
        self.started = true;
        let now = self.now;
        for robot in &mut self.robots {
            robot.clock.now = now;
            for s in 0..robot.slots.len() {
                let slot = &mut robot.slots[s];
                if !slot.instantiate(now)
                    || slot.run_hook(Hook::Start, now, robot.id, &robot.name)
                        == HookOutcome::Stopped
                {
                    robot.inputs[s].stop();
                }
                robot.apply_commands(s);
            }
            for s in 0..robot.slots.len() {
                robot.route_outbox(s);
            }
        }
        self.world.exchange(&mut self.robots);
    }

    /// Processes every event up to and including `end`, then sets the clock to `end`.
    ///
    /// The robots run side by side through windows of the network's
    /// [`min_delay`](SimNetwork::min_delay) (one instant when it is zero), on the
    /// threads of the current rayon pool.
    pub fn run_until(&mut self, end: Time) {
        self.start();
        let lookahead_ns =
            u64::try_from(self.world.network.min_delay().as_nanos()).unwrap_or(u64::MAX);
        while let Some(first) = self.robots.iter().filter_map(|r| r.clock.next_time()).min() {
            if first > end {
                break;
            }
            let limit = if lookahead_ns == 0 {
                first
            } else {
                Time::from_nanos(first.as_nanos().saturating_add(lookahead_ns - 1)).min(end)
            };
            let busy = self
                .robots
                .iter()
                .filter(|r| r.clock.next_time().is_some_and(|t| t <= limit))
                .count();
            if busy > 1 {
                self.robots
                    .par_iter_mut()
                    .for_each(|robot| robot.run_window(limit));
            } else {
                for robot in &mut self.robots {
                    robot.run_window(limit);
                }
            }
            self.now = self.now.max(limit);
            self.world.exchange(&mut self.robots);
        }
        self.now = self.now.max(end);
        for robot in &mut self.robots {
            robot.clock.now = robot.clock.now.max(self.now);
            // Reports and the stop hooks read the slots.
            robot.join_all();
        }
    }

    /// Per-robot counters so far.
    #[must_use]
    pub fn reports(&self) -> Vec<RobotReport> {
        self.robots
            .iter()
            .map(|r| RobotReport {
                name: r.name.to_string(),
                actors: r
                    .slots
                    .iter()
                    .zip(&r.inputs)
                    .map(|(s, i)| s.report(i))
                    .collect(),
                topics: r.registry.stats(),
            })
            .collect()
    }

    /// Calls every actor's stop hook and returns the per-robot reports.
    pub fn finish(mut self) -> Vec<RobotReport> {
        self.start();
        let now = self.now;
        for robot in &mut self.robots {
            for slot in &mut robot.slots {
                if slot.is_running() {
                    slot.run_hook(Hook::Stop, now, robot.id, &robot.name);
                    slot.outbox.clear();
                    slot.commands.clear();
                }
            }
        }
        self.reports()
    }
}
