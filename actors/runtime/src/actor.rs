//! The actor trait and the events it handles.

use std::fmt;

use crate::context::{Context, TimerId};
use crate::topic::Received;

/// One thing for an actor to handle.
#[derive(Debug)]
pub enum Event {
    /// A message on one of the actor's subscriptions; read it with [`Received::get`].
    Message(Received),
    /// A timer set with [`Context::set_timer`] fired. Ticks that fire while the actor
    /// is still busy coalesce into one (counted as a drop).
    Timer(TimerId),
}

impl Event {
    /// The message, if this event is one.
    #[must_use]
    pub fn message(&self) -> Option<&Received> {
        match self {
            Event::Message(m) => Some(m),
            Event::Timer(_) => None,
        }
    }
}

/// A failure an actor reports from a hook. The runtime logs and counts it; the
/// actor keeps running. (A *panic* is different: the runtime restarts the actor.)
#[derive(Debug)]
pub struct ActorError {
    message: String,
    source: Option<Box<dyn std::error::Error + Send + Sync>>,
}

impl ActorError {
    /// An error with a message.
    #[must_use]
    pub fn msg(message: impl Into<String>) -> Self {
        ActorError {
            message: message.into(),
            source: None,
        }
    }

    /// An error with a message and the error that caused it.
    #[must_use]
    pub fn with_source(
        message: impl Into<String>,
        source: impl std::error::Error + Send + Sync + 'static,
    ) -> Self {
        ActorError {
            message: message.into(),
            source: Some(Box::new(source)),
        }
    }
}

impl fmt::Display for ActorError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for ActorError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        self.source
            .as_deref()
            .map(|e| e as &(dyn std::error::Error + 'static))
    }
}

/// Result of an actor hook.
pub type ActorResult = Result<(), ActorError>;

/// A unit of behaviour inside a robot: it owns its state, receives [`Event`]s one at
/// a time, and talks to other actors only by publishing messages.
///
/// The same actor runs unchanged under the deterministic sim-time executor and the
/// real-time executor. The runtime calls the hooks in this order:
///
/// 1. [`Actor::start`] once when the robot starts, and again on a fresh instance after
///    every restart. Declare subscriptions and timers here (re-declaring after a
///    restart keeps the existing queues and their contents).
/// 2. [`Actor::handle`] for each event, never concurrently with another hook of the
///    same actor.
/// 3. [`Actor::stop`] once when the run ends.
///
/// Hooks must not block on I/O or sleep: under the sim-time executor, time only
/// moves between events, and the modelled compute latency (configured per actor,
/// see [`ActorOptions`](crate::ActorOptions)) stands for the time a handler takes.
/// Heavy but finite compute is fine, including `rayon` inside a handler, as long as
/// results do not depend on thread timing (use ordered collects, not racy reductions).
/// The sim-time executor runs the robots of a team on several threads at once: actors
/// of different robots must share nothing mutable except through topics and the link
/// (within one robot, anything goes — its actors never run at the same time there).
/// Messages published inside a hook are delivered when it returns (in sim time:
/// after the modelled latency).
///
/// A panic inside a hook is contained: it is logged, counted, and the actor is
/// rebuilt from its factory according to its
/// [`RestartPolicy`](crate::RestartPolicy); the rest of the robot keeps running.
pub trait Actor: Send + 'static {
    /// Declares subscriptions and timers; may publish initial messages.
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        let _ = ctx;
        Ok(())
    }

    /// Handles one event.
    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult;

    /// Called once at the end of a run.
    fn stop(&mut self, ctx: &mut Context<'_>) {
        let _ = ctx;
    }

    /// Whether the sim-time executor may run this call of [`Actor::handle`] beside
    /// the robot's later events while the call's modelled latency passes (default:
    /// never). Only for calls that neither subscribe, set nor cancel timers, nor call
    /// [`Context::bookkeeping_only`]: such a call's outputs appear only once its
    /// latency has passed and nothing else of the robot reads the actor meanwhile, so
    /// running it on another core gives the same run, bit for bit. Heavy calls — a
    /// frame rendered, a keyframe fitted — then leave no core idle while the robots'
    /// other work waits for them. The real-time executor ignores it.
    fn overlaps(&self, event: &Event) -> bool {
        let _ = event;
        false
    }
}

impl Actor for Box<dyn Actor> {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        (**self).start(ctx)
    }
    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        (**self).handle(event, ctx)
    }
    fn stop(&mut self, ctx: &mut Context<'_>) {
        (**self).stop(ctx);
    }
    fn overlaps(&self, event: &Event) -> bool {
        (**self).overlaps(event)
    }
}

/// An actor whose construction failed: its start hook reports the error (counted and
/// logged like any hook error) and it handles nothing, so the rest of the robot runs
/// on. Lets factories return `Result<A, ActorError>`.
impl<A: Actor> Actor for Result<A, ActorError> {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        match self {
            Ok(actor) => actor.start(ctx),
            Err(e) => Err(ActorError::msg(format!("actor could not be built: {e}"))),
        }
    }
    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        match self {
            Ok(actor) => actor.handle(event, ctx),
            Err(_) => Ok(()),
        }
    }
    fn stop(&mut self, ctx: &mut Context<'_>) {
        if let Ok(actor) = self {
            actor.stop(ctx);
        }
    }
    fn overlaps(&self, event: &Event) -> bool {
        self.as_ref().is_ok_and(|actor| actor.overlaps(event))
    }
}
