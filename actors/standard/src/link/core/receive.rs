//! Incoming: frames from the network checked, reassembled, opened and delivered;
//! the roster of store-and-forward recipients and their silence; rejections.

use std::time::Duration;

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use troupe_algorithms::frame::Odometry;
use troupe_algorithms::team::{PeerKeyframe, PeerOdometry, PeerPlan};
use troupe_comms::shaping::{AckOutcome, Incoming, MessageId};
use troupe_comms::wire::{self, Class, Envelope, Payload};
use troupe_runtime::{ActorError, ErrorChain, RobotId};

use super::super::convert::{keyframe_from_wire, plan_from_wire};
use super::super::frames::{PeerFrame, transform_keyframe, transform_plan};
use super::super::rejections::Rejection;
use super::super::replay::{ReplayWindow, Verdict};
use super::{LinkCore, LinkOutput};
use crate::msgs::PeerGridChanges;

/// A rejected envelope: the reason counted and the error logged.
type Rejected = (Rejection, ActorError);

impl LinkCore {
    /// The transform from a peer's world frame into ours, if it differs.
    fn frame_of(&self, peer: RobotId) -> Option<Isometry3<f64>> {
        self.config
            .peer_frames
            .iter()
            .find(|f| f.robot == peer.0)
            .map(PeerFrame::transform)
    }

    /// A peer proved it is a team member (a valid message or an ack): it becomes a
    /// recipient of store-and-forward messages (with the stored backlog) and its
    /// silence clock restarts.
    fn heard(&mut self, peer: RobotId) {
        let silent = !self.last_heard.contains_key(&peer.0);
        self.last_heard.insert(peer.0, self.now);
        let suspended = silent && self.shaper.suspended_peers().contains(&peer.0);
        if self.shaper.add_peer(peer.0) {
            if suspended {
                tracing::info!(
                    robot = self.robot_name(),
                    %peer,
                    "store-and-forward peer heard again: it rejoins and gets what it missed"
                );
            } else {
                tracing::debug!(robot = self.robot_name(), %peer, "store-and-forward peer added");
            }
            self.pump();
        }
    }

    /// Suspends peers silent for longer than `peer_timeout_s`: nothing more is sent
    /// to them and they no longer hold back the others; what they miss is kept for
    /// them (within their own bounds) until they are heard again.
    pub(super) fn expire_peers(&mut self) {
        if self.config.peer_timeout_s <= 0.0 {
            return;
        }
        let timeout = Duration::from_secs_f64(self.config.peer_timeout_s);
        let now = self.now;
        let silent: Vec<u32> = self
            .last_heard
            .iter()
            .filter(|(_, at)| now.saturating_since(**at) > timeout)
            .map(|(p, _)| *p)
            .collect();
        for peer in silent {
            self.last_heard.remove(&peer);
            if self.shaper.suspend_peer(peer) {
                self.peer_timeouts += 1;
                self.log_suspended(peer);
            }
        }
        self.pump();
    }

    /// Says that `peer` was suspended for its silence.
    fn log_suspended(&self, peer: u32) {
        let (pending, pending_bytes) = self.shaper.pending_for(Class::Keyframe, peer);
        if self.config.base_id == Some(peer) {
            // A team may fly without its base (or before it starts): one line per
            // silence, not a warning.
            tracing::info!(
                robot = self.robot_name(),
                base = peer,
                pending,
                pending_bytes,
                "base station not heard for {} s: what it misses is kept for it and sent \
                 when it is heard",
                self.config.peer_timeout_s
            );
        } else {
            tracing::warn!(
                robot = self.robot_name(),
                peer,
                pending,
                pending_bytes,
                "peer silent for more than {} s: suspended as a store-and-forward recipient \
                 until heard again",
                self.config.peer_timeout_s
            );
        }
    }

