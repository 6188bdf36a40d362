//! A map on disk: the keyframe mixtures of a mapping run with their poses and support
//! sizes, in a small versioned binary file, and a PLY point cloud sampled from it.
//!
//! # File layout (version 1, all numbers little-endian)
//!
//! | bytes | field |
//! |---|---|
//! | 8 | magic `TROUPEMP` |
//! | 4 | `u32` format version (1) |
//! | 1 | `u8` model: 0 = sogmm, 1 = windowed |
//! | 3 | zero |
//! | 4 | `u32` number of keyframes `K` |
//! | 8 | `u64` length of the body in bytes |
//! | body | `K` keyframe records |
//! | 8 | `u64` FNV-1a 64 checksum of every byte before it |
//!
//! A keyframe record: `f64` stamp (s); pose as `f64` translation x, y, z (m) and unit
//! quaternion i, j, k, w; `u64` occupied support size; `u64` free-space support size;
//! `u32` occupied components `M`; `u32` free-space components `F`; then `M` 4D
//! components (`f64` weight, 4 mean, 16 covariance entries row by row) and `F` 3D
//! components (weight, 3 mean, 9 covariance entries). Values are `f64` and covariances
//! are stored whole (a fitted covariance may be asymmetric in its last bits), so a save
//! and load round trip is exact; a 4D component costs 168 bytes here (the wire format
//! of `troupe-comms` sends 60 B in f32).
//!
//! Loading checks the magic, version, lengths and checksum before decoding, and every
//! mixture's invariants (weights sum to 1, covariances positive definite) after, and
//! says which check failed; it never panics on any input.

use std::io::Write;
use std::path::{Path, PathBuf};

use nalgebra::{
    Isometry3, Matrix3, Matrix4, Quaternion, Translation3, UnitQuaternion, Vector3, Vector4,
};
use rand::Rng;

use crate::mixture::box_muller;
use crate::mixture::merge_gmm4;
use crate::mixture::{Gmm3, Gmm4, MixtureError};
use crate::model::MapModel;

/// The 8 bytes every map file starts with.
pub const MAGIC: [u8; 8] = *b"TROUPEMP";
/// The format version this code writes and reads.
pub const FORMAT_VERSION: u32 = 1;
const HEADER_BYTES: usize = 8 + 4 + 1 + 3 + 4 + 8;
const CHECKSUM_BYTES: usize = 8;
/// Bytes of one 4D component record.
pub const COMPONENT4_BYTES: usize = 8 * (1 + 4 + 16);
/// Bytes of one 3D component record.
pub const COMPONENT3_BYTES: usize = 8 * (1 + 3 + 9);
const KEYFRAME_FIXED_BYTES: usize = 8 + 8 * 7 + 8 + 8 + 4 + 4;

/// Why a map could not be read or written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum MapFileError {
    /// The file could not be opened, read or written.
    #[error("{path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The first 8 bytes are not [`MAGIC`].
    #[error("not a troupe map file (bad magic bytes)")]
    BadMagic,
    /// A version this code does not read.
    #[error("map format version {found} is not supported (this build reads {FORMAT_VERSION})")]
    UnsupportedVersion {
        /// The version in the file.
        found: u32,
    },
    /// The model byte is not 0 or 1.
    #[error("unknown map model code {0}")]
    UnknownModel(u8),
    /// The data ends early.
    #[error("truncated map: {what} needs {needed} bytes at offset {offset}, {available} left")]
    Truncated {
        /// What was being read.
        what: &'static str,
        /// Where.
        offset: usize,
        /// Bytes needed.
        needed: usize,
        /// Bytes left.
        available: usize,
    },
    /// The checksum does not match the contents.
    #[error("map is corrupt: checksum {found:#018x}, contents hash to {computed:#018x}")]
    Checksum {
        /// Stored checksum.
        found: u64,
        /// Checksum of the contents.
        computed: u64,
    },
    /// The body length in the header disagrees with the records.
    #[error("map body is {declared} bytes by its header but its records take {actual}")]
    BodyLength {
        /// From the header.
        declared: u64,
        /// From the records.
        actual: u64,
    },
    /// A keyframe's pose is not finite or its quaternion is not of unit length.
    #[error("keyframe {keyframe}: pose is not a finite rigid transform")]
    BadPose {
        /// Keyframe index.
        keyframe: usize,
    },
    /// A keyframe's mixture breaks an invariant.
    #[error("keyframe {keyframe}")]
    BadMixture {
        /// Keyframe index.
        keyframe: usize,
        /// What is wrong.
        source: MixtureError,
    },
}

