//! The simulated camera as a [`FrameSource`] for the standard sensor actor.

use std::sync::Arc;

use troupe_actors::sensor::FrameSource;
use troupe_algorithms::frame::{DepthFrame, Odometry};
use troupe_core::Time;
use troupe_runtime::ActorError;

use crate::camera::{CameraParams, CameraRenderer, GpuUnavailable};
use crate::world::World;

/// Renders the world from the robot's latest odometry pose, on the backend named by
/// `camera.backend` (see [`CameraRenderer`]).
pub struct SimCameraSource {
    /// The renderer, or why backend `"gpu"` could not be had (reported by every
    /// capture, so the sensor actor fails loudly instead of seeing nothing).
    renderer: Result<CameraRenderer, GpuUnavailable>,
    noise_seed: u64,
    frames: u64,
}

impl SimCameraSource {
    /// A camera for one robot; `noise_seed` should differ per robot and run.
    #[must_use]
    pub fn new(world: Arc<dyn World>, camera: CameraParams, noise_seed: u64) -> Self {
        SimCameraSource {
            renderer: CameraRenderer::new(world, camera),
            noise_seed,
            frames: 0,
        }
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
        let renderer = self.renderer.as_mut().map_err(|reason| {
            ActorError::with_source("camera.backend = \"gpu\"", reason.clone())
        })?;
        let seed = self.noise_seed ^ self.frames.wrapping_mul(0x9e37_79b9_7f4a_7c15);
        self.frames += 1;
        renderer
            .render(now, &odometry.pose, seed)
            .map(Some)
            .map_err(|e| ActorError::with_source("rendering a camera frame", e))
    }
}