    /// Counts a rejection and logs it, at most one line per reason per second
    /// (with the count since the last line).
    pub(super) fn reject(
        &mut self,
        reason: Rejection,
        from: RobotId,
        detail: impl std::fmt::Display,
    ) {
        self.rejections.count(reason);
        if let Some(count) = self.rejection_log.note(reason, self.now) {
            tracing::warn!(
                robot = self.robot_name(),
                reason = reason.name(),
                count,
                "link rejected {count} since the last line; latest from {from}: {detail}"
            );
        }
    }

    /// Logs the rejections held back by the rate limit (on the status tick).
    pub(super) fn flush_rejection_log(&mut self) {
        for (reason, count) in self.rejection_log.flush(self.now) {
            tracing::warn!(
                robot = self.robot_name(),
                reason = reason.name(),
                count,
                "link rejected {count} since the last line"
            );
        }
    }

    /// Whether `from` may talk to us: in the roster and not our own id. Nothing of
    /// a frame that fails is kept (no reassembly, no recipient, no silence clock).
    fn admits(&mut self, from: RobotId) -> bool {
        if from == self.identity.robot {
            self.reject(Rejection::OwnId, from, "a frame claims this robot's id");
            false
        } else if !self.roster.is_empty() && !self.roster.contains(&from.0) {
            self.reject(Rejection::NotInRoster, from, "not in the team roster");
            false
        } else {
            true
        }
    }

    pub(super) fn receive_frame(&mut self, from: RobotId, bytes: &[u8]) -> Result<(), ActorError> {
        if !self.admits(from) {
            return Ok(());
        }
        let now = self.now.as_nanos();
        let incoming = match self.reassembler.push(now, from.0, bytes) {
            Ok(incoming) => incoming,
            Err(e) => {
                self.reject(Rejection::MalformedFrame, from, ErrorChain(&e));
                return Ok(());
            }
        };
        match incoming {
            None => Ok(()),
            Some(Incoming::Message(message)) => {
                let opened = self
                    .open_envelope(from, &message.bytes)
                    .and_then(|envelope| self.not_ahead(from, envelope))
                    .and_then(|envelope| self.in_role(from, envelope))
                    .and_then(|envelope| self.fresh(from, envelope));
                let envelope = match opened {
                    Ok(envelope) => envelope,
                    Err((reason, e)) => {
                        // Not a valid envelope of our team from this sender: it proves
                        // nothing, so it is neither acknowledged nor remembered as
                        // received (junk carrying a peer's next message ids must not
                        // make us drop that peer's real messages as repeats, nor
                        // acknowledge them in its name).
                        self.reassembler.forget(from.0, message.message_id);
                        self.rejected += 1;
                        self.reject(reason, from, ErrorChain(&e));
                        return Ok(());
                    }
                };
                // A valid envelope is acknowledged even when its payload is unusable
                // (a retransmission would not make it usable); on disk, only once
                // it is journaled (an ack promises the message survives a crash).
                if message.ack_requested {
                    if let Err(e) =
                        self.journal
                            .record_received(from.0, message.message_id, &message.bytes)
                    {
                        self.reassembler.forget(from.0, message.message_id);
                        return Err(ActorError::with_source("writing the link journal", e));
                    }
                    self.shaper.queue_ack(from.0, message.message_id);
                    self.pump();
                }
                if let Err(e) = self.deliver(from, envelope) {
                    self.rejected += 1;
                    self.reject(Rejection::InvalidPayload, from, ErrorChain(&e));
                }
                self.heard(from);
                Ok(())
            }
            Some(Incoming::Duplicate {
                message_id,
                ack_requested,
                ..
            }) => {
                if ack_requested {
                    self.shaper.queue_ack(from.0, message_id);
                    self.pump();
                }
                Ok(())
            }
            Some(Incoming::Ack { ids, .. }) => {
                // Acks are addressed to us; each releases our stored message for
                // that peer only (the store keeps it until every peer has it).
                self.heard(from);
                for id in ids {
                    if self.shaper.acknowledge(now, from.0, MessageId(id)) == AckOutcome::NotSent {
                        self.reject(
                            Rejection::UnheldAck,
                            from,
                            format_args!("acknowledges message {id}, not yet sent to it"),
                        );
                    }
                }
                self.pump();
                Ok(())
            }
        }
    }