/// One keyframe of a map: its mixtures, the sensor pose and the support sizes.
#[derive(Clone, Debug)]
pub struct MapKeyframe {
    /// Observation time, seconds: run time in a simulated team's maps, the team clock
    /// (Unix time) in a base station's.
    pub stamp_s: f64,
    /// Sensor (body) pose in the map frame.
    pub pose: Isometry3<f64>,
    /// Points the occupied mixture represents (`N_i` of Eq. 3.4).
    pub support: u64,
    /// Occupied surface over (x, y, z, intensity).
    pub occupied: Gmm4,
    /// Free-space mixture (windowed model).
    pub free: Option<Gmm3>,
    /// Support size of `free`.
    pub free_support: u64,
}

impl PartialEq for MapKeyframe {
    /// Equal fields; mixtures compare by their parameters.
    fn eq(&self, other: &Self) -> bool {
        let same_free = match (&self.free, &other.free) {
            (None, None) => true,
            (Some(a), Some(b)) => {
                a.weights() == b.weights()
                    && a.means() == b.means()
                    && a.covariances() == b.covariances()
            }
            _ => false,
        };
        self.stamp_s == other.stamp_s
            && self.pose == other.pose
            && self.support == other.support
            && self.occupied == other.occupied
            && self.free_support == other.free_support
            && same_free
    }
}

/// A map: the keyframe mixtures of one robot's run, all in one frame. The global
/// surface is their union weighted by support (Eq. 3.5, [`GmmMap::merged_occupied`]).
#[derive(Clone, Debug, PartialEq)]
pub struct GmmMap {
    /// How the keyframes were fitted.
    pub model: MapModel,
    /// The keyframes, in order.
    pub keyframes: Vec<MapKeyframe>,
}

/// FNV-1a, 64 bit.
fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in bytes {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

struct Reader<'a> {
    bytes: &'a [u8],
    offset: usize,
}

impl<'a> Reader<'a> {
    /// An error naming `what` if fewer than `n` bytes are left; takes nothing.
    fn ensure(&self, n: usize, what: &'static str) -> Result<(), MapFileError> {
        let available = self.bytes.len() - self.offset;
        if n > available {
            return Err(MapFileError::Truncated {
                what,
                offset: self.offset,
                needed: n,
                available,
            });
        }
        Ok(())
    }

    fn take(&mut self, n: usize, what: &'static str) -> Result<&'a [u8], MapFileError> {
        self.ensure(n, what)?;
        let s = &self.bytes[self.offset..self.offset + n];
        self.offset += n;
        Ok(s)
    }

    fn array<const N: usize>(&mut self, what: &'static str) -> Result<[u8; N], MapFileError> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N, what)?);
        Ok(a)
    }

    fn u32(&mut self, what: &'static str) -> Result<u32, MapFileError> {
        Ok(u32::from_le_bytes(self.array(what)?))
    }

    fn u64(&mut self, what: &'static str) -> Result<u64, MapFileError> {
        Ok(u64::from_le_bytes(self.array(what)?))
    }

    fn f64(&mut self, what: &'static str) -> Result<f64, MapFileError> {
        Ok(f64::from_le_bytes(self.array(what)?))
    }

    fn f64s<const N: usize>(&mut self, what: &'static str) -> Result<[f64; N], MapFileError> {
        let mut out = [0.0; N];
        for v in &mut out {
            *v = self.f64(what)?;
        }
        Ok(out)
    }
}

fn put_f64s(out: &mut Vec<u8>, values: &[f64]) {
    for v in values {
        out.extend_from_slice(&v.to_le_bytes());
    }
}

impl GmmMap {
    /// Total occupied components over all keyframes.
    #[must_use]
    pub fn occupied_components(&self) -> usize {
        self.keyframes.iter().map(|k| k.occupied.len()).sum()
    }

