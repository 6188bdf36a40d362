//! Depth + intensity frame → 4D points `(x, y, z, g)` in the world frame (§6.1: the
//! point cloud `Z` of the image pair), plus the 2D `(depth, intensity)` data the mean
//! shift runs on (§6.1.3).
//!
//! Camera convention (`msgs::DepthFrame`): the camera looks along body +x; image u
//! (to the right) is body −y, image v (down) is body −z; pixel centres at
//! `(col + 0.5, row + 0.5)`. Pixel `(u, v)` with z-depth `d` is the body point
//! `(d, −(u − cx)/fx · d, −(v − cy)/fy · d)`, mapped to the world by the body pose.

use nalgebra::{Isometry3, Vector4};

use super::SogmmError;
use crate::camera::PinholeIntrinsics;

/// The valid pixels of one frame.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FramePoints {
    /// `(x, y, z, intensity)`, world frame, metres.
    pub points: Vec<Vector4<f64>>,
    /// `(z-depth, intensity)` of the same pixels: the mean-shift data `Y` (§6.1.3).
    pub depth_intensity: Vec<[f64; 2]>,
    /// Row-major pixel index of each point.
    pub pixels: Vec<u32>,
}

impl FramePoints {
    /// Number of valid pixels.
    #[must_use]
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// True when no pixel had a valid return.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }
}

/// Body-frame ray point of pixel `(col, row)` at z-depth `d` (see the module doc).
/// Convert a row-major frame to world-frame 4D points, dropping pixels with no return
/// (depth `≤ 0`, non-finite, or beyond `max_depth_m`) or a non-finite intensity.
pub fn frame_points(
    depth_m: &[f32],
    intensity: &[f32],
    intrinsics: &PinholeIntrinsics,
    pose: &Isometry3<f64>,
) -> Result<FramePoints, SogmmError> {
    crate::frame::check_buffers(intrinsics, depth_m, intensity)?;
    let (w, h) = (intrinsics.width as usize, intrinsics.height as usize);
    let mut out = FramePoints::default();
    for row in 0..h {
        for col in 0..w {
            let i = row * w + col;
            let d = f64::from(depth_m[i]);
            let g = f64::from(intensity[i]);
            if !d.is_finite() || d <= 0.0 || d > intrinsics.max_depth_m || !g.is_finite() {
                continue;
            }
            let p = pose * intrinsics.back_project(col as u32, row as u32, d);
            out.points.push(Vector4::new(p.x, p.y, p.z, g));
            out.depth_intensity.push([d, g]);
            out.pixels.push(i as u32);
        }
    }
    Ok(out)
}
