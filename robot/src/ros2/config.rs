//! The `[ros2]` table of a hardware robot file.

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use serde::{Deserialize, Serialize};
use troupe_algorithms::camera::PinholeIntrinsics;
use troupe_comms::zenoh::ZenohConfig;

use crate::ConfigError;

use super::keyexpr::{BridgeNamespace, KeyFormat, NAMESPACE_RULE, WireFormat, strip_topic};

/// ROS topic names (absolute, e.g. `/camera/depth/image_rect_raw`). Depth comes
/// either from `depth` + `camera_info` (+ optional `intensity`) or from `points`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ros2Topics {
    /// `sensor_msgs/Image` depth, 16UC1 (mm) or 32FC1 (m).
    pub depth: Option<String>,
    /// `sensor_msgs/CameraInfo` of the depth image.
    pub camera_info: Option<String>,
    /// `sensor_msgs/Image` intensity (infrared), mono8 or mono16, registered to depth.
    pub intensity: Option<String>,
    /// `sensor_msgs/PointCloud2` in the camera's optical frame, instead of `depth`.
    pub points: Option<String>,
    /// `nav_msgs/Odometry` of the body (ENU world, FLU body).
    pub odometry: String,
    /// Where the committed plan goes (`nav_msgs/Path`); none: not published.
    pub plan: Option<String>,
    /// Where keyframe maps go (`sensor_msgs/PointCloud2`); none: not published.
    pub map: Option<String>,
    /// Where status goes (`std_msgs/String`, JSON); none: not published.
    pub status: Option<String>,
    /// Where the vehicle's state goes (`diagnostic_msgs/DiagnosticArray`: armed, mode,
    /// whether it holds and why, setpoint rate, heartbeat age; ROS's convention is
    /// `/diagnostics`); none: not published.
    pub diagnostics: Option<String>,
}

/// The camera extrinsics: the pose of the depth camera's optical frame (z forward,
/// x right, y down) in the body frame, as `tf2_echo base_link <optical frame>`
/// prints it. The default is a camera at the body origin looking along body +x.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Extrinsics {
    /// Translation, metres.
    pub translation_m: [f64; 3],
    /// Rotation as a quaternion `[x, y, z, w]` (normalised on use).
    pub rotation_xyzw: [f64; 4],
}

impl Default for Extrinsics {
    fn default() -> Self {
        Extrinsics {
            translation_m: [0.0; 3],
            rotation_xyzw: [-0.5, 0.5, -0.5, 0.5],
        }
    }
}

impl Extrinsics {
    /// The optical frame's pose in the body; `None` if not finite or a zero quaternion.
    #[must_use]
    pub fn isometry(&self) -> Option<Isometry3<f64>> {
        let [x, y, z, w] = self.rotation_xyzw;
        let all = self.translation_m.iter().chain(&self.rotation_xyzw);
        let q = Quaternion::new(w, x, y, z);
        if !all.clone().all(|v| v.is_finite()) || q.norm() < 1e-9 {
            return None;
        }
        let [tx, ty, tz] = self.translation_m;
        Some(Isometry3::from_parts(
            Translation3::new(tx, ty, tz),
            UnitQuaternion::from_quaternion(q),
        ))
    }
}

