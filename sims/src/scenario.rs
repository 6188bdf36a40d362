//! Scenario files: what `troupe run` simulates.
//!
//! A scenario is a TOML file; every table and key is optional and defaults to the
//! built-in default scenario (two robots exploring a procedural cave for 120 s).
//! Unknown keys are errors, and every error names the file and the key.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use troupe_comms::simnet::SimNetConfig;
use troupe_core::ConfigError;
use troupe_record::Compression;
use troupe_robot::RobotConfig;
use troupe_robot::base::TeamSettings;
use troupe_robot::toml_file::{TomlFileError, parse_toml};

use crate::camera::{CameraBackend, CameraParams};
pub use crate::faults::Fault;
use crate::vehicle::VehicleConfig;
pub use crate::world::{WorldConfig, WorldKind};

/// Ground-truth metrics.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MetricsConfig {
    /// Edge of a coverage cell, metres.
    pub coverage_cell_m: f64,
    /// Every n-th pixel (in u and v) is traced for coverage.
    pub coverage_pixel_stride: usize,
    /// Period of the time series, seconds.
    pub sample_period_s: f64,
    /// Cell edges at which to count what the occupancy-grid baseline would send for
    /// each robot's own depth frames, whatever the robot shares (thesis §8.2.6,
    /// Table 8.1: 0.1, 0.05, 0.025 m); reported in `summary.json` as `og_change_sets`.
    /// Empty (the default): not counted. Memory grows with the cells observed.
    pub og_change_set_resolutions_m: Vec<f64>,
    /// Write `run.mcap`, a recording of the run in Foxglove's schemas
    /// (`docs/recordings.md`); `false` turns it off. `troupe run` only (a sweep's
    /// runs are not recorded).
    pub record: bool,
    /// Recorded local grids (occupied cells, frontiers) and remembered frontiers per
    /// robot per second; 0 records none.
    pub record_grid_hz: f64,
    /// Recorded depth frames per robot per second (`foxglove.RawImage`, about 100 kB
    /// each at the default 160 × 120); 0, the default, records none.
    pub record_depth_hz: f64,
    /// How `run.mcap`'s chunks are compressed: `"zstd"` (the default), `"lz4"` or
    /// `"none"`.
    pub record_compression: Compression,
}

impl Default for MetricsConfig {
    fn default() -> Self {
        MetricsConfig {
            coverage_cell_m: 0.4,
            coverage_pixel_stride: 4,
            sample_period_s: 1.0,
            og_change_set_resolutions_m: Vec::new(),
            record: true,
            record_grid_hz: 1.0,
            record_depth_hz: 0.0,
            record_compression: Compression::default(),
        }
    }
}

/// A whole scenario.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Scenario {
    /// Name; outputs go to `runs/<name>/`.
    pub name: String,
    /// Run seed: seeds every actor's generator and the camera noise.
    pub seed: u64,
    /// Simulated duration, seconds.
    pub duration_s: f64,
    /// Number of robots.
    pub robots: u32,
    /// World.
    pub world: WorldConfig,
    /// Camera of every robot.
    pub camera: CameraParams,
    /// Every robot's configuration.
    pub robot: RobotConfig,
    /// The simulated vehicle of every robot.
    pub vehicle: VehicleConfig,
    /// The simulated network between robots (`[network.default]` for every pair,
    /// `[[network.pairs]]` overrides, `[[network.partitions]]`).
    pub network: SimNetConfig,
    /// Metrics.
    pub metrics: MetricsConfig,
    /// Scheduled faults.
    pub faults: Vec<Fault>,
}

impl Default for Scenario {
    fn default() -> Self {
        Scenario {
            name: "default".into(),
            seed: 1,
            duration_s: 120.0,
            robots: 2,
            world: WorldConfig::default(),
            camera: CameraParams::standard(),
            robot: RobotConfig::default(),
            vehicle: VehicleConfig::default(),
            network: SimNetConfig::default(),
            metrics: MetricsConfig::default(),
            faults: Vec::new(),
        }
    }
}

