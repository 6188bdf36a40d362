//! Outgoing: this robot's messages into the shaper, and the shaper's frames out
//! as the token bucket allows.

use std::sync::Arc;
use std::time::Duration;

use troupe_algorithms::keyframe::Keyframe;
use troupe_comms::shaping::LaneId;
use troupe_comms::wire::{self, Envelope, Payload};
use troupe_runtime::{ActorError, Destination, LinkTx, RobotId, Time};

use super::super::config::KeyframeEncoding;
use super::super::convert::{keyframe_to_wire, plan_to_wire};
use super::{HEARTBEAT_AFTER, LinkCore, LinkOutput, LinkTimer};
use crate::msgs::GridChanges;

impl LinkCore {
    /// Encodes and offers one payload to the shaper (its class's queue).
    pub(super) fn send(&mut self, payload: Payload, stamp: Time) -> Result<(), ActorError> {
        self.send_in(payload, stamp, None)
    }

    /// Encodes and offers one payload to its class's queue or to a shared
    /// topic's lane (with its addressee).
    pub(super) fn send_in(
        &mut self,
        payload: Payload,
        stamp: Time,
        lane: Option<(LaneId, Option<u32>)>,
    ) -> Result<(), ActorError> {
        let class = payload.class();
        let clock = self.identity.clock;
        let envelope = Envelope::new(
            self.config.team,
            self.identity.robot.0,
            self.sequence,
            clock.to_team_ns(stamp),
            payload,
        )
        .from_run(clock.origin_ns());
        let bytes = wire::encode(&envelope)
            .map_err(|e| ActorError::with_source("encoding a message", e))?;
        self.sequence += 1;
        self.last_offered = Some(self.now);
        let now = self.now.as_nanos();
        let offered = match lane {
            None => self.shaper.offer(now, class, bytes),
            Some((lane, to)) => self.shaper.offer_to_lane(now, lane, to, bytes),
        };
        if let Err(refused) = offered {
            tracing::debug!(
                robot = self.robot_name(),
                ?class,
                "link refused a message: {refused}"
            );
        }
        self.pump();
        Ok(())
    }

    /// Sends every frame the bucket allows now and arms the pump for the next one.
    pub(super) fn pump(&mut self) {
        let now = self.now.as_nanos();
        while let Some(frame) = self.shaper.poll(now) {
            self.outbox.push(LinkOutput::Transmit(LinkTx {
                to: frame
                    .to
                    .map_or(Destination::Broadcast, |p| Destination::Robot(RobotId(p))),
                bytes: Arc::from(frame.bytes),
            }));
        }
        self.outbox.push(match self.shaper.next_send_time(now) {
            Some(next) => LinkOutput::SetTimer(
                LinkTimer::Pump,
                Duration::from_nanos(next.saturating_sub(now).max(1)),
            ),
            None => LinkOutput::CancelTimer(LinkTimer::Pump),
        });
    }

    pub(super) fn send_odometry(&mut self) -> Result<(), ActorError> {
        let Some(odometry) = self.latest.clone() else {
            return Ok(());
        };
        if self.sent_stamp == Some(odometry.stamp) {
            return Ok(());
        }
        let q = odometry.pose.rotation.quaternion();
        let payload = Payload::Odometry(wire::Odometry {
            position_m: odometry.pose.translation.vector.into(),
            orientation_xyzw: [q.i, q.j, q.k, q.w],
            velocity_mps: odometry.velocity_mps.into(),
        });
        self.sent_stamp = Some(odometry.stamp);
        self.send(payload, odometry.stamp)
    }

    /// Sends a keyframe, compacted when so configured.
    pub(super) fn send_keyframe(&mut self, keyframe: &Keyframe) -> Result<(), ActorError> {
        let mut wire = keyframe_to_wire(keyframe);
        if self.config.keyframe_encoding == KeyframeEncoding::Compact {
            match wire.mixture.compact() {
                Ok(compact) => wire.mixture = compact,
                Err(e) => tracing::debug!(
                    robot = self.robot_name(),
                    "keyframe {} goes exact: {e}",
                    keyframe.id
                ),
            }
        }
        self.send(Payload::Keyframe(wire), keyframe.stamp)
    }

    /// Sends a grid change set.
    pub(super) fn send_grid_changes(&mut self, changes: &GridChanges) -> Result<(), ActorError> {
        self.send(Payload::GridChanges(changes.set.clone()), changes.stamp)
    }

    /// Sends a heartbeat when this link has offered nothing for [`HEARTBEAT_AFTER`]
    /// and has a team to tell.
    pub(super) fn send_heartbeat_if_idle(&mut self) -> Result<(), ActorError> {
        let now = self.now;
        let idle = self
            .last_offered
            .is_none_or(|at| now.saturating_since(at) >= HEARTBEAT_AFTER);
        if !idle || (self.roster.is_empty() && self.config.peers.is_empty()) {
            return Ok(());
        }
        let uptime_s = now.as_secs_f64();
        self.send(Payload::Heartbeat(wire::Heartbeat { uptime_s }), now)
    }

    /// Minimum time between two plans; `None` when plans are not shared.
    fn plan_period(&self) -> Option<Duration> {
        (self.config.plan_rate_hz > 0.0)
            .then(|| Duration::from_secs_f64(1.0 / self.config.plan_rate_hz))
    }

    /// Sends the latest unsent plan now if the rate allows, else arms the timer
    /// for when it will.
    pub(super) fn send_plan(&mut self) -> Result<(), ActorError> {
        let Some(period) = self.plan_period() else {
            self.unsent_plan = None;
            return Ok(());
        };
        if self.unsent_plan.is_none() {
            self.outbox.push(LinkOutput::CancelTimer(LinkTimer::Plan));
            return Ok(());
        }
        let now = self.now;
        if let Some(last) = self.plan_sent_at {
            let since = now.saturating_since(last);
            if since < period {
                self.outbox
                    .push(LinkOutput::SetTimer(LinkTimer::Plan, period - since));
                return Ok(());
            }
        }
        self.outbox.push(LinkOutput::CancelTimer(LinkTimer::Plan));
        let Some(plan) = self.unsent_plan.take() else {
            return Ok(());
        };
        let Some(wire_plan) = plan_to_wire(
            &plan,
            self.plans_sent,
            self.config.priority,
            self.identity.clock,
        ) else {
            return Ok(()); // an empty trajectory: nothing to share
        };
        self.plans_sent = self.plans_sent.wrapping_add(1);
        self.plan_sent_at = Some(now);
        self.send(Payload::Plan(wire_plan), plan.stamp)
    }
}
