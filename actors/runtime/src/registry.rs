//! The topics of one robot and who subscribes to them.

use std::any::TypeId;
use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;
use std::time::Duration;

use crate::context::Command;
use crate::inputs::Inputs;
use crate::stats::TopicStats;

/// A subscriber: (actor slot index, subscription index inside that slot).
pub(crate) type SubscriberRef = (usize, usize);

pub(crate) struct TopicEntry {
    pub(crate) name: Arc<str>,
    pub(crate) type_id: TypeId,
    pub(crate) type_name: &'static str,
    pub(crate) subscribers: Vec<SubscriberRef>,
    pub(crate) stats: TopicStats,
}

/// Topic name → type and subscribers, for one robot.
#[derive(Default)]
pub(crate) struct TopicRegistry {
    topics: HashMap<Arc<str>, TopicEntry>,
}

/// A topic was used with two different message types.
#[derive(Debug)]
pub(crate) struct TypeMismatch {
    pub(crate) topic: Arc<str>,
    pub(crate) declared: &'static str,
    pub(crate) used: &'static str,
}

impl TopicRegistry {
    /// The entry for `name`, created with this type if new; an error if the topic
    /// already carries another type.
    pub(crate) fn entry(
        &mut self,
        name: &str,
        type_id: TypeId,
        type_name: &'static str,
    ) -> Result<&mut TopicEntry, TypeMismatch> {
        if !self.topics.contains_key(name) {
            let name: Arc<str> = Arc::from(name);
            self.topics.insert(
                name.clone(),
                TopicEntry {
                    name,
                    type_id,
                    type_name,
                    subscribers: Vec::new(),
                    stats: TopicStats::default(),
                },
            );
        }
        let entry = self
            .topics
            .get_mut(name)
            .expect("entry was inserted just above");
        if entry.type_id != type_id {
            entry.stats.type_mismatches += 1;
            return Err(TypeMismatch {
                topic: entry.name.clone(),
                declared: entry.type_name,
                used: type_name,
            });
        }
        Ok(entry)
    }

    /// Registers a subscriber (idempotent).
    pub(crate) fn add_subscriber(
        &mut self,
        name: &str,
        type_id: TypeId,
        type_name: &'static str,
        who: SubscriberRef,
    ) -> Result<(), TypeMismatch> {
        let entry = self.entry(name, type_id, type_name)?;
        if !entry.subscribers.contains(&who) {
            entry.subscribers.push(who);
        }
        Ok(())
    }

    /// The entries, consumed (the real-time executor takes them over after `start`).
    pub(crate) fn into_entries(self) -> impl Iterator<Item = TopicEntry> {
        self.topics.into_values()
    }

    /// Per-topic counters sorted by name.
    pub(crate) fn stats(&self) -> BTreeMap<String, TopicStats> {
        self.topics
            .values()
            .map(|e| (e.name.to_string(), e.stats))
            .collect()
    }
}

/// A timer that a command (re)started: its index in the actor's inputs, its new
/// generation and its period. The executor schedules its first tick.
pub(crate) struct TimerStarted {
    pub(crate) index: usize,
    pub(crate) generation: u64,
    pub(crate) period: Duration,
}

/// What registers a subscriber with the robot's topics (as
/// [`TopicRegistry::add_subscriber`]): its registry under the simulated executor
/// and while real-time actors start, the shared topic table once they run.
pub(crate) type AddSubscriber<'a> =
    &'a mut dyn FnMut(&str, TypeId, &'static str, SubscriberRef) -> Result<(), TypeMismatch>;

/// Applies one command of actor `slot` to its inputs and, through
/// `add_subscriber`, the robot's topics — the same rules under both executors.
/// Returns the timer to schedule, if any.
pub(crate) fn apply_command(
    command: Command,
    slot: usize,
    inputs: &mut Inputs,
    add_subscriber: AddSubscriber<'_>,
    robot: &str,
    actor: &str,
) -> Option<TimerStarted> {
    match command {
        Command::Subscribe {
            topic,
            type_id,
            type_name,
            policy,
        } => {
            let sub = inputs.subscribe(&topic, type_id, policy);
            if let Err(e) = add_subscriber(&topic, type_id, type_name, (slot, sub)) {
                tracing::error!(robot, actor, topic = %e.topic,
                    "cannot subscribe with type {}: the topic carries {}", e.used, e.declared);
            }
            None
        }
        Command::SetTimer { id, period } if period.is_zero() => {
            tracing::warn!(robot, actor, ?id, "ignoring a timer with zero period");
            None
        }
        Command::SetTimer { id, period } => {
            let (index, generation) = inputs.set_timer(id, period);
            Some(TimerStarted {
                index,
                generation,
                period,
            })
        }
        Command::CancelTimer { id } => {
            inputs.cancel_timer(id);
            None
        }
    }
}
