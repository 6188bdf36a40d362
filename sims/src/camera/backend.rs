//! Choosing between the CPU and the GPU camera ([`CameraBackend`]) and rendering with
//! the choice ([`CameraRenderer`]).

use std::collections::HashSet;
use std::sync::{Arc, Mutex};

use nalgebra::Isometry3;
use serde::{Deserialize, Serialize};
use troupe_algorithms::frame::DepthFrame;
use troupe_core::Time;

use super::CameraParams;
use super::gpu::{self, GpuCamera, GpuContext, GpuError};
use crate::world::World;

/// Where the camera renders: `[camera] backend = "cpu" | "gpu" | "auto"`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CameraBackend {
    /// Sphere tracing on the CPU threads (`render.rs`).
    Cpu,
    /// The wgpu compute shader; a team does not start if there is no Vulkan adapter or
    /// the world has no GPU description.
    Gpu,
    /// The GPU when a hardware adapter is found and the world has a GPU description,
    /// else the CPU; the choice and its reason are logged once. A software adapter
    /// (lavapipe) is passed over: it renders the same images several times slower than
    /// the CPU path.
    #[default]
    Auto,
}

/// Why a backend ended up as it did (for logs and tests).
#[derive(Debug, Clone, PartialEq)]
pub enum Choice {
    /// Rendering on the CPU, with the reason.
    Cpu(String),
    /// Rendering on the named GPU adapter.
    Gpu(String),
}

/// A camera bound to one world, rendering on the backend chosen at creation.
pub struct CameraRenderer {
    world: Arc<dyn World>,
    params: CameraParams,
    gpu: Option<GpuCamera>,
    choice: Choice,
}

/// Logs `message` at info level the first time it is seen in this process.
fn log_once(message: &str) {
    static SEEN: Mutex<Option<HashSet<String>>> = Mutex::new(None);
    let first = SEEN
        .lock()
        .map(|mut seen| {
            seen.get_or_insert_with(HashSet::new)
                .insert(message.to_owned())
        })
        .unwrap_or(true);
    if first {
        tracing::info!("{message}");
    }
}

/// Why the GPU camera cannot be had: backend `"gpu"` fails with it, `"auto"` falls
/// back to the CPU and logs it.
#[derive(Debug, Clone, thiserror::Error)]
pub enum GpuUnavailable {
    /// The world cannot be described to the GPU.
    #[error(
        "the world has no GPU description (mesh worlds and worlds with artifacts render on the CPU)"
    )]
    NoGpuScene,
    /// The only adapter renders in software (`"auto"` passes it over).
    #[error(
        "the only Vulkan adapter, {adapter}, is a software rasteriser, slower than the CPU \
         path (camera.backend = \"gpu\" uses it anyway)"
    )]
    SoftwareAdapter {
        /// The adapter's name.
        adapter: String,
    },
    /// No adapter or device, or the camera's buffers could not be made.
    #[error(transparent)]
    Gpu(#[from] GpuError),
}

/// Whether this process's GPU adapter will do; a software adapter counts only if
/// `allow_software`.
fn check_adapter(allow_software: bool) -> Result<(), GpuUnavailable> {
    let adapter = GpuContext::adapter_info()?;
    if gpu::is_software(&adapter) && !allow_software {
        return Err(GpuUnavailable::SoftwareAdapter {
            adapter: gpu::adapter_name(&adapter),
        });
    }
    GpuContext::shared()?;
    Ok(())
}

/// What `backend` comes to for `world` in this process: `Auto` becomes `Gpu` when a
/// hardware adapter is found and the world has a GPU description, else `Cpu` (the
/// choice and its reason are logged once); `Cpu` and `Gpu` stay. A team resolves it
/// once for all its robots and reports it, since GPU (`f32`) images change flights.
#[must_use]
pub fn resolve_backend(world: &dyn World, backend: CameraBackend) -> CameraBackend {
    if backend != CameraBackend::Auto {
        return backend;
    }
    let usable = if world.gpu_scene().is_some() {
        check_adapter(false)
    } else {
        Err(GpuUnavailable::NoGpuScene)
    };
    match usable {
        Ok(()) => CameraBackend::Gpu,
        Err(reason) => {
            log_once(&format!("camera renders on the CPU: {reason}"));
            CameraBackend::Cpu
        }
    }
}

