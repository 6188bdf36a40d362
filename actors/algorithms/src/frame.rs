//! What a robot's sensors give it: registered depth + intensity frames with the pose
//! they were taken from (assumption A3 of the thesis: poses are given) and odometry.

use nalgebra::{Isometry3, Vector3};
use troupe_core::{Message, Time};

use crate::camera::PinholeIntrinsics;

/// The robot's pose (body frame: x forward, y left, z up) and velocity in its world frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Odometry {
    /// When the pose was valid.
    pub stamp: Time,
    /// Body pose in the world frame.
    pub pose: Isometry3<f64>,
    /// Linear velocity in the world frame, m/s.
    pub velocity_mps: Vector3<f64>,
}
impl Message for Odometry {}

/// A registered depth + intensity image and the sensor pose it was taken from
/// (assumption A3 of the thesis: poses are given).
#[derive(Clone, Debug, PartialEq)]
pub struct DepthFrame {
    /// Capture time.
    pub stamp: Time,
    /// Camera body pose in the world frame (camera looks along body +x; image x is
    /// body −y, image y is body −z).
    pub pose: Isometry3<f64>,
    /// Intrinsics.
    pub intrinsics: PinholeIntrinsics,
    /// Row-major z-depth in metres; 0 means no return.
    pub depth_m: Vec<f32>,
    /// Row-major intensity in [0, 1]; 0 where there is no return.
    pub intensity: Vec<f32>,
}

impl Message for DepthFrame {
    fn payload_bytes(&self) -> usize {
        std::mem::size_of::<Self>() + 4 * (self.depth_m.len() + self.intensity.len())
    }
}

/// Why a depth frame (or its image buffers) cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum FrameError {
    /// The intrinsics describe an image without pixels.
    #[error("frame has zero pixels")]
    NoPixels,
    /// Focal lengths must be finite and positive.
    #[error("focal lengths must be finite and > 0, got fx = {fx}, fy = {fy}")]
    Focal {
        /// Focal length in x, pixels.
        fx: f64,
        /// Focal length in y, pixels.
        fy: f64,
    },
    /// Depth or intensity buffer size does not match the intrinsics.
    #[error("frame of {expected} pixels has {depth} depth and {intensity} intensity values")]
    BufferSize {
        /// `width · height`.
        expected: usize,
        /// Depth values given.
        depth: usize,
        /// Intensity values given.
        intensity: usize,
    },
    /// A depth is negative or not finite.
    #[error("depth pixel {pixel} is {depth_m}")]
    Depth {
        /// Row-major pixel index.
        pixel: usize,
        /// The value.
        depth_m: f32,
    },
    /// The sensor pose has a non-finite component.
    #[error("frame pose is not finite")]
    Pose,
}

/// Checks that image buffers fit the intrinsics: pixels exist, the focal lengths are
/// usable and both buffers hold `width · height` values.
pub fn check_buffers(
    intrinsics: &PinholeIntrinsics,
    depth_m: &[f32],
    intensity: &[f32],
) -> Result<(), FrameError> {
    let pixels = intrinsics.pixels();
    if pixels == 0 {
        return Err(FrameError::NoPixels);
    }
    let (fx, fy) = (intrinsics.fx, intrinsics.fy);
    if !(fx.is_finite() && fy.is_finite() && fx > 0.0 && fy > 0.0) {
        return Err(FrameError::Focal { fx, fy });
    }
    if depth_m.len() != pixels || intensity.len() != pixels {
        return Err(FrameError::BufferSize {
            expected: pixels,
            depth: depth_m.len(),
            intensity: intensity.len(),
        });
    }
    Ok(())
}

impl DepthFrame {
    /// Checks that the frame is usable: [`check_buffers`], depths finite and
    /// non-negative, the pose finite. Frames with no valid pixel are allowed
    /// (everything beyond range is information too).
    pub fn validate(&self) -> Result<(), FrameError> {
        check_buffers(&self.intrinsics, &self.depth_m, &self.intensity)?;
        if let Some(pixel) = self.depth_m.iter().position(|d| !d.is_finite() || *d < 0.0) {
            return Err(FrameError::Depth {
                pixel,
                depth_m: self.depth_m[pixel],
            });
        }
        let pose_ok = self.pose.translation.vector.iter().all(|v| v.is_finite())
            && self.pose.rotation.coords.iter().all(|v| v.is_finite());
        if !pose_ok {
            return Err(FrameError::Pose);
        }
        Ok(())
    }

    /// Number of pixels with a depth return.
    #[must_use]
    pub fn valid_pixels(&self) -> usize {
        self.depth_m.iter().filter(|d| **d > 0.0).count()
    }

    /// The frame with one pixel per `factor × factor` block
    /// ([`PinholeIntrinsics::decimated`]): the block's nearest return and its
    /// intensity (no return where the block has none), so an obstacle a block sees
    /// is kept, and no depth between two surfaces is made up at their edge. `factor`
    /// 1 (or 0) returns a copy. The buffers must match the intrinsics
    /// ([`DepthFrame::validate`]).
    ///
    /// ```
    /// use nalgebra::Isometry3;
    /// use troupe_algorithms::camera::PinholeIntrinsics;
    /// use troupe_algorithms::frame::DepthFrame;
    /// use troupe_core::Time;
    ///
    /// let intrinsics = PinholeIntrinsics { width: 4, height: 2, fx: 4.0, fy: 4.0, cx: 2.0, cy: 1.0, max_depth_m: 5.0 };
    /// let frame = DepthFrame {
    ///     stamp: Time::ZERO,
    ///     pose: Isometry3::identity(),
    ///     intrinsics,
    ///     depth_m: vec![2.0, 0.0, 0.0, 0.0, 1.5, 3.0, 0.0, 0.0],
    ///     intensity: vec![0.2, 0.0, 0.0, 0.0, 0.6, 0.9, 0.0, 0.0],
    /// };
    /// let small = frame.decimated(2);
    /// assert_eq!(small.depth_m, vec![1.5, 0.0]);
    /// assert_eq!(small.intensity, vec![0.6, 0.0]);
    /// assert_eq!(small.intrinsics.width, 2);
    /// ```
    #[must_use]
    pub fn decimated(&self, factor: u32) -> DepthFrame {
        let k = factor.max(1);
        if k == 1 {
            return self.clone();
        }
        let intrinsics = self.intrinsics.decimated(k);
        let (width, k) = (self.intrinsics.width as usize, k as usize);
        let pixels = intrinsics.pixels();
        let mut depth_m = vec![0.0; pixels];
        let mut intensity = vec![0.0; pixels];
        for row in 0..intrinsics.height as usize {
            for col in 0..intrinsics.width as usize {
                let block = (0..k).flat_map(|dv| {
                    let start = (row * k + dv) * width + col * k;
                    start..start + k
                });
                let nearest = block
                    .filter(|&i| self.depth_m.get(i).is_some_and(|d| *d > 0.0))
                    .min_by(|&a, &b| self.depth_m[a].total_cmp(&self.depth_m[b]));
                if let Some(i) = nearest {
                    let out = row * intrinsics.width as usize + col;
                    depth_m[out] = self.depth_m[i];
                    intensity[out] = self.intensity.get(i).copied().unwrap_or(0.0);
                }
            }
        }
        DepthFrame {
            stamp: self.stamp,
            pose: self.pose,
            intrinsics,
            depth_m,
            intensity,
        }
    }
}
