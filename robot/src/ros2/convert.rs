//! Conversions between ROS 2 messages and troupe's, written once.
//!
//! Frames. ROS optical frames (REP 103/105: `*_optical_frame`) look along +z with
//! x right and y down; troupe's camera body frame looks along +x with y left and
//! z up, so image x is body −y and image y is body −z
//! ([`DepthFrame`]). [`optical_to_camera`] is that rotation. ROS odometry uses
//! an ENU world and a FLU body (x forward, y left, z up), the same axes as
//! troupe's world and body frames, so poses pass through unchanged; the camera
//! pose of a frame is the body pose composed with the configured extrinsics (the
//! optical frame's pose in the body, as TF gives it) and that rotation
//! ([`camera_pose`]).
//!
//! Pixels. ROS puts pixel centres at integer coordinates (`cx` is measured from the
//! centre of pixel 0); troupe puts them at integer + 0.5, so troupe's `cx = cx_ros
//! + 0.5` (and `cy` likewise).

use nalgebra::{Isometry3, Matrix3, Quaternion, Rotation3, UnitQuaternion, Vector3};
use rand::Rng;
use troupe_algorithms::camera::PinholeIntrinsics;
use troupe_algorithms::frame::{DepthFrame, Odometry};
use troupe_algorithms::plan::Plan;
use troupe_algorithms::sogmm::{Gmm4, IntensityConditional};
use troupe_core::Time;

use super::msgs::{
    CameraInfo, Header, Image, Path, PointCloud2, PointField, Pose, PoseStamped, RosTime,
};

/// Why a message could not be converted. [`ConvertError::reason`] names the kind
/// for counters.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ConvertError {
    /// The image's encoding is not one the configuration accepts.
    #[error("{role} image encoding `{encoding}` is not accepted (accepted: {accepted})")]
    Encoding {
        /// `depth` or `intensity`.
        role: &'static str,
        /// The encoding received.
        encoding: String,
        /// The accepted ones, comma-separated.
        accepted: String,
    },
    /// An image and its calibration (or the depth and intensity images) disagree.
    #[error("{role} image is {width}×{height} but {other} is {other_width}×{other_height}")]
    SizeMismatch {
        /// Which image.
        role: &'static str,
        /// Its width.
        width: u32,
        /// Its height.
        height: u32,
        /// What it was compared with.
        other: &'static str,
        /// That one's width.
        other_width: u32,
        /// That one's height.
        other_height: u32,
    },
    /// A row step too small for the width, or data that does not fill the rows.
    #[error(
        "{role} image rows do not fit: step {step} B for {width} pixels of {pixel_bytes} B, \
         {data_bytes} B of data for {height} rows"
    )]
    Layout {
        /// Which image.
        role: &'static str,
        /// The row step, bytes.
        step: u32,
        /// Pixels per row.
        width: u32,
        /// Rows.
        height: u32,
        /// Bytes per pixel of the encoding.
        pixel_bytes: u32,
        /// Bytes of data received.
        data_bytes: usize,
    },
    /// `is_bigendian` is neither 0 nor 1.
    #[error("{role} image has is_bigendian = {flag}, expected 0 or 1")]
    Endianness {
        /// Which image.
        role: &'static str,
        /// The flag.
        flag: u8,
    },
    /// An empty image or calibration.
    #[error("{0} has no pixels")]
    Empty(&'static str),
    /// The calibration matrix is unusable.
    #[error("camera intrinsics are unusable: fx {fx}, fy {fy}, cx {cx}, cy {cy}")]
    Intrinsics {
        /// Focal length x.
        fx: f64,
        /// Focal length y.
        fy: f64,
        /// Principal point x.
        cx: f64,
        /// Principal point y.
        cy: f64,
    },
    /// A point cloud without float32 x, y and z fields inside its points.
    #[error("point cloud has no float32 `{0}` field inside its {1}-byte points")]
    PointField(&'static str, u32),
    /// A point cloud whose data does not hold its points.
    #[error("point cloud of {width}×{height} points of {point_step} B has {data_bytes} B of data")]
    PointLayout {
        /// Points per row.
        width: u32,
        /// Rows.
        height: u32,
        /// Bytes per point.
        point_step: u32,
        /// Bytes received.
        data_bytes: usize,
    },
    /// A pose with NaN, infinity or a zero quaternion.
    #[error("odometry pose or twist is not finite, or its quaternion is zero")]
    Pose,
}

impl ConvertError {
    /// A short name of the kind of error, for counters.
    #[must_use]
    pub fn reason(&self) -> &'static str {
        match self {
            ConvertError::Encoding { .. } => "encoding",
            ConvertError::SizeMismatch { .. } => "size_mismatch",
            ConvertError::Layout { .. } => "layout",
            ConvertError::Endianness { .. } => "endianness",
            ConvertError::Empty(_) => "empty",
            ConvertError::Intrinsics { .. } => "intrinsics",
            ConvertError::PointField(..) | ConvertError::PointLayout { .. } => "point_layout",
            ConvertError::Pose => "pose",
        }
    }
}

