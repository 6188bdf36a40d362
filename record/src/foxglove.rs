//! Foxglove's well-known message types, as the JSON that Foxglove (and Lichtblick)
//! decode for a channel with `json` message encoding and a `jsonschema` schema named
//! `foxglove.<Type>`: times as `{sec, nsec}`, enums as numbers, every array present.
//! Only the types and fields a recording writes are here.

use nalgebra::{Isometry3, Point3, UnitQuaternion};
use serde::Serialize;
use troupe_core::Time;

/// A time (`foxglove` `time`): whole seconds and nanoseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Timestamp {
    /// Seconds.
    pub sec: u32,
    /// Nanoseconds, below 1e9.
    pub nsec: u32,
}

impl Timestamp {
    /// The time `nanos` nanoseconds after the epoch of the recording's clock.
    #[must_use]
    pub fn from_nanos(nanos: u64) -> Self {
        Timestamp {
            sec: u32::try_from(nanos / 1_000_000_000).unwrap_or(u32::MAX),
            nsec: (nanos % 1_000_000_000) as u32,
        }
    }

    /// A run's time.
    #[must_use]
    pub fn of(time: Time) -> Self {
        Timestamp::from_nanos(time.as_nanos())
    }
}

/// A duration (`foxglove` `duration`); zero means forever for a scene entity.
pub type Duration = Timestamp;

/// `foxglove.Vector3`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

impl From<Point3<f64>> for Vector3 {
    fn from(p: Point3<f64>) -> Self {
        Vector3 {
            x: p.x,
            y: p.y,
            z: p.z,
        }
    }
}

impl From<nalgebra::Vector3<f64>> for Vector3 {
    fn from(p: nalgebra::Vector3<f64>) -> Self {
        Vector3 {
            x: p.x,
            y: p.y,
            z: p.z,
        }
    }
}

/// `foxglove.Quaternion`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
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
        Quaternion::from(UnitQuaternion::identity())
    }
}

impl From<UnitQuaternion<f64>> for Quaternion {
    fn from(q: UnitQuaternion<f64>) -> Self {
        Quaternion {
            x: q.i,
            y: q.j,
            z: q.k,
            w: q.w,
        }
    }
}

/// `foxglove.Pose`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Pose {
    /// Position, metres.
    pub position: Vector3,
    /// Orientation.
    pub orientation: Quaternion,
}

impl From<&Isometry3<f64>> for Pose {
    fn from(p: &Isometry3<f64>) -> Self {
        Pose {
            position: p.translation.vector.into(),
            orientation: p.rotation.into(),
        }
    }
}

/// `foxglove.Color`, components in 0..=1.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Color {
    /// Red.
    pub r: f64,
    /// Green.
    pub g: f64,
    /// Blue.
    pub b: f64,
    /// Alpha.
    pub a: f64,
}

impl Color {
    /// The colour of these components, each in 0..=1.
    #[must_use]
    pub const fn rgba(r: f64, g: f64, b: f64, a: f64) -> Self {
        Color { r, g, b, a }
    }
}

/// `foxglove.FrameTransform`: the pose of `child_frame_id` in `parent_frame_id`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FrameTransform {
    /// When.
    pub timestamp: Timestamp,
    /// Parent frame.
    pub parent_frame_id: String,
    /// Child frame.
    pub child_frame_id: String,
    /// Child origin in the parent frame, metres.
    pub translation: Vector3,
    /// Child orientation in the parent frame.
    pub rotation: Quaternion,
}

/// `foxglove.PoseInFrame`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PoseInFrame {
    /// When.
    pub timestamp: Timestamp,
    /// Frame the pose is in.
    pub frame_id: String,
    /// The pose.
    pub pose: Pose,
}

/// `foxglove.KeyValuePair`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct KeyValuePair {
    /// Key.
    pub key: String,
    /// Value.
    pub value: String,
}

impl KeyValuePair {
    /// A pair.
    pub fn new(key: &str, value: impl ToString) -> Self {
        KeyValuePair {
            key: key.into(),
            value: value.to_string(),
        }
    }
}

/// `foxglove.SpherePrimitive`: an ellipsoid with diameters `size` along the axes of `pose`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SpherePrimitive {
    /// Centre and axes.
    pub pose: Pose,
    /// Diameters along the pose's x, y, z axes, metres.
    pub size: Vector3,
    /// Colour.
    pub color: Color,
}

