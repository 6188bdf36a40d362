//! Recorded depth + intensity sequences in the TUM RGB-D layout: read them as
//! [`DepthFrame`]s (also as a [`FrameSource`] for a robot), and record the simulated
//! camera into one.
//!
//! # Layout of a sequence directory
//!
//! ```text
//! SEQ/
//!   camera.toml       fx, fy, cx, cy (pixels), width, height, depth_scale, [max_depth_m]
//!   depth.txt         "timestamp path" per line, e.g. "12.500000 depth/12.500000.png"
//!   rgb.txt           the same for the intensity (grey) or colour images
//!   groundtruth.txt   "timestamp tx ty tz qx qy qz qw" per line
//!   associations.txt  optional: "t_rgb rgb_path t_depth depth_path" per line
//!   depth/*.png       16-bit greyscale; metres = value / depth_scale; 0 = no return
//!   rgb/*.png         8- or 16-bit grey, RGB or RGBA (colour becomes Rec. 601 luma)
//! ```
//!
//! Lines starting with `#` and blank lines are ignored in the lists (as in the TUM
//! files). `camera.toml` (every key but `max_depth_m` required; unknown keys are
//! errors):
//!
//! ```toml
//! fx = 80.0           # focal lengths, pixels
//! fy = 80.0
//! cx = 80.0           # principal point, pixels (pixel centres at integer + 0.5)
//! cy = 60.0
//! width = 160         # image size, pixels
//! height = 120
//! depth_scale = 1000.0  # depth PNG units per metre (1000: millimetres; TUM uses 5000)
//! max_depth_m = 5.0     # optional, default 5: returns beyond it are dropped
//! ```
//!
//! **Association.** With `associations.txt`, its pairs are the frames. Otherwise every
//! depth image is paired with the intensity image of nearest timestamp, if within
//! [`MAX_ASSOCIATION_S`]. Either way the pose is the ground-truth line of nearest
//! timestamp within [`MAX_ASSOCIATION_S`]; frames with no intensity image or pose that
//! near are skipped and counted ([`Sequence::skipped`]).
//!
//! **Poses** follow TUM: the pose of the camera's optical frame (x right, y down,
//! z forward) in the world. troupe's body frame (x forward, y left, z up; see
//! `msgs::DepthFrame`) is `optical · R` with `R` = [`optical_from_body`].

mod build;
mod png_io;
#[cfg(test)]
mod tests;

pub use build::{MapBuildOptions, MapStats, build_map, integrate};

use std::path::{Path, PathBuf};

use nalgebra::{Isometry3, Matrix3, Quaternion, Rotation3, Translation3, UnitQuaternion};
use serde::{Deserialize, Serialize};
use troupe_actors::sensor::FrameSource;
use troupe_algorithms::camera::PinholeIntrinsics;
use troupe_algorithms::frame::{DepthFrame, Odometry};
use troupe_core::{ConfigError, Time};
use troupe_runtime::ActorError;

use png_io::Plane;

/// Largest timestamp difference, seconds, for pairing a depth image with an intensity
/// image or a pose (TUM's `associate.py` default).
pub const MAX_ASSOCIATION_S: f64 = 0.02;

/// What went wrong with a sequence; every variant names the file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SequenceError {
    /// A file could not be read or written.
    #[error("{path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A required file is missing.
    #[error("{path}: missing ({what})")]
    Missing {
        /// The file.
        path: PathBuf,
        /// What it should hold.
        what: &'static str,
    },
    /// A line of a list or poses file does not parse.
    #[error("{path}:{line}: {reason}")]
    BadLine {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// The camera file is malformed.
    #[error("{path}: {reason}")]
    BadCamera {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A value of the camera file breaks a rule.
    #[error("{path}: invalid setting")]
    InvalidCamera {
        /// The file.
        path: PathBuf,
        /// The key, the rule and the value.
        source: ConfigError,
    },
    /// An image cannot be decoded or does not fit the camera.
    #[error("{path}: {reason}")]
    BadImage {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// No frame has a depth image, an intensity image and a pose.
    #[error(
        "{path}: no frame has a depth image, an intensity image and a pose within {MAX_ASSOCIATION_S} s"
    )]
    Empty {
        /// The sequence directory.
        path: PathBuf,
    },
}

