//! The link actor: the only actor that talks to other robots.
//!
//! This first version forwards the robot's odometry to every peer at a fixed rate
//! and publishes what peers send as [`PEER_ODOMETRY`]. Packets that do not decode,
//! come from another team, or whose envelope sender disagrees with the network's
//! sender are rejected with a reason and counted (as actor errors).

use std::sync::Arc;
use std::time::Duration;

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use troupe_comms::wire::{self, Envelope, Payload};

use crate::msgs::{ODOMETRY, Odometry, PEER_ODOMETRY, PeerOdometry};
use crate::runtime::{
    Actor, ActorError, ActorResult, Context, Destination, Event, LINK_RX, LINK_TX, LinkTx,
    QueuePolicy, Time, TimerId,
};

/// Link settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LinkConfig {
    /// Team id written in every envelope; packets of other teams are rejected.
    pub team: u32,
    /// How often odometry is sent to peers, Hz (thesis §8.2.3: 10 Hz).
    pub odometry_rate_hz: f64,
}

impl Default for LinkConfig {
    fn default() -> Self {
        LinkConfig {
            team: 0,
            odometry_rate_hz: 10.0,
        }
    }
}

const SEND: TimerId = TimerId(0);

/// See the [module docs](self).
pub struct LinkActor {
    config: LinkConfig,
    sequence: u64,
    latest: Option<Arc<Odometry>>,
    sent_stamp: Option<Time>,
}

impl LinkActor {
    /// A link actor with the given settings.
    #[must_use]
    pub fn new(config: LinkConfig) -> Self {
        LinkActor {
            config,
            sequence: 0,
            latest: None,
            sent_stamp: None,
        }
    }

    fn send_odometry(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        let Some(odometry) = self.latest.as_ref() else {
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
        let envelope = Envelope::new(
            self.config.team,
            ctx.robot().0,
            self.sequence,
            odometry.stamp.as_nanos(),
            payload,
        );
        let bytes =
            wire::encode(&envelope).map_err(|e| ActorError::with_source("encoding odometry", e))?;
        self.sequence += 1;
        self.sent_stamp = Some(odometry.stamp);
        ctx.publish(
            &LINK_TX,
            LinkTx {
                to: Destination::Broadcast,
                bytes: Arc::from(bytes),
            },
        );
        Ok(())
    }

    fn receive(
        &mut self,
        from: crate::runtime::RobotId,
        bytes: &[u8],
        ctx: &mut Context<'_>,
    ) -> ActorResult {
        let envelope = wire::decode(bytes)
            .map_err(|e| ActorError::with_source(format!("rejected a packet from {from}"), e))?;
        if envelope.team != self.config.team {
            return Err(ActorError::msg(format!(
                "rejected a packet from {from}: team {} is not ours ({})",
                envelope.team, self.config.team
            )));
        }
        if envelope.sender != from.0 {
            return Err(ActorError::msg(format!(
                "rejected a packet from {from}: envelope names robot{} as its sender",
                envelope.sender
            )));
        }
        match envelope.payload {
            Payload::Odometry(o) => {
                let [x, y, z, w] = o.orientation_xyzw;
                let pose = Isometry3::from_parts(
                    Translation3::from(Vector3::from(o.position_m)),
                    UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z)),
                );
                ctx.publish(
                    &PEER_ODOMETRY,
                    PeerOdometry {
                        robot: from,
                        odometry: Odometry {
                            stamp: Time::from_nanos(envelope.stamp_ns),
                            pose,
                            velocity_mps: Vector3::from(o.velocity_mps),
                        },
                        received_at: ctx.now(),
                    },
                );
            }
            Payload::Heartbeat(_) => {}
            // Keyframes, plans and grid change sets: not consumed yet.
            _ => {}
        }
        Ok(())
    }
}

impl Actor for LinkActor {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&ODOMETRY, QueuePolicy::LATEST);
        ctx.subscribe(&LINK_RX, QueuePolicy::fifo(1024));
        if self.config.odometry_rate_hz > 0.0 {
            ctx.set_timer(
                SEND,
                Duration::from_secs_f64(1.0 / self.config.odometry_rate_hz),
            );
        }
        Ok(())
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        match event {
            Event::Timer(_) => self.send_odometry(ctx),
            Event::Message(m) => {
                if let Some(odometry) = m.get_arc(&ODOMETRY) {
                    self.latest = Some(odometry);
                    Ok(())
                } else if let Some(rx) = m.get(&LINK_RX) {
                    self.receive(rx.from, &rx.bytes, ctx)
                } else {
                    Ok(())
                }
            }
        }
    }
}