/// Whether backend `"gpu"` can render `world` in this process (a software adapter
/// counts): a team checks it before its robots start, so that a missing GPU stops the
/// run with one error instead of leaving every robot without a camera.
///
/// # Errors
///
/// Why the GPU camera is unavailable.
pub fn gpu_camera_available(world: &dyn World) -> Result<(), GpuUnavailable> {
    world.gpu_scene().ok_or(GpuUnavailable::NoGpuScene)?;
    check_adapter(true)
}

/// The GPU camera for `world`, or why not; a software adapter only if `allow_software`.
fn open_gpu(
    world: &dyn World,
    params: &CameraParams,
    allow_software: bool,
) -> Result<GpuCamera, GpuUnavailable> {
    let scene = world.gpu_scene().ok_or(GpuUnavailable::NoGpuScene)?;
    check_adapter(allow_software)?;
    Ok(GpuCamera::new(params, &scene)?)
}

impl CameraRenderer {
    /// A camera for `world` on `params.backend`.
    ///
    /// # Errors
    ///
    /// Only for [`CameraBackend::Gpu`]: why the GPU camera is unavailable.
    pub fn new(
        world: Arc<dyn World>,
        params: CameraParams,
    ) -> Result<CameraRenderer, GpuUnavailable> {
        let (gpu, choice) = match params.backend {
            CameraBackend::Cpu => (None, Choice::Cpu("camera.backend = \"cpu\"".to_owned())),
            CameraBackend::Gpu => {
                let gpu = open_gpu(world.as_ref(), &params, true)?;
                let name = gpu.context().adapter_name();
                (Some(gpu), Choice::Gpu(name))
            }
            CameraBackend::Auto => match open_gpu(world.as_ref(), &params, false) {
                Ok(gpu) => {
                    let name = gpu.context().adapter_name();
                    (Some(gpu), Choice::Gpu(name))
                }
                Err(reason) => (None, Choice::Cpu(reason.to_string())),
            },
        };
        match &choice {
            Choice::Cpu(reason) => log_once(&format!("camera renders on the CPU: {reason}")),
            Choice::Gpu(name) => log_once(&format!("camera renders on the GPU: {name}")),
        }
        Ok(CameraRenderer {
            world,
            params,
            gpu,
            choice,
        })
    }

    /// The backend in use and why.
    #[must_use]
    pub fn choice(&self) -> &Choice {
        &self.choice
    }

    /// The camera parameters.
    #[must_use]
    pub fn params(&self) -> &CameraParams {
        &self.params
    }

    /// Renders the frame taken at `stamp` from `body_pose` (body to world); see
    /// [`CameraParams::render`]. With `auto`, a failing GPU frame is rendered on the
    /// CPU instead and the camera stays on the CPU from then on.
    ///
    /// # Errors
    ///
    /// A failing GPU frame with backend `gpu`.
    pub fn render(
        &mut self,
        stamp: Time,
        body_pose: &Isometry3<f64>,
        noise_seed: u64,
    ) -> Result<DepthFrame, GpuError> {
        if let Some(gpu) = &mut self.gpu {
            match gpu.render(stamp, body_pose, noise_seed) {
                Ok(mut frame) => {
                    self.params.clear_unrendered(&mut frame);
                    return Ok(frame);
                }
                Err(e) if self.params.backend == CameraBackend::Gpu => return Err(e),
                Err(e) => {
                    tracing::warn!("GPU camera failed ({e}); rendering on the CPU from now on");
                    self.gpu = None;
                    self.choice = Choice::Cpu(e.to_string());
                }
            }
        }
        Ok(self
            .params
            .render(self.world.as_ref(), stamp, body_pose, noise_seed))
    }
}