/// Why a scenario was not accepted.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// The file cannot be read, is not TOML, or has an unknown key or a value of the
    /// wrong type.
    #[error(transparent)]
    File(#[from] TomlFileError),
    /// Parsed, but a value breaks a rule.
    #[error("scenario file `{path}`: key `{key}` {reason}")]
    Invalid {
        /// File (`<built-in>` for the default).
        path: PathBuf,
        /// Dotted key.
        key: String,
        /// The rule and the value.
        reason: String,
    },
}

impl Scenario {
    /// Reads and validates a scenario file.
    pub fn load(path: &Path) -> Result<Scenario, ScenarioError> {
        Scenario::load_with_text(path).map(|(scenario, _)| scenario)
    }

    /// Reads and validates a scenario file, and returns its text too (for what
    /// depends on which keys the file names, such as a robot process's keyframe
    /// policy).
    pub fn load_with_text(path: &Path) -> Result<(Scenario, String), ScenarioError> {
        let text = std::fs::read_to_string(path).map_err(|source| TomlFileError::Read {
            path: path.to_owned(),
            source,
        })?;
        Ok((Scenario::from_toml(&text, path)?, text))
    }

    /// Parses and validates scenario text; `path` is only used in messages.
    pub fn from_toml(text: &str, path: &Path) -> Result<Scenario, ScenarioError> {
        let mut scenario: Scenario = parse_toml(text, path)?;
        // A mesh file is named relative to the scenario file.
        let mesh = &mut scenario.world.mesh.path;
        if mesh.is_relative()
            && !mesh.as_os_str().is_empty()
            && let Some(dir) = path.parent().filter(|d| d.is_dir())
        {
            *mesh = dir.join(&*mesh);
        }
        scenario.validate(path)?;
        Ok(scenario)
    }

    /// The team as a base station sees it: name, robots, seed and `[robot]`.
    #[must_use]
    pub fn team(&self) -> TeamSettings {
        TeamSettings {
            name: self.name.clone(),
            robots: self.robots,
            seed: self.seed,
            robot: self.robot.clone(),
        }
    }

    /// Checks that every reader of the camera's frames stays on the pixels it renders
    /// ([`CameraParams::render_stride`]: a pixel not rendered reads as no return): the
    /// grid's, mapper's and coverage meter's strides are multiples of it, and it is 1
    /// when the artifact detector (which reads every pixel) runs. [`Self::validate`]
    /// and [`crate::team::Team::new`] both apply it.
    ///
    /// # Errors
    ///
    /// The offending key, its rule and its value.
    pub fn check_render_stride(&self) -> Result<(), ConfigError> {
        let render_stride = u64::from(self.camera.render_stride);
        for (key, stride) in [
            (
                "robot.grid.pixel_stride",
                u64::from(self.robot.grid.pixel_stride),
            ),
            (
                "robot.mapper.pixel_stride",
                u64::from(self.robot.mapper.pixel_stride),
            ),
            (
                "metrics.coverage_pixel_stride",
                self.metrics.coverage_pixel_stride as u64,
            ),
        ] {
            if stride % render_stride.max(1) != 0 {
                return Err(ConfigError::new(
                    key,
                    format!(
                        "must be a multiple of camera.render_stride ({render_stride}): the \
                         camera renders no other pixel"
                    ),
                    stride,
                ));
            }
        }
        if self.robot.artifacts.enabled && render_stride != 1 {
            return Err(ConfigError::new(
                "camera.render_stride",
                "must be 1 with [robot.artifacts] enabled: the artifact detector reads every \
                 pixel",
                render_stride,
            ));
        }
        Ok(())
    }