/// The rotation from a ROS optical frame (z forward, x right, y down) to troupe's
/// camera body frame (x forward, y left, z up): `(x, y, z)_optical ↦ (z, −x, −y)`.
#[must_use]
pub fn optical_to_camera() -> UnitQuaternion<f64> {
    let m = Matrix3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0);
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m))
}

/// Troupe intrinsics from a calibration (`K` row-major; centres moved by half a pixel).
pub fn intrinsics_from_camera_info(
    info: &CameraInfo,
    max_depth_m: f64,
) -> Result<PinholeIntrinsics, ConvertError> {
    if info.width == 0 || info.height == 0 {
        return Err(ConvertError::Empty("camera info"));
    }
    let (fx, fy, cx, cy) = (info.k[0], info.k[4], info.k[2], info.k[5]);
    let ok = [fx, fy, cx, cy].iter().all(|v| v.is_finite()) && fx > 0.0 && fy > 0.0;
    if !ok {
        return Err(ConvertError::Intrinsics { fx, fy, cx, cy });
    }
    Ok(PinholeIntrinsics {
        width: info.width,
        height: info.height,
        fx,
        fy,
        cx: cx + 0.5,
        cy: cy + 0.5,
        max_depth_m,
    })
}

/// Depth pixel encodings.
const DEPTH_ENCODINGS: [(&str, u32); 2] = [("16UC1", 2), ("32FC1", 4)];
/// Intensity pixel encodings.
const INTENSITY_ENCODINGS: [(&str, u32); 2] = [("mono8", 1), ("mono16", 2)];

/// Checks an image's encoding against the accepted list and its row layout; returns
/// the bytes per pixel.
fn check_image(
    role: &'static str,
    image: &Image,
    known: &[(&str, u32)],
    accepted: &[String],
) -> Result<u32, ConvertError> {
    let pixel_bytes = known
        .iter()
        .find(|(name, _)| *name == image.encoding && accepted.iter().any(|a| a == name))
        .map(|(_, bytes)| *bytes)
        .ok_or_else(|| ConvertError::Encoding {
            role,
            encoding: image.encoding.clone(),
            accepted: accepted.join(", "),
        })?;
    if image.is_bigendian > 1 {
        return Err(ConvertError::Endianness {
            role,
            flag: image.is_bigendian,
        });
    }
    if image.width == 0 || image.height == 0 {
        return Err(ConvertError::Empty(role));
    }
    let row_bytes = u64::from(image.width) * u64::from(pixel_bytes);
    let needed = u64::from(image.step) * u64::from(image.height - 1) + row_bytes;
    if u64::from(image.step) < row_bytes || (image.data.len() as u64) < needed {
        return Err(ConvertError::Layout {
            role,
            step: image.step,
            width: image.width,
            height: image.height,
            pixel_bytes,
            data_bytes: image.data.len(),
        });
    }
    Ok(pixel_bytes)
}

/// Reads pixel `(col, row)` of a checked image as an `f64` in the encoding's unit.
fn pixel(image: &Image, pixel_bytes: u32, col: u32, row: u32) -> f64 {
    let at = row as usize * image.step as usize + col as usize * pixel_bytes as usize;
    let big = image.is_bigendian == 1;
    let bytes = &image.data[at..at + pixel_bytes as usize];
    match (image.encoding.as_str(), bytes) {
        ("32FC1", [a, b, c, d]) => f64::from(if big {
            f32::from_be_bytes([*a, *b, *c, *d])
        } else {
            f32::from_le_bytes([*a, *b, *c, *d])
        }),
        (_, [a, b]) => f64::from(if big {
            u16::from_be_bytes([*a, *b])
        } else {
            u16::from_le_bytes([*a, *b])
        }),
        (_, [a]) => f64::from(*a),
        _ => 0.0,
    }
}

