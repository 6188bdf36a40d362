//! The simulator's parts, registered by name ([`troupe_robot::registry`]): the
//! simulated camera (`sim_camera`, the default sensor), a recorded sequence
//! (`sequence`) and the simulated vehicle (`sim`, the default vehicle), beside
//! troupe-robot's `ros2` and `mavlink`. A simulated robot's parts are given its
//! [`SimEnvironment`]: the scenario, the world, where the robot starts and its camera
//! noise seed — what a user's simulated driver needs too (`examples/custom_parts/`).
//!
//! ```
//! use troupe_robot::PartChoice;
//! use troupe_sims::parts::registry;
//!
//! let registry = registry();
//! assert_eq!(registry.sensor_names().collect::<Vec<_>>(), ["ros2", "sequence", "sim_camera"]);
//! assert_eq!(registry.vehicle_names().collect::<Vec<_>>(), ["mavlink", "sim"]);
//! let (sensor, vehicle) = registry.choices(&troupe_robot::RobotConfig::default());
//! assert_eq!((sensor, vehicle), (PartChoice::named("sim_camera"), PartChoice::named("sim")));
//! ```

use std::path::PathBuf;
use std::sync::Arc;

use nalgebra::Isometry3;
use serde::Deserialize;
use troupe_actors::vehicle::vehicle_actor;
use troupe_core::ConfigError;
use troupe_robot::registry::{PartContext, Registry, SensorDriver};

use crate::scenario::Scenario;
use crate::sequence::{Sequence, SequenceSource};
use crate::sim_sensor::SimCameraSource;
use crate::vehicle::{SimVehicle, new_body};
use crate::world::{Site, World};

/// The simulated camera's name (the default sensor of a simulated robot).
pub const SIM_CAMERA: &str = "sim_camera";
/// The recorded sequence's name (`[robot.sensor] kind = "sequence"`, `path = "…"`).
pub const SEQUENCE: &str = "sequence";
/// The simulated vehicle's name (the default vehicle of a simulated robot).
pub const SIM_VEHICLE: &str = "sim";

/// What a simulated robot's parts are given
/// ([`PartContext::environment`]): `ctx.environment::<SimEnvironment>(…)`.
pub struct SimEnvironment {
    /// The scenario (its `[camera]` and `[vehicle]` tables, seed, team size).
    pub scenario: Scenario,
    /// The world (ground truth: what a simulated sensor renders).
    pub world: Arc<dyn Site>,
    /// Where and how the robot starts.
    pub start_pose: Isometry3<f64>,
    /// The seed of this robot's camera noise (distinct per robot and run seed).
    pub noise_seed: u64,
}

impl SimEnvironment {
    /// The environment a part of a simulated robot needs, or an error naming the
    /// part's key.
    pub fn of<'a>(ctx: &'a PartContext<'_>) -> Result<&'a SimEnvironment, ConfigError> {
        ctx.environment("a simulated world (`troupe run`, `troupe robot`)")
    }
}

/// Settings of a part that has none.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct NoSettings {}

/// The recorded sequence's settings.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SequenceSettings {
    /// The sequence directory (TUM RGB-D layout), relative to the working directory.
    path: PathBuf,
}

/// troupe-robot's parts ([`Registry::hardware`]) and the simulator's (module docs),
/// with the simulated camera and vehicle as the defaults: what `troupe` runs with.
#[must_use]
pub fn registry() -> Registry {
    let mut registry = Registry::hardware();
    registry.add_sensor(SIM_CAMERA, |ctx: &PartContext<'_>| {
        let NoSettings {} = ctx.settings()?;
        let env = SimEnvironment::of(ctx)?;
        let world: Arc<dyn World> = env.world.clone();
        let (camera, noise_seed) = (env.scenario.camera.clone(), env.noise_seed);
        Ok(SensorDriver {
            frames: Box::new(move || {
                Box::new(SimCameraSource::new(
                    world.clone(),
                    camera.clone(),
                    noise_seed,
                ))
            }),
            camera: env.scenario.camera.intrinsics(),
        })
    });
    registry.add_sensor(SEQUENCE, |ctx: &PartContext<'_>| {
        let SequenceSettings { path } = ctx.settings()?;
        let sequence = Sequence::open(&path).map_err(|e| {
            ConfigError::new(
                format!("{}.path", ctx.key),
                "must be a readable recorded sequence (TUM RGB-D layout)",
                format!("{}: {e}", path.display()),
            )
        })?;
        Ok(SensorDriver {
            camera: sequence.camera().intrinsics(),
            frames: Box::new(move || Box::new(SequenceSource::new(sequence.clone()))),
        })
    });
    registry.add_vehicle(SIM_VEHICLE, |ctx: &PartContext<'_>| {
        let NoSettings {} = ctx.settings()?;
        let env = SimEnvironment::of(ctx)?;
        let body = new_body(env.start_pose);
        let config = env.scenario.vehicle.clone();
        Ok(
            vehicle_actor(move || SimVehicle::new(body.clone(), config.clone()))
                .with_options(ctx.options(ctx.config.latency_s.vehicle)),
        )
    });
    registry.set_defaults(SIM_CAMERA, SIM_VEHICLE);
    registry
}
