//! The `[mavlink]` configuration section and its validation.

use mavlink::ConnectionAddress;
use serde::{Deserialize, Serialize};

use crate::ConfigError;
use crate::safety::{Geofence, GeofenceConfig};

/// Where the robot's odometry comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OdometrySource {
    /// The autopilot's estimate (`LOCAL_POSITION_NED` + `ATTITUDE`), published by the
    /// MAVLink vehicle on `odometry`.
    #[default]
    Autopilot,
    /// Another driver (e.g. a ROS 2 VIO source) publishes `odometry`; the vehicle only
    /// watches it. Its world frame must be the autopilot's local frame (ENU), as when
    /// the VIO estimate is also fed to the autopilot.
    External,
}

/// The `[mavlink]` section: how to reach the autopilot and the safety limits.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MavlinkConfig {
    /// Connection string as the `mavlink` crate reads it: `udpin:0.0.0.0:14540`,
    /// `udpout:192.168.1.10:14580`, `tcpout:127.0.0.1:5760`, `tcpin:0.0.0.0:5760`,
    /// `serial:/dev/ttyACM0:921600`.
    pub connection: String,
    /// This program's MAVLink system id (usually the vehicle's own).
    #[serde(default = "default_source_system_id")]
    pub source_system_id: u8,
    /// This program's component id (191: onboard computer).
    #[serde(default = "default_source_component_id")]
    pub source_component_id: u8,
    /// The autopilot's system id; absent: taken from the first autopilot heartbeat.
    #[serde(default)]
    pub target_system_id: Option<u8>,
    /// The autopilot's component id; absent: taken from the first autopilot heartbeat.
    #[serde(default)]
    pub target_component_id: Option<u8>,
    /// Setpoint stream rate, Hz (PX4 leaves offboard below 2 Hz; at least 20).
    #[serde(default = "default_setpoint_rate_hz")]
    pub setpoint_rate_hz: f64,
    /// Longest gap between autopilot heartbeats before setpoints stop, seconds.
    #[serde(default = "default_heartbeat_timeout_s")]
    pub heartbeat_timeout_s: f64,
    /// Longest gap between depth frames before the vehicle holds, seconds.
    #[serde(default = "default_sensor_timeout_s")]
    pub sensor_timeout_s: f64,
    /// Longest gap between odometry messages before the vehicle holds, seconds.
    #[serde(default = "default_odometry_timeout_s")]
    pub odometry_timeout_s: f64,
    /// Where odometry comes from.
    #[serde(default)]
    pub odometry_source: OdometrySource,
    /// No autopilot heartbeat within this long after the start: the robot stops with
    /// an error (exit status 1), seconds; 0: it waits for ever.
    #[serde(default = "default_autopilot_wait_s")]
    pub autopilot_wait_s: f64,
    /// The autopilot not armed and in OFFBOARD (PX4) or GUIDED (ArduPilot) within this
    /// long after the start: the robot stops with an error, seconds; 0: it waits for
    /// ever. Until the pilot hands control over the robot holds where the vehicle is
    /// and plans nothing (after the first hand-over, it waits for as long as the pilot
    /// flies, whatever this says).
    #[serde(default = "default_control_wait_s")]
    pub control_wait_s: f64,
    /// The box no setpoint may leave (required).
    pub geofence: GeofenceConfig,
}

fn default_source_system_id() -> u8 {
    1
}
fn default_source_component_id() -> u8 {
    191
}
fn default_setpoint_rate_hz() -> f64 {
    30.0
}
fn default_heartbeat_timeout_s() -> f64 {
    3.0
}
fn default_sensor_timeout_s() -> f64 {
    1.0
}
fn default_odometry_timeout_s() -> f64 {
    0.5
}
fn default_autopilot_wait_s() -> f64 {
    10.0
}
fn default_control_wait_s() -> f64 {
    120.0
}

/// A checked [`MavlinkConfig`].
#[derive(Clone, Debug, PartialEq)]
pub struct MavlinkSettings {
    /// The connection string (parsed once to check it).
    pub connection: String,
    /// This program's system id.
    pub source_system_id: u8,
    /// This program's component id.
    pub source_component_id: u8,
    /// The autopilot's system id, if fixed.
    pub target_system_id: Option<u8>,
    /// The autopilot's component id, if fixed.
    pub target_component_id: Option<u8>,
    /// Setpoint stream rate, Hz.
    pub setpoint_rate_hz: f64,
    /// Heartbeat timeout, seconds.
    pub heartbeat_timeout_s: f64,
    /// Depth frame timeout, seconds.
    pub sensor_timeout_s: f64,
    /// Odometry timeout, seconds.
    pub odometry_timeout_s: f64,
    /// Where odometry comes from.
    pub odometry_source: OdometrySource,
    /// How long to wait for the autopilot's first heartbeat, seconds (0: for ever).
    pub autopilot_wait_s: f64,
    /// How long to wait for the pilot's first hand-over, seconds (0: for ever).
    pub control_wait_s: f64,
    /// The fence.
    pub geofence: Geofence,
}