    /// Total free-space components over all keyframes.
    #[must_use]
    pub fn free_components(&self) -> usize {
        self.keyframes
            .iter()
            .map(|k| k.free.as_ref().map_or(0, Gmm3::len))
            .sum()
    }

    /// The global occupied surface: every keyframe's mixture merged by Eq. 3.5 with its
    /// support size. Errors on an empty map.
    pub fn merged_occupied(&self) -> Result<Gmm4, MixtureError> {
        let parts: Vec<(f64, &Gmm4)> = self
            .keyframes
            .iter()
            .map(|k| (k.support as f64, &k.occupied))
            .collect();
        merge_gmm4(&parts)
    }

    /// Size of [`GmmMap::to_bytes`] without building it.
    #[must_use]
    pub fn encoded_len(&self) -> usize {
        HEADER_BYTES + self.body_len() + CHECKSUM_BYTES
    }

    fn body_len(&self) -> usize {
        self.keyframes
            .iter()
            .map(|k| {
                KEYFRAME_FIXED_BYTES
                    + k.occupied.len() * COMPONENT4_BYTES
                    + k.free.as_ref().map_or(0, Gmm3::len) * COMPONENT3_BYTES
            })
            .sum()
    }

    /// Encode in the layout of the module doc.
    #[must_use]
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(self.encoded_len());
        out.extend_from_slice(&MAGIC);
        out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
        out.push(match self.model {
            MapModel::Sogmm => 0,
            MapModel::Windowed => 1,
        });
        out.extend_from_slice(&[0; 3]);
        out.extend_from_slice(&(self.keyframes.len() as u32).to_le_bytes());
        out.extend_from_slice(&(self.body_len() as u64).to_le_bytes());
        for k in &self.keyframes {
            let t = k.pose.translation.vector;
            let q = k.pose.rotation.quaternion().coords; // i, j, k, w
            put_f64s(
                &mut out,
                &[k.stamp_s, t.x, t.y, t.z, q[0], q[1], q[2], q[3]],
            );
            out.extend_from_slice(&k.support.to_le_bytes());
            out.extend_from_slice(&k.free_support.to_le_bytes());
            out.extend_from_slice(&(k.occupied.len() as u32).to_le_bytes());
            let nf = k.free.as_ref().map_or(0, Gmm3::len);
            out.extend_from_slice(&(nf as u32).to_le_bytes());
            for ((w, m), c) in k
                .occupied
                .weights()
                .iter()
                .zip(k.occupied.means())
                .zip(k.occupied.covariances())
            {
                put_f64s(&mut out, &[*w, m[0], m[1], m[2], m[3]]);
                for r in 0..4 {
                    for col in 0..4 {
                        out.extend_from_slice(&c[(r, col)].to_le_bytes());
                    }
                }
            }
            if let Some(free) = &k.free {
                for ((w, m), c) in free
                    .weights()
                    .iter()
                    .zip(free.means())
                    .zip(free.covariances())
                {
                    put_f64s(&mut out, &[*w, m[0], m[1], m[2]]);
                    for r in 0..3 {
                        for col in 0..3 {
                            out.extend_from_slice(&c[(r, col)].to_le_bytes());
                        }
                    }
                }
            }
        }
        let sum = fnv1a64(&out);
        out.extend_from_slice(&sum.to_le_bytes());
        out
    }

