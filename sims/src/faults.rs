//! Scenario-scheduled faults.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use troupe_actors::runtime::{Actor, ActorResult, Context, Event, Time};

/// Wraps an actor so that its handler panics once, at the first event at or after
/// `at` (the flag is shared across restarts, so the rebuilt actor runs normally).
pub struct PanicOnce {
    inner: Box<dyn Actor>,
    at: Time,
    fired: Arc<AtomicBool>,
}

impl PanicOnce {
    /// Wraps `inner`.
    #[must_use]
    pub fn new(inner: Box<dyn Actor>, at: Time, fired: Arc<AtomicBool>) -> Self {
        PanicOnce { inner, at, fired }
    }
}

impl Actor for PanicOnce {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        self.inner.start(ctx)
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        if ctx.now() >= self.at && !self.fired.swap(true, Ordering::SeqCst) {
            panic!(
                "injected fault: {} panics at {}",
                ctx.actor_name(),
                ctx.now()
            );
        }
        self.inner.handle(event, ctx)
    }

    fn stop(&mut self, ctx: &mut Context<'_>) {
        self.inner.stop(ctx);
    }
}
