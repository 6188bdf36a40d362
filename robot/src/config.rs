//! A robot's configuration (the `[robot]` table of a scenario, or a robot file).

use serde::{Deserialize, Serialize};
use troupe_actors::artifacts::ArtifactsConfig;
use troupe_actors::collision::CollisionActorConfig;
use troupe_actors::link::LinkConfig;
use troupe_actors::mapper::MapperConfig;
use troupe_actors::planner::{PlannerConfig, ScriptedCommand};
use troupe_algorithms::collision::body::BodyConfig;
use troupe_algorithms::collision::geofence::GeofenceConfig;
use troupe_algorithms::grid::GridConfig;
use troupe_algorithms::planner::teleop::TeleopParams;
use troupe_policies::priority::PriorityConfig;
use troupe_runtime::RestartPolicy;

/// The `behaviour` value that selects the grid + planner pipeline.
pub const PLANNER: &str = "planner";

/// The `behaviour` value that selects the local grid + teleoperation (thesis §5):
/// commands on `teleop/command` are mapped to the closest safe primitive (the
/// planner's limits, safety margin, rate and knot spacing apply).
pub const TELEOP: &str = "teleop";

/// Modelled compute latency per standard actor, seconds (sim-time executor).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ActorLatencies {
    /// Vehicle.
    pub vehicle: f64,
    /// Sensor (capture + rendering).
    pub sensor: f64,
    /// Explorer / planner.
    pub explorer: f64,
    /// Link.
    pub link: f64,
    /// Local grid (ray tracing and distance fields).
    pub grid: f64,
    /// Planner (one round).
    pub planner: f64,
    /// Mapper (one keyframe fit; thesis Table 4.1: 0.4 s).
    pub mapper: f64,
    /// Collision actor (one round's checks).
    pub collision: f64,
}

impl Default for ActorLatencies {
    fn default() -> Self {
        ActorLatencies {
            vehicle: 0.0,
            sensor: 0.01,
            explorer: 0.01,
            link: 0.0,
            grid: 0.05,
            planner: 0.1,
            mapper: 0.4,
            collision: 0.005,
        }
    }
}

/// The `[robot.collision]` table: the collision actor between planning and the vehicle
/// (thesis §7, §8.2.3). On by default (part of the standard robot).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CollisionConfig {
    /// Whether the robot has a collision actor (plans then go through it).
    pub enabled: bool,
    /// The body ellipsoid (`[robot.collision.body]`); its bounding radius is the
    /// clearance required in the local grid's distance field.
    pub body: BodyConfig,
    /// Extra clearance from unsafe space, metres.
    pub margin_m: f64,
    /// Spacing of the distance-field samples, seconds.
    pub check_step_s: f64,
    /// The box no committed plan may leave (`geofence = { min_m = [x, y, z], max_m =
    /// [x, y, z] }`, world frame, metres); absent: none. A hardware robot takes it
    /// from `[mavlink.geofence]`, which also clamps its setpoints.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub geofence: Option<GeofenceConfig>,
    /// Take the base station's hold / resume / velocity commands for this robot
    /// (`troupe base`, docs/base-station.md): adds the operator actor; off by default.
    pub operator_commands: bool,
    /// Inter-robot avoidance (`[robot.collision.peers]`): priority, cylinder size,
    /// check radius, sample cap, stale-plan age. Its priority is also the one the link
    /// sends with this robot's plans.
    pub peers: PriorityConfig,
}

impl Default for CollisionConfig {
    fn default() -> Self {
        let check = CollisionActorConfig::default();
        CollisionConfig {
            enabled: true,
            body: check.body,
            margin_m: check.margin_m,
            check_step_s: check.check_step_s,
            geofence: check.geofence,
            operator_commands: false,
            peers: PriorityConfig::default(),
        }
    }
}

