//! What an actor may do from inside a hook.

use std::any::TypeId;
use std::borrow::Cow;
use std::sync::Arc;
use std::time::Duration;

use rand_chacha::ChaCha8Rng;

use crate::queue::QueuePolicy;
use crate::topic::{Payload, Topic};
use troupe_core::{Message, RobotId, TeamClock, Time, TimeSource};

/// Names one of an actor's timers. Actors pick their own ids (`const TICK: TimerId = TimerId(0);`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct TimerId(pub u32);

/// A publication waiting to be routed when the hook returns.
pub(crate) struct Outgoing {
    pub(crate) topic: Cow<'static, str>,
    pub(crate) type_id: TypeId,
    pub(crate) type_name: &'static str,
    pub(crate) payload: Payload,
    pub(crate) bytes: usize,
}

impl Outgoing {
    /// A publication of `message` on `topic`.
    pub(crate) fn new<T: Message>(topic: &Topic<T>, message: Arc<T>) -> Self {
        Outgoing {
            topic: topic.name_cow(),
            type_id: TypeId::of::<T>(),
            type_name: std::any::type_name::<T>(),
            bytes: message.payload_bytes(),
            payload: message,
        }
    }
}

/// A request to the runtime made from a hook.
#[derive(Debug)]
pub(crate) enum Command {
    Subscribe {
        topic: Arc<str>,
        type_id: TypeId,
        type_name: &'static str,
        policy: QueuePolicy,
    },
    SetTimer {
        id: TimerId,
        period: Duration,
    },
    CancelTimer {
        id: TimerId,
    },
}

/// The view of the runtime that an actor gets inside [`Actor`](crate::Actor) hooks.
///
/// Everything is buffered: publications, subscriptions and timer changes take effect
/// when the hook returns.
pub struct Context<'a> {
    pub(crate) now: Time,
    pub(crate) robot: RobotId,
    pub(crate) robot_name: &'a str,
    pub(crate) actor_name: &'a str,
    pub(crate) outbox: &'a mut Vec<Outgoing>,
    pub(crate) commands: &'a mut Vec<Command>,
    pub(crate) rng: &'a mut ChaCha8Rng,
    pub(crate) bookkeeping: &'a mut bool,
    pub(crate) clock: TeamClock,
    pub(crate) time_source: TimeSource,
}

impl Context<'_> {
    /// Current time: simulated under the sim-time executor, elapsed wall time under
    /// the real-time one. It is the time at which the event is handled.
    #[must_use]
    pub fn now(&self) -> Time {
        self.now
    }

    /// Where this run's time sits on the clock the team shares: run time itself
    /// under the sim-time executor ([`TeamClock::SHARED`]), Unix time from the
    /// executor's start under the real-time one. What crosses to other robots is
    /// stamped on it.
    #[must_use]
    pub fn team_clock(&self) -> TeamClock {
        self.clock
    }

    /// What moves this run's time: [`TimeSource::Simulated`] under the sim-time
    /// executor, where nothing an actor does may depend on the wall clock (an anytime
    /// computation stops on a fixed amount of work instead of a wall-clock budget),
    /// [`TimeSource::WallClock`] under the real-time one.
    #[must_use]
    pub fn time_source(&self) -> TimeSource {
        self.time_source
    }

    /// This robot's index in the team.
    #[must_use]
    pub fn robot(&self) -> RobotId {
        self.robot
    }

    /// This robot's name.
    #[must_use]
    pub fn robot_name(&self) -> &str {
        self.robot_name
    }

    /// This actor's name.
    #[must_use]
    pub fn actor_name(&self) -> &str {
        self.actor_name
    }

    /// A random generator private to this actor, seeded from the team seed, the robot
    /// and the actor name: deterministic under the sim-time executor. It keeps its
    /// state across restarts.
    pub fn rng(&mut self) -> &mut ChaCha8Rng {
        self.rng
    }

    /// Publishes a message on a topic of this robot.
    pub fn publish<T: Message>(&mut self, topic: &Topic<T>, message: T) {
        self.publish_arc(topic, Arc::new(message));
    }

    /// Publishes an already shared message (no copy).
    pub fn publish_arc<T: Message>(&mut self, topic: &Topic<T>, message: Arc<T>) {
        self.outbox.push(Outgoing::new(topic, message));
    }

    /// Subscribes to a topic with the given queue policy, usually from
    /// [`Actor::start`](crate::Actor::start); from any later hook it takes effect
    /// when the hook returns, under both executors (messages published before
    /// that are not delivered). Subscribing twice to the same topic updates the
    /// policy and keeps the queue.
    pub fn subscribe<T: Message>(&mut self, topic: &Topic<T>, policy: QueuePolicy) {
        self.commands.push(Command::Subscribe {
            topic: Arc::from(topic.name()),
            type_id: TypeId::of::<T>(),
            type_name: std::any::type_name::<T>(),
            policy,
        });
    }

    /// Sets (or resets) a periodic timer; the first tick comes one period from now.
    /// A zero period is rejected by the runtime with a warning.
    pub fn set_timer(&mut self, id: TimerId, period: Duration) {
        self.commands.push(Command::SetTimer { id, period });
    }

    /// Marks this handler call as bookkeeping — it only stored what arrived (the
    /// latest odometry, a peer's plan) or merged it at a cost far below the modelled
    /// one (a peer's grid change set) — so that the sim-time executor charges it no
    /// compute latency. The modelled latency ([`LatencyModel`](crate::LatencyModel))
    /// stands for the actor's real work (a planning round: thesis Table 4.1); charged
    /// to every stored message, it would keep a planner that hears many peers busy
    /// and delay its rounds. No effect under the real-time executor.
    pub fn bookkeeping_only(&mut self) {
        *self.bookkeeping = true;
    }

    /// Cancels a timer (no effect if it is not set).
    pub fn cancel_timer(&mut self, id: TimerId) {
        self.commands.push(Command::CancelTimer { id });
    }
}
