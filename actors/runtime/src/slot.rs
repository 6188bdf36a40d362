//! One actor inside a running robot: its instance, generators and supervision.
//! Shared by both executors.

use std::collections::VecDeque;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::Arc;
use std::time::{Duration, Instant};

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::actor::{Actor, ActorResult, Event};
use crate::context::{Command, Context, Outgoing};
use crate::inputs::Inputs;
use crate::spec::{ActorFactory, ActorOptions, ActorSpec};
use crate::stats::{ActorReport, ActorStats};
use troupe_core::{RobotId, TeamClock, Time, TimeSource};

/// Which hook to run.
pub(crate) enum Hook<'e> {
    Start,
    Handle(&'e Event),
    Stop,
}

/// How a hook call ended.
#[derive(Debug, PartialEq, Eq)]
pub(crate) enum HookOutcome {
    Ok,
    Error,
    /// Panicked; the actor was rebuilt and started again.
    Restarted,
    /// Panicked; the actor is stopped for the rest of the run.
    Stopped,
}

/// What a [`Slot`] holds while its slot is elsewhere ([`Slot::take`]): nothing runs.
struct Shell;

impl Actor for Shell {
    fn handle(&mut self, _: &Event, _: &mut Context<'_>) -> ActorResult {
        Ok(())
    }
}

