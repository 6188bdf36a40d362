//! troupe-robot: running robots — assembling one robot's actors from configuration,
//! the hardware drivers, and the deployment layer every troupe process stands on.
//!
//! - [`assemble`]: one robot from a [`RobotConfig`] and the parts the caller provides;
//!   [`registry`]: the parts chosen by name in the robot's file (sensor and vehicle
//!   drivers, extra actors) and built by the factories registered under those names.
//! - [`ros2`], [`mavlink`], [`safety`]: the hardware drivers and their guards;
//!   [`hardware`]: a hardware robot in one process (the `troupe-robot` binary).
//! - [`harness`]: the robot-process harness (journal, team link, executor, signals,
//!   duration, recording, `summary.json`, exit codes) that a simulated robot process
//!   (`troupe robot`), a hardware robot and the base station share.
//! - [`base`]: the base station (`troupe base`); [`router`]: a zenoh router
//!   (`troupe router`); [`keys`]: a team's TLS credentials (`troupe keys`);
//!   [`launch`]: a team as separate processes on one machine (`troupe launch`).
//!
//! [`assemble`] wires the actors a [`RobotConfig`] names around a vehicle and a frame
//! source that the caller provides (a simulator provides simulated ones; hardware
//! provides drivers). The default configuration is the standard robot of the thesis
//! (§8.2): sensor, SOGMM mapper, local grid, motion-primitive planner, collision
//! actor with priority avoidance, and link. Route behaviours (`waypoint_route`) and
//! teleoperation replace the grid + planner pair; the mapper and collision actor can
//! be switched off (`[robot.mapper] enabled = false`, `[robot.collision] enabled =
//! false`), and the artifact reporter switched on (`[robot.artifacts] enabled = true`).
//!
//! A robot file overrides the standard robot key by key, and every value is checked
//! before a robot is assembled:
//!
//! ```
//! use troupe_robot::RobotConfig;
//!
//! let config: RobotConfig = toml::from_str("speed_mps = 1.5\n[grid]\nresolution_m = 0.1\n").unwrap();
//! config.validate().unwrap();
//! assert_eq!(config.grid.resolution_m, 0.1);
//!
//! let mut bad = RobotConfig::default();
//! bad.grid.resolution_m = 0.0;
//! let e = bad.validate().unwrap_err();
//! assert_eq!(e.key, "grid.resolution_m");
//! assert_eq!(e.to_string(), "`grid.resolution_m` must be ≥ 0.01, got 0");
//! ```
#![deny(missing_docs)]

pub mod base;
mod config;
pub mod frames;
pub mod hardware;
pub mod harness;
pub mod keys;
pub mod launch;
pub mod mavlink;
pub mod registry;
pub mod ros2;
pub mod router;
pub mod safety;
pub mod toml_file;

use nalgebra::{Isometry3, Point3};
use troupe_actors::artifacts::ArtifactActor;
use troupe_actors::collision::{CollisionActor, OperatorActor};
use troupe_actors::explorer::ExplorerActor;
use troupe_actors::grid::GridActor;
use troupe_actors::link::{LinkActor, LinkJournal};
use troupe_actors::mapper::MapperActor;
use troupe_actors::planner::{PlannerActor, ScriptedTeleop, TeleopActor, TeleopConfig};
use troupe_actors::sensor::{FrameSource, SensorActor};
use troupe_algorithms::camera::PinholeIntrinsics;
use troupe_core::RobotId;
use troupe_policies::priority::PriorityAvoidance;
use troupe_policies::{BehaviourInputs, PolicyError, behaviour_by_name, selection_by_name};
use troupe_runtime::{ActorOptions, ActorSpec, LatencyModel, RobotSpec};

pub use config::{
    ActorLatencies, CollisionConfig, ConfigError, MapSharing, PLANNER, PartChoice, RobotConfig,
    TELEOP, TeleopSettings,
};

/// Builds a frame source (called at start and on every sensor restart).
pub type FrameSourceFactory = Box<dyn FnMut() -> Box<dyn FrameSource> + Send>;

