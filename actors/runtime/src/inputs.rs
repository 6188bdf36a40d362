//! An actor's pending inputs: subscription queues and timer ticks, taken in arrival
//! order. The sim-time executor owns it directly; the real-time one shares it behind
//! a mutex with the publishers.

use std::any::TypeId;
use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Duration;

use crate::actor::Event;
use crate::context::TimerId;
use crate::queue::{BoundedQueue, QueuePolicy};
use crate::topic::Received;

/// One subscription of an actor.
pub(crate) struct Subscription {
    pub(crate) topic: Arc<str>,
    pub(crate) type_id: TypeId,
    pub(crate) queue: BoundedQueue<Received>,
}

/// One timer of an actor.
pub(crate) struct TimerSlot {
    pub(crate) id: TimerId,
    pub(crate) period: Duration,
    /// Bumped on every reset or cancel so that stale scheduled ticks are ignored.
    pub(crate) generation: u64,
    pub(crate) active: bool,
    /// Arrival sequence number of an unhandled tick.
    pub(crate) pending: Option<u64>,
}

#[derive(Default)]
pub(crate) struct Inputs {
    pub(crate) subscriptions: Vec<Subscription>,
    pub(crate) timers: Vec<TimerSlot>,
    pub(crate) stopped: bool,
    pub(crate) dropped_while_stopped: u64,
    pub(crate) timer_overruns: u64,
}

impl Inputs {
    /// Offers a message to subscription `sub`; returns whether it was queued.
    pub(crate) fn offer(&mut self, sub: usize, arrival: u64, message: Received) -> bool {
        if self.stopped {
            self.dropped_while_stopped += 1;
            return false;
        }
        let bytes = message.bytes;
        self.subscriptions[sub]
            .queue
            .push_sized(arrival, message, bytes)
    }

    /// Marks a timer tick as pending; returns false if it was coalesced.
    pub(crate) fn tick(&mut self, timer: usize, arrival: u64) -> bool {
        let t = &mut self.timers[timer];
        if t.pending.is_some() {
            self.timer_overruns += 1;
            false
        } else {
            t.pending = Some(arrival);
            true
        }
    }

    /// Whether there is an input waiting.
    pub(crate) fn has_input(&self) -> bool {
        !self.stopped
            && (self.subscriptions.iter().any(|s| s.queue.len() > 0)
                || self.timers.iter().any(|t| t.pending.is_some()))
    }

    /// Takes the input that arrived first, across subscriptions and timers.
    pub(crate) fn next_event(&mut self) -> Option<Event> {
        if self.stopped {
            return None;
        }
        let mut best: Option<(u64, usize, bool)> = None;
        for (i, s) in self.subscriptions.iter().enumerate() {
            if let Some(seq) = s.queue.front_arrival()
                && best.is_none_or(|(b, _, _)| seq < b)
            {
                best = Some((seq, i, false));
            }
        }
        for (i, t) in self.timers.iter().enumerate() {
            if let Some(seq) = t.pending
                && best.is_none_or(|(b, _, _)| seq < b)
            {
                best = Some((seq, i, true));
            }
        }
        let (_, index, is_timer) = best?;
        if is_timer {
            let t = &mut self.timers[index];
            t.pending = None;
            Some(Event::Timer(t.id))
        } else {
            self.subscriptions[index].queue.pop().map(Event::Message)
        }
    }

    /// The actor stopped for good: drop (and count) what is queued, accept nothing more.
    pub(crate) fn stop(&mut self) {
        self.stopped = true;
        for s in &mut self.subscriptions {
            while s.queue.pop().is_some() {
                self.dropped_while_stopped += 1;
            }
        }
        for t in &mut self.timers {
            t.active = false;
            t.pending = None;
        }
    }

    /// Adds a subscription, or updates the policy of an existing one (keeping its
    /// queue); returns its index.
    pub(crate) fn subscribe(&mut self, topic: &str, type_id: TypeId, policy: QueuePolicy) -> usize {
        if let Some(i) = self
            .subscriptions
            .iter()
            .position(|s| &*s.topic == topic && s.type_id == type_id)
        {
            self.subscriptions[i].queue.set_policy(policy);
            return i;
        }
        self.subscriptions.push(Subscription {
            topic: Arc::from(topic),
            type_id,
            queue: BoundedQueue::new(policy),
        });
        self.subscriptions.len() - 1
    }

    /// Sets or resets a timer; returns its index and new generation.
    pub(crate) fn set_timer(&mut self, id: TimerId, period: Duration) -> (usize, u64) {
        let index = match self.timers.iter().position(|t| t.id == id) {
            Some(i) => i,
            None => {
                self.timers.push(TimerSlot {
                    id,
                    period,
                    generation: 0,
                    active: false,
                    pending: None,
                });
                self.timers.len() - 1
            }
        };
        let t = &mut self.timers[index];
        t.period = period;
        t.generation += 1;
        t.active = true;
        (index, t.generation)
    }

    /// Cancels a timer (no effect if it is not set).
    pub(crate) fn cancel_timer(&mut self, id: TimerId) {
        if let Some(t) = self.timers.iter_mut().find(|t| t.id == id) {
            t.generation += 1;
            t.active = false;
            t.pending = None;
        }
    }

    pub(crate) fn dropped_by_topic(&self) -> BTreeMap<String, u64> {
        let mut dropped = BTreeMap::new();
        for s in &self.subscriptions {
            *dropped.entry(s.topic.to_string()).or_insert(0) += s.queue.dropped();
        }
        dropped
    }
}