/// What a depth frame is built from.
#[derive(Clone, Copy, Debug)]
pub struct DepthInputs<'a> {
    /// The depth image (16UC1 millimetres or 32FC1 metres).
    pub depth: &'a Image,
    /// Its calibration.
    pub info: &'a CameraInfo,
    /// An optional intensity image of the same size (mono8 or mono16).
    pub intensity: Option<&'a Image>,
    /// Accepted depth encodings.
    pub depth_encodings: &'a [String],
    /// Accepted intensity encodings.
    pub intensity_encodings: &'a [String],
    /// Depths beyond this are no return, metres.
    pub max_depth_m: f64,
}

/// A depth (+ intensity) image and its calibration → a troupe [`DepthFrame`] with
/// `pose` (the camera body pose) and `stamp`. Depths that are 0, NaN, infinite,
/// negative or beyond `max_depth_m` are no return (0). Without an intensity image,
/// every return has intensity 1.
pub fn depth_frame_from_image(
    inputs: &DepthInputs<'_>,
    pose: Isometry3<f64>,
    stamp: Time,
) -> Result<DepthFrame, ConvertError> {
    let depth = inputs.depth;
    let depth_bytes = check_image("depth", depth, &DEPTH_ENCODINGS, inputs.depth_encodings)?;
    if (depth.width, depth.height) != (inputs.info.width, inputs.info.height) {
        return Err(ConvertError::SizeMismatch {
            role: "depth",
            width: depth.width,
            height: depth.height,
            other: "camera info",
            other_width: inputs.info.width,
            other_height: inputs.info.height,
        });
    }
    let intrinsics = intrinsics_from_camera_info(inputs.info, inputs.max_depth_m)?;
    let intensity = match inputs.intensity {
        Some(image) => {
            let bytes = check_image(
                "intensity",
                image,
                &INTENSITY_ENCODINGS,
                inputs.intensity_encodings,
            )?;
            if (image.width, image.height) != (depth.width, depth.height) {
                return Err(ConvertError::SizeMismatch {
                    role: "intensity",
                    width: image.width,
                    height: image.height,
                    other: "depth image",
                    other_width: depth.width,
                    other_height: depth.height,
                });
            }
            let full_scale = if bytes == 1 { 255.0 } else { 65535.0 };
            Some((image, bytes, full_scale))
        }
        None => None,
    };
    let scale_m = if depth.encoding == "16UC1" { 1e-3 } else { 1.0 };
    let pixels = depth.width as usize * depth.height as usize;
    let mut depth_m = Vec::with_capacity(pixels);
    let mut intensity_out = Vec::with_capacity(pixels);
    for row in 0..depth.height {
        for col in 0..depth.width {
            let d = pixel(depth, depth_bytes, col, row) * scale_m;
            let hit = d.is_finite() && d > 0.0 && d <= inputs.max_depth_m;
            depth_m.push(if hit { d as f32 } else { 0.0 });
            let g = match (hit, intensity) {
                (false, _) => 0.0,
                (true, None) => 1.0,
                (true, Some((image, bytes, full_scale))) => {
                    pixel(image, bytes, col, row) / full_scale
                }
            };
            intensity_out.push(g as f32);
        }
    }
    Ok(DepthFrame {
        stamp,
        pose,
        intrinsics,
        depth_m,
        intensity: intensity_out,
    })
}

/// Byte offset of a float32 field with one element that fits inside a point.
fn float_field(cloud: &PointCloud2, name: &'static str) -> Result<usize, ConvertError> {
    cloud
        .fields
        .iter()
        .find(|f| {
            f.name == name
                && f.datatype == PointField::FLOAT32
                && f.count >= 1
                && u64::from(f.offset) + 4 <= u64::from(cloud.point_step)
        })
        .map(|f| f.offset as usize)
        .ok_or(ConvertError::PointField(name, cloud.point_step))
}