/// Lowest accepted setpoint rate, Hz.
pub const MIN_SETPOINT_RATE_HZ: f64 = 20.0;
/// Highest accepted setpoint rate, Hz.
pub const MAX_SETPOINT_RATE_HZ: f64 = 200.0;

fn in_range(
    key: &'static str,
    value: f64,
    lo: f64,
    hi: f64,
    rule: &'static str,
) -> Result<(), ConfigError> {
    if value.is_finite() && value >= lo && value <= hi {
        Ok(())
    } else {
        Err(ConfigError::new(key, rule, value))
    }
}

fn nonzero_id(key: &'static str, id: Option<u8>) -> Result<(), ConfigError> {
    if id == Some(0) {
        Err(ConfigError::new(
            key,
            "must be 1..=255 (0 is the broadcast id)",
            0,
        ))
    } else {
        Ok(())
    }
}

impl MavlinkConfig {
    /// A configuration with the defaults, the given connection and fence.
    #[must_use]
    pub fn new(connection: impl Into<String>, geofence: GeofenceConfig) -> Self {
        MavlinkConfig {
            connection: connection.into(),
            source_system_id: default_source_system_id(),
            source_component_id: default_source_component_id(),
            target_system_id: None,
            target_component_id: None,
            setpoint_rate_hz: default_setpoint_rate_hz(),
            heartbeat_timeout_s: default_heartbeat_timeout_s(),
            sensor_timeout_s: default_sensor_timeout_s(),
            odometry_timeout_s: default_odometry_timeout_s(),
            odometry_source: OdometrySource::default(),
            autopilot_wait_s: default_autopilot_wait_s(),
            control_wait_s: default_control_wait_s(),
            geofence,
        }
    }