    /// Decode and validate (see the module doc); never panics.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, MapFileError> {
        let mut r = Reader { bytes, offset: 0 };
        if r.array::<8>("magic")? != MAGIC {
            return Err(MapFileError::BadMagic);
        }
        let version = r.u32("version")?;
        if version != FORMAT_VERSION {
            return Err(MapFileError::UnsupportedVersion { found: version });
        }
        let model = match r.array::<4>("model")?[0] {
            0 => MapModel::Sogmm,
            1 => MapModel::Windowed,
            other => return Err(MapFileError::UnknownModel(other)),
        };
        let count = r.u32("keyframe count")? as usize;
        let body = r.u64("body length")?;
        let body_usize = usize::try_from(body).unwrap_or(usize::MAX);
        r.take(body_usize, "keyframe records")?;
        let end = r.offset;
        let found = r.u64("checksum")?;
        let computed = fnv1a64(&bytes[..end]);
        if found != computed {
            return Err(MapFileError::Checksum { found, computed });
        }
        if r.offset != bytes.len() {
            return Err(MapFileError::BodyLength {
                declared: body,
                actual: (bytes.len() - HEADER_BYTES - CHECKSUM_BYTES) as u64,
            });
        }
        let mut r = Reader {
            bytes: &bytes[..end],
            offset: HEADER_BYTES,
        };
        let mut keyframes = Vec::with_capacity(count.min(body_usize / KEYFRAME_FIXED_BYTES));
        for keyframe in 0..count {
            let [stamp_s, tx, ty, tz, qi, qj, qk, qw] = r.f64s::<8>("keyframe pose")?;
            let support = r.u64("support size")?;
            let free_support = r.u64("free support size")?;
            let m = r.u32("component count")? as usize;
            let f = r.u32("free component count")? as usize;
            let q = Quaternion::new(qw, qi, qj, qk);
            let values = [stamp_s, tx, ty, tz, qi, qj, qk, qw];
            if !values.iter().all(|v| v.is_finite()) || (q.norm() - 1.0).abs() > 1e-6 {
                return Err(MapFileError::BadPose { keyframe });
            }
            let pose = Isometry3::from_parts(
                Translation3::new(tx, ty, tz),
                // Checked above to be of unit length within 1e-6; kept bit-exact.
                UnitQuaternion::new_unchecked(q),
            );
            // Checked before allocating for them.
            r.ensure(m.saturating_mul(COMPONENT4_BYTES), "occupied components")?;
            let (mut w, mut mu, mut cov) = (
                Vec::with_capacity(m),
                Vec::with_capacity(m),
                Vec::with_capacity(m),
            );
            for _ in 0..m {
                let [wi, m0, m1, m2, m3] = r.f64s::<5>("component")?;
                let u = r.f64s::<16>("covariance")?;
                w.push(wi);
                mu.push(Vector4::new(m0, m1, m2, m3));
                cov.push(Matrix4::from_row_slice(&u));
            }
            let occupied = Gmm4::new(w, mu, cov)
                .map_err(|source| MapFileError::BadMixture { keyframe, source })?;
            let free = if f == 0 {
                None
            } else {
                r.ensure(f.saturating_mul(COMPONENT3_BYTES), "free-space components")?;
                let (mut w, mut mu, mut cov) = (
                    Vec::with_capacity(f),
                    Vec::with_capacity(f),
                    Vec::with_capacity(f),
                );
                for _ in 0..f {
                    let [wi, m0, m1, m2] = r.f64s::<4>("free component")?;
                    let u = r.f64s::<9>("free covariance")?;
                    w.push(wi);
                    mu.push(Vector3::new(m0, m1, m2));
                    cov.push(Matrix3::from_row_slice(&u));
                }
                Some(
                    Gmm3::new(w, mu, cov)
                        .map_err(|source| MapFileError::BadMixture { keyframe, source })?,
                )
            };
            keyframes.push(MapKeyframe {
                stamp_s,
                pose,
                support,
                occupied,
                free,
                free_support,
            });
        }
        if r.offset != end {
            return Err(MapFileError::BodyLength {
                declared: body,
                actual: (r.offset - HEADER_BYTES) as u64,
            });
        }
        Ok(GmmMap { model, keyframes })
    }

    /// Write to `path` (through a temporary file renamed into place, so a reader never
    /// sees half a map).
    pub fn save(&self, path: &Path) -> Result<(), MapFileError> {
        write_atomically(path, &self.to_bytes())
    }

    /// Read and validate `path`.
    pub fn load(path: &Path) -> Result<Self, MapFileError> {
        let bytes = std::fs::read(path).map_err(|source| MapFileError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_bytes(&bytes)
    }
}