    /// Checks every value; the error names the key.
    pub fn validate(&self, path: &Path) -> Result<(), ScenarioError> {
        let invalid = |key: &str, reason: String| ScenarioError::Invalid {
            path: path.to_owned(),
            key: key.to_string(),
            reason,
        };
        if self.name.is_empty()
            || !self
                .name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_' || c == '.')
            || self.name.starts_with('.')
        {
            return Err(invalid(
                "name",
                format!(
                    "must be non-empty and use only letters, digits, `-`, `_`, `.`; got {:?}",
                    self.name
                ),
            ));
        }
        if !(self.duration_s.is_finite() && self.duration_s > 0.0 && self.duration_s <= 1e6) {
            return Err(invalid(
                "duration_s",
                format!("must be in (0, 1e6] seconds, got {}", self.duration_s),
            ));
        }
        if !(1..=64).contains(&self.robots) {
            return Err(invalid(
                "robots",
                format!("must be between 1 and 64, got {}", self.robots),
            ));
        }
        let config = |table: &str, e: ConfigError| {
            let e = e.within(table);
            invalid(&e.key, format!("{}, got {}", e.rule, e.value))
        };
        self.world.validate().map_err(|e| config("world", e))?;
        self.camera.validate().map_err(|e| config("camera", e))?;
        if self.world.artifacts.count > 0 && self.camera.backend == CameraBackend::Gpu {
            return Err(invalid(
                "camera.backend",
                "must be \"cpu\" or \"auto\" in a world with [world.artifacts]: the GPU \
                 camera has no artifacts (their reflectance, 4.0, is outside the [0, 1] \
                 albedo the GPU shader renders), so such a world renders on the CPU; got \"gpu\""
                    .to_owned(),
            ));
        }
        self.robot.validate().map_err(|e| config("robot", e))?;
        self.vehicle.validate().map_err(|e| config("vehicle", e))?;
        self.network.validate().map_err(|e| config("network", e))?;
        let m = &self.metrics;
        if !(m.coverage_cell_m.is_finite() && m.coverage_cell_m >= 0.05) {
            return Err(invalid(
                "metrics.coverage_cell_m",
                format!("must be ≥ 0.05 m, got {}", m.coverage_cell_m),
            ));
        }
        if m.coverage_pixel_stride == 0 {
            return Err(invalid(
                "metrics.coverage_pixel_stride",
                "must be ≥ 1, got 0".into(),
            ));
        }
        self.check_render_stride()
            .map_err(|e| invalid(&e.key, format!("{}, got {}", e.rule, e.value)))?;
        if !(m.sample_period_s.is_finite() && m.sample_period_s >= 0.01) {
            return Err(invalid(
                "metrics.sample_period_s",
                format!("must be ≥ 0.01 s, got {}", m.sample_period_s),
            ));
        }
        for (key, hz) in [
            ("metrics.record_grid_hz", m.record_grid_hz),
            ("metrics.record_depth_hz", m.record_depth_hz),
        ] {
            if !(hz.is_finite() && (0.0..=30.0).contains(&hz)) {
                return Err(invalid(
                    key,
                    format!("must be between 0 and 30 Hz, got {hz}"),
                ));
            }
        }
        for (i, r) in m.og_change_set_resolutions_m.iter().enumerate() {
            if !(r.is_finite() && *r >= 0.01) {
                return Err(invalid(
                    &format!("metrics.og_change_set_resolutions_m[{i}]"),
                    format!("must be ≥ 0.01 m, got {r}"),
                ));
            }
        }
        for (i, fault) in self.faults.iter().enumerate() {
            fault
                .validate(self.robots)
                .map_err(|(key, reason)| invalid(&format!("faults[{i}].{key}"), reason))?;
        }
        Ok(())
    }
}

