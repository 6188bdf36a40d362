//! Observing every publication of a run from outside the robots (ground-truth
//! metrics, recorders) without adding actors to them.

use crate::topic::{Payload, Topic};
use troupe_core::Message;
use troupe_core::RobotId;
use troupe_core::Time;

/// One publication, as seen by a [`Tap`].
pub struct Publication<'a> {
    /// When it was delivered.
    pub time: Time,
    /// Which robot published it.
    pub robot: RobotId,
    /// Topic name.
    pub topic: &'a str,
    /// The shared message.
    pub payload: &'a Payload,
    /// Its [`Message::payload_bytes`].
    pub bytes: usize,
}

impl Publication<'_> {
    /// The message if it was published on `topic`.
    #[must_use]
    pub fn get<T: Message>(&self, topic: &Topic<T>) -> Option<&T> {
        if self.topic == topic.name() {
            self.payload.downcast_ref::<T>()
        } else {
            None
        }
    }
}

/// Sees every publication of every robot. Under the sim-time executor it is called
/// between the windows in which the robots run side by side, in `(time, robot, order
/// of publication)` order, so what it records is deterministic; it must not reach into
/// the robots.
pub trait Tap: Send {
    /// Called once per publication.
    fn on_publish(&mut self, publication: &Publication<'_>);
}

impl<F: FnMut(&Publication<'_>) + Send> Tap for F {
    fn on_publish(&mut self, publication: &Publication<'_>) {
        self(publication);
    }
}
