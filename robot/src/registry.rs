//! Robots assembled from named parts: the sensor driver, the vehicle driver and any
//! extra actors of a robot are chosen by name in its file (`[robot] sensor`,
//! `vehicle`, `[[robot.actors]]`, see [`PartChoice`]) and built by the factories a
//! [`Registry`] holds under those names. A user's crate registers its own driver or
//! actor beside troupe's and names it in a scenario file, without editing troupe
//! (`examples/custom_parts/`, `docs/custom-parts.md`).
//!
//! - [`Registry::hardware`]: troupe-robot's parts — the `ros2` sensor driver (needs
//!   the hardware robot's [`HardwareEnvironment`]) and the `mavlink` vehicle driver —
//!   with `ros2` and `mavlink` as the defaults. The simulator's registry
//!   (`troupe_sims::parts::registry`) adds `sim_camera`, `sequence` and `sim`.
//! - A factory gets a [`PartContext`]: the robot's name, index and configuration, the
//!   part's own settings ([`PartContext::settings`] reads them into a typed struct,
//!   errors naming the key) and the process's environment
//!   ([`PartContext::environment`]: the simulated world in a simulation, the ROS 2
//!   inputs on hardware), so that no crate reaches upward for what it needs.
//! - [`Registry::check`] rejects unknown names before anything is built, listing the
//!   known ones; [`Registry::assemble`] builds the parts and hands them to
//!   [`crate::assemble`], then adds the extra actors.
//!
//! ```
//! use troupe_robot::registry::{PartContext, Registry};
//! use troupe_robot::{PartChoice, RobotConfig};
//! use troupe_runtime::{ActorResult, ActorSpec, Context, Event};
//!
//! struct Quiet;
//! impl troupe_runtime::Actor for Quiet {
//!     fn handle(&mut self, _: &Event, _: &mut Context<'_>) -> ActorResult { Ok(()) }
//! }
//!
//! let mut registry = Registry::hardware();
//! registry.add_actor("quiet", |ctx: &PartContext<'_>| {
//!     Ok(ActorSpec::new("quiet", || Quiet).with_options(ctx.options(0.0)))
//! });
//! let mut config = RobotConfig::default();
//! config.actors.push(PartChoice::named("quiet"));
//! registry.check(&config).unwrap();
//! config.actors.push(PartChoice::named("loud"));
//! let e = registry.check(&config).unwrap_err();
//! assert_eq!(e.key, "actors[1]");
//! assert_eq!(e.to_string(), "`actors[1]` must name a registered actor (quiet), got \"loud\"");
//! ```

use std::any::Any;
use std::collections::BTreeMap;
use std::sync::Arc;

use nalgebra::Point3;
use serde::de::DeserializeOwned;
use troupe_actors::link::LinkJournal;
use troupe_algorithms::camera::PinholeIntrinsics;
use troupe_runtime::{ActorOptions, ActorSpec, RobotSpec};

use crate::mavlink::{MavlinkConfig, mavlink_vehicle};
use crate::ros2::Ros2Inputs;
use crate::{AssembleError, ConfigError, FrameSourceFactory, PartChoice, RobotConfig, RobotParts};

/// What a part's factory is given.
pub struct PartContext<'a> {
    /// The robot's name (`robot<i>`).
    pub robot: &'a str,
    /// Its index in the team (its robot id).
    pub index: usize,
    /// Its configuration (the `[robot]` table).
    pub config: &'a RobotConfig,
    /// Where the part is named in that table (`sensor`, `vehicle`, `actors[2]`): the
    /// key errors name.
    pub key: String,
    /// The part's name and its own settings.
    pub choice: &'a PartChoice,
    environment: &'a dyn Any,
}

