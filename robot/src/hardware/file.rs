//! The hardware robot file: reading, checking, resolving its paths.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use troupe_algorithms::camera::PinholeIntrinsics;
use troupe_comms::zenoh::ZenohConfig;
use troupe_record::{Compression, check_rate_hz};

use crate::harness::HarnessError;
use crate::mavlink::MavlinkConfig;
use crate::ros2::{Ros2Config, Ros2Error};
use crate::toml_file::{
    KEYFRAME_POLICY_KEY, SettingsFileError, TomlFileError, names_key, parse_toml,
};
use crate::{AssembleError, ConfigError, RobotConfig};

/// A hardware robot file as written (see the [module docs](crate::hardware) and
/// `robot/examples/hardware_robot.toml`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HardwareFile {
    /// This robot's index in the team: its id on the link, `robot<id>` in logs.
    pub id: u32,
    /// Robots in the team (ids `0..team_size`); list the ones to keep plans and maps
    /// for from the start in `[robot.link] peers`.
    pub team_size: u32,
    /// Wall seconds to run; absent: until SIGINT or SIGTERM (`--duration-s` overrides).
    #[serde(default)]
    pub duration_s: Option<f64>,
    /// Output directory, relative to the robot file; default `hw<id>/` next to it.
    #[serde(default)]
    pub out: Option<PathBuf>,
    /// The standard robot's settings (the tables of a scenario's `[robot]`).
    #[serde(default)]
    pub robot: RobotConfig,
    /// The depth camera's intrinsics for the planner; absent: taken from the first
    /// depth frame (its `CameraInfo`) at start.
    #[serde(default)]
    pub camera: Option<PinholeIntrinsics>,
    /// The ROS 2 drivers (camera and odometry in; plan, map, status out).
    pub ros2: Ros2Config,
    /// The flight controller.
    pub mavlink: MavlinkConfig,
    /// The team link's zenoh session (the same table as a simulated robot file's).
    #[serde(default)]
    pub zenoh: ZenohConfig,
    /// Write `out/run.mcap`: what the robot published (poses, plans, keyframes, link
    /// status) in Foxglove's schemas, in wall time; `false` turns it off.
    #[serde(default = "record_by_default")]
    pub record: bool,
    /// Depth frames recorded per second (`/robot<id>/depth`, `32FC1` metres, about
    /// 4 bytes a pixel before compression); 0, the default, records none.
    #[serde(default)]
    pub record_depth_hz: f64,
    /// How `run.mcap`'s chunks are compressed: `"zstd"` (the default), `"lz4"` or
    /// `"none"`.
    #[serde(default)]
    pub record_compression: Compression,
}

fn record_by_default() -> bool {
    true
}

/// A checked robot file with its paths resolved.
#[derive(Clone, Debug)]
pub struct HardwareRobot {
    /// The robot file (names it in errors).
    pub path: PathBuf,
    /// The file's settings, paths made relative to the working directory.
    pub file: HardwareFile,
    /// Where `summary.json` and `events.csv` go.
    pub out: PathBuf,
}

