//! Simulated depth + intensity camera (pinhole, D435-like defaults).
//!
//! The camera sits at the body origin and looks along body `+x`; image `x` (columns, `u`)
//! runs to the right (body `-y`) and image `y` (rows, `v`) runs down (body `-z`). Pixel
//! `(col, row)` has its centre at `(u, v) = (col + 0.5, row + 0.5)`. Depth is the z-depth
//! along the optical axis, as a depth camera reports it, not the ray length. The
//! geometry is that of the robots' own camera model, [`PinholeIntrinsics`] (one
//! back-projection for the whole system), and frames come out as the standard
//! [`DepthFrame`] message, ready to publish.
//!
//! [`CameraParams::render`] sphere-traces a [`World`] on the CPU; see `render` for the
//! exact rules (each tile of [`TILE_PX`]² pixels first marches a cone holding all its
//! rays, so a pixel's march starts where its tile is known to be free).
//! [`CameraRenderer`] renders on the backend named by [`CameraParams::backend`]: the
//! CPU, or the wgpu compute shader of `gpu` (same rules in `f32`, every pixel marched
//! from the camera: the same surfaces within [`HIT_EPS_M`]) for worlds that describe
//! themselves with [`World::gpu_scene`].

mod backend;
mod gpu;
mod render;

pub use backend::{
    CameraBackend, CameraRenderer, Choice, GpuUnavailable, gpu_camera_available, resolve_backend,
};
pub use gpu::{GpuCamera, GpuContext, GpuError};
pub use render::{HIT_EPS_M, LIGHT_HALF_DISTANCE_M, MAX_TRACE_STEPS, OVER_RELAXATION, TILE_PX};

use nalgebra::Isometry3;
use serde::{Deserialize, Serialize};
use troupe_algorithms::camera::PinholeIntrinsics;
use troupe_algorithms::frame::DepthFrame;
use troupe_core::{ConfigError, Time};

use crate::world::World;

/// Camera configuration; angles in degrees, lengths in metres.
///
/// A scenario's `[camera]` table changes only the keys it names: the others are those
/// of [`CameraParams::standard`], the camera of the default scenario (depth noise,
/// dropouts and render stride included). [`CameraParams::default`] is the same camera
/// without noise or dropouts, rendering every pixel.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default = "CameraParams::standard")]
pub struct CameraParams {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Horizontal field of view.
    pub hfov_deg: f64,
    /// Vertical field of view.
    pub vfov_deg: f64,
    /// Largest z-depth that gives a return.
    pub range_m: f64,
    /// Standard deviation of the Gaussian noise added to each depth.
    pub depth_noise_std_m: f64,
    /// Probability that a pixel returns nothing, independently per pixel.
    pub dropout_prob: f64,
    /// Where frames are rendered: `"cpu"`, `"gpu"` or `"auto"` (the GPU when a Vulkan
    /// adapter is found and the world has a GPU description, else the CPU).
    pub backend: CameraBackend,
    /// Render only every n-th pixel in u and v, from pixel `(0, 0)`; the others report
    /// no return. A robot whose grid and mapper read every second pixel
    /// (`pixel_stride = 2`) gets the same frames from 2 as from 1, a quarter of the
    /// rays later. 1 renders every pixel ([`CameraParams::default`]); a scenario's
    /// camera renders every second one unless its table says otherwise
    /// ([`CameraParams::standard`]).
    pub render_stride: u32,
}

impl Default for CameraParams {
    fn default() -> Self {
        Self {
            width: 160,
            height: 120,
            hfov_deg: 89.57,
            vfov_deg: 59.24,
            range_m: 5.0,
            depth_noise_std_m: 0.0,
            dropout_prob: 0.0,
            backend: CameraBackend::Auto,
            render_stride: 1,
        }
    }
}

impl CameraParams {
    /// The standard robot's camera, as the default scenario flies it: D435-like
    /// (thesis §4.2) with 1 cm depth noise and 1 % dropouts, rendering every second
    /// pixel in u and v — all that the standard robot's grid, mapper and coverage meter
    /// read.
    #[must_use]
    pub fn standard() -> Self {
        Self {
            depth_noise_std_m: 0.01,
            dropout_prob: 0.01,
            render_stride: 2,
            ..Self::default()
        }
    }