/// A point cloud in the camera's optical frame (x, y, z float32 fields at any offsets
/// and point step; an optional float32 `intensity` in [0, 1]) → a [`DepthFrame`] by
/// projecting every point into `intrinsics` and keeping the nearest per pixel.
/// Points behind the camera, outside the image, beyond range or not finite are
/// dropped. Without an intensity field, every return has intensity 1.
pub fn depth_frame_from_points(
    cloud: &PointCloud2,
    intrinsics: PinholeIntrinsics,
    pose: Isometry3<f64>,
    stamp: Time,
) -> Result<DepthFrame, ConvertError> {
    let (x, y, z) = (
        float_field(cloud, "x")?,
        float_field(cloud, "y")?,
        float_field(cloud, "z")?,
    );
    let intensity = float_field(cloud, "intensity").ok();
    let step = cloud.point_step as usize;
    let row_ok = u64::from(cloud.row_step) >= u64::from(cloud.width) * u64::from(cloud.point_step);
    let needed = u64::from(cloud.row_step) * u64::from(cloud.height);
    if cloud.point_step == 0 || !row_ok || (cloud.data.len() as u64) < needed {
        return Err(ConvertError::PointLayout {
            width: cloud.width,
            height: cloud.height,
            point_step: cloud.point_step,
            data_bytes: cloud.data.len(),
        });
    }
    if intrinsics.width == 0 || intrinsics.height == 0 {
        return Err(ConvertError::Empty("point-cloud intrinsics"));
    }
    let read = |at: usize| {
        let b = [
            cloud.data[at],
            cloud.data[at + 1],
            cloud.data[at + 2],
            cloud.data[at + 3],
        ];
        f64::from(if cloud.is_bigendian {
            f32::from_be_bytes(b)
        } else {
            f32::from_le_bytes(b)
        })
    };
    let pixels = intrinsics.width as usize * intrinsics.height as usize;
    let mut depth_m = vec![0.0f32; pixels];
    let mut intensity_out = vec![0.0f32; pixels];
    for row in 0..cloud.height as usize {
        for col in 0..cloud.width as usize {
            let base = row * cloud.row_step as usize + col * step;
            let (px, py, pz) = (read(base + x), read(base + y), read(base + z));
            if !(pz.is_finite() && px.is_finite() && py.is_finite())
                || pz <= 0.0
                || pz > intrinsics.max_depth_m
            {
                continue;
            }
            let u = intrinsics.fx * px / pz + intrinsics.cx;
            let v = intrinsics.fy * py / pz + intrinsics.cy;
            if !(u >= 0.0 && v >= 0.0) {
                continue;
            }
            let (u, v) = (u.floor() as u64, v.floor() as u64);
            if u >= u64::from(intrinsics.width) || v >= u64::from(intrinsics.height) {
                continue;
            }
            let i = v as usize * intrinsics.width as usize + u as usize;
            if depth_m[i] == 0.0 || (pz as f32) < depth_m[i] {
                depth_m[i] = pz as f32;
                intensity_out[i] = match intensity {
                    Some(off) => read(base + off).clamp(0.0, 1.0) as f32,
                    None => 1.0,
                };
                if !intensity_out[i].is_finite() {
                    intensity_out[i] = 0.0;
                }
            }
        }
    }
    Ok(DepthFrame {
        stamp,
        pose,
        intrinsics,
        depth_m,
        intensity: intensity_out,
    })
}

/// A ROS pose → an isometry; `None` when not finite or the quaternion is zero.
#[must_use]
pub fn isometry_from_pose(pose: &Pose) -> Option<Isometry3<f64>> {
    let p = pose.position;
    let q = pose.orientation;
    let values = [p.x, p.y, p.z, q.x, q.y, q.z, q.w];
    if !values.iter().all(|v| v.is_finite()) {
        return None;
    }
    let quaternion = Quaternion::new(q.w, q.x, q.y, q.z);
    if quaternion.norm() < 1e-9 {
        return None;
    }
    Some(Isometry3::from_parts(
        Vector3::new(p.x, p.y, p.z).into(),
        UnitQuaternion::from_quaternion(quaternion),
    ))
}

/// An isometry → a ROS pose.
#[must_use]
pub fn pose_from_isometry(pose: &Isometry3<f64>) -> Pose {
    let t = pose.translation.vector;
    let q = pose.rotation.quaternion();
    Pose {
        position: super::msgs::Point {
            x: t.x,
            y: t.y,
            z: t.z,
        },
        orientation: super::msgs::Quaternion {
            x: q.i,
            y: q.j,
            z: q.k,
            w: q.w,
        },
    }
}

/// `nav_msgs/Odometry` (ENU world, FLU body; twist in the body frame) → troupe
/// odometry (velocity in the world frame) stamped `stamp`.
pub fn odometry_from_ros(
    odometry: &super::msgs::Odometry,
    stamp: Time,
) -> Result<Odometry, ConvertError> {
    let pose = isometry_from_pose(&odometry.pose.pose).ok_or(ConvertError::Pose)?;
    let v = odometry.twist.twist.linear;
    let body_velocity = Vector3::new(v.x, v.y, v.z);
    if !body_velocity.iter().all(|c| c.is_finite()) {
        return Err(ConvertError::Pose);
    }
    Ok(Odometry {
        stamp,
        pose,
        velocity_mps: pose.rotation * body_velocity,
    })
}

