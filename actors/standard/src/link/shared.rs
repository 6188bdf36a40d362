//! Shared topics: a custom actor's robot-local topic that the link carries to the
//! team, typed at both ends.
//!
//! A [`SharedTopic<T>`] names a topic, the schema version of `T` and a default
//! [`SharePolicy`] (class, queue policy, addressee). An actor calls
//! [`SharedTopic::share`] in its `start`; from then on the link sends every
//! message published on [`SharedTopic::topic`] as a
//! [`UserMessage`](troupe_comms::wire::UserMessage) in a shaper lane of its own
//! ([`LinkShaper::add_lane`](troupe_comms::shaping::LinkShaper::add_lane)): the
//! class's priority, the policy's keep-latest / drop-oldest / store-and-forward
//! behaviour, fragmentation, acknowledgements and counters, like the built-in
//! payloads. On the receiving robots (those that shared the same topic) the link
//! publishes each message on [`SharedTopic::peer_topic`] as a [`Peer<T>`] that
//! says who sent it and when. A robot file overrides the policy per name
//! (`[link.shared."artifacts/report"]`, see
//! [`SharedConfig`](super::SharedConfig)).
//!
//! ```
//! use serde::{Deserialize, Serialize};
//! use troupe_actors::link::{SharePolicy, SharedTopic};
//! use troupe_runtime::Message;
//!
//! #[derive(Clone, Debug, Serialize, Deserialize)]
//! struct GasReading { ppm: f32, position_m: [f32; 3] }
//! impl Message for GasReading {}
//!
//! const GAS: SharedTopic<GasReading> =
//!     SharedTopic::new("gas/reading", 1, SharePolicy::store_and_forward_in_plan_class());
//! assert_eq!(GAS.topic().name(), "gas/reading");
//! assert_eq!(GAS.peer_topic().name(), "peer/gas/reading");
//! ```
//!
//! Positions inside `T` are the link's business no more than any other field:
//! they arrive in the sender's world frame (use the peer's `PeerFrame` when the
//! frames differ).

use std::marker::PhantomData;
use std::sync::Arc;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use troupe_comms::shaping::QueuePolicy as ShaperPolicy;
use troupe_comms::wire::Class;
use troupe_runtime::{Context, Message, QueuePolicy, Received, RobotId, Time, Topic};

/// Who receives a shared topic's messages.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ShareTo {
    /// Every peer the link knows (robots and the base station).
    Peers,
    /// One robot (or the base station) by index: its frames are addressed to it,
    /// a store-and-forward lane waits for its acknowledgement only, and other
    /// receivers drop the message (counted as `not_addressed`).
    Robot(u32),
}

/// Whom the receivers accept a shared topic's messages from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ShareFrom {
    /// Any member of the team roster.
    Peers,
    /// The base station only ([`LinkConfig::base_id`](super::LinkConfig::base_id)):
    /// a message from any other id is dropped and counted
    /// ([`Rejection::NotFromBase`](super::Rejection::NotFromBase)). Operator
    /// commands travel so (issue 17).
    Base,
}

/// Traffic class of a shared topic, by the names a robot file uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ShareClass {
    /// With odometry (highest priority).
    Odometry,
    /// With plans.
    Plan,
    /// With keyframes and grid change sets.
    Keyframe,
    /// Lowest priority.
    Bulk,
}

impl From<ShareClass> for Class {
    fn from(c: ShareClass) -> Class {
        match c {
            ShareClass::Odometry => Class::Odometry,
            ShareClass::Plan => Class::Plan,
            ShareClass::Keyframe => Class::Keyframe,
            ShareClass::Bulk => Class::Bulk,
        }
    }
}

/// How a shared topic travels: its priority class, its lane's queue policy, its
/// addressee, and whom receivers accept it from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SharePolicy {
    /// Priority class (the lane goes after the class's own queue).
    pub class: ShareClass,
    /// Keep-latest, drop-oldest or store-and-forward (with the default
    /// capacities of `troupe_comms::shaping::ClassConfig`).
    pub policy: ShaperPolicy,
    /// Every peer, or one.
    pub to: ShareTo,
    /// Any team member, or the base station only.
    pub from: ShareFrom,
}

impl SharePolicy {
    /// Reports that must not be lost: store-and-forward, at plan priority (ahead
    /// of keyframes), to every peer.
    #[must_use]
    pub const fn store_and_forward_in_plan_class() -> Self {
        SharePolicy {
            class: ShareClass::Plan,
            policy: ShaperPolicy::StoreAndForward,
            to: ShareTo::Peers,
            from: ShareFrom::Peers,
        }
    }
}

/// A message of a shared topic as received from a peer.
#[derive(Clone, Debug, PartialEq)]
pub struct Peer<T> {
    /// Who sent it.
    pub robot: RobotId,
    /// When it was sent, on the sender's clock.
    pub sent_at: Time,
    /// When this robot's link received it.
    pub received_at: Time,
    /// The message.
    pub message: T,
}
impl<T: Message> Message for Peer<T> {}

/// A robot-local topic of type `T` that the link shares with the team (see the
/// [module docs](crate::link)).
pub struct SharedTopic<T> {
    name: &'static str,
    version: u16,
    policy: SharePolicy,
    _message: PhantomData<fn() -> T>,
}

impl<T> Clone for SharedTopic<T> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<T> Copy for SharedTopic<T> {}