/// Why a hardware robot could not start or finish.
#[derive(Debug, thiserror::Error)]
pub enum HardwareError {
    /// The robot file cannot be read, does not have the expected shape, or a value
    /// breaks a rule; a rule's source names the dotted key (`id`, `camera`,
    /// `robot.speed_mps`, `mavlink.setpoint_rate_hz`, `ros2.topics.depth`).
    #[error(transparent)]
    File(#[from] SettingsFileError),
    /// The ROS 2 drivers could not start (a silent topic names itself here).
    #[error("starting the ROS 2 drivers")]
    Ros2(#[from] Ros2Error),
    /// No depth frame arrived to take the camera's calibration from.
    #[error(
        "no depth frame paired with odometry arrived within {timeout_s} s to take the camera \
         intrinsics from (check odometry stamps and `ros2.odometry_tolerance_s`, or set \
         `[camera]`)"
    )]
    NoCalibration {
        /// The startup timeout, seconds.
        timeout_s: f64,
    },
    /// The robot could not be assembled.
    #[error("assembling the robot")]
    Assemble(#[from] AssembleError),
    /// The harness could not open the link's journal, the team link or the
    /// recording, or could not write the outputs.
    #[error(transparent)]
    Harness(#[from] HarnessError),
    /// The MAVLink vehicle gave up waiting for the autopilot (`[mavlink]
    /// autopilot_wait_s`, `control_wait_s`); the outputs were written.
    #[error("the MAVLink vehicle gave up after {setpoints} setpoints")]
    Vehicle {
        /// Why.
        source: crate::mavlink::GaveUp,
        /// Setpoints sent before it gave up.
        setpoints: u64,
    },
}

impl HardwareRobot {
    /// Reads, checks and resolves a robot file.
    pub fn load(path: &Path) -> Result<Self, HardwareError> {
        let text = std::fs::read_to_string(path).map_err(|source| {
            SettingsFileError::from(TomlFileError::Read {
                path: path.to_path_buf(),
                source,
            })
        })?;
        let base = path.parent().unwrap_or(Path::new("."));
        Self::from_toml(&text, path, base)
    }

    /// Parses and checks a robot file's text; `path` names it in errors and relative
    /// paths are resolved against `base`.
    pub fn from_toml(text: &str, path: &Path, base: &Path) -> Result<Self, HardwareError> {
        let mut file: HardwareFile = parse_toml(text, path).map_err(SettingsFileError::from)?;
        file.robot.link = file
            .robot
            .link
            .with_process_keyframes(names_key(text, KEYFRAME_POLICY_KEY));
        share_geofence(&mut file).map_err(|e| SettingsFileError::config(path, e))?;
        resolve_zenoh(&mut file.zenoh, base);
        resolve_zenoh(&mut file.ros2.zenoh, base);
        file.validate(path)?;
        let out = base.join(
            file.out
                .clone()
                .unwrap_or_else(|| PathBuf::from(format!("hw{}", file.id))),
        );
        Ok(HardwareRobot {
            path: path.to_path_buf(),
            file,
            out,
        })
    }
}

impl HardwareFile {
    /// Checks every table; errors name the file and the key.
    pub fn validate(&self, path: &Path) -> Result<(), HardwareError> {
        let config = |e: ConfigError| HardwareError::from(SettingsFileError::config(path, e));
        if self.id >= self.team_size {
            return Err(config(ConfigError::new(
                "id",
                format!("must be below `team_size` ({})", self.team_size),
                self.id,
            )));
        }
        if let Some(d) = self.duration_s {
            ConfigError::positive("duration_s", d).map_err(config)?;
        }
        check_rate_hz("record_depth_hz", self.record_depth_hz).map_err(config)?;
        if let Some(c) = &self.camera {
            let positive = [c.fx, c.fy, c.max_depth_m]
                .iter()
                .all(|v| v.is_finite() && *v > 0.0);
            let centre = c.cx.is_finite() && c.cy.is_finite();
            if !(positive && centre && c.width > 0 && c.height > 0) {
                return Err(config(ConfigError::new(
                    "camera",
                    "needs width, height > 0 and finite fx, fy, max_depth_m > 0, cx, cy",
                    format!("{c:?}"),
                )));
            }
        }
        self.robot
            .validate()
            .map_err(|e| config(e.within("robot")))?;
        self.ros2.validate().map_err(|e| config(e.within("ros2")))?;
        self.mavlink
            .validate()
            .map_err(|e| config(e.within("mavlink")))?;
        for (table, zenoh) in [("zenoh", &self.zenoh), ("ros2.zenoh", &self.ros2.zenoh)] {
            zenoh
                .validate()
                .map_err(|e| SettingsFileError::zenoh(path, table, e))?;
        }
        Ok(())
    }
}

/// The one fence of a robot file, `[mavlink.geofence]`, feeds both the MAVLink
/// vehicle's setpoint clamp and the collision actor's plan check
/// (`robot.collision.geofence`), which may therefore be left out or repeat it.
fn share_geofence(file: &mut HardwareFile) -> Result<(), ConfigError> {
    let fence = file.mavlink.geofence;
    match file.robot.collision.geofence.replace(fence) {
        Some(other) if other != fence => Err(ConfigError::new(
            "robot.collision.geofence",
            "must be left out: a hardware robot's fence is `[mavlink.geofence]` (it \
             feeds both the plan check and the setpoint clamp)",
            format!("min_m = {:?}, max_m = {:?}", other.min_m, other.max_m),
        )),
        _ => Ok(()),
    }
}

/// Makes the TLS and password-file paths of a zenoh table relative to `base`.
fn resolve_zenoh(zenoh: &mut ZenohConfig, base: &Path) {
    zenoh.resolve_paths(base);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example_path() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/hardware_robot.toml")
    }

    fn example_text() -> String {
        std::fs::read_to_string(example_path()).unwrap()
    }

    fn load(text: &str) -> Result<HardwareRobot, HardwareError> {
        HardwareRobot::from_toml(text, Path::new("hw.toml"), Path::new("/robots"))
    }

    /// The error and its causes on one line, as the binary prints them.
    fn chain(e: &dyn std::error::Error) -> String {
        let mut text = e.to_string();
        let mut cause = e.source();
        while let Some(c) = cause {
            text = format!("{text}: {c}");
            cause = c.source();
        }
        text
    }

    #[test]
    fn the_example_file_parses_and_validates() {
        let robot = HardwareRobot::load(&example_path()).unwrap();
        let f = &robot.file;
        assert_eq!(f.id, 0);
        assert!(f.team_size >= 1);
        assert_eq!(f.mavlink.connection, "udpin:0.0.0.0:14540");
        assert_eq!(
            f.ros2.topics.depth.as_deref(),
            Some("/camera/depth/image_rect_raw")
        );
        let camera = f.camera.unwrap();
        assert_eq!((camera.width, camera.height), (848, 480));
        assert!(f.mavlink.setpoint_rate_hz >= 20.0);
        // The one fence feeds the plan check too.
        assert_eq!(f.robot.collision.geofence, Some(f.mavlink.geofence));
        assert_eq!(f.record_depth_hz, 0.0);
        assert_eq!(f.record_compression, troupe_record::Compression::Zstd);
        assert!(
            robot
                .out
                .starts_with(Path::new(env!("CARGO_MANIFEST_DIR")).join("examples"))
        );
    }

    #[test]
    fn relative_paths_are_resolved_against_the_file() {
        let base = std::env::temp_dir().join(format!("troupe-hw-file-{}", std::process::id()));
        std::fs::create_dir_all(base.join("certs")).unwrap();
        for name in ["ca.pem", "hw0.pem", "hw0.key"] {
            std::fs::write(base.join("certs").join(name), "").unwrap();
        }
        let text = example_text()
            .replace(
                "[zenoh]\n",
                "[zenoh]\ntls = { root_ca_path = \"certs/ca.pem\", cert_path = \"certs/hw0.pem\", \
                 key_path = \"certs/hw0.key\" }\n",
            )
            .replace("listen = [\"tcp/", "listen = [\"tls/");
        let robot = HardwareRobot::from_toml(&text, Path::new("hw.toml"), &base).unwrap();
        let tls = robot.file.zenoh.tls.unwrap();
        assert_eq!(tls.root_ca_path, base.join("certs/ca.pem"));
        assert_eq!(tls.key_path, base.join("certs/hw0.key"));
        assert_eq!(robot.out, base.join("runs/hw0"));
        // Missing files are named.
        let e = load(&text).unwrap_err();
        assert!(
            chain(&e).contains("/robots/certs/ca.pem is not a readable file"),
            "{}",
            chain(&e)
        );
        std::fs::remove_dir_all(base).unwrap();
    }

    #[test]
    fn bad_files_name_the_key() {
        let text = example_text();
        let cases = [
            (
                text.replace("team_size = 3", "team_size = 0"),
                "hw.toml: invalid setting: `id` must be below",
            ),
            (
                text.replacen("id = 0", "id = 0\nspeed = 1", 1),
                "unknown field `speed`",
            ),
            (
                text.replace("setpoint_rate_hz = 30.0", "setpoint_rate_hz = 5.0"),
                "invalid setting: `mavlink.setpoint_rate_hz` must be in [20, 200] Hz, got 5",
            ),
            (
                text.replace("sensor_rate_hz = 15.0", "sensor_rate_hz = -1.0"),
                "invalid setting: `robot.sensor_rate_hz`",
            ),
            (text.replace("fx = ", "fx = -"), "`camera` needs"),
            (
                text.replacen("id = 0", "id = 0\nduration_s = -1.0", 1),
                "`duration_s` must be",
            ),
            (text.replacen("id = 0", "id = \"zero\"", 1), "`id`, line 8"),
            (
                text.replacen("id = 0", "id = 0\nrecord_depth_hz = 90.0", 1),
                "`record_depth_hz` must be between 0 and 30 Hz, got 90",
            ),
            (
                text.replacen("id = 0", "id = 0\nrecord_compression = \"gzip\"", 1),
                "unknown variant `gzip`, expected one of `zstd`, `lz4`, `none`",
            ),
            (
                text.replace("connect = [\"tcp/10", "connect = [\"nowhere\", \"tcp/10"),
                "invalid `[zenoh]` table",
            ),
            (
                text.replace("odometry = \"/odom\"", ""),
                "missing field `odometry`",
            ),
            (
                text.replace(
                    "[robot.collision]\n",
                    "[robot.collision]\ngeofence = { min_m = [0.0, 0.0, 0.0], max_m = [1.0, 1.0, 1.0] }\n",
                ),
                "`robot.collision.geofence` must be left out",
            ),
        ];
        for (text, expected) in cases {
            let e = load(&text).unwrap_err();
            assert!(
                chain(&e).contains(expected),
                "{expected:?} not in {:?}",
                chain(&e)
            );
        }
    }

    #[test]
    fn a_vehicle_that_gave_up_is_one_line_saying_why_once() {
        let e = HardwareError::Vehicle {
            source: crate::mavlink::GaveUp::NoAutopilot {
                connection: "udpin:0.0.0.0:14540".into(),
                wait_s: 10.0,
            },
            setpoints: 0,
        };
        let line = chain(&e);
        assert!(
            line.starts_with(
                "the MAVLink vehicle gave up after 0 setpoints: no autopilot heartbeat on \
                 `udpin:0.0.0.0:14540` within 10 s of the start"
            ),
            "{line}"
        );
        assert_eq!(line.matches("no autopilot heartbeat").count(), 1, "{line}");
    }
}