/// Maps ROS stamps (wall-clock time since the Unix epoch) to troupe run time by the
/// age of the stamp: a message stamped `a` seconds before `unix_now_ns` happened `a`
/// seconds before `troupe_now`. This assumes the ROS host's clock and ours agree
/// (one host, or NTP/PTP); stamps from the future are clamped to `troupe_now`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StampMap {
    /// Troupe time now.
    pub troupe_now: Time,
    /// Wall-clock time now, ns since the Unix epoch.
    pub unix_now_ns: i64,
}

impl StampMap {
    /// The troupe time of a ROS stamp.
    #[must_use]
    pub fn to_troupe(&self, stamp: RosTime) -> Time {
        let age_ns = self.unix_now_ns.saturating_sub(stamp.as_nanos()).max(0);
        Time::from_nanos(
            self.troupe_now
                .as_nanos()
                .saturating_sub(u64::try_from(age_ns).unwrap_or(0)),
        )
    }

    /// The ROS stamp of a troupe time (the inverse of [`StampMap::to_troupe`]).
    #[must_use]
    pub fn to_ros(&self, time: Time) -> RosTime {
        let ahead_ns = i128::from(time.as_nanos()) - i128::from(self.troupe_now.as_nanos());
        let ns = i128::from(self.unix_now_ns) + ahead_ns;
        RosTime::from_nanos(i64::try_from(ns).unwrap_or(i64::MAX))
    }
}

/// The committed plan's knots as a `nav_msgs/Path` in `frame_id` (level poses with
/// the knot's yaw, each stamped with its knot time).
#[must_use]
pub fn path_from_plan(plan: &Plan, frame_id: &str, stamps: &StampMap) -> Path {
    let header = |time| Header {
        stamp: stamps.to_ros(time),
        frame_id: frame_id.to_owned(),
    };
    let poses = plan
        .trajectory
        .knots()
        .iter()
        .map(|knot| {
            let rotation = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), knot.yaw_rad);
            let pose = Isometry3::from_parts(knot.position_m.coords.into(), rotation);
            PoseStamped {
                header: header(knot.time),
                pose: pose_from_isometry(&pose),
            }
        })
        .collect();
    Path {
        header: header(plan.stamp),
        poses,
    }
}

/// Points drawn from a mixture's spatial marginal (§6.1.5) with the expected intensity
/// at each (Eq. 6.13, clamped to [0, 1]), as an unordered `PointCloud2` with float32
/// fields `x, y, z, intensity` (16-byte points, little-endian) in `frame_id`.
/// An empty mixture gives an empty cloud.
pub fn cloud_from_gmm<R: Rng + ?Sized>(
    gmm: &Gmm4,
    points: usize,
    header: Header,
    rng: &mut R,
) -> PointCloud2 {
    let samples: Vec<Vector3<f64>> = if gmm.is_empty() {
        Vec::new()
    } else {
        gmm.marginal_spatial().sample(points, rng)
    };
    let conditional = IntensityConditional::new(gmm);
    let mut data = Vec::with_capacity(samples.len() * 16);
    for p in &samples {
        let g = conditional.estimate(p).mean.clamp(0.0, 1.0);
        for v in [p.x, p.y, p.z, g] {
            data.extend_from_slice(&(v as f32).to_le_bytes());
        }
    }
    let field = |name: &str, offset| PointField {
        name: name.to_owned(),
        offset,
        datatype: PointField::FLOAT32,
        count: 1,
    };
    let width = u32::try_from(samples.len()).unwrap_or(u32::MAX);
    PointCloud2 {
        header,
        height: 1,
        width,
        fields: vec![
            field("x", 0),
            field("y", 4),
            field("z", 8),
            field("intensity", 12),
        ],
        is_bigendian: false,
        point_step: 16,
        row_step: width.saturating_mul(16),
        data,
        is_dense: true,
    }
}

/// The camera body pose of a frame: the body pose, then the optical frame's pose in
/// the body (the camera extrinsics as ROS TF gives them, e.g. `base_link` →
/// `camera_depth_optical_frame`), then the optical → camera body rotation.
#[must_use]
pub fn camera_pose(body: &Isometry3<f64>, optical_in_body: &Isometry3<f64>) -> Isometry3<f64> {
    body * optical_in_body * optical_to_camera().inverse()
}

#[cfg(test)]
#[path = "convert_tests.rs"]
mod tests;
