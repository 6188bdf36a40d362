//! The GPU camera: a wgpu compute shader (`trace.wgsl`, one invocation per pixel) that
//! sphere-traces a world's [`GpuScene`] in `f32` with the rules of `camera/render.rs`.
//!
//! One device serves the whole process ([`GpuContext::shared`], Vulkan only; Mesa's
//! lavapipe counts). Each [`GpuCamera`] compiles its pipeline and uploads its scene once;
//! a frame writes the pose uniform, dispatches, and reads the `(depth, intensity)` pairs
//! back. Noise and dropouts are then added on the CPU with the same per-pixel rule as
//! the CPU path, so they are identical; only the geometry differs, by `f32` rounding.

mod pack;

use std::sync::{OnceLock, mpsc};

use nalgebra::Isometry3;
use troupe_algorithms::frame::DepthFrame;
use troupe_core::Time;
use wgpu::util::DeviceExt;

use super::CameraParams;
use super::render::{
    HIT_EPS_M, LIGHT_HALF_DISTANCE_M, MAX_TRACE_STEPS, MIN_REFINE_COS, OVER_RELAXATION,
    noisy_depth_m,
};
use crate::world::{GpuScene, NORMAL_STEP_M};

/// Edge of the shader's square workgroups, in pixels (`@workgroup_size` in the shader).
const WORKGROUP_EDGE: u32 = 8;

/// Why the GPU camera cannot render.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GpuError {
    /// No Vulkan adapter (no driver, or no `libvulkan`).
    #[error("no Vulkan adapter found ({0})")]
    NoAdapter(String),
    /// The adapter would not give a device.
    #[error("the GPU device could not be opened: {0}")]
    Device(String),
    /// A frame failed (device lost, mapping failed, ...).
    #[error("GPU frame failed: {0}")]
    Frame(String),
}

/// The process-wide device and queue.
#[derive(Debug)]
pub struct GpuContext {
    device: wgpu::Device,
    queue: wgpu::Queue,
    adapter: wgpu::AdapterInfo,
}

impl GpuContext {
    /// The shared context, opened on first use; the same error every time when there is
    /// no usable adapter.
    ///
    /// # Errors
    ///
    /// [`GpuError::NoAdapter`] or [`GpuError::Device`].
    pub fn shared() -> Result<&'static GpuContext, GpuError> {
        static SHARED: OnceLock<Result<GpuContext, GpuError>> = OnceLock::new();
        SHARED
            .get_or_init(Self::open)
            .as_ref()
            .map_err(Clone::clone)
    }

    /// What the shared context's adapter is, found without opening a device: on a
    /// machine whose only adapter is a software rasteriser, opening one takes 64 MiB
    /// that a CPU camera never uses.
    ///
    /// # Errors
    ///
    /// [`GpuError::NoAdapter`].
    pub fn adapter_info() -> Result<wgpu::AdapterInfo, GpuError> {
        Self::adapter().map(wgpu::Adapter::get_info)
    }

    /// The process's adapter, found once: the context's device is opened on it.
    fn adapter() -> Result<&'static wgpu::Adapter, GpuError> {
        static ADAPTER: OnceLock<Result<wgpu::Adapter, GpuError>> = OnceLock::new();
        ADAPTER
            .get_or_init(Self::find_adapter)
            .as_ref()
            .map_err(Clone::clone)
    }

    fn find_adapter() -> Result<wgpu::Adapter, GpuError> {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
        desc.backends = wgpu::Backends::VULKAN;
        // No validation layers (they are rarely installed and slow every call).
        desc.flags = wgpu::InstanceFlags::empty();
        let instance = wgpu::Instance::new(desc);
        pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            ..wgpu::RequestAdapterOptions::default()
        }))
        .map_err(|e| GpuError::NoAdapter(e.to_string()))
    }

    fn open() -> Result<GpuContext, GpuError> {
        let adapter = Self::adapter()?;
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("troupe camera"),
            required_limits: wgpu::Limits::downlevel_defaults().using_resolution(adapter.limits()),
            ..wgpu::DeviceDescriptor::default()
        }))
        .map_err(|e| GpuError::Device(e.to_string()))?;
        Ok(GpuContext {
            device,
            queue,
            adapter: adapter.get_info(),
        })
    }

    /// Whether the adapter is a software rasteriser (Mesa's lavapipe/llvmpipe): correct,
    /// but slower than the CPU path (see the `camera` bench), so `auto` passes it over.
    #[must_use]
    pub fn is_software(&self) -> bool {
        is_software(&self.adapter)
    }

    /// The adapter in words, e.g. `"llvmpipe (LLVM 15.0.6, 256 bits) (Cpu, Vulkan)"`.
    #[must_use]
    pub fn adapter_name(&self) -> String {
        adapter_name(&self.adapter)
    }
}

/// Whether `adapter` is a software rasteriser ([`GpuContext::is_software`]).
#[must_use]
pub fn is_software(adapter: &wgpu::AdapterInfo) -> bool {
    adapter.device_type == wgpu::DeviceType::Cpu
}

/// `adapter` in words ([`GpuContext::adapter_name`]).
#[must_use]
pub fn adapter_name(adapter: &wgpu::AdapterInfo) -> String {
    let wgpu::AdapterInfo {
        name,
        device_type,
        backend,
        ..
    } = adapter;
    format!("{name} ({device_type:?}, {backend:?})")
}