impl CollisionConfig {
    /// The collision actor's own settings.
    #[must_use]
    pub fn actor(&self) -> CollisionActorConfig {
        CollisionActorConfig {
            body: self.body.clone(),
            margin_m: self.margin_m,
            check_step_s: self.check_step_s,
            geofence: self.geofence,
        }
    }
}

/// How a robot shares its map with its peers (thesis §8.2.5–§8.2.7 compares the
/// first two under the same planning).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MapSharing {
    /// The mapper's keyframe GMMs (§8.2.2).
    #[default]
    Gmm,
    /// Occupancy-grid change sets: the cells each own depth frame changed (the "OG"
    /// baseline, §8.2.5); keyframes stay local.
    Grid,
    /// Nothing: each robot maps alone (plans and odometry are still shared).
    None,
}

/// Teleoperation settings (`behaviour = "teleop"`, thesis §5.1.2). Commands arrive
/// on `teleop/command` from a joystick driver or another actor; a non-empty `script`
/// adds a `joystick` actor that plays it, so a scenario file alone can fly the robot.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TeleopSettings {
    /// Command library and Eq. 5.1 speed adaptation.
    pub params: TeleopParams,
    /// Scripted commands (v_x, v_z, ω from `from_s` on); empty: none.
    pub script: Vec<ScriptedCommand>,
    /// Rate at which the script publishes its command in force, Hz.
    pub command_rate_hz: f64,
}

impl Default for TeleopSettings {
    fn default() -> Self {
        TeleopSettings {
            params: TeleopParams::default(),
            script: Vec::new(),
            command_rate_hz: 5.0,
        }
    }
}

/// Everything that shapes one robot.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RobotConfig {
    /// How the robot decides where to go: a route behaviour by name (see
    /// `troupe_policies::BEHAVIOURS`), or `"planner"` for the local grid and the
    /// information-driven motion-primitive planner.
    pub behaviour: String,
    /// Action selection of the planner (see `troupe_policies::SELECTIONS`).
    pub selection: String,
    /// The local grid (planner behaviour).
    pub grid: GridConfig,
    /// The planner (planner behaviour).
    pub planner: PlannerConfig,
    /// Teleoperation (teleop behaviour): the command library and, optionally, a
    /// scripted operator.
    pub teleop: TeleopSettings,
    /// The SOGMM mapper (keyframes shared over the link); on by default.
    pub mapper: MapperConfig,
    /// The collision actor and inter-robot avoidance; on by default.
    pub collision: CollisionConfig,
    /// What the link shares of the map: `"gmm"` (keyframes, the default), `"grid"`
    /// (occupancy change sets) or `"none"`.
    pub map_sharing: MapSharing,
    /// Cruise speed, m/s.
    pub speed_mps: f64,
    /// Turn-in-place rate, rad/s.
    pub yaw_rate_rad_s: f64,
    /// How often the explorer replans, Hz.
    pub replan_rate_hz: f64,
    /// Camera frame rate, Hz (default 5 Hz; a hardware robot's file usually gives its
    /// camera's rate).
    pub sensor_rate_hz: f64,
    /// Frames wider than this are decimated before anything reads them, pixels: one
    /// pixel per block, the block's nearest return (`DepthFrame::decimated`), and the
    /// planner scores views with the decimated intrinsics. The default, 160, is the
    /// thesis' SOGMM frame (160 × 120): a 640 × 480 camera then costs the mapper, grid
    /// and planner what the simulated camera does (a full-size frame cost 16× as much
    /// and made planning rounds miss their lead). 0: frames as they come.
    pub sensor_max_width_px: u32,
    /// Body radius used for collision checks against the world, metres.
    pub radius_m: f64,
    /// Link settings.
    pub link: LinkConfig,
    /// The optional artifact reporter (`enabled = true` runs it).
    pub artifacts: ArtifactsConfig,
    /// Modelled compute latencies.
    pub latency_s: ActorLatencies,
    /// What happens when an actor panics.
    pub restart: RestartPolicy,
    /// The sensor driver, by its registered name (`sensor = "sim_camera"`), or a table
    /// with its name under `kind` and its own settings (`[robot.sensor] kind =
    /// "sequence"`, `path = "…"`); absent: the process's own (the simulated camera in
    /// `troupe run` and `troupe robot`, ROS 2 in `troupe-robot`). See
    /// [`crate::registry`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sensor: Option<PartChoice>,
    /// The vehicle driver, by its registered name (`vehicle = "sim"`) or as a table
    /// like `sensor`; absent: the process's own (the simulated vehicle, or MAVLink in
    /// `troupe-robot`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vehicle: Option<PartChoice>,
    /// Extra actors, each by its registered name and its own settings
    /// (`[[robot.actors]] kind = "odometer"`, …), added after the standard ones in
    /// this order.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub actors: Vec<PartChoice>,
}