/// `foxglove.LinePrimitive` type: a strip through every point.
pub const LINE_STRIP: u8 = 0;

/// `foxglove.LinePrimitive`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LinePrimitive {
    /// [`LINE_STRIP`], 1 loop, 2 list.
    #[serde(rename = "type")]
    pub kind: u8,
    /// Origin of the points.
    pub pose: Pose,
    /// Width, metres (pixels when `scale_invariant`).
    pub thickness: f64,
    /// Whether `thickness` is in pixels.
    pub scale_invariant: bool,
    /// Vertices, metres.
    pub points: Vec<Vector3>,
    /// Colour of the whole line.
    pub color: Color,
    /// Per-vertex colours (empty: `color`).
    pub colors: Vec<Color>,
    /// Vertex order (empty: as given).
    pub indices: Vec<u32>,
}

/// `foxglove.TriangleListPrimitive`: every three points are one triangle.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TriangleListPrimitive {
    /// Origin of the points.
    pub pose: Pose,
    /// Vertices, metres.
    pub points: Vec<Vector3>,
    /// Colour of the whole list.
    pub color: Color,
    /// Per-vertex colours (empty: `color`).
    pub colors: Vec<Color>,
    /// Vertex order (empty: as given).
    pub indices: Vec<u32>,
}

/// `foxglove.SceneEntity`: primitives that share a frame, an id and a lifetime. The
/// primitive lists a recording never fills are written empty.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SceneEntity {
    /// When.
    pub timestamp: Timestamp,
    /// Frame of the primitives.
    pub frame_id: String,
    /// Id: a later entity with the same id on the topic replaces this one.
    pub id: String,
    /// How long it shows (zero: until replaced or deleted).
    pub lifetime: Duration,
    /// Whether it moves with its frame.
    pub frame_locked: bool,
    /// What it is, for the user.
    pub metadata: Vec<KeyValuePair>,
    /// Arrows (unused).
    pub arrows: Vec<serde_json::Value>,
    /// Cubes (unused).
    pub cubes: Vec<serde_json::Value>,
    /// Ellipsoids.
    pub spheres: Vec<SpherePrimitive>,
    /// Cylinders (unused).
    pub cylinders: Vec<serde_json::Value>,
    /// Lines.
    pub lines: Vec<LinePrimitive>,
    /// Triangles.
    pub triangles: Vec<TriangleListPrimitive>,
    /// Texts (unused).
    pub texts: Vec<serde_json::Value>,
    /// Models (unused).
    pub models: Vec<serde_json::Value>,
}

impl SceneEntity {
    /// An entity with no primitives yet, shown until replaced.
    #[must_use]
    pub fn new(timestamp: Timestamp, frame_id: &str, id: String) -> Self {
        SceneEntity {
            timestamp,
            frame_id: frame_id.into(),
            id,
            lifetime: Duration::default(),
            frame_locked: false,
            metadata: Vec::new(),
            arrows: Vec::new(),
            cubes: Vec::new(),
            spheres: Vec::new(),
            cylinders: Vec::new(),
            lines: Vec::new(),
            triangles: Vec::new(),
            texts: Vec::new(),
            models: Vec::new(),
        }
    }
}

/// `foxglove.SceneUpdate`: entities to add or replace (a recording deletes none).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SceneUpdate {
    /// Deletions (always empty here).
    pub deletions: Vec<serde_json::Value>,
    /// Entities.
    pub entities: Vec<SceneEntity>,
}

/// Bytes of a Foxglove `bytes` field, written as base64 text (the JSON encoding of
/// `bytes` that Foxglove decodes).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Bytes(pub Vec<u8>);

impl Serialize for Bytes {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use base64::Engine as _;
        serializer.serialize_str(&base64::engine::general_purpose::STANDARD.encode(&self.0))
    }
}

/// `foxglove.NumericType` of a 32-bit float.
pub const FLOAT32: u8 = 7;

/// `foxglove.PackedElementField`: one field of each point of a [`PointCloud`].
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PackedElementField {
    /// Field name (`x`, `y`, `z` place the point; others colour it).
    pub name: String,
    /// Byte offset within a point.
    pub offset: u32,
    /// `foxglove.NumericType` ([`FLOAT32`]).
    #[serde(rename = "type")]
    pub kind: u8,
}

