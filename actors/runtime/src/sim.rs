//! The deterministic sim-time executor: every robot of a team in one discrete-event
//! loop.
//!
//! Events are ordered by `(time, sequence)`, where the sequence number is assigned
//! when an event is scheduled; nothing depends on wall-clock time or thread timing,
//! so the same team, seed and inputs give bit-identical results. Each handler call
//! is charged the compute latency of its actor's [`LatencyModel`](crate::LatencyModel):
//! its outputs appear after that latency and the actor is busy until then. A call that
//! only stored what arrived ([`Context::bookkeeping_only`](crate::Context::bookkeeping_only))
//! is charged nothing.

use std::any::TypeId;
use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::sync::Arc;

use crate::context::Outgoing;
use crate::inputs::Inputs;
use crate::network::{IdealNetwork, LINK_RX, LINK_TX, LinkRx, LinkTx, SimNetwork};
use crate::registry::{TopicRegistry, apply_command};
use crate::slot::{Hook, HookOutcome, Slot};
use crate::spec::RobotSpec;
use crate::stats::RobotReport;
use crate::tap::{Publication, Tap};
use crate::topic::Received;
use troupe_core::RobotId;
use troupe_core::Time;

enum Kind {
    Activate {
        robot: u32,
        slot: u32,
    },
    Timer {
        robot: u32,
        slot: u32,
        timer: u32,
        generation: u64,
    },
    Deliver {
        robot: u32,
        outputs: Vec<Outgoing>,
    },
    Network {
        to: u32,
        from: RobotId,
        bytes: Arc<[u8]>,
    },
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

/// The event queue and the clock.
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
}

#[derive(Clone, Copy, Default)]
struct SlotSchedule {
    busy_until: Time,
    activation_pending: bool,
}

struct SimRobot {
    id: RobotId,
    name: Arc<str>,
    slots: Vec<Slot>,
    inputs: Vec<Inputs>,
    schedule: Vec<SlotSchedule>,
    registry: TopicRegistry,
}

impl SimRobot {
    /// Schedules an activation of `slot` if it has input and none is pending.
    fn wake(&mut self, clock: &mut Clock, slot: usize) {
        let state = &mut self.schedule[slot];
        if !state.activation_pending && self.inputs[slot].has_input() {
            state.activation_pending = true;
            let at = state.busy_until.max(clock.now);
            clock.schedule(
                at,
                Kind::Activate {
                    robot: self.id.0,
                    slot: slot as u32,
                },
            );
        }
    }

    /// Applies the subscribe / timer commands a hook left behind.
    fn apply_commands(&mut self, clock: &mut Clock, slot: usize) {
        let commands = std::mem::take(&mut self.slots[slot].commands);
        for command in commands {
            let started = apply_command(
                command,
                slot,
                &mut self.inputs[slot],
                &mut self.registry,
                &self.name,
                &self.slots[slot].name,
            );
            if let Some(timer) = started {
                clock.schedule(
                    clock.now + timer.period,
                    Kind::Timer {
                        robot: self.id.0,
                        slot: slot as u32,
                        timer: timer.index as u32,
                        generation: timer.generation,
                    },
                );
            }
        }
    }
}

/// Outside observers and the network, split from the robots for borrowing.
struct World {
    network: Box<dyn SimNetwork>,
    taps: Vec<Box<dyn Tap>>,
    team_size: usize,
    deliveries: Vec<(RobotId, Time)>,
}

impl World {
    /// Delivers publications of one robot to its subscribers, taps and the network.
    fn route(&mut self, clock: &mut Clock, robot: &mut SimRobot, outputs: &mut Vec<Outgoing>) {
        for out in outputs.drain(..) {
            let entry = match robot.registry.entry(&out.topic, out.type_id, out.type_name) {
                Ok(entry) => entry,
                Err(e) => {
                    tracing::error!(robot = %robot.name, topic = %e.topic,
                        "dropped a publication of type {}: the topic carries {}", e.used, e.declared);
                    continue;
                }
            };
            entry.stats.messages += 1;
            entry.stats.bytes += out.bytes as u64;
            for tap in &mut self.taps {
                tap.on_publish(&Publication {
                    time: clock.now,
                    robot: robot.id,
                    topic: &entry.name,
                    payload: &out.payload,
                    bytes: out.bytes,
                });
            }
            for &(slot, sub) in &entry.subscribers {
                let arrival = clock.next_seq();
                let message = Received {
                    topic: entry.name.clone(),
                    payload: out.payload.clone(),
                    published_at: clock.now,
                    bytes: out.bytes,
                };
                if robot.inputs[slot].offer(sub, arrival, message) {
                    let state = &mut robot.schedule[slot];
                    if !state.activation_pending {
                        state.activation_pending = true;
                        let at = state.busy_until.max(clock.now);
                        clock.schedule(
                            at,
                            Kind::Activate {
                                robot: robot.id.0,
                                slot: slot as u32,
                            },
                        );
                    }
                }
            }
            if out.type_id == TypeId::of::<LinkTx>()
                && *out.topic == *LINK_TX.name()
                && let Some(packet) = out.payload.downcast_ref::<LinkTx>()
            {
                self.deliveries.clear();
                self.network.route(
                    clock.now,
                    robot.id,
                    packet.to,
                    &packet.bytes,
                    self.team_size,
                    &mut self.deliveries,
                );
                for &(to, at) in &self.deliveries {
                    clock.schedule(
                        at.max(clock.now),
                        Kind::Network {
                            to: to.0,
                            from: robot.id,
                            bytes: packet.bytes.clone(),
                        },
                    );
                }
            }
        }
    }
}

