//! A robot whose sensor is a recorded sequence instead of the simulated camera
//! (`sequence = "…"` in a `troupe robot` file): it replays what a real robot saw,
//! maps it and shares the map and its poses with the team as any robot would.
//!
//! The recording fixes where the robot was, so a replaying robot does not plan or
//! move: it keeps the sensor (playing the sequence's frames in order at the robot's
//! `sensor_rate_hz`, see [`SequenceSource`]), the mapper, the local grid (when the
//! behaviour has one, for occupancy-grid map sharing) and the link, and its odometry
//! is the recorded pose of the latest frame played ([`ReplayOdometry`]). Peers see its
//! keyframes, change sets and odometry; it sends no plans. When the sequence ends
//! the robot holds its last pose and keeps its link up, so that store-and-forward
//! messages still reach peers that join late.

use std::time::Duration;

use nalgebra::{Isometry3, Vector3};
use troupe_actors::link::LinkJournal;
use troupe_actors::msgs::{DEPTH_FRAME, ODOMETRY};
use troupe_algorithms::frame::Odometry;
use troupe_core::Time;
use troupe_robot::registry::Registry;
use troupe_robot::{AssembleError, RobotConfig, RobotParts, assemble};
use troupe_runtime::{
    Actor, ActorOptions, ActorResult, ActorSpec, Context, Event, LatencyModel, QueuePolicy,
    RobotSpec, TimerId,
};

use crate::sequence::{Sequence, SequenceSource};

/// The actors a replaying robot keeps from the standard robot (module docs); the
/// others move the robot (planner, explorer, teleop, collision, joystick).
pub const REPLAY_ACTORS: [&str; 5] = ["vehicle", "sensor", "mapper", "grid", "link"];

/// Stands in for the vehicle of a replaying robot: publishes the recorded body pose
/// of the latest played frame as odometry at a fixed rate (peers expect odometry at
/// 10 Hz, thesis §8.2.3, whatever the sensor rate), with the velocity between the
/// last two frames, and zero velocity once frames stop coming (the sequence ended).
#[derive(Debug)]
pub struct ReplayOdometry {
    period: Duration,
    /// The latest frame's stamp and pose, and the velocity that led to it.
    latest: Option<(Time, Isometry3<f64>, Vector3<f64>)>,
}

impl ReplayOdometry {
    /// Publishes odometry at `rate_hz` (> 0) once the first frame has played.
    #[must_use]
    pub fn new(rate_hz: f64) -> Self {
        ReplayOdometry {
            period: Duration::from_secs_f64(1.0 / rate_hz.max(1e-3)),
            latest: None,
        }
    }
}

/// Frames further apart than this mean the sequence has ended: the robot is still.
const STILL_AFTER_S: f64 = 1.0;

const PUBLISH: TimerId = TimerId(0);

impl Actor for ReplayOdometry {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&DEPTH_FRAME, QueuePolicy::LATEST);
        ctx.set_timer(PUBLISH, self.period);
        Ok(())
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        let now = ctx.now();
        match event {
            Event::Message(m) => {
                if let Some(frame) = m.get_arc(&DEPTH_FRAME) {
                    let velocity_mps = match self.latest {
                        Some((stamp, pose, _)) if now > stamp => {
                            (frame.pose.translation.vector - pose.translation.vector)
                                / (now.as_secs_f64() - stamp.as_secs_f64())
                        }
                        Some((_, _, velocity)) => velocity,
                        None => Vector3::zeros(),
                    };
                    self.latest = Some((now, frame.pose, velocity_mps));
                }
            }
            Event::Timer(_) => {
                if let Some((stamp, pose, velocity)) = self.latest {
                    let still = now.as_secs_f64() - stamp.as_secs_f64() > STILL_AFTER_S;
                    ctx.publish(
                        &ODOMETRY,
                        Odometry {
                            stamp: now,
                            pose,
                            velocity_mps: if still { Vector3::zeros() } else { velocity },
                        },
                    );
                }
            }
        }
        Ok(())
    }
}

/// Assembles robot `name` (at `index` in its team) with `config` around a recorded
/// sequence (module docs), publishing odometry at `odometry_rate_hz`, with the extra
/// actors `config` names from `registry` (`[[robot.actors]]`; they are offered no
/// environment: there is no simulated world). A restarted sensor plays the sequence
/// from its first frame again.
pub fn replaying_robot(
    name: &str,
    index: usize,
    config: &RobotConfig,
    sequence: Sequence,
    odometry_rate_hz: f64,
    link_journal: LinkJournal,
    registry: &Registry,
) -> Result<RobotSpec, AssembleError> {
    let camera = sequence.camera().intrinsics();
    let parts = RobotParts {
        frame_source: Box::new(move || Box::new(SequenceSource::new(sequence.clone()))),
        vehicle: ActorSpec::new("vehicle", move || ReplayOdometry::new(odometry_rate_hz))
            .with_options(ActorOptions {
                latency: LatencyModel::fixed(config.latency_s.vehicle),
                restart: config.restart,
                blocking: false,
            }),
        route: Vec::new(),
        depart_at_s: 0.0,
        camera,
        link_journal,
    };
    let standard = assemble(name, config, parts)?;
    let mut robot = RobotSpec::new(name);
    for actor in standard.into_actors() {
        if REPLAY_ACTORS.contains(&actor.name()) {
            robot.add(actor);
        }
    }
    registry
        .add_actors(&mut robot, config, index, &())
        .map_err(|e| AssembleError::Config(e.within("robot")))?;
    Ok(robot)
}
