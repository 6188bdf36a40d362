//! The simulated camera as a [`FrameSource`] for the standard sensor actor.

use std::sync::Arc;

use troupe_actors::msgs::{DepthFrame, Odometry, PinholeIntrinsics};
use troupe_actors::runtime::{ActorError, Time};
use troupe_actors::sensor::FrameSource;

use crate::camera::{CameraParams, CameraRenderer, DepthImage};
use crate::world::World;

/// Renders the world from the robot's latest odometry pose, on the backend named by
/// `camera.backend` (see [`CameraRenderer`]).
pub struct SimCameraSource {
    camera: CameraParams,
    /// The renderer, or why backend `"gpu"` could not be had (reported by every
    /// capture, so the sensor actor fails loudly instead of seeing nothing).
    renderer: Result<CameraRenderer, String>,
    noise_seed: u64,
    frames: u64,
}

impl SimCameraSource {
    /// A camera for one robot; `noise_seed` should differ per robot and run.
    #[must_use]
    pub fn new(world: Arc<dyn World>, camera: CameraParams, noise_seed: u64) -> Self {
        SimCameraSource {
            renderer: CameraRenderer::new(world, camera.clone()),
            camera,
            noise_seed,
            frames: 0,
        }
    }
}

/// The intrinsics of a simulated camera in message form.
#[must_use]
pub fn intrinsics_of(camera: &CameraParams) -> PinholeIntrinsics {
    let k = camera.intrinsics();
    PinholeIntrinsics {
        width: camera.width,
        height: camera.height,
        fx: k.fx,
        fy: k.fy,
        cx: k.cx,
        cy: k.cy,
        max_depth_m: camera.range_m,
    }
}

/// The image of a frame, in the camera module's form.
#[must_use]
pub fn image_of(frame: &DepthFrame) -> DepthImage {
    DepthImage {
        width: frame.intrinsics.width,
        height: frame.intrinsics.height,
        depth_m: frame.depth_m.clone(),
        intensity: frame.intensity.clone(),
    }
}

impl FrameSource for SimCameraSource {
    fn capture(
        &mut self,
        now: Time,
        odometry: Option<&Odometry>,
    ) -> Result<Option<DepthFrame>, ActorError> {
        let Some(odometry) = odometry else {
            return Ok(None);
        };
        let renderer = self
            .renderer
            .as_mut()
            .map_err(|reason| ActorError::msg(reason.clone()))?;
        let seed = self.noise_seed ^ self.frames.wrapping_mul(0x9e37_79b9_7f4a_7c15);
        self.frames += 1;
        let image = renderer
            .render(&odometry.pose, seed)
            .map_err(|e| ActorError::with_source("rendering a camera frame", e))?;
        Ok(Some(DepthFrame {
            stamp: now,
            pose: odometry.pose,
            intrinsics: intrinsics_of(&self.camera),
            depth_m: image.depth_m,
            intensity: image.intensity,
        }))
    }
}