impl PartContext<'_> {
    /// The part's settings as `T` (a serde struct, best with `deny_unknown_fields`
    /// and `default`); an error names the key (`sensor.dropout`) and what is wrong.
    pub fn settings<T: DeserializeOwned>(&self) -> Result<T, ConfigError> {
        let value = toml::Value::Table(self.choice.settings.clone());
        serde_path_to_error::deserialize(value).map_err(|e| {
            let path = e.path().to_string();
            let key = if path == "." {
                self.key.clone()
            } else {
                format!("{}.{path}", self.key)
            };
            ConfigError::new(
                key,
                format!("does not fit the settings of `{}`", self.choice.kind),
                e.into_inner(),
            )
        })
    }

    /// The process's environment as `T` (the simulator's world, the hardware robot's
    /// ROS 2 inputs); an error says that this part needs a `what` this process does
    /// not have.
    pub fn environment<T: Any>(&self, what: &'static str) -> Result<&T, ConfigError> {
        self.environment.downcast_ref().ok_or_else(|| {
            ConfigError::new(
                self.key.clone(),
                format!("names a part that needs {what}, which this process does not have"),
                format!("{:?}", self.choice.kind),
            )
        })
    }

    /// The process's environment as `T`, if it is one.
    #[must_use]
    pub fn environment_if<T: Any>(&self) -> Option<&T> {
        self.environment.downcast_ref()
    }

    /// The standard actor options: modelled latency `latency_s` (sim time), the
    /// robot's restart policy, not blocking.
    #[must_use]
    pub fn options(&self, latency_s: f64) -> ActorOptions {
        crate::actor_options(self.config, latency_s, false)
    }
}

/// What a sensor driver provides: its frame source and the camera it sees through.
pub struct SensorDriver {
    /// Builds the frame source (at start and on every sensor restart).
    pub frames: FrameSourceFactory,
    /// The camera's intrinsics (before the sensor's decimation).
    pub camera: PinholeIntrinsics,
}