/// `foxglove.PointCloud`: points packed as little-endian `f32` `x, y, z, intensity`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PointCloud {
    /// When.
    pub timestamp: Timestamp,
    /// Frame of the points.
    pub frame_id: String,
    /// Origin of the points in the frame.
    pub pose: Pose,
    /// Bytes per point.
    pub point_stride: u32,
    /// The fields of a point.
    pub fields: Vec<PackedElementField>,
    /// The points.
    pub data: Bytes,
}

impl PointCloud {
    /// Bytes per point: four `f32`.
    pub const STRIDE: u32 = 16;

    /// A cloud in `frame_id` of `(position, intensity)` points.
    pub fn xyzi(
        timestamp: Timestamp,
        frame_id: &str,
        points: impl IntoIterator<Item = (Point3<f64>, f64)>,
    ) -> Self {
        let mut data = Vec::new();
        for (p, intensity) in points {
            for v in [p.x, p.y, p.z, intensity] {
                data.extend_from_slice(&(v as f32).to_le_bytes());
            }
        }
        let fields = ["x", "y", "z", "intensity"]
            .iter()
            .zip(0..)
            .map(|(name, k)| PackedElementField {
                name: (*name).into(),
                offset: 4 * k,
                kind: FLOAT32,
            })
            .collect();
        PointCloud {
            timestamp,
            frame_id: frame_id.into(),
            pose: Pose::default(),
            point_stride: Self::STRIDE,
            fields,
            data: Bytes(data),
        }
    }

    /// Points in the cloud.
    #[must_use]
    pub fn len(&self) -> usize {
        self.data.0.len() / Self::STRIDE as usize
    }

    /// Whether the cloud has no point.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.data.0.is_empty()
    }
}

/// `foxglove.RawImage`: an uncompressed image.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RawImage {
    /// When.
    pub timestamp: Timestamp,
    /// Frame of the camera.
    pub frame_id: String,
    /// Pixels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Pixel encoding (`32FC1`: one little-endian `f32` per pixel).
    pub encoding: String,
    /// Bytes per row.
    pub step: u32,
    /// Row-major pixels.
    pub data: Bytes,
}

impl RawImage {
    /// A `32FC1` image of row-major `values` (e.g. depth in metres).
    #[must_use]
    pub fn float32(
        timestamp: Timestamp,
        frame_id: &str,
        width: u32,
        height: u32,
        values: &[f32],
    ) -> Self {
        RawImage {
            timestamp,
            frame_id: frame_id.into(),
            width,
            height,
            encoding: "32FC1".into(),
            step: 4 * width,
            data: Bytes(values.iter().flat_map(|v| v.to_le_bytes()).collect()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use base64::Engine as _;

    #[test]
    fn a_point_cloud_packs_little_endian_f32_points_as_base64() {
        let cloud = PointCloud::xyzi(
            Timestamp::from_nanos(1_500_000_000),
            "world",
            [
                (Point3::new(1.0, -2.0, 0.5), 0.25),
                (Point3::new(0.0, 3.0, -1.0), 1.0),
            ],
        );
        assert_eq!(cloud.len(), 2);
        let json = serde_json::to_value(&cloud).expect("serialises");
        assert_eq!(json["point_stride"], 16);
        assert_eq!(json["fields"][3]["name"], "intensity");
        assert_eq!(json["fields"][3]["offset"], 12);
        assert_eq!(json["fields"][3]["type"], FLOAT32);
        let data = base64::engine::general_purpose::STANDARD
            .decode(json["data"].as_str().expect("a string"))
            .expect("base64");
        let values: Vec<f32> = data
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        assert_eq!(values, [1.0, -2.0, 0.5, 0.25, 0.0, 3.0, -1.0, 1.0]);
        assert!(PointCloud::xyzi(Timestamp::default(), "world", []).is_empty());
    }

    #[test]
    fn a_depth_image_is_32fc1_rows() {
        let image = RawImage::float32(Timestamp::default(), "robot0/camera", 3, 2, &[1.0; 6]);
        assert_eq!((image.step, image.encoding.as_str()), (12, "32FC1"));
        assert_eq!(image.data.0.len(), 24);
    }
}