/// The camera file of a sequence (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraFile {
    /// Focal length in x, pixels.
    pub fx: f64,
    /// Focal length in y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Depth PNG units per metre (1000 for millimetres).
    pub depth_scale: f64,
    /// Largest valid depth, metres.
    #[serde(default = "default_max_depth_m")]
    pub max_depth_m: f64,
}

fn default_max_depth_m() -> f64 {
    5.0
}

impl CameraFile {
    /// The camera of a frame's intrinsics, with the given depth scale.
    #[must_use]
    pub fn from_intrinsics(k: &PinholeIntrinsics, depth_scale: f64) -> Self {
        CameraFile {
            fx: k.fx,
            fy: k.fy,
            cx: k.cx,
            cy: k.cy,
            width: k.width,
            height: k.height,
            depth_scale,
            max_depth_m: k.max_depth_m,
        }
    }

    /// The intrinsics in message form.
    #[must_use]
    pub fn intrinsics(&self) -> PinholeIntrinsics {
        PinholeIntrinsics {
            width: self.width,
            height: self.height,
            fx: self.fx,
            fy: self.fy,
            cx: self.cx,
            cy: self.cy,
            max_depth_m: self.max_depth_m,
        }
    }

    /// Checks every field.
    ///
    /// # Errors
    ///
    /// The offending key of `camera.toml`, its rule and its value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        for (key, v) in [
            ("fx", self.fx),
            ("fy", self.fy),
            ("depth_scale", self.depth_scale),
            ("max_depth_m", self.max_depth_m),
        ] {
            ConfigError::positive(key, v)?;
        }
        for (key, v) in [("cx", self.cx), ("cy", self.cy)] {
            if !v.is_finite() {
                return Err(ConfigError::new(key, "must be finite", v));
            }
        }
        for (key, v) in [("width", self.width), ("height", self.height)] {
            if v == 0 {
                return Err(ConfigError::new(key, "must be at least 1", v));
            }
        }
        Ok(())
    }

    /// Read and validate `path`.
    pub fn load(path: &Path) -> Result<Self, SequenceError> {
        let text = read_text(
            path,
            "camera file with fx, fy, cx, cy, width, height, depth_scale",
        )?;
        let camera: CameraFile = toml::from_str(&text).map_err(|e| SequenceError::BadCamera {
            path: path.to_path_buf(),
            reason: e.message().to_string(),
        })?;
        camera
            .validate()
            .map_err(|source| SequenceError::InvalidCamera {
                path: path.to_path_buf(),
                source,
            })?;
        Ok(camera)
    }
}

/// `R` such that the optical frame (x right, y down, z forward) is `body · R⁻¹`, i.e.
/// `body = optical · R`: body x = optical z, body y = −optical x, body z = −optical y.
#[must_use]
pub fn optical_from_body() -> UnitQuaternion<f64> {
    // Columns: the body axes expressed in the optical frame.
    let m = Matrix3::new(0.0, -1.0, 0.0, 0.0, 0.0, -1.0, 1.0, 0.0, 0.0);
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m))
}

/// Body pose (troupe convention) from a TUM optical-frame pose.
#[must_use]
pub fn body_pose(optical: &Isometry3<f64>) -> Isometry3<f64> {
    optical * Isometry3::from_parts(Translation3::identity(), optical_from_body())
}

/// TUM optical-frame pose from a body pose.
#[must_use]
pub fn optical_pose(body: &Isometry3<f64>) -> Isometry3<f64> {
    body * Isometry3::from_parts(Translation3::identity(), optical_from_body().inverse())
}