/// Reads and validates a scenario file for its team (`troupe base`'s team reader,
/// [`troupe_robot::base::BaseStation::load`]).
pub fn load_team(path: &Path) -> Result<TeamSettings, ScenarioError> {
    Scenario::load(path).map(|s| s.team())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Scenario, ScenarioError> {
        Scenario::from_toml(text, Path::new("s.toml"))
    }

    /// The dotted paths of every table in `value` (arrays of tables left out).
    fn table_paths(value: &toml::Value, path: &mut Vec<String>, out: &mut Vec<String>) {
        if let toml::Value::Table(table) = value {
            if !path.is_empty() {
                out.push(
                    path.iter()
                        .map(|k| format!("{k:?}"))
                        .collect::<Vec<_>>()
                        .join("."),
                );
            }
            for (key, child) in table {
                path.push(key.clone());
                table_paths(child, path, out);
                path.pop();
            }
        }
    }

    #[test]
    fn a_table_written_with_no_keys_reads_as_the_default() {
        // A nested table's own defaults are the ones its parent gives it, so that
        // setting one key of a table (`[robot.planner.round.library_params]
        // yaw_both_ways = true`) changes that key and nothing else.
        let default = Scenario::default();
        let mut paths = Vec::new();
        table_paths(
            &toml::Value::try_from(&default).unwrap(),
            &mut Vec::new(),
            &mut paths,
        );
        assert!(paths.len() > 40, "{paths:?}");
        let differ: Vec<&String> = paths
            .iter()
            .filter(|path| parse(&format!("[{path}]\n")).is_ok_and(|s| s != default))
            .collect();
        assert!(
            differ.is_empty(),
            "read as other than the default: {differ:?}"
        );
    }

    #[test]
    fn shipped_scenarios_parse() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios");
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            Scenario::load(&path).unwrap_or_else(|e| panic!("{e}"));
        }
        let default =
            Scenario::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/default.toml"))
                .unwrap();
        assert_eq!(
            default,
            Scenario::default(),
            "scenarios/default.toml must spell out the built-in default"
        );
    }

    #[test]
    fn a_partial_camera_table_changes_only_the_keys_it_names() {
        let scenario = parse("[camera]\nbackend = \"cpu\"\nwidth = 80\n").unwrap();
        assert_eq!(
            scenario.camera,
            CameraParams {
                backend: CameraBackend::Cpu,
                width: 80,
                ..CameraParams::standard()
            }
        );
        assert_eq!(
            parse("[camera]\n").unwrap().camera,
            Scenario::default().camera
        );
        assert_ne!(CameraParams::standard(), CameraParams::default());
    }

    #[test]
    fn a_team_assembled_in_code_is_held_to_the_render_stride_too() {
        let mut scenario = Scenario {
            duration_s: 1.0,
            ..Scenario::default()
        };
        scenario.robot.artifacts.enabled = true;
        let e = crate::team::Team::new(&scenario).err().expect("refused");
        assert!(e.to_string().contains("camera.render_stride"), "{e}");
        scenario.camera.render_stride = 1;
        assert!(crate::team::Team::new(&scenario).is_ok());
    }

    #[test]
    fn empty_file_is_the_default() {
        assert_eq!(parse("").unwrap(), Scenario::default());
    }

    #[test]
    fn errors_name_file_and_key() {
        let e = parse("robotz = 3").unwrap_err().to_string();
        assert!(e.contains("s.toml") && e.contains("robotz"), "{e}");
        let e = parse("robots = -1").unwrap_err().to_string();
        assert!(e.contains("s.toml") && e.contains("`robots`"), "{e}");
        let e = parse("robots = \"two\"").unwrap_err().to_string();
        assert!(e.contains("`robots`"), "{e}");
        let e = parse("[robot]\nspeed_mps = -1.0").unwrap_err().to_string();
        assert!(e.contains("`robot.speed_mps`"), "{e}");
        let e = parse("robots = 0").unwrap_err().to_string();
        assert!(e.contains("`robots`"), "{e}");
        let e =
            parse("[[faults]]\nkind = \"actor_panic\"\nrobot = 5\nactor = \"sensor\"\nat_s = 1.0")
                .unwrap_err()
                .to_string();
        assert!(e.contains("faults[0].robot"), "{e}");
        let e = parse("name = \"../x\"").unwrap_err().to_string();
        assert!(e.contains("`name`"), "{e}");
        let e = parse("duration_s = nan").unwrap_err().to_string();
        assert!(e.contains("`duration_s`"), "{e}");
        let e = parse("[world.cave]\ntunnel_count = 0")
            .unwrap_err()
            .to_string();
        assert!(
            e.ends_with("key `world.cave.tunnel_count` must be at least 1, got 0"),
            "{e}"
        );
        let e = parse("[world.artifacts]\ncount = 2000")
            .unwrap_err()
            .to_string();
        assert!(
            e.ends_with("key `world.artifacts.count` must be at most 1000, got 2000"),
            "{e}"
        );
        let e = parse("[camera]\nwidth = 0").unwrap_err().to_string();
        assert!(
            e.contains("`camera.width` must be at least 1, got 0"),
            "{e}"
        );
        let e = parse("[camera]\nbackend = \"gpu\"\n[world.artifacts]\ncount = 2")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("`camera.backend`") && e.contains("artifacts"),
            "{e}"
        );
        parse("[camera]\nbackend = \"auto\"\n[world.artifacts]\ncount = 2").unwrap();
    }
}
