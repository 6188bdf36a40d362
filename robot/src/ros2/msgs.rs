//! ROS 2 message types, field for field in CDR order, with their interface names
//! and type hashes.
//!
//! The RIHS01 hashes are copied from the type description files that the ROS 2
//! Kilted wheels ship (`share/<package>/msg/<Type>.json`, entry `type_hashes`;
//! packages `ros-sensor-msgs` 5.5.1, `ros-nav-msgs` 5.5.1, `ros-std-msgs` 5.5.1 and
//! `ros-diagnostic-msgs` 5.5.1 on PyPI). A hash changes only when the message definition changes; subscribers may
//! wildcard it ([`KeyFormat::subscribe_key`](super::KeyFormat::subscribe_key)).

use serde::de::{self, SeqAccess, Visitor};
use serde::ser::SerializeTuple;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::cdr::RosMessage;

/// `builtin_interfaces/msg/Time`: seconds and nanoseconds since the Unix epoch.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RosTime {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds, `< 1e9`.
    pub nanosec: u32,
}

impl RosTime {
    /// Nanoseconds since the epoch (negative before it).
    #[must_use]
    pub fn as_nanos(self) -> i64 {
        i64::from(self.sec) * 1_000_000_000 + i64::from(self.nanosec)
    }

    /// The time `nanos` nanoseconds after the epoch (saturating at the `i32` seconds range).
    #[must_use]
    pub fn from_nanos(nanos: i64) -> Self {
        let sec = nanos.div_euclid(1_000_000_000);
        RosTime {
            sec: i32::try_from(sec).unwrap_or(if sec < 0 { i32::MIN } else { i32::MAX }),
            // In 0..1e9 by construction.
            nanosec: u32::try_from(nanos.rem_euclid(1_000_000_000)).unwrap_or(0),
        }
    }
}

/// `std_msgs/msg/Header`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// Acquisition time.
    pub stamp: RosTime,
    /// Coordinate frame of the data.
    pub frame_id: String,
}

/// `sensor_msgs/msg/Image`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Image {
    /// Stamp and optical frame.
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Pixel encoding (`16UC1`, `32FC1`, `mono8`, `mono16`, ...).
    pub encoding: String,
    /// Non-zero when multi-byte pixels are big-endian.
    pub is_bigendian: u8,
    /// Bytes per row.
    pub step: u32,
    /// `step × height` bytes.
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}

/// `sensor_msgs/msg/RegionOfInterest`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RegionOfInterest {
    /// Left column.
    pub x_offset: u32,
    /// Top row.
    pub y_offset: u32,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// Whether the region should be rectified.
    pub do_rectify: bool,
}

/// `sensor_msgs/msg/CameraInfo`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CameraInfo {
    /// Stamp and optical frame.
    pub header: Header,
    /// Image rows the calibration is for.
    pub height: u32,
    /// Image columns the calibration is for.
    pub width: u32,
    /// Distortion model name (`plumb_bob`, ...).
    pub distortion_model: String,
    /// Distortion coefficients.
    pub d: Vec<f64>,
    /// Intrinsic matrix, row-major 3×3.
    pub k: [f64; 9],
    /// Rectification rotation, row-major 3×3.
    pub r: [f64; 9],
    /// Projection matrix, row-major 3×4.
    pub p: [f64; 12],
    /// Horizontal binning.
    pub binning_x: u32,
    /// Vertical binning.
    pub binning_y: u32,
    /// Region of interest.
    pub roi: RegionOfInterest,
}

/// `sensor_msgs/msg/PointField`.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct PointField {
    /// Field name (`x`, `y`, `z`, `intensity`, ...).
    pub name: String,
    /// Byte offset inside a point.
    pub offset: u32,
    /// Element type ([`PointField::FLOAT32`], ...).
    pub datatype: u8,
    /// Elements in the field.
    pub count: u32,
}

impl PointField {
    /// `datatype` of a 32-bit float.
    pub const FLOAT32: u8 = 7;
}

/// `sensor_msgs/msg/PointCloud2`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PointCloud2 {
    /// Stamp and frame of the points.
    pub header: Header,
    /// Rows (1 for an unordered cloud).
    pub height: u32,
    /// Points per row.
    pub width: u32,
    /// Layout of one point.
    pub fields: Vec<PointField>,
    /// Whether multi-byte fields are big-endian.
    pub is_bigendian: bool,
    /// Bytes per point.
    pub point_step: u32,
    /// Bytes per row.
    pub row_step: u32,
    /// `row_step × height` bytes.
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
    /// True when no point is invalid.
    pub is_dense: bool,
}

/// `geometry_msgs/msg/Point` (also the layout of `Vector3`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Point {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// `geometry_msgs/msg/Vector3`.
pub type Vector3 = Point;

/// `geometry_msgs/msg/Quaternion`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }
    }
}

/// `geometry_msgs/msg/Pose`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Position.
    pub position: Point,
    /// Orientation.
    pub orientation: Quaternion,
}