/// Stable 64-bit FNV-1a hash, used to derive per-actor seeds.
pub(crate) fn stable_hash(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
        (h ^ u64::from(*b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

pub(crate) struct Slot {
    pub(crate) name: Arc<str>,
    factory: ActorFactory,
    actor: Option<Box<dyn Actor>>,
    pub(crate) options: ActorOptions,
    pub(crate) stats: ActorStats,
    restart_times: VecDeque<Time>,
    rng: ChaCha8Rng,
    /// Generator for modelled latencies, separate so that it does not disturb the actor's.
    pub(crate) latency_rng: ChaCha8Rng,
    pub(crate) outbox: Vec<Outgoing>,
    pub(crate) commands: Vec<Command>,
    /// The last handler call said it only stored what arrived
    /// ([`Context::bookkeeping_only`](crate::Context::bookkeeping_only)).
    pub(crate) bookkeeping: bool,
    /// The run's place on the team clock ([`Context::team_clock`](crate::Context::team_clock)).
    clock: TeamClock,
    /// What moves the run's time ([`Context::time_source`](crate::Context::time_source)).
    time_source: TimeSource,
}

impl Slot {
    pub(crate) fn new(
        spec: ActorSpec,
        team_seed: u64,
        robot: RobotId,
        (clock, time_source): (TeamClock, TimeSource),
    ) -> Self {
        let seed = team_seed
            ^ stable_hash(spec.name.as_bytes()).rotate_left(17)
            ^ u64::from(robot.0).wrapping_mul(0x9e37_79b9_7f4a_7c15);
        Slot {
            name: spec.name,
            factory: spec.factory,
            actor: None,
            options: spec.options,
            stats: ActorStats::default(),
            restart_times: VecDeque::new(),
            rng: ChaCha8Rng::seed_from_u64(seed),
            latency_rng: ChaCha8Rng::seed_from_u64(seed ^ 0x5eed_1a7e),
            outbox: Vec::new(),
            commands: Vec::new(),
            bookkeeping: false,
            clock,
            time_source,
        }
    }

    /// Builds the first instance. A panicking factory counts like a panicking hook.
    pub(crate) fn instantiate(&mut self, now: Time) -> bool {
        match catch_unwind(AssertUnwindSafe(&mut self.factory)) {
            Ok(actor) => {
                self.actor = Some(actor);
                true
            }
            Err(panic) => {
                self.stats.panics += 1;
                tracing::error!(actor = %self.name, time = %now, "actor factory panicked: {}", panic_message(&panic));
                self.stats.stopped = true;
                false
            }
        }
    }

    pub(crate) fn is_running(&self) -> bool {
        !self.stats.stopped
    }

    /// Whether the actor lets this call run beside the robot's later events
    /// ([`Actor::overlaps`]).
    pub(crate) fn overlaps(&self, event: &Event) -> bool {
        self.actor.as_ref().is_some_and(|a| a.overlaps(event))
    }

    /// Moves the slot out for a call run elsewhere, leaving a shell with no actor in
    /// its place until the slot is put back.
    pub(crate) fn take(&mut self) -> Slot {
        let shell = Slot {
            name: self.name.clone(),
            factory: Box::new(|| Box::new(Shell) as Box<dyn Actor>),
            actor: None,
            options: self.options,
            stats: ActorStats::default(),
            restart_times: VecDeque::new(),
            rng: ChaCha8Rng::seed_from_u64(0),
            latency_rng: ChaCha8Rng::seed_from_u64(0),
            outbox: Vec::new(),
            commands: Vec::new(),
            bookkeeping: false,
            clock: self.clock,
            time_source: self.time_source,
        };
        std::mem::replace(self, shell)
    }

    /// Runs a hook with panic containment and supervision. Outputs and commands are
    /// left in `self.outbox` / `self.commands` for the executor (cleared on panic).
    pub(crate) fn run_hook(
        &mut self,
        hook: Hook<'_>,
        now: Time,
        robot: RobotId,
        robot_name: &str,
    ) -> HookOutcome {
        let Some(actor) = self.actor.as_mut() else {
            return HookOutcome::Stopped;
        };
        let started = Instant::now();
        self.bookkeeping = false;
        let mut ctx = Context {
            now,
            robot,
            robot_name,
            actor_name: &self.name,
            outbox: &mut self.outbox,
            commands: &mut self.commands,
            rng: &mut self.rng,
            bookkeeping: &mut self.bookkeeping,
            clock: self.clock,
            time_source: self.time_source,
        };
        let is_handle = matches!(hook, Hook::Handle(_));
        let result = catch_unwind(AssertUnwindSafe(|| -> ActorResult {
            match hook {
                Hook::Start => actor.start(&mut ctx),
                Hook::Handle(event) => actor.handle(event, &mut ctx),
                Hook::Stop => {
                    actor.stop(&mut ctx);
                    Ok(())
                }
            }
        }));
        if is_handle {
            self.stats.handled += 1;
            self.stats.handler_wall.record(started.elapsed());
        }
        match result {
            Ok(Ok(())) => HookOutcome::Ok,
            Ok(Err(error)) => {
                self.stats.errors += 1;
                tracing::warn!(robot = robot_name, actor = %self.name, time = %now, "actor error: {}", troupe_core::ErrorChain(&error));
                HookOutcome::Error
            }
            Err(panic) => {
                self.outbox.clear();
                self.commands.clear();
                self.stats.panics += 1;
                tracing::error!(robot = robot_name, actor = %self.name, time = %now, "actor panicked: {}", panic_message(&panic));
                self.supervise(now, robot, robot_name)
            }
        }
    }

    /// After a panic: restart per policy, or stop.
    fn supervise(&mut self, now: Time, robot: RobotId, robot_name: &str) -> HookOutcome {
        if let Some(old) = self.actor.take() {
            // Dropping a half-updated actor may panic too; contain it.
            let _ = catch_unwind(AssertUnwindSafe(move || drop(old)));
        }
        let policy = self.options.restart;
        let window = Duration::try_from_secs_f64(policy.window_s.max(0.0)).unwrap_or(Duration::MAX);
        while let Some(&first) = self.restart_times.front() {
            if now.saturating_since(first) > window {
                self.restart_times.pop_front();
            } else {
                break;
            }
        }
        if self.restart_times.len() >= policy.max_restarts as usize {
            self.stats.stopped = true;
            tracing::error!(
                robot = robot_name, actor = %self.name, time = %now,
                "actor stopped after {} restarts within {} s; the robot continues without it",
                self.restart_times.len(), policy.window_s
            );
            return HookOutcome::Stopped;
        }
        self.restart_times.push_back(now);
        self.stats.restarts += 1;
        if !self.instantiate(now) {
            return HookOutcome::Stopped;
        }
        tracing::warn!(robot = robot_name, actor = %self.name, time = %now, restarts = self.stats.restarts, "actor restarted");
        match self.run_hook(Hook::Start, now, robot, robot_name) {
            HookOutcome::Ok | HookOutcome::Error | HookOutcome::Restarted => HookOutcome::Restarted,
            HookOutcome::Stopped => HookOutcome::Stopped,
        }
    }

    /// The actor's report, with the input counters merged in.
    pub(crate) fn report(&self, inputs: &Inputs) -> ActorReport {
        let mut stats = self.stats.clone();
        stats.dropped_while_stopped = inputs.dropped_while_stopped;
        stats.timer_overruns = inputs.timer_overruns;
        ActorReport {
            name: self.name.to_string(),
            stats,
            dropped_by_topic: inputs.dropped_by_topic(),
        }
    }
}

/// The text of a panic payload.
pub(crate) fn panic_message(panic: &Box<dyn std::any::Any + Send>) -> String {
    if let Some(s) = panic.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = panic.downcast_ref::<String>() {
        s.clone()
    } else {
        "non-string panic payload".to_string()
    }
}