    /// Publishes again what the journal received before the process restarted
    /// (the team map of a restarted robot is whole again).
    pub(super) fn replay_received(&mut self) {
        let replay = std::mem::take(&mut self.replay);
        let count = replay.len();
        for m in replay {
            let from = RobotId(m.source);
            let result = self
                .open_envelope(from, &m.bytes)
                .map_err(|(_, e)| e)
                .and_then(|envelope| self.deliver(from, envelope));
            if let Err(e) = result {
                tracing::debug!(
                    robot = self.robot_name(),
                    "journaled message not replayed: {}",
                    ErrorChain(&e)
                );
            }
        }
        tracing::info!(
            robot = self.robot_name(),
            count,
            "replayed the messages received before the restart"
        );
    }

    /// Decodes a reassembled message and checks its team and sender.
    fn open_envelope(&self, from: RobotId, bytes: &[u8]) -> Result<Envelope, Rejected> {
        let envelope = wire::decode(bytes).map_err(|e| {
            (
                Rejection::Undecodable,
                ActorError::with_source(format!("rejected a message from {from}"), e),
            )
        })?;
        if envelope.team != self.config.team {
            return Err((
                Rejection::WrongTeam,
                ActorError::msg(format!(
                    "rejected a message from {from}: team {} is not ours ({})",
                    envelope.team, self.config.team
                )),
            ));
        }
        if envelope.sender != from.0 {
            return Err((
                Rejection::WrongSender,
                ActorError::msg(format!(
                    "rejected a message from {from}: envelope names robot{} as its sender",
                    envelope.sender
                )),
            ));
        }
        Ok(envelope)
    }

    /// Passes an envelope its sender's role may send: the base station sends no
    /// odometry, plans, keyframes or grid changes (its certificate may publish under
    /// its own id only, so this is what keeps it from acting as a robot).
    fn in_role(&self, from: RobotId, envelope: Envelope) -> Result<Envelope, Rejected> {
        let robot_payload = matches!(
            envelope.payload,
            Payload::Odometry(_)
                | Payload::Plan(_)
                | Payload::Keyframe(_)
                | Payload::GridChanges(_)
        );
        if robot_payload && self.config.base_id == Some(from.0) {
            return Err((
                Rejection::BaseAsRobot,
                ActorError::msg(format!(
                    "rejected a robot's message ({:?}) from the base station's id {from}",
                    envelope.payload.class()
                )),
            ));
        }
        Ok(envelope)
    }

    /// Passes an envelope whose sequence number its sender's run has not used
    /// before ([`ReplayWindow`]); the last check, so that only a message otherwise
    /// accepted takes its number.
    fn fresh(&mut self, from: RobotId, envelope: Envelope) -> Result<Envelope, Rejected> {
        let (run, sequence) = (envelope.run_start_ns, envelope.sequence);
        let verdict = match self.replay_windows.get_mut(&from.0) {
            Some(window) => window.check(run, sequence),
            None => {
                self.replay_windows
                    .insert(from.0, ReplayWindow::new(run, sequence));
                Verdict::Fresh
            }
        };
        if verdict == Verdict::Replayed {
            return Err((
                Rejection::Replayed,
                ActorError::msg(format!(
                    "rejected a message from {from}: its sequence number {sequence} was \
                     used before (a replay under a fresh message id)"
                )),
            ));
        }
        Ok(envelope)
    }