/// `geometry_msgs/msg/Twist`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Twist {
    /// Linear velocity, m/s.
    pub linear: Vector3,
    /// Angular velocity, rad/s.
    pub angular: Vector3,
}

/// A row-major 6×6 covariance (`float64[36]`, a fixed CDR array: no length prefix).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Covariance6(pub [f64; 36]);

impl Default for Covariance6 {
    fn default() -> Self {
        Covariance6([0.0; 36])
    }
}

impl Serialize for Covariance6 {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut t = serializer.serialize_tuple(36)?;
        for v in &self.0 {
            t.serialize_element(v)?;
        }
        t.end()
    }
}

impl<'de> Deserialize<'de> for Covariance6 {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct ArrayVisitor;
        impl<'de> Visitor<'de> for ArrayVisitor {
            type Value = Covariance6;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("36 float64 values")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Covariance6, A::Error> {
                let mut out = [0.0; 36];
                for (i, slot) in out.iter_mut().enumerate() {
                    *slot = seq
                        .next_element()?
                        .ok_or_else(|| de::Error::invalid_length(i, &self))?;
                }
                Ok(Covariance6(out))
            }
        }
        deserializer.deserialize_tuple(36, ArrayVisitor)
    }
}

/// `geometry_msgs/msg/PoseWithCovariance`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    /// Pose.
    pub pose: Pose,
    /// Covariance of (x, y, z, rot x, rot y, rot z).
    pub covariance: Covariance6,
}

/// `geometry_msgs/msg/TwistWithCovariance`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TwistWithCovariance {
    /// Twist.
    pub twist: Twist,
    /// Covariance of (vx, vy, vz, wx, wy, wz).
    pub covariance: Covariance6,
}

/// `nav_msgs/msg/Odometry`: pose in `header.frame_id`, twist in `child_frame_id`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Odometry {
    /// Stamp and world frame.
    pub header: Header,
    /// Body frame.
    pub child_frame_id: String,
    /// Body pose in the world frame.
    pub pose: PoseWithCovariance,
    /// Body velocity, in the body frame.
    pub twist: TwistWithCovariance,
}

/// `geometry_msgs/msg/PoseStamped`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseStamped {
    /// Stamp and frame.
    pub header: Header,
    /// Pose.
    pub pose: Pose,
}

/// `nav_msgs/msg/Path`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Path {
    /// Stamp and frame.
    pub header: Header,
    /// Poses along the path.
    pub poses: Vec<PoseStamped>,
}

/// `std_msgs/msg/String` (troupe's status is JSON in it).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RosString {
    /// Text.
    pub data: String,
}

/// `diagnostic_msgs/msg/KeyValue`.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct KeyValue {
    /// What the value is.
    pub key: String,
    /// The value, as text.
    pub value: String,
}

/// `diagnostic_msgs/msg/DiagnosticStatus`.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct DiagnosticStatus {
    /// `OK` (0), `WARN` (1), `ERROR` (2) or `STALE` (3).
    pub level: u8,
    /// What is described (`troupe/robot0/vehicle`).
    pub name: String,
    /// Its state in a few words.
    pub message: String,
    /// The hardware (the autopilot's MAVLink ids).
    pub hardware_id: String,
    /// The figures.
    pub values: Vec<KeyValue>,
}

/// `diagnostic_msgs/msg/DiagnosticArray`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DiagnosticArray {
    /// Stamp (and an empty frame).
    pub header: Header,
    /// One status per component.
    pub status: Vec<DiagnosticStatus>,
}

/// Implements [`RosMessage`] for each `Type => "interface name", "RIHS01 hash";` row.
macro_rules! ros_messages {
    ($($message:ty => $type_name:literal, $type_hash:literal;)+) => {
        $(
            impl RosMessage for $message {
                const TYPE_NAME: &'static str = $type_name;
                const TYPE_HASH: &'static str = $type_hash;
            }
        )+
    };
}

ros_messages! {
    DiagnosticArray => "diagnostic_msgs/msg/DiagnosticArray",
        "RIHS01_5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e";
    Image => "sensor_msgs/msg/Image",
        "RIHS01_d31d41a9a4c4bc8eae9be757b0beed306564f7526c88ea6a4588fb9582527d47";
    CameraInfo => "sensor_msgs/msg/CameraInfo",
        "RIHS01_b3dfd68ff46c9d56c80fd3bd4ed22c7a4ddce8c8348f2f59c299e73118e7e275";
    PointCloud2 => "sensor_msgs/msg/PointCloud2",
        "RIHS01_9198cabf7da3796ae6fe19c4cb3bdd3525492988c70522628af5daa124bae2b5";
    Odometry => "nav_msgs/msg/Odometry",
        "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0";
    Path => "nav_msgs/msg/Path",
        "RIHS01_1957a5bb3cee5da65c4e52e52b65a93df227efce4c20f8458b36e73066ca334b";
    RosString => "std_msgs/msg/String",
        "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18";
}