/// Runs a team of robots in simulated time.
///
/// Events are ordered by `(time, sequence)`, where the sequence number is assigned
/// when an event is scheduled; nothing depends on wall-clock time or thread timing,
/// so the same team, seed and inputs give bit-identical results. Each handler call
/// is charged the compute latency of its actor's [`LatencyModel`](crate::LatencyModel):
/// its outputs appear after that latency and the actor is busy until then.
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
    clock: Clock,
    world: World,
    started: bool,
    events: u64,
}

impl SimExecutor {
    /// A team of robots; `seed` seeds every actor's generator. The network defaults
    /// to an [`IdealNetwork`] with zero latency.
    #[must_use]
    pub fn new(team: Vec<RobotSpec>, seed: u64) -> Self {
        let team_size = team.len();
        let robots = team
            .into_iter()
            .enumerate()
            .map(|(i, spec)| {
                let id = RobotId(i as u32);
                let slots: Vec<Slot> = spec
                    .actors
                    .into_iter()
                    .map(|a| Slot::new(a, seed, id))
                    .collect();
                SimRobot {
                    id,
                    name: spec.name,
                    schedule: vec![SlotSchedule::default(); slots.len()],
                    inputs: slots.iter().map(|_| Inputs::default()).collect(),
                    slots,
                    registry: TopicRegistry::default(),
                }
            })
            .collect();
        SimExecutor {
            robots,
            clock: Clock {
                heap: BinaryHeap::new(),
                now: Time::ZERO,
                seq: 0,
            },
            world: World {
                network: Box::new(IdealNetwork::default()),
                taps: Vec::new(),
                team_size,
                deliveries: Vec::new(),
            },
            started: false,
            events: 0,
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
    }

    /// Current simulated time.
    #[must_use]
    pub fn now(&self) -> Time {
        self.clock.now
    }

    /// Events processed so far.
    #[must_use]
    pub fn events_processed(&self) -> u64 {
        self.events
    }

    /// Starts every actor (called by [`SimExecutor::run_until`] if needed).
    pub fn start(&mut self) {
        if self.started {
            return;
        }
        self.started = true;
        let now = self.clock.now;
        let mut initial = Vec::new();
        for robot in &mut self.robots {
            for s in 0..robot.slots.len() {
                let slot = &mut robot.slots[s];
                if !slot.instantiate(now)
                    || slot.run_hook(Hook::Start, now, robot.id, &robot.name)
                        == HookOutcome::Stopped
                {
                    robot.inputs[s].stop();
                }
                robot.apply_commands(&mut self.clock, s);
                let outputs = std::mem::take(&mut robot.slots[s].outbox);
                if !outputs.is_empty() {
                    initial.push((robot.id.0 as usize, outputs));
                }
            }
        }
        for (r, mut outputs) in initial {
            self.world
                .route(&mut self.clock, &mut self.robots[r], &mut outputs);
        }
    }

    /// Processes every event up to and including `end`, then sets the clock to `end`.
    pub fn run_until(&mut self, end: Time) {
        self.start();
        while self.clock.heap.peek().is_some_and(|e| e.time <= end) {
            if let Some(event) = self.clock.heap.pop() {
                self.clock.now = event.time;
                self.events += 1;
                self.dispatch(event.kind);
            }
        }
        self.clock.now = self.clock.now.max(end);
    }

    fn dispatch(&mut self, kind: Kind) {
        match kind {
            Kind::Activate { robot, slot } => self.activate(robot as usize, slot as usize),
            Kind::Timer {
                robot,
                slot,
                timer,
                generation,
            } => {
                let r = &mut self.robots[robot as usize];
                let s = &mut r.inputs[slot as usize];
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
                        robot,
                        slot,
                        timer,
                        generation,
                    },
                );
                r.wake(&mut self.clock, slot as usize);
            }
            Kind::Deliver { robot, mut outputs } => {
                self.world.route(
                    &mut self.clock,
                    &mut self.robots[robot as usize],
                    &mut outputs,
                );
            }
            Kind::Network { to, from, bytes } => {
                let message = Arc::new(LinkRx { from, bytes });
                let mut outputs = vec![Outgoing::new(&LINK_RX, message)];
                self.world
                    .route(&mut self.clock, &mut self.robots[to as usize], &mut outputs);
            }
        }
    }

    fn activate(&mut self, r: usize, s: usize) {
        let robot = &mut self.robots[r];
        robot.schedule[s].activation_pending = false;
        let Some(event) = robot.inputs[s].next_event() else {
            return;
        };
        let slot = &mut robot.slots[s];
        let now = self.clock.now;
        let latency = slot.options.latency.sample(&mut slot.latency_rng);
        let outcome = slot.run_hook(Hook::Handle(&event), now, robot.id, &robot.name);
        let latency = if slot.bookkeeping {
            std::time::Duration::ZERO
        } else {
            latency
        };
        drop(event);
        if outcome == HookOutcome::Stopped {
            robot.inputs[s].stop();
        }
        robot.apply_commands(&mut self.clock, s);
        let done = now + latency;
        if outcome != HookOutcome::Stopped && !robot.slots[s].outbox.is_empty() {
            if latency.is_zero() {
                let mut outputs = std::mem::take(&mut robot.slots[s].outbox);
                self.world.route(&mut self.clock, robot, &mut outputs);
                robot.slots[s].outbox = outputs;
            } else {
                let outputs = std::mem::take(&mut robot.slots[s].outbox);
                self.clock.schedule(
                    done,
                    Kind::Deliver {
                        robot: r as u32,
                        outputs,
                    },
                );
            }
        }
        robot.schedule[s].busy_until = done;
        robot.wake(&mut self.clock, s);
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
        let now = self.clock.now;
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
