//! Sphere tracing, shading and sensor noise.
//!
//! Per pixel, with unit world direction `d` and `cos_axis` the cosine between the ray and
//! the optical axis:
//!
//! 1. March from the camera with steps `world.safe_step_m(p)` (by default
//!    `sdf / lipschitz`), over-relaxed where provably safe (see `trace`). A hit is declared
//!    when the safe step falls below [`HIT_EPS_M`]; the march gives up with no return once
//!    no surface can lie before z-depth `range_m`, or after [`MAX_TRACE_STEPS`] steps.
//! 2. Refine once: `t += sdf(p) / max(n·(-d), 0.25)`, exact for a plane.
//! 3. The hit counts when its true z-depth `t * cos_axis <= range_m`.
//! 4. Intensity = `albedo * max(n·(-d), 0) / (1 + (t / LIGHT_HALF_DISTANCE_M)^2)` (a point
//!    light at the camera), clamped to `[0, 1]`.
//! 5. Noise: with probability `dropout_prob` the pixel has no return; otherwise Gaussian
//!    noise of `depth_noise_std_m` is added to the depth (after the range test, so a noisy
//!    depth may slightly exceed `range_m`); a noisy depth `<= 0` is reported as no return.
//!    The random numbers come from a hash of `(noise_seed, pixel index)`.

use nalgebra::{Isometry3, Point3, Vector3};
use rayon::prelude::*;

use troupe_algorithms::frame::DepthFrame;
use troupe_core::Time;

use super::CameraParams;
use crate::world::World;
use crate::world::noise::{mix64, unit_f64};

/// The march stops with a hit when the safe step falls below this, in metres.
pub const HIT_EPS_M: f64 = 1e-3;
/// Most sphere-tracing steps per pixel before giving up (no return).
pub const MAX_TRACE_STEPS: usize = 256;
/// Distance at which the carried light has half its intensity, in metres.
pub const LIGHT_HALF_DISTANCE_M: f64 = 2.5;
/// Over-relaxation factor of the sphere-tracing steps (1 = plain sphere tracing).
pub const OVER_RELAXATION: f64 = 1.2;
/// Smallest incidence cosine used by the refinement step.
pub(super) const MIN_REFINE_COS: f64 = 0.25;

/// A surface hit along a ray.
struct Hit {
    t_m: f64,
    point: Point3<f64>,
    normal: Vector3<f64>,
}

/// March from `origin` along unit `dir` up to ray length `t_max_m`; `origin_step_m` is
/// `world.safe_step_m(origin)` (the same for every pixel, so computed once per frame).
///
/// Steps are over-relaxed by [`OVER_RELAXATION`] while it is safe: after stepping
/// `ω·r0` from a point with empty radius `r0`, the step is kept only if the new point's
/// empty ball reaches back to the old one's (`r1 >= (ω - 1)·r0`), so no surface was
/// skipped; otherwise the march goes back to `t0 + r0` and continues with plain steps.
fn trace(
    world: &dyn World,
    origin: &Point3<f64>,
    origin_step_m: f64,
    dir: &Vector3<f64>,
    t_max_m: f64,
) -> Option<Hit> {
    let mut omega = OVER_RELAXATION;
    let mut t = 0.0;
    let mut radius = origin_step_m;
    for _ in 0..MAX_TRACE_STEPS {
        if radius < HIT_EPS_M {
            let p = origin + dir * t;
            let normal = world.normal(&p);
            let cos_inc = (-normal.dot(dir)).max(MIN_REFINE_COS);
            let t_hit = (t + world.sdf_m(&p) / cos_inc).max(0.0);
            if t_hit > t_max_m {
                return None;
            }
            return Some(Hit {
                t_m: t_hit,
                point: origin + dir * t_hit,
                normal,
            });
        }
        if t + radius > t_max_m {
            return None;
        }
        let t_try = t + omega * radius;
        let r_try = world.safe_step_m(&(origin + dir * t_try));
        if omega > 1.0 && r_try < (omega - 1.0) * radius {
            omega = 1.0;
            t += radius;
            radius = world.safe_step_m(&(origin + dir * t));
        } else {
            t = t_try;
            radius = r_try;
        }
    }
    None
}

/// Per-pixel random numbers from `(seed, index)`.
struct PixelRng {
    state: u64,
}

impl PixelRng {
    fn new(seed: u64, index: u64) -> Self {
        Self {
            state: mix64(seed ^ mix64(index ^ 0xD1B5_4A32_D192_ED03)),
        }
    }

    fn next_unit(&mut self) -> f64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        unit_f64(mix64(self.state))
    }

    /// Standard normal by Box–Muller.
    fn next_gaussian(&mut self) -> f64 {
        let u1 = 1.0 - self.next_unit(); // (0, 1]
        let u2 = self.next_unit();
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
}

/// Step 5 of the module doc for the pixel with row-major `index` and noise-free z-depth
/// `depth_m`: the reported depth, or `None` for a dropout or a depth `<= 0`. Shared by
/// the CPU and GPU paths, so both draw the same noise.
pub(super) fn noisy_depth_m(
    cam: &CameraParams,
    noise_seed: u64,
    index: u64,
    depth_m: f64,
) -> Option<f64> {
    let mut rng = PixelRng::new(noise_seed, index);
    let dropped = rng.next_unit() < cam.dropout_prob;
    let depth = depth_m + rng.next_gaussian() * cam.depth_noise_std_m;
    (!dropped && depth > 0.0).then_some(depth)
}

pub(super) fn render(
    cam: &CameraParams,
    world: &dyn World,
    stamp: Time,
    body_pose: &Isometry3<f64>,
    noise_seed: u64,
) -> DepthFrame {
    let mut frame = cam.blank_frame(stamp, body_pose);
    let k = frame.intrinsics;
    let w = k.width as usize;
    let origin = Point3::from(body_pose.translation.vector);
    let rotation = body_pose.rotation;
    let range_m = cam.range_m;
    let origin_step_m = world.safe_step_m(&origin);
    let rows = frame
        .depth_m
        .par_chunks_mut(w)
        .zip(frame.intensity.par_chunks_mut(w));
    rows.enumerate()
        .for_each(|(row, (depth_row, intensity_row))| {
            for col in 0..w {
                let unit_depth = k.pixel_ray(col as u32, row as u32);
                let cos_axis = 1.0 / unit_depth.norm();
                let dir = rotation * (unit_depth * cos_axis);
                let Some(hit) = trace(world, &origin, origin_step_m, &dir, range_m / cos_axis)
                else {
                    continue;
                };
                let index = (row * w + col) as u64;
                let Some(depth) = noisy_depth_m(cam, noise_seed, index, hit.t_m * cos_axis) else {
                    continue;
                };
                let lambert = (-hit.normal.dot(&dir)).max(0.0);
                let falloff = 1.0 / (1.0 + (hit.t_m / LIGHT_HALF_DISTANCE_M).powi(2));
                let intensity = (world.albedo(&hit.point) * lambert * falloff).clamp(0.0, 1.0);
                depth_row[col] = depth as f32;
                intensity_row[col] = intensity as f32;
            }
        });
    frame
}