/// Builds one part of a robot from its context.
pub type PartFactory<T> =
    Arc<dyn Fn(&PartContext<'_>) -> Result<T, ConfigError> + Send + Sync + 'static>;

/// The hardware robot's environment (`troupe-robot`): what its parts share.
#[derive(Clone)]
pub struct HardwareEnvironment {
    /// The ROS 2 inputs (camera, odometry) on the robot's zenoh session.
    pub inputs: Ros2Inputs,
    /// The camera's intrinsics (the file's `[camera]` or the first frame's).
    pub camera: PinholeIntrinsics,
    /// The file's `[mavlink]` table.
    pub mavlink: MavlinkConfig,
}

/// Name → factory maps of sensor drivers, vehicle drivers and extra actors, and the
/// names used where a robot's file names none (see the [module docs](self)).
#[derive(Clone)]
pub struct Registry {
    sensors: BTreeMap<String, PartFactory<SensorDriver>>,
    vehicles: BTreeMap<String, PartFactory<ActorSpec>>,
    actors: BTreeMap<String, PartFactory<ActorSpec>>,
    default_sensor: String,
    default_vehicle: String,
}

/// The ROS 2 sensor driver's name.
pub const ROS2: &str = "ros2";
/// The MAVLink vehicle driver's name.
pub const MAVLINK: &str = "mavlink";

impl Registry {
    /// A registry with no parts; `default_sensor` and `default_vehicle` are used
    /// where a robot's file names none (register them before assembling).
    #[must_use]
    pub fn empty(default_sensor: &str, default_vehicle: &str) -> Self {
        Registry {
            sensors: BTreeMap::new(),
            vehicles: BTreeMap::new(),
            actors: BTreeMap::new(),
            default_sensor: default_sensor.into(),
            default_vehicle: default_vehicle.into(),
        }
    }

    /// troupe-robot's parts (see the [module docs](self)): `ros2` and `mavlink`,
    /// which are also the defaults.
    #[must_use]
    pub fn hardware() -> Self {
        let mut registry = Registry::empty(ROS2, MAVLINK);
        registry.add_sensor(ROS2, |ctx: &PartContext<'_>| {
            let env: &HardwareEnvironment =
                ctx.environment("the hardware robot's ROS 2 session")?;
            let inputs = env.inputs.clone();
            Ok(SensorDriver {
                frames: Box::new(move || Box::new(inputs.frame_source())),
                camera: env.camera,
            })
        });
        registry.add_vehicle(MAVLINK, |ctx: &PartContext<'_>| {
            // On hardware the file's `[mavlink]` table; elsewhere the part's own.
            let config = match ctx.environment_if::<HardwareEnvironment>() {
                Some(env) if ctx.choice.settings.is_empty() => env.mavlink.clone(),
                Some(_) => {
                    return Err(ConfigError::new(
                        ctx.key.clone(),
                        "takes its settings from the robot file's `[mavlink]` table",
                        "a table",
                    ));
                }
                None => ctx.settings::<MavlinkConfig>()?,
            };
            mavlink_vehicle(&config).map_err(|e| e.within(&ctx.key))
        });
        registry
    }

    /// Registers (or replaces) the sensor driver `name`.
    pub fn add_sensor(
        &mut self,
        name: &str,
        factory: impl Fn(&PartContext<'_>) -> Result<SensorDriver, ConfigError> + Send + Sync + 'static,
    ) -> &mut Self {
        self.sensors.insert(name.into(), Arc::new(factory));
        self
    }

    /// Registers (or replaces) the vehicle driver `name`: its factory builds the
    /// robot's `vehicle` actor (it follows [`PLAN`](troupe_actors::msgs::PLAN) and
    /// publishes [`ODOMETRY`](troupe_actors::msgs::ODOMETRY)).
    pub fn add_vehicle(
        &mut self,
        name: &str,
        factory: impl Fn(&PartContext<'_>) -> Result<ActorSpec, ConfigError> + Send + Sync + 'static,
    ) -> &mut Self {
        self.vehicles.insert(name.into(), Arc::new(factory));
        self
    }

    /// Registers (or replaces) the extra actor `name`.
    pub fn add_actor(
        &mut self,
        name: &str,
        factory: impl Fn(&PartContext<'_>) -> Result<ActorSpec, ConfigError> + Send + Sync + 'static,
    ) -> &mut Self {
        self.actors.insert(name.into(), Arc::new(factory));
        self
    }

    /// Uses `sensor` and `vehicle` where a robot's file names none.
    pub fn set_defaults(&mut self, sensor: &str, vehicle: &str) -> &mut Self {
        self.default_sensor = sensor.into();
        self.default_vehicle = vehicle.into();
        self
    }

    /// The registered sensor drivers' names.
    pub fn sensor_names(&self) -> impl Iterator<Item = &str> {
        self.sensors.keys().map(String::as_str)
    }

    /// The registered vehicle drivers' names.
    pub fn vehicle_names(&self) -> impl Iterator<Item = &str> {
        self.vehicles.keys().map(String::as_str)
    }

    /// The registered extra actors' names.
    pub fn actor_names(&self) -> impl Iterator<Item = &str> {
        self.actors.keys().map(String::as_str)
    }

    /// The sensor and vehicle `config` chooses (the defaults where it names none).
    #[must_use]
    pub fn choices(&self, config: &RobotConfig) -> (PartChoice, PartChoice) {
        (
            config
                .sensor
                .clone()
                .unwrap_or_else(|| PartChoice::named(&self.default_sensor)),
            config
                .vehicle
                .clone()
                .unwrap_or_else(|| PartChoice::named(&self.default_vehicle)),
        )
    }

    /// Checks that every part `config` names (or leaves to the defaults) is
    /// registered; the error names the key and lists the known names.
    pub fn check(&self, config: &RobotConfig) -> Result<(), ConfigError> {
        let (sensor, vehicle) = self.choices(config);
        known("sensor", "sensor driver", &self.sensors, &sensor)?;
        known("vehicle", "vehicle driver", &self.vehicles, &vehicle)?;
        for (i, actor) in config.actors.iter().enumerate() {
            known(&format!("actors[{i}]"), "actor", &self.actors, actor)?;
        }
        Ok(())
    }

    /// Assembles robot `place.name` with `config`: checks the names, builds its
    /// sensor and vehicle drivers and hands them to [`crate::assemble`], then builds
    /// the extra actors in the file's order (each must have a name no other actor of
    /// the robot has).
    pub fn assemble(
        &self,
        config: &RobotConfig,
        place: Placement<'_>,
    ) -> Result<RobotSpec, AssembleError> {
        self.check(config)?;
        let (sensor, vehicle) = self.choices(config);
        let context = |key: String, choice| PartContext {
            robot: place.name,
            index: place.index,
            config,
            key,
            choice,
            environment: place.environment,
        };
        let sensor_driver = self.sensors[&sensor.kind](&context("sensor".into(), &sensor))?;
        let vehicle_actor = self.vehicles[&vehicle.kind](&context("vehicle".into(), &vehicle))?;
        if vehicle_actor.name() != "vehicle" {
            return Err(ConfigError::new(
                "vehicle",
                "must name a driver whose actor is called \"vehicle\"",
                format!(
                    "{:?} (its actor is {:?})",
                    vehicle.kind,
                    vehicle_actor.name()
                ),
            )
            .into());
        }
        let parts = RobotParts {
            frame_source: sensor_driver.frames,
            vehicle: vehicle_actor,
            route: place.route,
            depart_at_s: place.depart_at_s,
            camera: sensor_driver.camera,
            link_journal: place.link_journal,
        };
        let mut robot = crate::assemble(place.name, config, parts)?;
        self.add_actors(&mut robot, config, place.index, place.environment)?;
        Ok(robot)
    }
}

impl std::fmt::Debug for Registry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Registry")
            .field("sensors", &self.sensors.keys().collect::<Vec<_>>())
            .field("vehicles", &self.vehicles.keys().collect::<Vec<_>>())
            .field("actors", &self.actors.keys().collect::<Vec<_>>())
            .field("default_sensor", &self.default_sensor)
            .field("default_vehicle", &self.default_vehicle)
            .finish()
    }
}