/// The `[ros2]` table: how a hardware robot's ROS 2 drivers reach zenoh.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ros2Config {
    /// `"rmw_zenoh"` or `"bridge"` (zenoh-bridge-ros2dds).
    pub format: WireFormat,
    /// `ROS_DOMAIN_ID` (rmw_zenoh keys start with it).
    #[serde(default)]
    pub domain_id: u32,
    /// With `format = "bridge"` only: the namespace zenoh-bridge-ros2dds runs with
    /// (`-n`/`--namespace`). The bridge puts it in front of every key, so every topic
    /// is read and written at `<namespace>/<topic without its leading />`
    /// (`"/drone1"` + `/camera/depth/image` → `drone1/camera/depth/image`). Leading
    /// `/` optional; `"/"` (the bridge's default) and absent mean none. Refused with
    /// `format = "rmw_zenoh"`, where a namespace is part of each topic name.
    #[serde(default)]
    pub bridge_namespace: Option<String>,
    /// Topic names.
    pub topics: Ros2Topics,
    /// Depth encodings accepted (subset of `16UC1`, `32FC1`).
    #[serde(default = "default_depth_encodings")]
    pub depth_encodings: Vec<String>,
    /// Intensity encodings accepted (subset of `mono8`, `mono16`).
    #[serde(default = "default_intensity_encodings")]
    pub intensity_encodings: Vec<String>,
    /// Camera extrinsics.
    #[serde(default)]
    pub extrinsics: Extrinsics,
    /// Intrinsics to project `points` into (required with `topics.points`).
    #[serde(default)]
    pub points_intrinsics: Option<PinholeIntrinsics>,
    /// Depths beyond this are no return, metres (D435-like: 5).
    #[serde(default = "default_max_depth_m")]
    pub max_depth_m: f64,
    /// A configured input topic silent for this long after start is an error, seconds.
    #[serde(default = "default_startup_timeout_s")]
    pub startup_timeout_s: f64,
    /// A frame is paired with the odometry nearest its stamp, if within this, seconds.
    #[serde(default = "default_odometry_tolerance_s")]
    pub odometry_tolerance_s: f64,
    /// An intensity image is paired with the depth image nearest its stamp, if within this.
    #[serde(default = "default_intensity_tolerance_s")]
    pub intensity_tolerance_s: f64,
    /// Odometry messages kept for pairing (a bounded history).
    #[serde(default = "default_odometry_history")]
    pub odometry_history: usize,
    /// `frame_id` of what we publish in the world frame (plan, map).
    #[serde(default = "default_world_frame_id")]
    pub world_frame_id: String,
    /// Period of the status message, seconds.
    #[serde(default = "default_status_period_s")]
    pub status_period_s: f64,
    /// Points drawn per keyframe map cloud.
    #[serde(default = "default_map_points")]
    pub map_points: usize,
    /// Messages waiting for the publishing thread before new ones are dropped.
    #[serde(default = "default_send_queue")]
    pub send_queue: usize,
    /// The node name our rmw_zenoh liveliness tokens announce.
    #[serde(default = "default_node_name")]
    pub node_name: String,
    /// zenoh endpoints (peer/client, listen/connect, TLS, auth), like `[link.zenoh]`.
    #[serde(default)]
    pub zenoh: ZenohConfig,
}

fn default_depth_encodings() -> Vec<String> {
    vec!["16UC1".into(), "32FC1".into()]
}
fn default_intensity_encodings() -> Vec<String> {
    vec!["mono8".into(), "mono16".into()]
}
fn default_max_depth_m() -> f64 {
    5.0
}
fn default_startup_timeout_s() -> f64 {
    10.0
}
fn default_odometry_tolerance_s() -> f64 {
    0.05
}
fn default_intensity_tolerance_s() -> f64 {
    0.005
}
fn default_odometry_history() -> usize {
    200
}
fn default_world_frame_id() -> String {
    "odom".into()
}
fn default_status_period_s() -> f64 {
    1.0
}
fn default_map_points() -> usize {
    2000
}
fn default_send_queue() -> usize {
    16
}
fn default_node_name() -> String {
    "troupe".into()
}