fn read_text(path: &Path, what: &'static str) -> Result<String, SequenceError> {
    match std::fs::read_to_string(path) {
        Ok(text) => Ok(text),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Err(SequenceError::Missing {
            path: path.to_path_buf(),
            what,
        }),
        Err(source) => Err(SequenceError::Io {
            path: path.to_path_buf(),
            source,
        }),
    }
}

/// The non-comment lines of a list file with their 1-based numbers, split on
/// whitespace.
fn lines(text: &str) -> impl Iterator<Item = (usize, Vec<&str>)> {
    text.lines().enumerate().filter_map(|(i, l)| {
        let l = l.trim();
        (!l.is_empty() && !l.starts_with('#')).then(|| (i + 1, l.split_whitespace().collect()))
    })
}

fn parse_f64(path: &Path, line: usize, field: &str, s: &str) -> Result<f64, SequenceError> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(SequenceError::BadLine {
            path: path.to_path_buf(),
            line,
            reason: format!("{field} `{s}` is not a finite number"),
        }),
    }
}

/// `timestamp path` lines, sorted by time.
fn read_list(path: &Path, what: &'static str) -> Result<Vec<(f64, PathBuf)>, SequenceError> {
    let text = read_text(path, what)?;
    let mut out = Vec::new();
    for (line, fields) in lines(&text) {
        if fields.len() != 2 {
            return Err(SequenceError::BadLine {
                path: path.to_path_buf(),
                line,
                reason: format!("expected `timestamp path`, found {} fields", fields.len()),
            });
        }
        out.push((
            parse_f64(path, line, "timestamp", fields[0])?,
            PathBuf::from(fields[1]),
        ));
    }
    out.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(out)
}

/// `timestamp tx ty tz qx qy qz qw` lines (optical frame), sorted by time.
fn read_poses(path: &Path) -> Result<Vec<(f64, Isometry3<f64>)>, SequenceError> {
    let text = read_text(path, "poses, `timestamp tx ty tz qx qy qz qw` per line")?;
    let mut out = Vec::new();
    for (line, fields) in lines(&text) {
        if fields.len() != 8 {
            return Err(SequenceError::BadLine {
                path: path.to_path_buf(),
                line,
                reason: format!(
                    "expected `timestamp tx ty tz qx qy qz qw`, found {} fields",
                    fields.len()
                ),
            });
        }
        let names = ["timestamp", "tx", "ty", "tz", "qx", "qy", "qz", "qw"];
        let mut v = [0.0; 8];
        for (k, (name, s)) in names.iter().zip(&fields).enumerate() {
            v[k] = parse_f64(path, line, name, s)?;
        }
        let q = Quaternion::new(v[7], v[4], v[5], v[6]);
        if q.norm() < 1e-9 {
            return Err(SequenceError::BadLine {
                path: path.to_path_buf(),
                line,
                reason: "quaternion has zero length".into(),
            });
        }
        out.push((
            v[0],
            Isometry3::from_parts(
                Translation3::new(v[1], v[2], v[3]),
                UnitQuaternion::new_normalize(q),
            ),
        ));
    }
    out.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(out)
}

/// Index of the entry of `sorted` nearest to `t`, if within `MAX_ASSOCIATION_S`.
fn nearest<T>(sorted: &[(f64, T)], t: f64) -> Option<usize> {
    let i = sorted.partition_point(|(s, _)| *s < t);
    [i.checked_sub(1), (i < sorted.len()).then_some(i)]
        .into_iter()
        .flatten()
        .min_by(|&a, &b| (sorted[a].0 - t).abs().total_cmp(&(sorted[b].0 - t).abs()))
        .filter(|&k| (sorted[k].0 - t).abs() <= MAX_ASSOCIATION_S)
}