impl Registry {
    /// Builds the extra actors `config` names (`[[robot.actors]]`) into `robot`, in
    /// the file's order, for the robot at `index` in a process offering
    /// `environment`; each must have a name no other actor of the robot has.
    /// [`Registry::assemble`] does this after the standard actors; a caller that
    /// assembles a robot of its own kind (a robot replaying a recording) calls it.
    pub fn add_actors(
        &self,
        robot: &mut RobotSpec,
        config: &RobotConfig,
        index: usize,
        environment: &dyn Any,
    ) -> Result<(), ConfigError> {
        let name = robot.name().to_owned();
        for (i, choice) in config.actors.iter().enumerate() {
            let key = format!("actors[{i}]");
            known(&key, "actor", &self.actors, choice)?;
            let context = PartContext {
                robot: &name,
                index,
                config,
                key: key.clone(),
                choice,
                environment,
            };
            let actor = self.actors[&choice.kind](&context)?;
            if robot.actor_names().any(|n| n == actor.name()) {
                return Err(ConfigError::new(
                    key,
                    "must build an actor whose name no other actor of the robot has",
                    format!("{:?} (its actor is {:?})", choice.kind, actor.name()),
                ));
            }
            robot.add(actor);
        }
        Ok(())
    }
}

/// Where and how a robot is assembled, beyond its configuration.
pub struct Placement<'a> {
    /// The robot's name (`robot<i>`).
    pub name: &'a str,
    /// Its index in the team.
    pub index: usize,
    /// The process's environment, for the parts that need it
    /// ([`PartContext::environment`]).
    pub environment: &'a dyn Any,
    /// Waypoints for route-following behaviours.
    pub route: Vec<Point3<f64>>,
    /// Earliest departure on the route, seconds of run time.
    pub depart_at_s: f64,
    /// The link's non-volatile storage ([`RobotParts::link_journal`]).
    pub link_journal: LinkJournal,
}