    /// Checks every field.
    ///
    /// # Errors
    ///
    /// The offending key (relative to `[camera]`), its rule and its value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        for (key, v) in [("width", self.width), ("height", self.height)] {
            if v == 0 {
                return Err(ConfigError::new(key, "must be at least 1", v));
            }
        }
        for (key, v) in [("hfov_deg", self.hfov_deg), ("vfov_deg", self.vfov_deg)] {
            if !(v.is_finite() && v > 0.0 && v < 180.0) {
                return Err(ConfigError::new(key, "must be in (0, 180)", v));
            }
        }
        if self.render_stride == 0 {
            return Err(ConfigError::new("render_stride", "must be at least 1", 0));
        }
        ConfigError::positive("range_m", self.range_m)?;
        ConfigError::non_negative("depth_noise_std_m", self.depth_noise_std_m)?;
        if !(0.0..=1.0).contains(&self.dropout_prob) {
            return Err(ConfigError::new(
                "dropout_prob",
                "must be in [0, 1]",
                self.dropout_prob,
            ));
        }
        Ok(())
    }

    /// The pinhole intrinsics derived from size and field of view:
    /// `fx = (width / 2) / tan(hfov / 2)`, `fy = (height / 2) / tan(vfov / 2)`, the
    /// principal point at the image centre, `max_depth_m = range_m`.
    #[must_use]
    pub fn intrinsics(&self) -> PinholeIntrinsics {
        let (w, h) = (f64::from(self.width), f64::from(self.height));
        PinholeIntrinsics {
            width: self.width,
            height: self.height,
            fx: (w / 2.0) / (self.hfov_deg.to_radians() / 2.0).tan(),
            fy: (h / 2.0) / (self.vfov_deg.to_radians() / 2.0).tan(),
            cx: w / 2.0,
            cy: h / 2.0,
            max_depth_m: self.range_m,
        }
    }

    /// A frame of this camera taken at `stamp` from `body_pose` with no returns yet
    /// (every depth and intensity `0.0`).
    #[must_use]
    pub(crate) fn blank_frame(&self, stamp: Time, body_pose: &Isometry3<f64>) -> DepthFrame {
        let intrinsics = self.intrinsics();
        let pixels = intrinsics.pixels();
        DepthFrame {
            stamp,
            pose: *body_pose,
            intrinsics,
            depth_m: vec![0.0; pixels],
            intensity: vec![0.0; pixels],
        }
    }

    /// Whether pixel `(col, row)` is rendered ([`CameraParams::render_stride`]).
    #[must_use]
    pub fn renders(&self, col: usize, row: usize) -> bool {
        let stride = self.render_stride.max(1) as usize;
        col.is_multiple_of(stride) && row.is_multiple_of(stride)
    }

    /// Clears the returns of the pixels this camera does not render (for backends that
    /// render every pixel), so every backend reports the same pixels.
    pub(crate) fn clear_unrendered(&self, frame: &mut DepthFrame) {
        if self.render_stride <= 1 {
            return;
        }
        let width = frame.intrinsics.width as usize;
        for (i, (d, v)) in frame
            .depth_m
            .iter_mut()
            .zip(frame.intensity.iter_mut())
            .enumerate()
        {
            if !self.renders(i % width, i / width) {
                (*d, *v) = (0.0, 0.0);
            }
        }
    }

    /// Render the depth + intensity frame of `world` taken at `stamp` from `body_pose`
    /// (body to world) on the CPU, whatever [`CameraParams::backend`] says (see
    /// [`CameraRenderer`]).
    ///
    /// Noise and dropouts derive from `(noise_seed, pixel index)` only, so the frame is
    /// bit-identical for any thread count; pass a different `noise_seed` per frame (for
    /// example a hash of robot and frame number) to get fresh noise.
    #[must_use]
    pub fn render(
        &self,
        world: &dyn World,
        stamp: Time,
        body_pose: &Isometry3<f64>,
        noise_seed: u64,
    ) -> DepthFrame {
        render::render(self, world, stamp, body_pose, noise_seed)
    }
}

#[cfg(test)]
mod tests;