/// One associated frame of a sequence.
#[derive(Clone, Debug, PartialEq)]
pub struct SequenceEntry {
    /// Depth timestamp, seconds.
    pub stamp_s: f64,
    /// Depth PNG, absolute or relative to the current directory.
    pub depth: PathBuf,
    /// Intensity PNG.
    pub image: PathBuf,
    /// Body pose (troupe convention) in the world.
    pub pose: Isometry3<f64>,
}

/// An opened sequence: camera and the associated frames (images are read on demand).
#[derive(Clone, Debug)]
pub struct Sequence {
    dir: PathBuf,
    camera: CameraFile,
    entries: Vec<SequenceEntry>,
    skipped: usize,
}

impl Sequence {
    /// Read the camera, lists and poses of `dir` and associate them (module doc).
    pub fn open(dir: &Path) -> Result<Self, SequenceError> {
        if !dir.is_dir() {
            return Err(SequenceError::Missing {
                path: dir.to_path_buf(),
                what: "sequence directory",
            });
        }
        let camera = CameraFile::load(&dir.join("camera.toml"))?;
        let poses = read_poses(&dir.join("groundtruth.txt"))?;
        let assoc_path = dir.join("associations.txt");
        let pairs: Vec<(f64, PathBuf, PathBuf)> = if assoc_path.is_file() {
            let text = read_text(&assoc_path, "associations")?;
            let mut out = Vec::new();
            for (line, fields) in lines(&text) {
                if fields.len() != 4 {
                    return Err(SequenceError::BadLine {
                        path: assoc_path.clone(),
                        line,
                        reason: format!(
                            "expected `t_rgb rgb_path t_depth depth_path`, found {} fields",
                            fields.len()
                        ),
                    });
                }
                parse_f64(&assoc_path, line, "rgb timestamp", fields[0])?;
                let t = parse_f64(&assoc_path, line, "depth timestamp", fields[2])?;
                out.push((t, PathBuf::from(fields[3]), PathBuf::from(fields[1])));
            }
            out
        } else {
            let depth = read_list(&dir.join("depth.txt"), "list of depth images")?;
            let rgb = read_list(&dir.join("rgb.txt"), "list of intensity images")?;
            depth
                .into_iter()
                .filter_map(|(t, d)| nearest(&rgb, t).map(|k| (t, d, rgb[k].1.clone())))
                .collect()
        };
        let mut entries = Vec::with_capacity(pairs.len());
        let mut skipped = 0;
        for (t, depth, image) in pairs {
            match nearest(&poses, t) {
                Some(k) => entries.push(SequenceEntry {
                    stamp_s: t,
                    depth: dir.join(depth),
                    image: dir.join(image),
                    pose: body_pose(&poses[k].1),
                }),
                None => skipped += 1,
            }
        }
        if entries.is_empty() {
            return Err(SequenceError::Empty {
                path: dir.to_path_buf(),
            });
        }
        entries.sort_by(|a, b| a.stamp_s.total_cmp(&b.stamp_s));
        Ok(Sequence {
            dir: dir.to_path_buf(),
            camera,
            entries,
            skipped,
        })
    }

    /// The directory.
    #[must_use]
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The camera.
    #[must_use]
    pub fn camera(&self) -> &CameraFile {
        &self.camera
    }

    /// The associated frames, by time.
    #[must_use]
    pub fn entries(&self) -> &[SequenceEntry] {
        &self.entries
    }

    /// Number of frames.
    #[must_use]
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Never true for an opened sequence.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Depth images left out for want of a pose within [`MAX_ASSOCIATION_S`].
    #[must_use]
    pub fn skipped(&self) -> usize {
        self.skipped
    }