    /// Checks every value; the error names the key.
    pub fn validate(&self) -> Result<MavlinkSettings, ConfigError> {
        let bad_connection = || {
            ConfigError::new(
                "connection",
                "must be udpin:HOST:PORT, udpout:HOST:PORT, udpbcast:HOST:PORT, \
                   tcpin:HOST:PORT, tcpout:HOST:PORT or serial:DEVICE:BAUD",
                format!("{:?}", self.connection),
            )
        };
        let address =
            ConnectionAddress::parse_address(&self.connection).map_err(|_| bad_connection())?;
        if !matches!(
            address,
            ConnectionAddress::Serial(_) | ConnectionAddress::File(_)
        ) {
            let port = self.connection.rsplit_once(':').map(|(_, port)| port);
            if port.and_then(|p| p.parse::<u16>().ok()).is_none() {
                return Err(bad_connection());
            }
        }
        if self.connection.starts_with("file:") {
            return Err(ConfigError::new(
                "connection",
                "must be a live link (udp, tcp or serial), not a file",
                format!("{:?}", self.connection),
            ));
        }
        nonzero_id("source_system_id", Some(self.source_system_id))?;
        nonzero_id("target_system_id", self.target_system_id)?;
        in_range(
            "setpoint_rate_hz",
            self.setpoint_rate_hz,
            MIN_SETPOINT_RATE_HZ,
            MAX_SETPOINT_RATE_HZ,
            "must be in [20, 200] Hz",
        )?;
        in_range(
            "heartbeat_timeout_s",
            self.heartbeat_timeout_s,
            0.1,
            60.0,
            "must be in [0.1, 60] s",
        )?;
        in_range(
            "sensor_timeout_s",
            self.sensor_timeout_s,
            0.05,
            60.0,
            "must be in [0.05, 60] s",
        )?;
        in_range(
            "odometry_timeout_s",
            self.odometry_timeout_s,
            0.05,
            60.0,
            "must be in [0.05, 60] s",
        )?;
        for (key, value) in [
            ("autopilot_wait_s", self.autopilot_wait_s),
            ("control_wait_s", self.control_wait_s),
        ] {
            in_range(
                key,
                value,
                0.0,
                3600.0,
                "must be in [0, 3600] s (0: for ever)",
            )?;
        }
        let geofence = self.geofence.fence().map_err(|e| e.within("geofence"))?;
        Ok(MavlinkSettings {
            connection: self.connection.clone(),
            source_system_id: self.source_system_id,
            source_component_id: self.source_component_id,
            target_system_id: self.target_system_id,
            target_component_id: self.target_component_id,
            setpoint_rate_hz: self.setpoint_rate_hz,
            heartbeat_timeout_s: self.heartbeat_timeout_s,
            sensor_timeout_s: self.sensor_timeout_s,
            odometry_timeout_s: self.odometry_timeout_s,
            odometry_source: self.odometry_source,
            autopilot_wait_s: self.autopilot_wait_s,
            control_wait_s: self.control_wait_s,
            geofence,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;

    const EXAMPLE: &str = r#"
        connection = "udpin:0.0.0.0:14540"
        target_system_id = 1
        setpoint_rate_hz = 30.0
        sensor_timeout_s = 0.5
        odometry_source = "external"
        [geofence]
        min_m = [-10.0, -10.0, 0.0]
        max_m = [10.0, 10.0, 4.0]
    "#;

    fn parse(text: &str) -> Result<MavlinkConfig, toml::de::Error> {
        toml::from_str(text)
    }

    #[test]
    fn parses_and_validates_with_defaults() {
        let config = parse(EXAMPLE).unwrap();
        let settings = config.validate().unwrap();
        assert_eq!(settings.source_component_id, 191);
        assert_eq!(settings.target_system_id, Some(1));
        assert_eq!(settings.target_component_id, None);
        assert_eq!(settings.odometry_source, OdometrySource::External);
        assert_eq!(settings.heartbeat_timeout_s, 3.0);
        assert!(settings.geofence.contains(&Point3::new(0.0, 0.0, 1.0)));
    }

    #[test]
    fn the_documented_example_is_valid() {
        let page = include_str!("../../../docs/hardware-mavlink.md");
        let start = page.find("```toml\n").expect("a toml block") + "```toml\n".len();
        let end = start + page[start..].find("```").expect("the block ends");
        let table: toml::Table = toml::from_str(&page[start..end]).unwrap();
        let config: MavlinkConfig = table["mavlink"].clone().try_into().unwrap();
        let settings = config.validate().unwrap();
        assert_eq!(settings.connection, "udpin:0.0.0.0:14540");
        assert_eq!(settings.setpoint_rate_hz, 30.0);
        assert_eq!(settings.odometry_source, OdometrySource::Autopilot);
    }

    #[test]
    fn rejects_unknown_keys_and_missing_fence() {
        let err = parse(&EXAMPLE.replace("setpoint_rate_hz", "setpoint_rate")).unwrap_err();
        assert!(
            err.to_string().contains("unknown field `setpoint_rate`"),
            "{err}"
        );
        let err = parse("connection = \"udpin:0.0.0.0:14540\"").unwrap_err();
        assert!(
            err.to_string().contains("missing field `geofence`"),
            "{err}"
        );
    }

    #[test]
    fn errors_name_the_key_in_one_line() {
        let fence = GeofenceConfig {
            min_m: [0.0; 3],
            max_m: [1.0; 3],
        };
        let check = |edit: &dyn Fn(&mut MavlinkConfig)| {
            let mut c = MavlinkConfig::new("udpin:127.0.0.1:14540", fence);
            edit(&mut c);
            c.validate().unwrap_err()
        };
        let e = check(&|c| c.setpoint_rate_hz = 10.0);
        assert_eq!(
            e.to_string(),
            "`setpoint_rate_hz` must be in [20, 200] Hz, got 10"
        );
        let e = check(&|c| c.sensor_timeout_s = f64::NAN);
        assert_eq!(e.key, "sensor_timeout_s");
        let e = check(&|c| c.connection = "carrier-pigeon:1".into());
        assert_eq!(e.key, "connection");
        assert!(!e.to_string().contains('\n'));
        let e = check(&|c| c.connection = "udpin:127.0.0.1".into());
        assert_eq!(e.key, "connection");
        let e = check(&|c| c.connection = "file:/tmp/log.tlog".into());
        assert_eq!(e.key, "connection");
        let e = check(&|c| c.target_system_id = Some(0));
        assert_eq!(e.key, "target_system_id");
        let e = check(&|c| c.geofence.max_m[2] = -1.0);
        assert_eq!(e.key, "geofence");
        let e = check(&|c| c.odometry_timeout_s = 0.0);
        assert_eq!(e.key, "odometry_timeout_s");
        let e = check(&|c| c.heartbeat_timeout_s = -1.0);
        assert_eq!(e.key, "heartbeat_timeout_s");
    }
}
