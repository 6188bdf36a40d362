//! The link actor (module docs of [`crate::link`]): a thin wrapper that subscribes
//! to the link's topics, forwards each event to its [`LinkCore`] and publishes
//! what the core returns.

use troupe_runtime::{
    Actor, ActorError, ActorResult, Context, Event, LINK_RX, LINK_TRANSPORT, LINK_TX, QueuePolicy,
    TimerId, Topic,
};

use super::config::LinkConfig;
use super::core::{LinkCore, LinkIdentity, LinkInput, LinkOutput, LinkTimer};
use super::journal::LinkJournal;
use super::shared::SHARE_REQUESTS;
use super::status::LinkStatus;
use crate::msgs::{
    GRID_CHANGES, KEYFRAME, ODOMETRY, PEER_GRID_CHANGES, PEER_KEYFRAME, PEER_ODOMETRY, PEER_PLAN,
    PLAN,
};

/// Most received frames waiting for the link ([`LINK_RX`]); more are dropped and
/// counted by the runtime (the sender's store-and-forward resends what mattered).
pub const LINK_RX_MAX_FRAMES: usize = 4096;
/// Most bytes of received frames waiting for the link: a flood of large junk
/// frames cannot hold more memory than this (4096 frames of the largest MTU would
/// be 256 MiB).
pub const LINK_RX_MAX_BYTES: usize = 8 * 1024 * 1024;

/// Link counters.
pub const LINK_STATUS: Topic<LinkStatus> = Topic::new("link/status");

/// The runtime timer of one of the core's timers.
fn timer_id(timer: LinkTimer) -> TimerId {
    TimerId(match timer {
        LinkTimer::Odometry => 0,
        LinkTimer::Pump => 1,
        LinkTimer::Status => 2,
        LinkTimer::Plan => 3,
        LinkTimer::Replay => 4,
    })
}

/// The core's timer behind a runtime timer.
fn link_timer(id: TimerId) -> Option<LinkTimer> {
    Some(match id.0 {
        0 => LinkTimer::Odometry,
        1 => LinkTimer::Pump,
        2 => LinkTimer::Status,
        3 => LinkTimer::Plan,
        4 => LinkTimer::Replay,
        _ => return None,
    })
}

/// See the [module docs](crate::link).
pub struct LinkActor {
    core: LinkCore,
    /// Whether this robot's keyframes go to peers ([`LinkActor::without_keyframes`]).
    share_keyframes: bool,
    /// The core's outputs, reused between events.
    outputs: Vec<LinkOutput>,
}

impl LinkActor {
    /// A link actor; fails if the shaper or reassembly settings are invalid.
    pub fn new(config: LinkConfig) -> Result<Self, ActorError> {
        Ok(LinkActor {
            core: LinkCore::new(config)?,
            share_keyframes: true,
            outputs: Vec::new(),
        })
    }

    /// Keeps the link's durable state in `journal` and resumes from what it holds
    /// (see [`LinkJournal`]); fails if the stored state does not fit the settings.
    pub fn journaled(mut self, journal: LinkJournal) -> Result<Self, ActorError> {
        self.core = self.core.journaled(journal)?;
        Ok(self)
    }

    /// Keeps this robot's keyframes local (when the team shares occupancy-grid change
    /// sets instead, §8.2.5; change sets on `grid/changes` are always sent).
    #[must_use]
    pub fn without_keyframes(mut self) -> Self {
        self.share_keyframes = false;
        self
    }

    /// Publishes what the core returned, in order.
    fn publish(&mut self, ctx: &mut Context<'_>) {
        for output in self.outputs.drain(..) {
            match output {
                LinkOutput::Transmit(tx) => ctx.publish(&LINK_TX, tx),
                LinkOutput::PeerOdometry(o) => ctx.publish(&PEER_ODOMETRY, o),
                LinkOutput::PeerKeyframe(k) => ctx.publish(&PEER_KEYFRAME, k),
                LinkOutput::PeerPlan(p) => ctx.publish(&PEER_PLAN, p),
                LinkOutput::PeerGridChanges(g) => ctx.publish(&PEER_GRID_CHANGES, g),
                LinkOutput::PeerShared(delivery) => delivery.publish(ctx),
                LinkOutput::Status(status) => ctx.publish(&LINK_STATUS, *status),
                LinkOutput::Subscribe(request) => request.0.subscribe(ctx),
                LinkOutput::SetTimer(timer, period) => ctx.set_timer(timer_id(timer), period),
                LinkOutput::CancelTimer(timer) => ctx.cancel_timer(timer_id(timer)),
            }
        }
    }

    /// The core's input for an event, if the link listens to it.
    fn input<'a>(event: &'a Event) -> Option<LinkInput<'a>> {
        let m = match event {
            Event::Timer(id) => return link_timer(*id).map(LinkInput::Tick),
            Event::Message(m) => m,
        };
        Some(if let Some(odometry) = m.get_arc(&ODOMETRY) {
            LinkInput::Odometry(odometry)
        } else if let Some(stats) = m.get(&LINK_TRANSPORT) {
            LinkInput::Transport(*stats)
        } else if let Some(plan) = m.get_arc(&PLAN) {
            LinkInput::Plan(plan)
        } else if let Some(keyframe) = m.get(&KEYFRAME) {
            LinkInput::Keyframe(keyframe)
        } else if let Some(changes) = m.get(&GRID_CHANGES) {
            LinkInput::GridChanges(changes)
        } else if let Some(rx) = m.get(&LINK_RX) {
            LinkInput::Frame {
                from: rx.from,
                bytes: &rx.bytes,
            }
        } else if let Some(request) = m.get(&SHARE_REQUESTS) {
            LinkInput::Share(request)
        } else {
            LinkInput::Local(m)
        })
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
        let identity = LinkIdentity {
            robot: ctx.robot(),
            name: ctx.robot_name().to_owned(),
            clock: ctx.team_clock(),
        };
        let result = self.core.start(identity, ctx.now(), &mut self.outputs);
        self.publish(ctx);
        result
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        let Some(input) = Self::input(event) else {
            return Ok(());
        };
        let result = self.core.handle(ctx.now(), input, &mut self.outputs);
        self.publish(ctx);
        result
    }
}

#[cfg(test)]
#[path = "tests.rs"]
mod tests;