impl Ros2Config {
    /// The key format of these settings; an error names `bridge_namespace` if it is
    /// invalid or set with rmw_zenoh.
    pub fn key_format(&self) -> Result<KeyFormat, ConfigError> {
        let namespace = match (self.format, &self.bridge_namespace) {
            (_, None) => BridgeNamespace::ROOT,
            (WireFormat::Bridge, Some(ns)) => BridgeNamespace::new(ns).map_err(|_| {
                ConfigError::new("bridge_namespace", NAMESPACE_RULE, format!("{ns:?}"))
            })?,
            (WireFormat::RmwZenoh, Some(ns)) => {
                return Err(ConfigError::new(
                    "bridge_namespace",
                    "applies to `format = \"bridge\"` only: under rmw_zenoh a namespace is \
                     part of each topic name (e.g. `/drone1/odom`)",
                    format!("{ns:?}"),
                ));
            }
        };
        Ok(KeyFormat {
            format: self.format,
            domain_id: self.domain_id,
            namespace,
        })
    }

    /// Checks every setting except the zenoh table (its own `validate`); the error
    /// names the key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.key_format()?;
        self.validate_topics()?;
        for (key, list, known) in [
            ("depth_encodings", &self.depth_encodings, ["16UC1", "32FC1"]),
            (
                "intensity_encodings",
                &self.intensity_encodings,
                ["mono8", "mono16"],
            ),
        ] {
            if list.is_empty() {
                return Err(ConfigError::new(
                    key,
                    "must list at least one encoding",
                    "[]",
                ));
            }
            if let Some(bad) = list.iter().find(|e| !known.contains(&e.as_str())) {
                return Err(ConfigError::new(
                    key,
                    format!("must list supported encodings ({})", known.join(", ")),
                    format!("{bad:?}"),
                ));
            }
        }
        if self.extrinsics.isometry().is_none() {
            return Err(ConfigError::new(
                "extrinsics",
                "needs a finite translation and a non-zero quaternion",
                format!("{:?}", self.extrinsics),
            ));
        }
        ConfigError::positive("max_depth_m", self.max_depth_m)?;
        ConfigError::positive("startup_timeout_s", self.startup_timeout_s)?;
        ConfigError::positive("odometry_tolerance_s", self.odometry_tolerance_s)?;
        ConfigError::positive("intensity_tolerance_s", self.intensity_tolerance_s)?;
        ConfigError::positive("status_period_s", self.status_period_s)?;
        for (key, n) in [
            ("odometry_history", self.odometry_history),
            ("send_queue", self.send_queue),
        ] {
            if n == 0 {
                return Err(ConfigError::new(key, "must be at least 1", n));
            }
        }
        if self.world_frame_id.is_empty() {
            return Err(ConfigError::new(
                "world_frame_id",
                "must not be empty",
                "\"\"",
            ));
        }
        if self.node_name.is_empty()
            || !self
                .node_name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_')
        {
            return Err(ConfigError::new(
                "node_name",
                "must be a ROS node name (ASCII letters, digits, `_`)",
                format!("{:?}", self.node_name),
            ));
        }
        Ok(())
    }

    /// The topics: each a valid name, and either a depth image with its camera info
    /// or a point cloud with the intrinsics to project it into.
    fn validate_topics(&self) -> Result<(), ConfigError> {
        let t = &self.topics;
        let named = [
            ("topics.depth", &t.depth),
            ("topics.camera_info", &t.camera_info),
            ("topics.intensity", &t.intensity),
            ("topics.points", &t.points),
            ("topics.plan", &t.plan),
            ("topics.map", &t.map),
            ("topics.status", &t.status),
            ("topics.diagnostics", &t.diagnostics),
        ];
        for (key, topic) in named
            .iter()
            .filter_map(|(k, v)| v.as_deref().map(|v| (*k, v)))
            .chain([("topics.odometry", t.odometry.as_str())])
        {
            strip_topic(topic)
                .map_err(|e| ConfigError::new(key, e.to_string(), format!("{topic:?}")))?;
        }
        match (&t.depth, &t.camera_info, &t.points) {
            (Some(_), Some(_), None) => {}
            (None, None, Some(_)) => {
                if t.intensity.is_some() {
                    return Err(ConfigError::new(
                        "topics.intensity",
                        "goes with `depth`; a point cloud carries its own intensity field",
                        format!("{:?}", t.intensity),
                    ));
                }
                let Some(k) = self.points_intrinsics else {
                    return Err(ConfigError::new(
                        "points_intrinsics",
                        "is required with `topics.points` (the image to project into)",
                        "nothing",
                    ));
                };
                let ok = k.width > 0
                    && k.height > 0
                    && [k.fx, k.fy].iter().all(|f| f.is_finite() && *f > 0.0)
                    && k.cx.is_finite()
                    && k.cy.is_finite();
                if !ok {
                    return Err(ConfigError::new(
                        "points_intrinsics",
                        "needs a non-empty image and finite, positive focal lengths",
                        format!("{k:?}"),
                    ));
                }
            }
            (Some(_), None, _) => {
                return Err(ConfigError::new(
                    "topics.camera_info",
                    "is required with `depth`",
                    "nothing",
                ));
            }
            _ => {
                return Err(ConfigError::new(
                    "topics",
                    "must set either `depth` and `camera_info`, or `points`",
                    format!("{t:?}"),
                ));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Ros2Config, toml::de::Error> {
        toml::from_str(text)
    }

    const MINIMAL: &str = r#"
        format = "rmw_zenoh"
        [topics]
        depth = "/camera/depth/image_rect_raw"
        camera_info = "/camera/depth/camera_info"
        odometry = "/odom"
    "#;

    #[test]
    fn a_minimal_table_gets_d435_like_defaults() {
        let c = parse(MINIMAL).unwrap();
        c.validate().unwrap();
        assert_eq!(c.format, WireFormat::RmwZenoh);
        assert_eq!(c.domain_id, 0);
        assert_eq!(c.bridge_namespace, None);
        assert_eq!(c.key_format().unwrap().namespace, BridgeNamespace::ROOT);
        assert_eq!(c.max_depth_m, 5.0);
        assert_eq!(c.depth_encodings, ["16UC1", "32FC1"]);
        // The default extrinsics put the camera body frame on the body frame.
        let camera = crate::ros2::convert::camera_pose(
            &Isometry3::identity(),
            &c.extrinsics.isometry().unwrap(),
        );
        assert!((camera.rotation.angle()).abs() < 1e-12);
    }

    #[test]
    fn unknown_keys_are_rejected() {
        let err = parse(&format!("{MINIMAL}\nspeed = 3")).unwrap_err();
        assert!(err.to_string().contains("speed"), "{err}");
        let err = parse("format = \"dds\"\n[topics]\nodometry = \"/o\"").unwrap_err();
        assert!(err.to_string().contains("dds"), "{err}");
    }

    #[test]
    fn invalid_values_name_their_key() {
        let cases: [(&str, &str); 8] = [
            ("max_depth_m = nan", "max_depth_m"),
            ("odometry_tolerance_s = -1.0", "odometry_tolerance_s"),
            ("depth_encodings = [\"bgr8\"]", "depth_encodings"),
            ("intensity_encodings = []", "intensity_encodings"),
            ("send_queue = 0", "send_queue"),
            ("node_name = \"a b\"", "node_name"),
            (
                "extrinsics = { rotation_xyzw = [0.0, 0.0, 0.0, 0.0] }",
                "extrinsics",
            ),
            ("world_frame_id = \"\"", "world_frame_id"),
        ];
        for (line, key) in cases {
            let text = MINIMAL.replacen("[topics]", &format!("{line}\n[topics]"), 1);
            let err = parse(&text).unwrap().validate().unwrap_err();
            assert_eq!(err.key, key, "{line}: {err}");
            assert!(
                err.to_string().starts_with(&format!("`{key}`")),
                "{line}: {err}"
            );
        }
        let text = MINIMAL.replacen(
            "[topics]",
            "zenoh = { listen = [\"carrier-pigeon\"] }\n[topics]",
            1,
        );
        assert!(parse(&text).unwrap().zenoh.validate().is_err());
    }

    #[test]
    fn topic_sets_must_be_complete() {
        let no_info = MINIMAL.replace("camera_info = \"/camera/depth/camera_info\"", "");
        let err = parse(&no_info).unwrap().validate().unwrap_err();
        assert_eq!(err.key, "topics.camera_info");
        let bad_name = MINIMAL.replace("\"/odom\"", "\"/odom/\"");
        let err = parse(&bad_name).unwrap().validate().unwrap_err();
        assert_eq!(err.key, "topics.odometry");
        let points = r#"
            format = "bridge"
            [topics]
            points = "/camera/depth/points"
            odometry = "/odom"
        "#;
        let err = parse(points).unwrap().validate().unwrap_err();
        assert_eq!(err.key, "points_intrinsics");
        let with_k = format!(
            "points_intrinsics = {{ width = 8, height = 6, fx = 4.0, fy = 4.0, cx = 4.0, \
             cy = 3.0, max_depth_m = 5.0 }}\n{points}"
        );
        parse(&with_k).unwrap().validate().unwrap();
    }

    #[test]
    fn the_bridge_namespace_prefixes_every_bridge_key() {
        let bridge = MINIMAL.replace("\"rmw_zenoh\"", "\"bridge\"");
        let text = bridge.replacen("[topics]", "bridge_namespace = \"/drone1\"\n[topics]", 1);
        let c = parse(&text).unwrap();
        c.validate().unwrap();
        let format = c.key_format().unwrap();
        assert_eq!(
            format
                .topic_key::<crate::ros2::msgs::Image>("/camera/depth/image")
                .unwrap(),
            "drone1/camera/depth/image"
        );
        assert_eq!(
            format
                .subscribe_key::<crate::ros2::msgs::Odometry>(&c.topics.odometry)
                .unwrap(),
            "drone1/odom"
        );
        // "/" is the bridge's default: no prefix.
        let root = bridge.replacen("[topics]", "bridge_namespace = \"/\"\n[topics]", 1);
        let c = parse(&root).unwrap();
        assert_eq!(
            c.key_format()
                .unwrap()
                .subscribe_key::<crate::ros2::msgs::Odometry>("/odom")
                .unwrap(),
            "odom"
        );
    }

    #[test]
    fn a_bad_or_misplaced_bridge_namespace_is_refused_by_name() {
        let bridge = MINIMAL.replace("\"rmw_zenoh\"", "\"bridge\"");
        for bad in ["", "/drone1/", "//drone1", "/drone*", "/a/$b", "/a#", "/a?"] {
            let text = bridge.replacen(
                "[topics]",
                &format!("bridge_namespace = {bad:?}\n[topics]"),
                1,
            );
            let err = parse(&text).unwrap().validate().unwrap_err();
            assert_eq!(err.key, "bridge_namespace", "{bad:?}: {err}");
            assert_eq!(err.rule, NAMESPACE_RULE);
            assert_eq!(err.value, format!("{bad:?}"));
        }
        let text = MINIMAL.replacen("[topics]", "bridge_namespace = \"/drone1\"\n[topics]", 1);
        let c = parse(&text).unwrap();
        let err = c.validate().unwrap_err();
        assert_eq!(err.key, "bridge_namespace");
        assert!(
            err.to_string().starts_with(
                "`bridge_namespace` applies to `format = \"bridge\"` only: under rmw_zenoh"
            ),
            "{err}"
        );
        assert_eq!(c.key_format().unwrap_err(), err);
    }

    #[test]
    fn the_documented_table_is_valid() {
        let page = include_str!("../../../docs/hardware-ros2.md");
        let mut blocks = page.split("```toml\n").skip(1);
        for block in blocks.by_ref() {
            let end = block.find("```").expect("the block ends");
            let table: toml::Table = toml::from_str(&block[..end]).unwrap();
            let config: Ros2Config = table["ros2"].clone().try_into().unwrap();
            config.validate().unwrap();
            config.zenoh.validate().unwrap();
        }
    }
}