    /// Read frame `i` (depth in metres, intensity in [0, 1], body pose, intrinsics,
    /// stamp from the file). Images must match the camera size.
    pub fn frame(&self, i: usize) -> Result<DepthFrame, SequenceError> {
        let Some(e) = self.entries.get(i) else {
            return Err(SequenceError::Empty {
                path: self.dir.clone(),
            });
        };
        let depth = png_io::read_depth(&e.depth)?;
        let image = png_io::read_intensity(&e.image)?;
        let (w, h) = (self.camera.width, self.camera.height);
        for (path, pw, ph) in [
            (&e.depth, depth.width, depth.height),
            (&e.image, image.width, image.height),
        ] {
            if (pw, ph) != (w, h) {
                return Err(SequenceError::BadImage {
                    path: path.clone(),
                    reason: format!("image is {pw}×{ph}, the camera file says {w}×{h}"),
                });
            }
        }
        let scale = self.camera.depth_scale;
        let depth_m: Vec<f32> = depth
            .data
            .iter()
            .map(|&v| (f64::from(v) / scale) as f32)
            .collect();
        let intensity = image
            .data
            .iter()
            .zip(&depth_m)
            .map(|(g, d)| if *d > 0.0 { *g } else { 0.0 })
            .collect();
        Ok(DepthFrame {
            stamp: Time::from_secs_f64(e.stamp_s.max(0.0)),
            pose: e.pose,
            intrinsics: self.camera.intrinsics(),
            depth_m,
            intensity,
        })
    }

    /// Frames in order (each read when reached).
    pub fn frames(&self) -> impl Iterator<Item = Result<DepthFrame, SequenceError>> + '_ {
        (0..self.len()).map(|i| self.frame(i))
    }
}

/// A recorded sequence as a robot's [`FrameSource`]: each capture yields the next
/// frame (stamped with the capture time), then nothing once the sequence ends.
pub struct SequenceSource {
    sequence: Sequence,
    next: usize,
}

impl SequenceSource {
    /// A source playing `sequence` from its first frame.
    #[must_use]
    pub fn new(sequence: Sequence) -> Self {
        SequenceSource { sequence, next: 0 }
    }
}

impl FrameSource for SequenceSource {
    fn capture(
        &mut self,
        now: Time,
        _odometry: Option<&Odometry>,
    ) -> Result<Option<DepthFrame>, ActorError> {
        if self.next >= self.sequence.len() {
            return Ok(None);
        }
        let i = self.next;
        self.next += 1;
        let mut frame = self
            .sequence
            .frame(i)
            .map_err(|e| ActorError::with_source("reading a recorded frame", e))?;
        frame.stamp = now;
        Ok(Some(frame))
    }
}

/// Records frames into a sequence directory (module doc layout): images as they come,
/// the lists, poses and camera file on [`SequenceWriter::finish`].
pub struct SequenceWriter {
    dir: PathBuf,
    camera: Option<CameraFile>,
    depth_scale: f64,
    depth_lines: Vec<String>,
    rgb_lines: Vec<String>,
    pose_lines: Vec<String>,
}

impl SequenceWriter {
    /// Create `dir` (and `depth/`, `rgb/` inside); depth is stored at `depth_scale`
    /// units per metre (1000: millimetres).
    pub fn create(dir: &Path, depth_scale: f64) -> Result<Self, SequenceError> {
        ConfigError::positive("depth_scale", depth_scale).map_err(|source| {
            SequenceError::InvalidCamera {
                path: dir.join("camera.toml"),
                source,
            }
        })?;
        for sub in ["depth", "rgb"] {
            let p = dir.join(sub);
            std::fs::create_dir_all(&p).map_err(|source| SequenceError::Io { path: p, source })?;
        }
        Ok(SequenceWriter {
            dir: dir.to_path_buf(),
            camera: None,
            depth_scale,
            depth_lines: Vec::new(),
            rgb_lines: Vec::new(),
            pose_lines: Vec::new(),
        })
    }