/// What the caller provides: the hardware (or its simulation) and mission inputs.
pub struct RobotParts {
    /// The sensor's frame source.
    pub frame_source: FrameSourceFactory,
    /// The vehicle actor (publishes odometry, follows plans).
    pub vehicle: ActorSpec,
    /// Waypoints for route-following behaviours.
    pub route: Vec<Point3<f64>>,
    /// Earliest departure on the route, seconds of run time.
    pub depart_at_s: f64,
    /// The camera's intrinsics (the planner scores views with them).
    pub camera: PinholeIntrinsics,
    /// The link's non-volatile storage: it outlives restarts of the link actor and
    /// reboots of the robot, so that nothing accepted into a store-and-forward class
    /// is lost and message ids are never reused. `LinkJournal::default()` in
    /// simulation; a process that may be restarted without its journal starts it
    /// at a fresh id ([`LinkJournal::starting_at`]).
    pub link_journal: LinkJournal,
}

/// Why a robot could not be assembled.
#[derive(Debug, thiserror::Error)]
pub enum AssembleError {
    /// The configuration is invalid.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The behaviour could not be built.
    #[error(transparent)]
    Policy(#[from] PolicyError),
}

struct BoxedSource(Box<dyn FrameSource>);

impl FrameSource for BoxedSource {
    fn capture(
        &mut self,
        now: troupe_core::Time,
        odometry: Option<&troupe_algorithms::frame::Odometry>,
    ) -> Result<Option<troupe_algorithms::frame::DepthFrame>, troupe_runtime::ActorError> {
        self.0.capture(now, odometry)
    }
}

/// Assembles a robot: vehicle, sensor, the mapper if enabled, then either the
/// explorer (route behaviours), the local grid and the planner
/// (`behaviour = "planner"`) or the local grid and teleoperation
/// (`behaviour = "teleop"`), the collision actor if enabled (then the explorer or
/// planner offers candidates to it and it commits plans; the link sends the collision
/// priority with them) with the operator actor if `operator_commands` is on, then
/// the link.
pub fn assemble(
    name: &str,
    config: &RobotConfig,
    parts: RobotParts,
) -> Result<RobotSpec, AssembleError> {
    config.validate()?;
    let mut frame_source = parts.frame_source;
    let (sensor_rate_hz, max_width_px) = (config.sensor_rate_hz, config.sensor_max_width_px);
    // The planner scores views with the frames the sensor publishes.
    let camera = parts.camera.decimated(PinholeIntrinsics::decimation(
        parts.camera.width,
        max_width_px,
    ));
    let mut robot = RobotSpec::new(name);
    robot.add(parts.vehicle).add(
        ActorSpec::new("sensor", move || {
            SensorActor::new(BoxedSource(frame_source()), sensor_rate_hz)
                .decimating_to(max_width_px)
        })
        .with_options(actor_options(config, config.latency_s.sensor, true)),
    );
    if config.mapper.enabled {
        let mapper = config.mapper;
        robot.add(
            ActorSpec::new("mapper", move || MapperActor::new(mapper)).with_options(actor_options(
                config,
                config.latency_s.mapper,
                true,
            )),
        );
    }
    add_behaviour(&mut robot, config, camera, parts.route, parts.depart_at_s)?;
    if config.collision.enabled {
        add_collision(&mut robot, config);
    }
    if config.artifacts.enabled {
        let artifacts = config.artifacts;
        robot.add(
            ActorSpec::new("artifacts", move || ArtifactActor::new(artifacts))
                .with_options(actor_options(config, 0.0, false)),
        );
    }
    let mut link = config.link.clone();
    if config.collision.enabled {
        link.priority = config.collision.peers.priority;
    }
    let sharing = config.map_sharing;
    let journal = parts.link_journal;
    robot.add(
        ActorSpec::new("link", move || {
            let actor = LinkActor::new(link.clone())?.journaled(journal.clone())?;
            Ok(if sharing == MapSharing::Gmm {
                actor
            } else {
                actor.without_keyframes()
            })
        })
        .with_options(actor_options(config, config.latency_s.link, false)),
    );
    Ok(robot)
}

/// An actor's options: its fixed latency, the robot's restart policy, and whether
/// its handler blocks (heavy work run off the executor's thread).
pub(crate) fn actor_options(config: &RobotConfig, latency_s: f64, blocking: bool) -> ActorOptions {
    ActorOptions {
        latency: LatencyModel::fixed(latency_s),
        restart: config.restart,
        blocking,
    }
}

/// The behaviour's actors: the local grid and teleoperation (with a scripted
/// joystick if one is given), the local grid and the planner, or the explorer
/// following a named route behaviour.
fn add_behaviour(
    robot: &mut RobotSpec,
    config: &RobotConfig,
    camera: PinholeIntrinsics,
    route: Vec<Point3<f64>>,
    depart_at_s: f64,
) -> Result<(), AssembleError> {
    let collision = config.collision.enabled;
    let (sharing, grid) = (config.map_sharing, config.grid);
    let grid_actor = move || {
        let actor = GridActor::new(grid);
        if sharing == MapSharing::Grid {
            actor.sharing_changes()
        } else {
            actor
        }
    };
    let grid_options = actor_options(config, config.latency_s.grid, true);
    let planner_options = actor_options(config, config.latency_s.planner, true);
    if config.behaviour == TELEOP {
        let teleop = TeleopConfig {
            rate_hz: config.planner.rate_hz,
            round: config.planner.round,
            knot_step_s: config.planner.knot_step_s,
            params: config.teleop.params,
        };
        robot
            .add(ActorSpec::new("grid", grid_actor).with_options(grid_options))
            .add(
                ActorSpec::new("teleop", move || TeleopActor::new(teleop))
                    .with_options(planner_options),
            );
        if !config.teleop.script.is_empty() {
            let (script, rate_hz) = (config.teleop.script.clone(), config.teleop.command_rate_hz);
            robot.add(ActorSpec::new("joystick", move || {
                ScriptedTeleop::new(script.clone(), rate_hz)
            }));
        }
    } else if config.behaviour == PLANNER {
        let selection = selection_by_name(&config.selection)?;
        let planner = config.planner;
        let peer_frames: Vec<(RobotId, Isometry3<f64>)> = config
            .link
            .peer_frames
            .iter()
            .map(|f| (RobotId(f.robot), f.transform()))
            .collect();
        robot
            .add(ActorSpec::new("grid", grid_actor).with_options(grid_options))
            .add(
                ActorSpec::new("planner", move || {
                    let actor = PlannerActor::new(planner, camera, selection())
                        .with_peer_frames(peer_frames.iter().copied());
                    if collision {
                        actor.deferring_to_collision()
                    } else {
                        actor
                    }
                })
                .with_options(planner_options),
            );
    } else {
        let behaviour = behaviour_by_name(
            &config.behaviour,
            &BehaviourInputs {
                route,
                speed_mps: config.speed_mps,
                yaw_rate_rad_s: config.yaw_rate_rad_s,
                depart_at_s,
            },
        )?;
        let replan_rate_hz = config.replan_rate_hz;
        robot.add(
            ActorSpec::new("explorer", move || {
                let actor = ExplorerActor::new(behaviour(), replan_rate_hz);
                if collision {
                    actor.deferring_to_collision()
                } else {
                    actor
                }
            })
            .with_options(actor_options(config, config.latency_s.explorer, false)),
        );
    }
    Ok(())
}

/// The collision actor (priority avoidance, braking for peers), and the operator
/// actor if `operator_commands` is on.
fn add_collision(robot: &mut RobotSpec, config: &RobotConfig) {
    let check = config.collision.actor();
    let peers = config.collision.peers;
    let operator = config.collision.operator_commands;
    let (limits, knot_step_s) = (config.planner.round.limits, config.planner.knot_step_s);
    robot.add(
        ActorSpec::new("collision", move || {
            let actor = CollisionActor::new(check.clone(), PriorityAvoidance::new(peers))
                .braking_for_peers(limits, knot_step_s);
            if operator {
                actor.obeying_operator()
            } else {
                actor
            }
        })
        .with_options(actor_options(config, config.latency_s.collision, false)),
    );
    if operator {
        robot.add(
            ActorSpec::new("operator", OperatorActor::new)
                .with_options(actor_options(config, 0.0, false)),
        );
    }
}