    /// Passes an envelope made no later than `max_clock_ahead_s` from now on the team
    /// clock. (Messages replayed from the journal were checked when they arrived.)
    fn not_ahead(&self, from: RobotId, envelope: Envelope) -> Result<Envelope, Rejected> {
        let now_ns = self.identity.clock.to_team_ns(self.now);
        let ahead_s = envelope.stamp_ns.saturating_sub(now_ns) as f64 * 1e-9;
        if ahead_s > self.config.max_clock_ahead_s {
            return Err((
                Rejection::FromTheFuture,
                ActorError::msg(format!(
                    "rejected a message from {from}: stamped {ahead_s:.3} s ahead of this \
                     robot's clock (at most {} s; are the hosts' clocks synchronised?)",
                    self.config.max_clock_ahead_s
                )),
            ));
        }
        Ok(envelope)
    }

    /// Keeps the latest run heard of each peer and says once when a peer restarted
    /// (a message of a later run than before).
    fn note_run(&mut self, from: RobotId, run_start_ns: u64) {
        let known = self.peer_runs.entry(from.0).or_insert(run_start_ns);
        if run_start_ns > *known {
            let earlier = *known;
            *known = run_start_ns;
            tracing::info!(
                robot = self.identity.name.as_str(),
                peer = %from,
                "{from} restarted ({:.3} s after its previous start): what it said before no \
                 longer holds",
                (run_start_ns - earlier) as f64 * 1e-9
            );
        }
    }

    /// Publishes a checked envelope's payload on the peer topics; an invalid
    /// payload is an error.
    fn deliver(&mut self, from: RobotId, envelope: Envelope) -> Result<(), ActorError> {
        let clock = self.identity.clock;
        let stamp = clock.from_team_ns(envelope.stamp_ns);
        let run_start_ns = envelope.run_start_ns;
        let received_at = self.now;
        self.note_run(from, run_start_ns);
        let frame = self.frame_of(from);
        let output = match envelope.payload {
            Payload::User(message) => return self.receive_shared(from, stamp, &message),
            Payload::Keyframe(keyframe) => {
                let context = || format!("rejected a keyframe from {from}");
                let mut keyframe = keyframe_from_wire(&keyframe, stamp)
                    .map_err(|e| ActorError::with_source(context(), e))?;
                if let Some(t) = frame {
                    keyframe = transform_keyframe(&keyframe, &t)
                        .map_err(|e| ActorError::with_source(context(), e))?;
                }
                LinkOutput::PeerKeyframe(PeerKeyframe {
                    robot: from,
                    keyframe,
                    made_ns: envelope.stamp_ns,
                    received_at,
                })
            }
            Payload::Plan(p) => {
                let reject = |e| ActorError::with_source(format!("rejected a plan from {from}"), e);
                let mut plan = plan_from_wire(&p, stamp, clock)?;
                if let Some(t) = frame {
                    plan = transform_plan(&plan, &t).map_err(reject)?;
                }
                LinkOutput::PeerPlan(PeerPlan {
                    robot: from,
                    priority: p.priority,
                    plan,
                    run_start_ns,
                    received_at,
                })
            }
            Payload::GridChanges(set) => LinkOutput::PeerGridChanges(PeerGridChanges {
                robot: from,
                set,
                frame,
                received_at,
            }),
            Payload::Odometry(o) => {
                let [x, y, z, w] = o.orientation_xyzw;
                let pose = Isometry3::from_parts(
                    Translation3::from(Vector3::from(o.position_m)),
                    UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z)),
                );
                let velocity = Vector3::from(o.velocity_mps);
                LinkOutput::PeerOdometry(PeerOdometry {
                    robot: from,
                    odometry: Odometry {
                        stamp,
                        pose: frame.map_or(pose, |t| t * pose),
                        velocity_mps: frame.map_or(velocity, |t| t.rotation * velocity),
                    },
                    run_start_ns,
                    received_at,
                })
            }
            // Heartbeats only prove liveness.
            _ => return Ok(()),
        };
        self.outbox.push(output);
        Ok(())
    }
}