    /// Write one frame (its stamp names the files). Every frame must have the
    /// intrinsics of the first. Depths are rounded to the depth unit; depths that do not
    /// fit 16 bits are written as 0 (no return).
    pub fn write(&mut self, frame: &DepthFrame) -> Result<(), SequenceError> {
        let camera = CameraFile::from_intrinsics(&frame.intrinsics, self.depth_scale);
        match &self.camera {
            None => self.camera = Some(camera),
            Some(c) if *c == camera => {}
            Some(_) => {
                return Err(SequenceError::BadCamera {
                    path: self.dir.join("camera.toml"),
                    reason: "a frame's intrinsics differ from the first frame's".into(),
                });
            }
        }
        let t = frame.stamp.as_secs_f64();
        let name = format!("{t:.6}.png");
        let (w, h) = (frame.intrinsics.width, frame.intrinsics.height);
        let depth = Plane {
            width: w,
            height: h,
            data: frame
                .depth_m
                .iter()
                .map(|d| {
                    let v = (f64::from(*d) * self.depth_scale).round();
                    if v.is_finite() && v > 0.0 && v <= f64::from(u16::MAX) {
                        v as u16
                    } else {
                        0
                    }
                })
                .collect(),
        };
        png_io::write_depth(&self.dir.join("depth").join(&name), &depth)?;
        let image = Plane {
            width: w,
            height: h,
            data: frame.intensity.clone(),
        };
        png_io::write_intensity(&self.dir.join("rgb").join(&name), &image)?;
        self.depth_lines.push(format!("{t:.6} depth/{name}"));
        self.rgb_lines.push(format!("{t:.6} rgb/{name}"));
        let p = optical_pose(&frame.pose);
        let (tr, q) = (p.translation.vector, p.rotation.quaternion().coords);
        self.pose_lines.push(format!(
            "{t:.6} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9} {:.9}",
            tr.x, tr.y, tr.z, q[0], q[1], q[2], q[3]
        ));
        Ok(())
    }

    /// Write the lists, the poses and the camera file; returns the directory.
    pub fn finish(self) -> Result<PathBuf, SequenceError> {
        let Some(camera) = self.camera else {
            return Err(SequenceError::Empty { path: self.dir });
        };
        let write = |name: &str, header: &str, lines: &Vec<String>| {
            let path = self.dir.join(name);
            let mut text = format!("# {header}\n");
            for l in lines {
                text.push_str(l);
                text.push('\n');
            }
            std::fs::write(&path, text).map_err(|source| SequenceError::Io { path, source })
        };
        write(
            "depth.txt",
            "timestamp filename (16-bit depth PNG)",
            &self.depth_lines,
        )?;
        write(
            "rgb.txt",
            "timestamp filename (intensity PNG)",
            &self.rgb_lines,
        )?;
        write(
            "groundtruth.txt",
            "timestamp tx ty tz qx qy qz qw (camera optical frame in the world)",
            &self.pose_lines,
        )?;
        let toml = toml::to_string(&camera).map_err(|e| SequenceError::BadCamera {
            path: self.dir.join("camera.toml"),
            reason: e.to_string(),
        })?;
        let path = self.dir.join("camera.toml");
        std::fs::write(&path, toml).map_err(|source| SequenceError::Io { path, source })?;
        Ok(self.dir)
    }
}

/// Render `world` with `camera` at each `(time_s, body pose)` of `path` and record the
/// frames as a sequence in `dir` (depth in millimetres). Noise, if the camera has any,
/// is seeded by `noise_seed` and the frame number.
pub fn record_camera(
    dir: &Path,
    world: &dyn crate::world::World,
    camera: &crate::camera::CameraParams,
    path: &[(f64, Isometry3<f64>)],
    noise_seed: u64,
) -> Result<PathBuf, SequenceError> {
    let mut writer = SequenceWriter::create(dir, 1000.0)?;
    for (i, (t, pose)) in path.iter().enumerate() {
        writer.write(&camera.render(
            world,
            Time::from_secs_f64(t.max(0.0)),
            pose,
            noise_seed ^ (i as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15),
        ))?;
    }
    writer.finish()
}
