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

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use nalgebra::Isometry3;
    use troupe_robot::{AssembleError, PartChoice};

    use crate::camera::CameraParams;
    use crate::scenario::Scenario;
    use crate::sequence::record_camera;
    use crate::team::Team;
    use crate::world::{CaveParams, CaveWorld};

    fn short() -> Scenario {
        Scenario {
            robots: 1,
            duration_s: 2.0,
            ..Scenario::default()
        }
    }

    fn refusal(scenario: &Scenario) -> troupe_core::ConfigError {
        match Team::new(scenario) {
            Err(AssembleError::Config(e)) => e,
            Err(e) => panic!("{e}"),
            Ok(_) => panic!("assembled"),
        }
    }

    #[test]
    fn a_recorded_sequence_is_a_sensor_driver_by_name() {
        let dir = tempfile::tempdir().unwrap();
        let world = CaveWorld::generate(&CaveParams::default(), 1);
        let path: Vec<_> = (0..6)
            .map(|i| (0.2 * f64::from(i), Isometry3::translation(0.0, 0.0, 1.0)))
            .collect();
        let camera = CameraParams {
            width: 32,
            height: 24,
            ..CameraParams::default()
        };
        let seq = record_camera(&dir.path().join("seq"), &world, &camera, &path, 1).unwrap();
        let mut scenario = short();
        let mut sensor = PartChoice::named(super::SEQUENCE);
        sensor
            .settings
            .insert("path".into(), seq.display().to_string().into());
        scenario.robot.sensor = Some(sensor);
        let run = Team::new(&scenario).unwrap().run(|_| {});
        let frames = run.summary.per_robot[0].topics["sensor/frame"].messages;
        assert_eq!(frames, 6, "the sequence's six frames, then nothing");
    }

    #[test]
    fn bad_part_choices_are_refused_by_key() {
        let mut scenario = short();
        scenario.robot.sensor = Some(PartChoice::named("lidar"));
        let e = refusal(&scenario);
        assert_eq!(e.key, "robot.sensor");
        assert!(e.rule.contains("ros2, sequence, sim_camera"), "{e}");
        // ROS 2 needs the hardware robot's session.
        scenario.robot.sensor = Some(PartChoice::named("ros2"));
        let e = refusal(&scenario);
        assert_eq!(e.key, "robot.sensor");
        assert!(e.rule.contains("ROS 2"), "{e}");
        let mut sensor = PartChoice::named(super::SEQUENCE);
        sensor.settings.insert("path".into(), "/nonexistent".into());
        scenario.robot.sensor = Some(sensor);
        assert_eq!(refusal(&scenario).key, "robot.sensor.path");
        scenario.robot.sensor = None;
        let mut vehicle = PartChoice::named(super::SIM_VEHICLE);
        vehicle.settings.insert("lag_s".into(), 0.1.into());
        scenario.robot.vehicle = Some(vehicle);
        assert_eq!(refusal(&scenario).key, "robot.vehicle.lag_s");
    }
}
