//! Depth frames and keyframes ray-traced into the grid (thesis §3.2.3, §8.2.2).

use nalgebra::Point3;

use super::{LocalGrid, ScanScratch, UpdateRule};
use crate::frame::DepthFrame;
use crate::keyframe::Keyframe;

/// How far a pixel without a return may be taken as free space, metres: the sensor's
/// range when none of its eight neighbours on the `stride` lattice (the pixels `stride`
/// away in u and v, the ones a reader of every `stride`-th pixel reads) has a return
/// either (open space), else the nearest neighbouring return less `margin_m` (a
/// dropout, or a sphere-traced ray that gave up at a grazing surface, inside a surface
/// the neighbours did see: the ray certainly crosses free space that far, and taking
/// it to the range would clear a ray straight through that surface — the safety study
/// found robots flying into boxes that such rays had cleared). A frame's every
/// `stride`-th pixel therefore gives what the frame decimated by `stride` gives at
/// stride 1. `None` for a pixel with a return.
#[must_use]
pub fn free_range_m(
    frame: &DepthFrame,
    (row, col): (usize, usize),
    stride: usize,
    margin_m: f64,
) -> Option<f64> {
    let (w, h) = (
        frame.intrinsics.width as usize,
        frame.intrinsics.height as usize,
    );
    if frame.depth_m.get(row * w + col).is_none_or(|d| *d > 0.0) {
        return None;
    }
    let s = stride.max(1);
    let around = |i: usize, n: usize| {
        [i.checked_sub(s), Some(i), Some(i + s).filter(|j| *j < n)]
            .into_iter()
            .flatten()
    };
    let nearest = around(row, h)
        .flat_map(|r| around(col, w).map(move |c| r * w + c))
        .filter_map(|i| frame.depth_m.get(i).copied())
        .filter(|d| *d > 0.0)
        .fold(f32::INFINITY, f32::min);
    if nearest.is_finite() {
        Some(f64::from(nearest) - margin_m).filter(|r| *r > 0.0)
    } else {
        Some(frame.intrinsics.max_depth_m)
    }
}

/// Ray-traces a depth frame into a grid: a hit at every valid pixel (every
/// `stride`-th in u and v), free space as far as [`free_range_m`] allows (two cells
/// short of a neighbouring return) where a pixel has none.
pub fn insert_frame(grid: &mut LocalGrid, frame: &DepthFrame, stride: u32) {
    let k = &frame.intrinsics;
    let origin = Point3::from(frame.pose.translation.vector);
    let margin_m = 2.0 * grid.resolution_m();
    let stride = stride.max(1) as usize;
    for row in (0..k.height as usize).step_by(stride) {
        for col in (0..k.width as usize).step_by(stride) {
            let Some(&depth) = frame.depth_m.get(row * k.width as usize + col) else {
                continue;
            };
            let ray = k.pixel_ray(col as u32, row as u32);
            let (z, hit) = if depth > 0.0 {
                (f64::from(depth), true)
            } else if let Some(range_m) = free_range_m(frame, (row, col), stride, margin_m) {
                (range_m, false)
            } else {
                continue;
            };
            let end = origin + frame.pose.rotation * (ray * z);
            grid.insert_ray(&origin, &end, hit, None);
        }
    }
}

/// The two scans a depth frame makes under the per-scan rules, as world points: its
/// returns (`hits`) and its no-return pixels, free as far as [`free_range_m`] allows
/// with `margin_m` (`misses`); every `stride`-th pixel in u and v.
#[must_use]
pub fn frame_scans(frame: &DepthFrame, stride: u32, margin_m: f64) -> FrameScans {
    let k = &frame.intrinsics;
    let origin = Point3::from(frame.pose.translation.vector);
    let stride = stride.max(1) as usize;
    let (mut hits, mut misses) = (Vec::new(), Vec::new());
    for row in (0..k.height as usize).step_by(stride) {
        for col in (0..k.width as usize).step_by(stride) {
            let Some(&depth) = frame.depth_m.get(row * k.width as usize + col) else {
                continue;
            };
            let ray = k.pixel_ray(col as u32, row as u32);
            if depth > 0.0 {
                hits.push(origin + frame.pose.rotation * (ray * f64::from(depth)));
            } else if let Some(range_m) = free_range_m(frame, (row, col), stride, margin_m) {
                misses.push(origin + frame.pose.rotation * (ray * range_m));
            }
        }
    }
    FrameScans {
        origin,
        hits,
        misses,
    }
}

/// A depth frame as two scans from its sensor position ([`frame_scans`]).
#[derive(Clone, Debug, PartialEq)]
pub struct FrameScans {
    /// The sensor position, where every ray starts.
    pub origin: Point3<f64>,
    /// Ends of the rays that hit a surface.
    pub hits: Vec<Point3<f64>>,
    /// Ends of the free-space rays of pixels without a return.
    pub misses: Vec<Point3<f64>>,
}

/// [`insert_frame`] under an [`UpdateRule`]: with [`UpdateRule::PerScan`] or
/// [`UpdateRule::PerEndVoxel`] the frame's returns form one scan and its no-return
/// pixels (free up to the range) a second ([`frame_scans`]).
pub fn insert_frame_with(
    grid: &mut LocalGrid,
    frame: &DepthFrame,
    stride: u32,
    rule: UpdateRule,
    scratch: &mut ScanScratch,
) {
    if rule == UpdateRule::PerRay {
        insert_frame(grid, frame, stride);
        return;
    }
    let scans = frame_scans(frame, stride, 2.0 * grid.resolution_m());
    scratch.insert_by(rule, grid, &scans.origin, &scans.hits, true, None);
    scratch.insert_by(rule, grid, &scans.origin, &scans.misses, false, None);
}

/// Ray-traces a keyframe GMM into a grid (§8.2.2): `min(support, max_samples)`
/// points drawn from its spatial marginal, each a hit at the end of a ray from the
/// keyframe's sensor position.
pub fn insert_keyframe(
    grid: &mut LocalGrid,
    keyframe: &Keyframe,
    max_samples: usize,
    rng: &mut impl rand::Rng,
) {
    let origin = Point3::from(keyframe.pose.translation.vector);
    let n = (keyframe.support_size as usize).min(max_samples);
    for p in keyframe.gmm.marginal_spatial().sample(n, rng) {
        grid.insert_ray(&origin, &Point3::from(p), true, None);
    }
}
