//! Shared topics in the core: registration (a lane each), local messages out,
//! peers' messages checked, decoded and counted per name.

use std::collections::BTreeMap;
use std::sync::Arc;

use troupe_comms::shaping::LaneId;
use troupe_comms::wire::{Class, Payload, UserMessage, valid_user_name};
use troupe_runtime::{ActorError, Received, RobotId, Time};

use super::super::journal::JournaledLane;
use super::super::rejections::Rejection;
use super::super::shared::{ShareFrom, ShareRequest, ShareTo, SharedCodec};
use super::super::status::{MAX_UNKNOWN_NAMES, OTHER_UNKNOWN_NAMES, SharedStats};
use super::{LinkCore, LinkOutput};

/// A shared topic as the link keeps it.
pub(super) struct SharedEntry {
    /// `None` while known only from the journal (not yet asked for again).
    pub(super) codec: Option<Arc<dyn SharedCodec>>,
    pub(super) class: Class,
    pub(super) lane: Option<LaneId>,
    pub(super) to: ShareTo,
    pub(super) stats: SharedStats,
}

impl LinkCore {
    /// An actor asked to share a topic ([`SharedTopic::share`](super::super::SharedTopic::share)):
    /// the topic gets its lane (the declared policy with the robot file's
    /// overrides, or the lane the journal kept) and the link subscribes to it.
    pub(super) fn register(&mut self, request: &ShareRequest) -> Result<(), ActorError> {
        let codec = request.0.clone();
        let name = codec.name().to_owned();
        if !valid_user_name(&name) {
            return Err(ActorError::msg(format!(
                "cannot share topic {name:?}: a name is 1 to 64 ASCII letters, digits and / _ - ."
            )));
        }
        let (class, lane_config, to) = self
            .config
            .shared
            .get(&name)
            .copied()
            .unwrap_or_default()
            .apply(codec.policy());
        let class = Class::from(class);
        let entry = self
            .shared
            .entry(name.clone())
            .or_insert_with(|| SharedEntry {
                codec: None,
                class,
                lane: None,
                to,
                stats: SharedStats::default(),
            });
        if let Some(known) = &entry.codec
            && known.version() != codec.version()
        {
            tracing::warn!(
                robot = self.identity.name.as_str(),
                topic = name,
                "shared topic asked for again with version {} (was {}); the new one counts",
                codec.version(),
                known.version()
            );
        }
        if entry.lane.is_none() {
            let lane = self
                .shaper
                .add_lane(class, lane_config)
                .map_err(|e| ActorError::with_source(format!("cannot share topic {name}"), e))?;
            entry.lane = Some(lane);
            entry.class = class;
            self.lanes.push(JournaledLane {
                name: name.clone(),
                class,
                config: lane_config,
                request: None,
            });
        }
        if let Some(journaled) = self.lanes.iter_mut().find(|l| l.name == name) {
            journaled.request = Some(request.clone());
            self.lanes_changed = true;
        }
        entry.stats.registered = true;
        entry.stats.class = Some(entry.class);
        entry.stats.version = codec.version();
        entry.codec = Some(codec);
        self.outbox.push(LinkOutput::Subscribe(request.clone()));
        tracing::debug!(
            robot = self.identity.name.as_str(),
            topic = name,
            "sharing a topic"
        );
        Ok(())
    }

    /// A local message on a shared topic goes out in its lane; `None` when the
    /// message is not on a shared topic.
    pub(super) fn send_shared(&mut self, received: &Received) -> Option<Result<(), ActorError>> {
        let entry = self.shared.get_mut(received.topic())?;
        let codec = entry.codec.as_ref()?;
        let body = match codec.encode(received)? {
            Ok(body) => body,
            Err(e) => {
                entry.stats.unencodable += 1;
                return Some(Err(ActorError::with_source(
                    format!("cannot serialise a message of {}", received.topic()),
                    e,
                )));
            }
        };
        let to = match entry.to {
            ShareTo::Peers => None,
            ShareTo::Robot(r) => Some(r),
        };
        let payload = Payload::User(UserMessage {
            class: entry.class,
            name: received.topic().to_owned(),
            version: codec.version(),
            to,
            body,
        });
        let lane = entry.lane.map(|l| (l, to));
        Some(self.send_in(payload, received.published_at(), lane))
    }

    /// A peer's message on a shared topic: checked against this robot's
    /// registration, decoded and published as `Peer<T>`, or counted and dropped.
    pub(super) fn receive_shared(
        &mut self,
        from: RobotId,
        stamp: Time,
        message: &UserMessage,
    ) -> Result<(), ActorError> {
        let me = self.identity.robot.0;
        let now = self.now;
        let name = if self.shared.contains_key(&message.name)
            || self.shared.len() < MAX_UNKNOWN_NAMES + self.lanes.len()
        {
            message.name.as_str()
        } else {
            OTHER_UNKNOWN_NAMES
        };
        let entry = self
            .shared
            .entry(name.to_owned())
            .or_insert_with(|| SharedEntry {
                codec: None,
                class: message.class,
                lane: None,
                to: ShareTo::Peers,
                stats: SharedStats::default(),
            });
        let stats = &mut entry.stats;
        let Some(codec) = &entry.codec else {
            stats.unknown_name += 1;
            return Ok(());
        };
        if message.to.is_some_and(|to| to != me) {
            stats.not_addressed += 1;
            return Ok(());
        }
        if codec.policy().from == ShareFrom::Base && self.config.base_id != Some(from.0) {
            self.reject(
                Rejection::NotFromBase,
                from,
                format_args!("{} may come from the base station only", message.name),
            );
            return Ok(());
        }
        if message.version != codec.version() {
            if message.version < codec.version() {
                stats.older_version += 1;
            } else {
                stats.newer_version += 1;
            }
            return Err(ActorError::msg(format!(
                "rejected {} from {from}: version {}, this robot speaks {}",
                message.name,
                message.version,
                codec.version()
            )));
        }
        match codec.decode(from, stamp, now, &message.body) {
            Ok(delivery) => {
                stats.received += 1;
                self.outbox.push(LinkOutput::PeerShared(delivery));
                Ok(())
            }
            Err(e) => {
                stats.undecodable += 1;
                Err(ActorError::with_source(
                    format!("rejected {} from {from}", message.name),
                    e,
                ))
            }
        }
    }

    /// Per shared topic counters, with each lane's current stats.
    pub(super) fn shared_stats(&self) -> BTreeMap<String, SharedStats> {
        self.shared
            .iter()
            .map(|(name, entry)| {
                let mut stats = entry.stats.clone();
                if let Some(lane) = entry.lane.and_then(|l| self.shaper.lane_stats(l)) {
                    stats.sent = *lane;
                }
                (name.clone(), stats)
            })
            .collect()
    }
}