impl<T: Message + Serialize + DeserializeOwned> SharedTopic<T> {
    /// A shared topic: its name (1–64 ASCII letters, digits and `/ _ - .`; the
    /// link refuses others), the schema version of `T` (bump it when `T`'s
    /// serialised form changes: receivers accept only their own version), and the
    /// default policy (a robot file may override it by name).
    #[must_use]
    pub const fn new(name: &'static str, version: u16, policy: SharePolicy) -> Self {
        SharedTopic {
            name,
            version,
            policy,
            _message: PhantomData,
        }
    }

    /// The name, on the wire and in the counters.
    #[must_use]
    pub const fn name(&self) -> &'static str {
        self.name
    }

    /// Where this robot publishes what it shares.
    #[must_use]
    pub const fn topic(&self) -> Topic<T> {
        Topic::new(self.name)
    }

    /// Where the link publishes what peers shared: `peer/<name>`.
    #[must_use]
    pub fn peer_topic(&self) -> Topic<Peer<T>> {
        Topic::named(format!("peer/{}", self.name))
    }

    /// The registration [`share`](Self::share) sends.
    #[must_use]
    pub fn request(&self) -> ShareRequest {
        ShareRequest(Arc::new(*self))
    }

    /// Asks this robot's link to share the topic (call it from the actor's
    /// `start`; calling it again, e.g. after a restart, changes nothing).
    pub fn share(&self, ctx: &mut Context<'_>) {
        ctx.publish(&SHARE_REQUESTS, self.request());
    }
}

/// A registration for the link: a shared topic with its types erased.
#[derive(Clone)]
pub struct ShareRequest(pub(crate) Arc<dyn SharedCodec>);
impl Message for ShareRequest {}

impl std::fmt::Debug for ShareRequest {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "ShareRequest({} v{})", self.0.name(), self.0.version())
    }
}

/// Where actors ask the link to share their topics ([`SharedTopic::share`]).
pub const SHARE_REQUESTS: Topic<ShareRequest> = Topic::new("link/share");

/// What the link needs to know of a shared topic without knowing its type.
pub(crate) trait SharedCodec: Send + Sync {
    fn name(&self) -> &str;
    fn version(&self) -> u16;
    fn policy(&self) -> SharePolicy;
    /// Subscribes the link to the local topic.
    fn subscribe(&self, ctx: &mut Context<'_>);
    /// The message's bytes if it came on the local topic.
    fn encode(&self, received: &Received) -> Option<Result<Vec<u8>, postcard::Error>>;
    /// Decodes a peer's bytes into what the link publishes on the peer topic.
    fn decode(
        &self,
        from: RobotId,
        sent_at: Time,
        received_at: Time,
        body: &[u8],
    ) -> Result<SharedDelivery, postcard::Error>;
}

/// A peer's message on a shared topic, decoded by the
/// [`LinkCore`](super::LinkCore): what the link publishes as a [`Peer<T>`] on the
/// topic's [`peer_topic`](SharedTopic::peer_topic).
pub struct SharedDelivery(Box<dyn PeerMessage>);

impl SharedDelivery {
    /// The shared topic's name.
    #[must_use]
    pub fn name(&self) -> &str {
        self.0.name()
    }

    /// The message as its type, if it is a `Peer<T>`.
    #[must_use]
    pub fn message<T: Message>(&self) -> Option<&Peer<T>> {
        self.0.as_any().downcast_ref()
    }

    /// Publishes the message on its peer topic.
    pub fn publish(self, ctx: &mut Context<'_>) {
        self.0.publish(ctx);
    }
}

impl std::fmt::Debug for SharedDelivery {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "SharedDelivery({})", self.0.name())
    }
}

/// A decoded `Peer<T>` with its topic, types erased.
trait PeerMessage: Send {
    fn name(&self) -> &str;
    fn as_any(&self) -> &dyn std::any::Any;
    fn publish(self: Box<Self>, ctx: &mut Context<'_>);
}

impl<T: Message + Serialize + DeserializeOwned> PeerMessage for (SharedTopic<T>, Peer<T>) {
    fn name(&self) -> &str {
        self.0.name
    }
    fn as_any(&self) -> &dyn std::any::Any {
        &self.1
    }
    fn publish(self: Box<Self>, ctx: &mut Context<'_>) {
        let (topic, peer) = *self;
        ctx.publish(&topic.peer_topic(), peer);
    }
}

impl<T: Message + Serialize + DeserializeOwned> SharedCodec for SharedTopic<T> {
    fn name(&self) -> &str {
        self.name
    }
    fn version(&self) -> u16 {
        self.version
    }
    fn policy(&self) -> SharePolicy {
        self.policy
    }
    fn subscribe(&self, ctx: &mut Context<'_>) {
        ctx.subscribe(&self.topic(), QueuePolicy::fifo(256));
    }
    fn encode(&self, received: &Received) -> Option<Result<Vec<u8>, postcard::Error>> {
        received.get(&self.topic()).map(postcard::to_allocvec)
    }
    fn decode(
        &self,
        from: RobotId,
        sent_at: Time,
        received_at: Time,
        body: &[u8],
    ) -> Result<SharedDelivery, postcard::Error> {
        let (message, rest) = postcard::take_from_bytes::<T>(body)?;
        if !rest.is_empty() {
            return Err(postcard::Error::DeserializeBadEncoding);
        }
        let peer = Peer {
            robot: from,
            sent_at,
            received_at,
            message,
        };
        Ok(SharedDelivery(Box::new((*self, peer))))
    }
}