/// A part of a robot chosen by name from the registry ([`crate::registry`]): written
/// as its name alone (`sensor = "sim_camera"`) or as a table with the name under
/// `kind` and the part's own settings beside it (`[robot.sensor] kind = "flaky"`,
/// `dropout = 0.1`), which its factory reads
/// ([`PartContext::settings`](crate::registry::PartContext::settings)).
///
/// ```
/// use troupe_robot::PartChoice;
///
/// let short: PartChoice = toml::from_str::<toml::Table>("p = \"sim\"").unwrap()["p"].clone().try_into().unwrap();
/// assert_eq!(short, PartChoice::named("sim"));
/// let long: PartChoice = toml::from_str("kind = \"flaky\"\ndropout = 0.5\n").unwrap();
/// assert_eq!(long.kind, "flaky");
/// assert_eq!(long.settings["dropout"].as_float(), Some(0.5));
/// ```
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PartChoice {
    /// The part's registered name.
    pub kind: String,
    /// Its own settings (every key of its table but `kind`).
    pub settings: toml::Table,
}

impl PartChoice {
    /// The part called `kind`, with no settings of its own.
    #[must_use]
    pub fn named(kind: impl Into<String>) -> Self {
        PartChoice {
            kind: kind.into(),
            settings: toml::Table::new(),
        }
    }
}

impl Serialize for PartChoice {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap as _;
        if self.settings.is_empty() {
            return serializer.serialize_str(&self.kind);
        }
        let mut map = serializer.serialize_map(Some(self.settings.len() + 1))?;
        map.serialize_entry("kind", &self.kind)?;
        for (key, value) in &self.settings {
            map.serialize_entry(key, value)?;
        }
        map.end()
    }
}

impl<'de> Deserialize<'de> for PartChoice {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        use serde::de::Error as _;
        match toml::Value::deserialize(deserializer)? {
            toml::Value::String(kind) => Ok(PartChoice::named(kind)),
            toml::Value::Table(mut settings) => match settings.remove("kind") {
                Some(toml::Value::String(kind)) => Ok(PartChoice { kind, settings }),
                _ => Err(D::Error::custom(
                    "a part's table needs `kind = \"<registered name>\"`",
                )),
            },
            other => Err(D::Error::custom(format!(
                "expected a part's name (\"sim_camera\") or a table with `kind`, got {}",
                other.type_str()
            ))),
        }
    }
}

impl Default for RobotConfig {
    fn default() -> Self {
        RobotConfig {
            behaviour: PLANNER.into(),
            selection: "greedy".into(),
            grid: GridConfig::default(),
            planner: PlannerConfig::default(),
            teleop: TeleopSettings::default(),
            mapper: MapperConfig::default(),
            collision: CollisionConfig::default(),
            map_sharing: MapSharing::default(),
            speed_mps: 1.0,
            yaw_rate_rad_s: 1.0,
            replan_rate_hz: 1.0,
            sensor_rate_hz: 5.0,
            sensor_max_width_px: 160,
            radius_m: 0.3,
            link: LinkConfig::default(),
            artifacts: ArtifactsConfig::default(),
            latency_s: ActorLatencies::default(),
            restart: RestartPolicy::default(),
            sensor: None,
            vehicle: None,
            actors: Vec::new(),
        }
    }
}