/// Write `bytes` to `path` via `path.tmp` and a rename.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), MapFileError> {
    let io = |source| MapFileError::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    std::fs::write(&tmp, bytes).map_err(io)?;
    std::fs::rename(&tmp, path).map_err(io)
}

/// A point of the reconstructed surface with its intensity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    /// Position, metres.
    pub position: Vector3<f64>,
    /// Intensity in [0, 1].
    pub intensity: f64,
}

/// Draw `n` surface points from a 4D mixture (§6.1.5): a component `m` by weight, a
/// position `x` from its spatial marginal (Eq. 6.11), and the intensity that
/// component predicts there, `μ_g + Σ_gx Σ_xx⁻¹ (x − μ_x)` (the per-component term of
/// Eq. 6.13), clamped to [0, 1]. O(1) per point whatever the map size (the full
/// Eq. 6.13 sums over every component). Deterministic for a given `rng` state.
pub fn sample_surface<R: Rng + ?Sized>(gmm: &Gmm4, n: usize, rng: &mut R) -> Vec<SurfacePoint> {
    struct Part {
        mean: Vector4<f64>,
        l: Matrix3<f64>,
        b: Vector3<f64>,
    }
    let parts: Vec<Option<Part>> = gmm
        .means()
        .iter()
        .zip(gmm.covariances())
        .map(|(mean, cov)| {
            let sxx = cov.fixed_view::<3, 3>(0, 0).into_owned();
            let sxg: Vector3<f64> = cov.fixed_view::<3, 1>(0, 3).into_owned();
            let ch = sxx.cholesky()?;
            Some(Part {
                mean: *mean,
                b: ch.solve(&sxg),
                l: ch.l(),
            })
        })
        .collect();
    let mut cumulative = Vec::with_capacity(gmm.len());
    let mut acc = 0.0;
    for w in gmm.weights() {
        acc += w;
        cumulative.push(acc);
    }
    let last = gmm.len().saturating_sub(1);
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        let u = rng.random::<f64>() * acc;
        let m = cumulative.partition_point(|c| *c <= u).min(last);
        let (z0, z1) = box_muller(rng);
        let (z2, _) = box_muller(rng);
        // A validated mixture's spatial blocks are PD; a `None` cannot occur, and if it
        // did the draw is simply repeated with another component.
        let Some(p) = &parts[m] else { continue };
        let dx = p.l * Vector3::new(z0, z1, z2);
        let g = p.mean[3] + p.b.dot(&dx);
        out.push(SurfacePoint {
            position: p.mean.xyz() + dx,
            intensity: g.clamp(0.0, 1.0),
        });
    }
    out
}

/// Write points as a binary little-endian PLY: per vertex `float x, y, z`,
/// `float intensity` and `uchar red, green, blue` (the intensity as grey, so common
/// viewers show it).
pub fn write_ply<W: Write>(out: W, points: &[SurfacePoint]) -> std::io::Result<()> {
    write_ply_with_source(out, points, None)
}