fn known<T>(
    key: &str,
    what: &str,
    registered: &BTreeMap<String, T>,
    choice: &PartChoice,
) -> Result<(), ConfigError> {
    if registered.contains_key(&choice.kind) {
        return Ok(());
    }
    let names: Vec<&str> = registered.keys().map(String::as_str).collect();
    Err(ConfigError::new(
        key,
        format!("must name a registered {what} ({})", names.join(", ")),
        format!("{:?}", choice.kind),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use troupe_runtime::{Actor, ActorResult, Context, Event};

    struct Quiet;
    impl Actor for Quiet {
        fn handle(&mut self, _: &Event, _: &mut Context<'_>) -> ActorResult {
            Ok(())
        }
    }

    #[derive(serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Settings {
        #[serde(default)]
        count: u32,
    }

    fn registry() -> Registry {
        let mut registry = Registry::hardware();
        registry.add_actor("quiet", |ctx: &PartContext<'_>| {
            let settings: Settings = ctx.settings()?;
            Ok(ActorSpec::new(format!("quiet{}", settings.count), || Quiet))
        });
        registry
    }

    #[test]
    fn unknown_names_are_config_errors_listing_the_known_ones() {
        let registry = registry();
        let mut config = RobotConfig::default();
        registry.check(&config).unwrap();
        config.sensor = Some(PartChoice::named("lidar"));
        let e = registry.check(&config).unwrap_err();
        assert_eq!(e.key, "sensor");
        assert!(e.rule.contains("(ros2)"), "{e}");
        config.sensor = None;
        config.vehicle = Some(PartChoice::named("boat"));
        assert!(
            registry
                .check(&config)
                .unwrap_err()
                .rule
                .contains("(mavlink)")
        );
    }

    #[test]
    fn parts_read_their_settings_and_need_their_environment() {
        let registry = registry();
        let config: RobotConfig = toml::from_str(
            "[[actors]]\nkind = \"quiet\"\ncount = 2\n[[actors]]\nkind = \"quiet\"\ncolour = 1\n",
        )
        .unwrap();
        let place = |environment: &'static dyn Any| Placement {
            name: "robot0",
            index: 0,
            environment,
            route: Vec::new(),
            depart_at_s: 0.0,
            link_journal: LinkJournal::default(),
        };
        // The ROS 2 sensor needs the hardware environment.
        let Err(AssembleError::Config(e)) = registry.assemble(&config, place(&())) else {
            panic!("the ROS 2 sensor was built without ROS 2")
        };
        assert_eq!(e.key, "sensor");
        assert!(e.rule.contains("ROS 2"), "{e}");
        let choice = &config.actors[1];
        let context = PartContext {
            robot: "robot0",
            index: 0,
            config: &config,
            key: "actors[1]".into(),
            choice,
            environment: &(),
        };
        let e = context.settings::<Settings>().err().unwrap();
        assert_eq!(e.key, "actors[1].colour", "{e}");
        assert!(e.value.contains("unknown field"), "{e}");
        let context = PartContext {
            key: "actors[0]".into(),
            choice: &config.actors[0],
            ..context
        };
        assert_eq!(context.settings::<Settings>().unwrap().count, 2);
    }

    #[test]
    fn extra_actors_join_in_order_and_may_not_take_a_name() {
        let registry = registry();
        let config: RobotConfig = toml::from_str(
            "[[actors]]\nkind = \"quiet\"\n[[actors]]\nkind = \"quiet\"\ncount = 1\n",
        )
        .unwrap();
        let mut robot = RobotSpec::new("r0");
        registry.add_actors(&mut robot, &config, 0, &()).unwrap();
        assert_eq!(
            robot.actor_names().collect::<Vec<_>>(),
            ["quiet0", "quiet1"]
        );
        let e = registry
            .add_actors(&mut robot, &config, 0, &())
            .unwrap_err();
        assert_eq!(e.key, "actors[0]");
        assert!(e.value.contains("quiet0"), "{e}");
    }

    #[test]
    fn part_choices_read_as_names_or_tables_and_write_back_the_same() {
        let config: RobotConfig = toml::from_str(
            "sensor = \"ros2\"\n[vehicle]\nkind = \"mavlink\"\nconnection = \"udpin:0.0.0.0:14540\"\n",
        )
        .unwrap();
        assert_eq!(config.sensor, Some(PartChoice::named("ros2")));
        let vehicle = config.vehicle.clone().unwrap();
        assert_eq!(vehicle.kind, "mavlink");
        assert_eq!(vehicle.settings.len(), 1);
        let text = toml::to_string(&config).unwrap();
        let back: RobotConfig = toml::from_str(&text).unwrap();
        assert_eq!(back, config);
        let e = toml::from_str::<RobotConfig>("[sensor]\npath = \"x\"\n").unwrap_err();
        assert!(e.to_string().contains("kind"), "{e}");
        // Defaults write nothing new.
        let text = toml::to_string(&RobotConfig::default()).unwrap();
        let table: toml::Table = toml::from_str(&text).unwrap();
        for key in ["sensor", "vehicle", "actors"] {
            assert!(!table.contains_key(key), "{key} in {text}");
        }
    }
}
