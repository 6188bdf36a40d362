//! Typed topics and type-erased messages.

use std::borrow::Cow;
use std::fmt;
use std::marker::PhantomData;
use std::sync::Arc;

use troupe_core::{Message, Time};

/// The name and message type of a topic inside one robot.
///
/// Topics are robot-local: two robots that publish `"odometry"` do not see each
/// other's messages; crossing robots is the link actor's job. Declare topics as
/// constants next to the message type:
///
/// ```
/// use troupe_runtime::{Message, Topic};
/// struct Battery { volts: f64 }
/// impl Message for Battery {}
/// const BATTERY: Topic<Battery> = Topic::new("battery");
/// assert_eq!(BATTERY.name(), "battery");
/// ```
pub struct Topic<T> {
    name: Cow<'static, str>,
    _message: PhantomData<fn() -> T>,
}

impl<T: Message> Topic<T> {
    /// A topic with a static name.
    #[must_use]
    pub const fn new(name: &'static str) -> Self {
        Topic {
            name: Cow::Borrowed(name),
            _message: PhantomData,
        }
    }

    /// A topic whose name is built at run time.
    #[must_use]
    pub fn named(name: impl Into<String>) -> Self {
        Topic {
            name: Cow::Owned(name.into()),
            _message: PhantomData,
        }
    }
}

impl<T> Topic<T> {
    /// The topic's name.
    #[must_use]
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The name without allocating for static names.
    pub(crate) fn name_cow(&self) -> Cow<'static, str> {
        self.name.clone()
    }
}

impl<T> Clone for Topic<T> {
    fn clone(&self) -> Self {
        Topic {
            name: self.name.clone(),
            _message: PhantomData,
        }
    }
}

impl<T> fmt::Debug for Topic<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Topic({:?}: {})", self.name, std::any::type_name::<T>())
    }
}

/// A shared, type-erased message payload.
pub type Payload = Arc<dyn std::any::Any + Send + Sync>;

/// A message as delivered to a subscriber.
#[derive(Clone)]
pub struct Received {
    pub(crate) topic: Arc<str>,
    pub(crate) payload: Payload,
    pub(crate) published_at: Time,
    /// Its payload bytes ([`Message::payload_bytes`]), charged to byte-bounded queues.
    pub(crate) bytes: usize,
}

impl Received {
    /// The message if it came on `topic`, `None` otherwise.
    #[must_use]
    pub fn get<T: Message>(&self, topic: &Topic<T>) -> Option<&T> {
        if *self.topic == *topic.name() {
            self.payload.downcast_ref::<T>()
        } else {
            None
        }
    }

    /// Like [`Received::get`], but returns the shared pointer (no copy).
    #[must_use]
    pub fn get_arc<T: Message>(&self, topic: &Topic<T>) -> Option<Arc<T>> {
        if *self.topic == *topic.name() {
            self.payload.clone().downcast::<T>().ok()
        } else {
            None
        }
    }

    /// Name of the topic the message came on.
    #[must_use]
    pub fn topic(&self) -> &str {
        &self.topic
    }

    /// When the message was published (sim or wall time of the run).
    #[must_use]
    pub fn published_at(&self) -> Time {
        self.published_at
    }
}

impl fmt::Debug for Received {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Received")
            .field("topic", &self.topic)
            .field("published_at", &self.published_at)
            .finish_non_exhaustive()
    }
}