pub use troupe_core::ConfigError;

fn positive(key: &str, value: f64) -> Result<(), ConfigError> {
    ConfigError::positive(key, value)
}

fn non_negative(key: &str, value: f64) -> Result<(), ConfigError> {
    ConfigError::non_negative(key, value)
}

impl RobotConfig {
    /// Checks every number; the error names the key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        positive("speed_mps", self.speed_mps)?;
        positive("yaw_rate_rad_s", self.yaw_rate_rad_s)?;
        positive("replan_rate_hz", self.replan_rate_hz)?;
        positive("sensor_rate_hz", self.sensor_rate_hz)?;
        if (1..16).contains(&self.sensor_max_width_px) {
            return Err(ConfigError::new(
                "sensor_max_width_px",
                "must be 0 (no decimation) or ≥ 16 pixels",
                self.sensor_max_width_px,
            ));
        }
        positive("radius_m", self.radius_m)?;
        self.link.validate().map_err(|e| e.within("link"))?;
        self.artifacts
            .validate()
            .map_err(|e| e.within("artifacts"))?;
        non_negative("latency_s.vehicle", self.latency_s.vehicle)?;
        non_negative("latency_s.sensor", self.latency_s.sensor)?;
        non_negative("latency_s.explorer", self.latency_s.explorer)?;
        non_negative("latency_s.link", self.latency_s.link)?;
        non_negative("latency_s.grid", self.latency_s.grid)?;
        non_negative("latency_s.planner", self.latency_s.planner)?;
        non_negative("latency_s.mapper", self.latency_s.mapper)?;
        non_negative("latency_s.collision", self.latency_s.collision)?;
        if self.collision.operator_commands && !self.collision.enabled {
            return Err(ConfigError::new(
                "collision.operator_commands",
                "needs the collision actor (`collision.enabled = true`), which holds the robot",
                true,
            ));
        }
        self.collision
            .actor()
            .validate()
            .map_err(|e| e.within("collision"))?;
        self.collision
            .peers
            .validate()
            .map_err(|e| e.within("collision.peers"))?;
        self.mapper.validate().map_err(|e| e.within("mapper"))?;
        if self.map_sharing == MapSharing::Grid && !self.grid.trace_depth_frames {
            return Err(ConfigError::new(
                "map_sharing",
                "\"grid\" needs grid.trace_depth_frames = true (change sets are the cells own frames changed)",
                "\"grid\"",
            ));
        }
        self.grid.validate().map_err(|e| e.within("grid"))?;
        positive("planner.rate_hz", self.planner.rate_hz)?;
        positive("planner.knot_step_s", self.planner.knot_step_s)?;
        non_negative("planner.lead_s", self.planner.lead_s)?;
        if self.planner.lead_s >= 1.0 / self.planner.rate_hz {
            return Err(ConfigError::new(
                "planner.lead_s",
                "must be shorter than the replanning period (1 / planner.rate_hz)",
                self.planner.lead_s,
            ));
        }
        positive(
            "planner.round.planning_period_s",
            self.planner.round.planning_period_s,
        )?;
        non_negative(
            "planner.round.collision_radius_m",
            self.planner.round.collision_radius_m,
        )?;
        self.planner
            .guidance
            .validate()
            .map_err(|e| e.within("planner.guidance"))?;
        self.planner
            .mission
            .validate()
            .map_err(|e| e.within("planner.mission"))?;
        if !troupe_policies::SELECTIONS.contains(&self.selection.as_str()) {
            return Err(ConfigError::new(
                "selection",
                "must name a known action selection (greedy, random)",
                format!("{:?}", self.selection),
            ));
        }
        positive("teleop.command_rate_hz", self.teleop.command_rate_hz)?;
        positive(
            "teleop.params.max_speed_mps",
            self.teleop.params.max_speed_mps,
        )?;
        positive("teleop.params.decel_mps2", self.teleop.params.decel_mps2)?;
        non_negative("teleop.params.latency_s", self.teleop.params.latency_s)?;
        for (i, c) in self.teleop.script.iter().enumerate() {
            let values = [c.from_s, c.vx_mps, c.vz_mps, c.yaw_rate_rad_s];
            if values.iter().any(|v| !v.is_finite()) || c.from_s < 0.0 {
                return Err(ConfigError::new(
                    format!("teleop.script[{i}]"),
                    "must have finite speeds and from_s >= 0",
                    format!("{c:?}"),
                ));
            }
        }
        non_negative("restart.window_s", self.restart.window_s)?;
        if self.behaviour != PLANNER
            && self.behaviour != TELEOP
            && !troupe_policies::BEHAVIOURS.contains(&self.behaviour.as_str())
        {
            return Err(ConfigError::new(
                "behaviour",
                "must be \"planner\", \"teleop\" or a known route behaviour (waypoint_route)",
                format!("{:?}", self.behaviour),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_bad_values_name_their_key() {
        RobotConfig::default().validate().unwrap();
        let c = RobotConfig {
            speed_mps: f64::NAN,
            ..RobotConfig::default()
        };
        assert_eq!(c.validate().unwrap_err().key, "speed_mps");
        let mut c = RobotConfig::default();
        c.latency_s.sensor = -1.0;
        assert_eq!(c.validate().unwrap_err().key, "latency_s.sensor");
        let mut c = RobotConfig::default();
        c.planner.lead_s = 1.0; // a whole replanning period at 1 Hz
        assert_eq!(c.validate().unwrap_err().key, "planner.lead_s");
        let c = RobotConfig {
            behaviour: "x".into(),
            ..RobotConfig::default()
        };
        assert_eq!(c.validate().unwrap_err().key, "behaviour");
        let mut c = RobotConfig::default();
        c.collision.peers.max_samples = 1;
        assert_eq!(c.validate().unwrap_err().key, "collision.peers.max_samples");
        let mut c = RobotConfig::default();
        c.collision.body.semi_axes_m = [0.3, 0.0, 0.1];
        assert_eq!(c.validate().unwrap_err().key, "collision.body");
        let mut c = RobotConfig::default();
        c.planner.guidance.cell_m = f64::NAN;
        assert_eq!(c.validate().unwrap_err().key, "planner.guidance.cell_m");
    }

    #[test]
    fn teleop_scripts_parse_and_bad_commands_name_their_entry() {
        let c: RobotConfig = toml::from_str(
            "behaviour = \"teleop\"\n[teleop]\nscript = [{ from_s = 0.0, vx_mps = 1.0, vz_mps = 0.0, yaw_rate_rad_s = 0.1 }]\n",
        )
        .unwrap();
        c.validate().unwrap();
        assert_eq!(c.teleop.script.len(), 1);
        let mut bad = c.clone();
        bad.teleop.script[0].vx_mps = f64::NAN;
        assert_eq!(bad.validate().unwrap_err().key, "teleop.script[0]");
        bad.teleop.script[0].vx_mps = 1.0;
        bad.teleop.script[0].from_s = -1.0;
        assert_eq!(bad.validate().unwrap_err().key, "teleop.script[0]");
    }

    #[test]
    fn collision_table_parses_with_defaults() {
        let c: RobotConfig = toml::from_str(
            "[collision]\nenabled = true\n[collision.peers]\npriority = 3\ncylinder_radius_m = 0.5\n",
        )
        .unwrap();
        assert!(c.collision.enabled);
        assert_eq!(c.collision.peers.priority, 3);
        assert_eq!(
            c.collision.peers.max_samples,
            PriorityConfig::default().max_samples
        );
        c.validate().unwrap();
    }
}