/// [`write_ply`] with, when `source` is given, one more per-vertex property
/// `uchar source` (for a team's merged map: the robot whose keyframe the point was
/// drawn from). `source` must have one entry per point.
pub fn write_ply_with_source<W: Write>(
    mut out: W,
    points: &[SurfacePoint],
    source: Option<&[u8]>,
) -> std::io::Result<()> {
    if source.is_some_and(|s| s.len() != points.len()) {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "one source tag per point is required",
        ));
    }
    write!(
        out,
        "ply\nformat binary_little_endian 1.0\ncomment troupe map sample\nelement vertex {}\n\
         property float x\nproperty float y\nproperty float z\nproperty float intensity\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\n{}end_header\n",
        points.len(),
        if source.is_some() {
            "property uchar source\n"
        } else {
            ""
        }
    )?;
    let mut buf = Vec::with_capacity(points.len() * 20);
    for (i, p) in points.iter().enumerate() {
        for v in [p.position.x, p.position.y, p.position.z, p.intensity] {
            buf.extend_from_slice(&(v as f32).to_le_bytes());
        }
        let grey = (p.intensity.clamp(0.0, 1.0) * 255.0).round() as u8;
        buf.extend_from_slice(&[grey; 3]);
        if let Some(tags) = source {
            buf.push(tags[i]);
        }
    }
    out.write_all(&buf)?;
    out.flush()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::sogmm::{SogmmConfig, fit_frame, synthetic};
    use crate::windowed::{WindowedConfig, fit_windowed};

    fn sample_map() -> GmmMap {
        let intr = synthetic::intrinsics(40, 30);
        let pose = synthetic::room_pose();
        let (d, g) = synthetic::Scene::room_corner().render(&intr, &pose);
        let sogmm = fit_frame(&d, &g, &intr, &pose, &SogmmConfig::default()).unwrap();
        let win = fit_windowed(
            &d,
            &g,
            &intr,
            &pose,
            &WindowedConfig {
                range_m: Some(4.0),
                min_window_points: 5,
                occupied_components: 3,
                free_components: 2,
                ..WindowedConfig::default()
            },
        )
        .unwrap();
        assert!(win.free.is_some());
        GmmMap {
            model: MapModel::Windowed,
            keyframes: vec![
                MapKeyframe {
                    stamp_s: 0.5,
                    pose,
                    support: sogmm.report.points as u64,
                    occupied: sogmm.gmm,
                    free: None,
                    free_support: 0,
                },
                MapKeyframe {
                    stamp_s: 1.5,
                    pose: Isometry3::translation(1.0, -2.0, 0.25),
                    support: win.occupied_support as u64,
                    occupied: win.occupied,
                    free: win.free,
                    free_support: win.free_support as u64,
                },
            ],
        }
    }

    #[test]
    fn save_and_load_round_trip_exactly() {
        let map = sample_map();
        let bytes = map.to_bytes();
        assert_eq!(bytes.len(), map.encoded_len());
        assert_eq!(GmmMap::from_bytes(&bytes).unwrap(), map);
        let dir = tempfile_dir();
        let path = dir.join("map.troupe");
        map.save(&path).unwrap();
        assert_eq!(GmmMap::load(&path).unwrap(), map);
        assert!(!dir.join("map.troupe.tmp").exists());
        let merged = map.merged_occupied().unwrap();
        assert_eq!(merged.len(), map.occupied_components());
        merged.validate().unwrap();
        std::fs::remove_dir_all(dir).unwrap();
    }

    fn tempfile_dir() -> PathBuf {
        let dir = std::env::temp_dir().join(format!(
            "troupe-mapfile-{}-{:?}",
            std::process::id(),
            std::thread::current().id()
        ));
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn every_truncation_is_an_error() {
        let bytes = sample_map().to_bytes();
        for len in (0..bytes.len()).step_by(7).chain([bytes.len() - 1]) {
            assert!(GmmMap::from_bytes(&bytes[..len]).is_err(), "length {len}");
        }
        let mut longer = bytes.clone();
        longer.push(0);
        assert!(GmmMap::from_bytes(&longer).is_err());
    }

    #[test]
    fn every_flipped_byte_is_an_error() {
        let bytes = sample_map().to_bytes();
        for i in (0..bytes.len()).step_by(13) {
            let mut bad = bytes.clone();
            bad[i] ^= 0x5a;
            assert!(GmmMap::from_bytes(&bad).is_err(), "byte {i}");
        }
        let mut bad = bytes.clone();
        bad[8] = 2; // version 2, checked before the checksum
        assert!(matches!(
            GmmMap::from_bytes(&bad),
            Err(MapFileError::UnsupportedVersion { found: 2 })
        ));
        assert!(matches!(
            GmmMap::from_bytes(b"PLY\n...."),
            Err(MapFileError::BadMagic | MapFileError::Truncated { .. })
        ));
    }

    #[test]
    fn an_invalid_mixture_with_a_good_checksum_is_rejected() {
        let map = sample_map();
        let mut bytes = map.to_bytes();
        // First weight of the first keyframe → 2.0, then re-checksum.
        let at = HEADER_BYTES + KEYFRAME_FIXED_BYTES;
        bytes[at..at + 8].copy_from_slice(&2.0f64.to_le_bytes());
        let n = bytes.len() - CHECKSUM_BYTES;
        let sum = fnv1a64(&bytes[..n]);
        bytes[n..].copy_from_slice(&sum.to_le_bytes());
        assert!(matches!(
            GmmMap::from_bytes(&bytes),
            Err(MapFileError::BadMixture { keyframe: 0, .. })
        ));
        let missing = GmmMap::load(Path::new("/nonexistent/troupe/map")).unwrap_err();
        assert!(missing.to_string().contains("/nonexistent/troupe/map"));
    }

    #[test]
    fn ply_has_a_valid_header_and_the_points() {
        let map = sample_map();
        let gmm = map.merged_occupied().unwrap();
        let pts = sample_surface(&gmm, 500, &mut ChaCha8Rng::seed_from_u64(1));
        assert!(pts.iter().all(|p| (0.0..=1.0).contains(&p.intensity)));
        let mut buf = Vec::new();
        write_ply(&mut buf, &pts).unwrap();
        let end = buf.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
        let header = std::str::from_utf8(&buf[..end]).unwrap();
        assert!(header.contains("element vertex 500\n"));
        assert_eq!(buf.len() - end, 500 * 19);
        let first = &buf[end..end + 16];
        let x = f32::from_le_bytes(first[0..4].try_into().unwrap());
        let g = f32::from_le_bytes(first[12..16].try_into().unwrap());
        assert_eq!(x, pts[0].position.x as f32);
        assert_eq!(g, pts[0].intensity as f32);
        // Samples follow the surface: near the scene on average.
        let scene = synthetic::Scene::room_corner();
        let err = pts
            .iter()
            .map(|p| scene.distance(&nalgebra::Point3::from(p.position)))
            .sum::<f64>()
            / pts.len() as f64;
        assert!(err < 0.1, "{err}");
    }

    #[test]
    fn ply_with_source_tags_every_vertex() {
        let map = sample_map();
        let gmm = map.merged_occupied().unwrap();
        let pts = sample_surface(&gmm, 10, &mut ChaCha8Rng::seed_from_u64(2));
        let tags: Vec<u8> = (0..10).map(|i| (i % 3) as u8).collect();
        let mut buf = Vec::new();
        write_ply_with_source(&mut buf, &pts, Some(&tags)).unwrap();
        let end = buf.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
        let header = std::str::from_utf8(&buf[..end]).unwrap();
        assert!(header.contains("property uchar source\nend_header"));
        assert_eq!(buf.len() - end, 10 * 20);
        let last_tags: Vec<u8> = buf[end..].chunks(20).map(|v| v[19]).collect();
        assert_eq!(last_tags, tags);
        assert!(write_ply_with_source(Vec::new(), &pts, Some(&tags[..3])).is_err());
    }
}