/// The shader source: the constants of `render.rs`, then `trace.wgsl`.
fn shader_source() -> String {
    format!(
        "const HIT_EPS_M: f32 = {HIT_EPS_M:e};\n\
         const MAX_TRACE_STEPS: u32 = {MAX_TRACE_STEPS}u;\n\
         const OVER_RELAXATION: f32 = {OVER_RELAXATION:e};\n\
         const MIN_REFINE_COS: f32 = {MIN_REFINE_COS:e};\n\
         const LIGHT_HALF_DISTANCE_M: f32 = {LIGHT_HALF_DISTANCE_M:e};\n\
         const NORMAL_STEP_M: f32 = {NORMAL_STEP_M:e};\n{}",
        include_str!("trace.wgsl")
    )
}

/// A camera rendering one world on the GPU; create once, render every frame.
#[derive(Debug)]
pub struct GpuCamera {
    ctx: &'static GpuContext,
    params: CameraParams,
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    pose: wgpu::Buffer,
    output: wgpu::Buffer,
    readback: wgpu::Buffer,
}

impl GpuCamera {
    /// Compiles the pipeline and uploads `scene` on the shared context.
    ///
    /// # Errors
    ///
    /// When no adapter or device is available.
    pub fn new(params: &CameraParams, scene: &GpuScene) -> Result<GpuCamera, GpuError> {
        let ctx = GpuContext::shared()?;
        let device = &ctx.device;
        let packed = pack::pack_scene(scene);
        let storage = |label: &str, words: &[u32]| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: &pack::to_bytes(words),
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let scene_uniform = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("scene"),
            contents: &pack::to_bytes(&packed.uniform),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let words = storage("words", &packed.words);
        let items = storage("items", &packed.items);
        let lattice = storage("lattice values", &packed.lattice_values);
        let pose = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("pose"),
            contents: &pack::to_bytes(&pack::pack_pose(params, &Isometry3::identity())),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        });
        // 8 bytes per pixel: (depth, intensity).
        let out_bytes = 8 * u64::from(params.width) * u64::from(params.height);
        let output = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("pixels"),
            size: out_bytes,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("pixels readback"),
            size: out_bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("trace.wgsl"),
            source: wgpu::ShaderSource::Wgsl(shader_source().into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("depth camera"),
            layout: None,
            module: &module,
            entry_point: Some("main"),
            compilation_options: wgpu::PipelineCompilationOptions::default(),
            cache: None,
        });
        let buffers = [&scene_uniform, &pose, &words, &items, &lattice, &output];
        let entries: Vec<wgpu::BindGroupEntry<'_>> = buffers
            .iter()
            .zip(0u32..)
            .map(|(b, binding)| wgpu::BindGroupEntry {
                binding,
                resource: b.as_entire_binding(),
            })
            .collect();
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("depth camera"),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &entries,
        });
        Ok(GpuCamera {
            ctx,
            params: params.clone(),
            pipeline,
            bind_group,
            pose,
            output,
            readback,
        })
    }

    /// The context the camera runs on.
    #[must_use]
    pub fn context(&self) -> &'static GpuContext {
        self.ctx
    }

    /// Renders the frame taken at `stamp` from `body_pose` (body to world), with noise
    /// from `noise_seed` exactly as [`CameraParams::render`] draws it.
    ///
    /// # Errors
    ///
    /// [`GpuError::Frame`] when the device fails.
    pub fn render(
        &mut self,
        stamp: Time,
        body_pose: &Isometry3<f64>,
        noise_seed: u64,
    ) -> Result<DepthFrame, GpuError> {
        let (device, queue) = (&self.ctx.device, &self.ctx.queue);
        let cam = &self.params;
        queue.write_buffer(
            &self.pose,
            0,
            &pack::to_bytes(&pack::pack_pose(cam, body_pose)),
        );
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("depth frame"),
        });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &self.bind_group, &[]);
            pass.dispatch_workgroups(
                cam.width.div_ceil(WORKGROUP_EDGE),
                cam.height.div_ceil(WORKGROUP_EDGE),
                1,
            );
        }
        encoder.copy_buffer_to_buffer(&self.output, 0, &self.readback, 0, self.output.size());
        queue.submit([encoder.finish()]);
        let slice = self.readback.slice(..);
        let (tx, rx) = mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            // The receiver waits below; a send can only fail if it is gone.
            let _ = tx.send(r);
        });
        device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Frame(e.to_string()))?;
        rx.recv()
            .map_err(|e| GpuError::Frame(e.to_string()))?
            .map_err(|e| GpuError::Frame(e.to_string()))?;
        let mut frame = cam.blank_frame(stamp, body_pose);
        {
            let bytes = slice
                .get_mapped_range()
                .map_err(|e| GpuError::Frame(e.to_string()))?;
            let word = |i: usize| {
                let b = [
                    bytes[4 * i],
                    bytes[4 * i + 1],
                    bytes[4 * i + 2],
                    bytes[4 * i + 3],
                ];
                f32::from_le_bytes(b)
            };
            for index in 0..frame.depth_m.len() {
                let depth = word(2 * index);
                if depth < 0.0 {
                    continue;
                }
                if let Some(d) = noisy_depth_m(cam, noise_seed, index as u64, f64::from(depth)) {
                    frame.depth_m[index] = d as f32;
                    frame.intensity[index] = word(2 * index + 1);
                }
            }
        }
        self.readback.unmap();
        Ok(frame)
    }
}

#[cfg(test)]
mod tests;
