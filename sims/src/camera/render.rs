//! Sphere tracing, shading and sensor noise.
//!
//! Per pixel, with unit world direction `d` and `cos_axis` the cosine between the ray and
//! the optical axis:
//!
//! 1. March from the camera with steps `world.safe_step_m(p)` (by default
//!    `sdf / lipschitz`), over-relaxed where provably safe (see `trace`). A hit is declared
//!    when the safe step falls below [`HIT_EPS_M`]; the march gives up with no return once
//!    no surface can lie before z-depth `range_m`, or after [`MAX_TRACE_STEPS`] steps.
//!    The march starts where a cone holding the rays of the pixel's tile (squares of
//!    [`TILE_PX`] pixels, then quarters of them) has been marched without touching a
//!    surface (see `cone_start_m`): no ray of the tile meets a surface before that
//!    distance, so the march finds the same first surface, within [`HIT_EPS_M`], as one
//!    from the camera, in fewer steps.
//! 2. Refine once: `t += sdf(p) / max(n·(-d), 0.25)`, exact for a plane.
//! 3. The hit counts when its true z-depth `t * cos_axis <= range_m`.
//! 4. Intensity = `albedo * max(n·(-d), 0) / (1 + (t / LIGHT_HALF_DISTANCE_M)^2)` (a point
//!    light at the camera), clamped to `[0, 1]`.
//! 5. Only the pixels on the [`CameraParams::render_stride`] lattice are traced (the
//!    tiles and their cones are the same, so those pixels get the bits a full frame
//!    gives them); the others report no return.
//! 6. Noise: with probability `dropout_prob` the pixel has no return; otherwise Gaussian
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

/// Edge of the square pixel tiles whose rays share a cone march, in pixels; each tile's
/// quarters then continue with a narrower cone, down to tiles of `MIN_TILE_PX` (2 px).
pub const TILE_PX: usize = 8;
/// Edge of the smallest tiles that are cone-marched, in pixels.
const MIN_TILE_PX: usize = 2;
/// A cone march stops once its step falls below this fraction of the empty radius at
/// its axis (most of the ball is spent on the cone's width; narrower cones take over).
const CONE_STOP_FRACTION: f64 = 0.5;
/// Relative slack on a cone's half-width for rounding (far above its error).
const CONE_SLACK: f64 = 1e-9;

/// A start for the march of a ray: ray length `t_m` reached with no surface before it,
/// and the certified empty radius `radius_m` around the point there.
#[derive(Clone, Copy, Debug)]
struct MarchStart {
    t_m: f64,
    radius_m: f64,
}

/// The unit direction of a pixel's ray, the cosine between it and the optical axis,
/// and its largest ray length (z-depth `range_m`).
#[derive(Clone, Copy, Debug)]
struct PixelRay {
    dir: Vector3<f64>,
    cos_axis: f64,
    t_max_m: f64,
}

/// How far every ray of `rays` (unit directions from `origin`) is free of surfaces,
/// continuing from `start` (valid for all of them).
///
/// The cone's axis `c` is the normalised mean direction and `δ >= max |d_i - c|` its
/// half-width; at axis point `q = origin + c t` with empty radius `r`, the point of ray
/// `i` at length `s ∈ [t, t + r - δ t]` lies within `δ t + (s - t) <= r` of `q`, so every
/// ray stays free up to `t + r - δ t`. The march (plain sphere tracing of the axis with
/// the step shrunk by `δ t`) stops when that step falls below
/// [`CONE_STOP_FRACTION`]` · r` or [`HIT_EPS_M`], after [`MAX_TRACE_STEPS`] steps, or
/// once the cone is past every ray's `t_max_m`.
fn cone_start_m(
    world: &dyn World,
    origin: &Point3<f64>,
    rays: &[PixelRay],
    start: MarchStart,
) -> MarchStart {
    let sum: Vector3<f64> = rays.iter().map(|r| r.dir).sum();
    let Some(axis) = sum.try_normalize(1e-12) else {
        return start;
    };
    let spread = rays
        .iter()
        .map(|r| (r.dir - axis).norm())
        .fold(0.0, f64::max)
        * (1.0 + CONE_SLACK);
    let t_max_m = rays.iter().map(|r| r.t_max_m).fold(0.0, f64::max);
    let mut t = start.t_m;
    let mut radius = if t > 0.0 {
        world.safe_step_m(&(origin + axis * t))
    } else {
        start.radius_m
    };
    for _ in 0..MAX_TRACE_STEPS {
        let step = radius - spread * t;
        if t > t_max_m || !(step >= CONE_STOP_FRACTION * radius && step >= HIT_EPS_M) {
            break;
        }
        t += step;
        radius = world.safe_step_m(&(origin + axis * t));
    }
    if t > 0.0 {
        MarchStart {
            t_m: t,
            radius_m: f64::NAN,
        }
    } else {
        // Still at the camera, where every ray's empty radius is the same.
        start
    }
}

/// March from `origin` along unit `dir` up to ray length `t_max_m`, from `start` (no
/// surface before `start.t_m`; `start.radius_m` is `world.safe_step_m` there, or NaN when
/// not yet known).
///
/// Steps are over-relaxed by [`OVER_RELAXATION`] while it is safe: after stepping
/// `ω·r0` from a point with empty radius `r0`, the step is kept only if the new point's
/// empty ball reaches back to the old one's (`r1 >= (ω - 1)·r0`), so no surface was
/// skipped; otherwise the march goes back to `t0 + r0` and continues with plain steps.
fn trace(
    world: &dyn World,
    origin: &Point3<f64>,
    start: MarchStart,
    dir: &Vector3<f64>,
    t_max_m: f64,
) -> Option<Hit> {
    if start.t_m > t_max_m {
        // No surface before t_max_m.
        return None;
    }
    let mut omega = OVER_RELAXATION;
    let mut t = start.t_m;
    let mut radius = if start.radius_m.is_nan() {
        world.safe_step_m(&(origin + dir * t))
    } else {
        start.radius_m
    };
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

/// Step 6 of the module doc for the pixel with row-major `index` and noise-free z-depth
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

/// Rows `row0..` of the frame being rendered, in row-major order.
struct Band<'a> {
    row0: usize,
    depth: &'a mut [f32],
    intensity: &'a mut [f32],
}

/// Everything a tile's pixels share: the world, the camera and the frame's noise seed.
struct TileJob<'a> {
    cam: &'a CameraParams,
    world: &'a dyn World,
    origin: Point3<f64>,
    noise_seed: u64,
    width: usize,
    /// Whether tiles are cone-marched (off only to compare with per-pixel marches).
    cones: bool,
}

impl TileJob<'_> {
    /// Renders the pixels `rays` (row-major, `cols` wide, the first at `(col0, row0)`
    /// of `band`) into `band`, cone-marching the tile and then its quarters from `start`
    /// (see `cone_start_m`).
    fn render_tile(
        &self,
        rays: &[PixelRay],
        cols: usize,
        (col0, row0): (usize, usize),
        start: MarchStart,
        band: &mut Band<'_>,
    ) {
        let rows = rays.len() / cols;
        let stride = self.cam.render_stride.max(1) as usize;
        let on_lattice = |first: usize, n: usize| first.div_ceil(stride) * stride < first + n;
        if !(on_lattice(col0, cols) && on_lattice(band.row0 + row0, rows)) {
            // No pixel of the tile is rendered: its cone serves nobody.
            return;
        }
        let start = if self.cones {
            cone_start_m(self.world, &self.origin, rays, start)
        } else {
            start
        };
        if cols > MIN_TILE_PX || rows > MIN_TILE_PX {
            let (half_c, half_r) = (cols.div_ceil(2), rows.div_ceil(2));
            let mut sub: Vec<PixelRay> = Vec::with_capacity(half_c * half_r);
            for (r0, nr) in [(0, half_r), (half_r, rows - half_r)] {
                for (c0, nc) in [(0, half_c), (half_c, cols - half_c)] {
                    if nr == 0 || nc == 0 {
                        continue;
                    }
                    sub.clear();
                    for r in r0..r0 + nr {
                        sub.extend_from_slice(&rays[r * cols + c0..r * cols + c0 + nc]);
                    }
                    self.render_tile(&sub, nc, (col0 + c0, row0 + r0), start, band);
                }
            }
            return;
        }
        for (i, ray) in rays.iter().enumerate() {
            let (col, row) = (col0 + i % cols, row0 + i / cols);
            if self.cam.renders(col, band.row0 + row) {
                self.shade(ray, start, (col, row), band);
            }
        }
    }

    /// Traces pixel `(col, row)` of `band` from `start` and writes its return, if any
    /// (steps 1–6 of the module doc).
    fn shade(
        &self,
        ray: &PixelRay,
        start: MarchStart,
        (col, row): (usize, usize),
        band: &mut Band<'_>,
    ) {
        let Some(hit) = trace(self.world, &self.origin, start, &ray.dir, ray.t_max_m) else {
            return;
        };
        let local = row * self.width + col;
        let index = (band.row0 * self.width + local) as u64;
        let Some(d) = noisy_depth_m(self.cam, self.noise_seed, index, hit.t_m * ray.cos_axis)
        else {
            return;
        };
        let lambert = (-hit.normal.dot(&ray.dir)).max(0.0);
        let falloff = 1.0 / (1.0 + (hit.t_m / LIGHT_HALF_DISTANCE_M).powi(2));
        let value = (self.world.albedo(&hit.point) * lambert * falloff).clamp(0.0, 1.0);
        band.depth[local] = d as f32;
        band.intensity[local] = value as f32;
    }
}

pub(super) fn render(
    cam: &CameraParams,
    world: &dyn World,
    stamp: Time,
    body_pose: &Isometry3<f64>,
    noise_seed: u64,
) -> DepthFrame {
    render_with(cam, world, stamp, body_pose, noise_seed, true)
}

/// [`render`] with every pixel marched from the camera (no cones), for comparisons.
#[cfg(test)]
pub(super) fn render_per_pixel(
    cam: &CameraParams,
    world: &dyn World,
    stamp: Time,
    body_pose: &Isometry3<f64>,
    noise_seed: u64,
) -> DepthFrame {
    render_with(cam, world, stamp, body_pose, noise_seed, false)
}

fn render_with(
    cam: &CameraParams,
    world: &dyn World,
    stamp: Time,
    body_pose: &Isometry3<f64>,
    noise_seed: u64,
    cones: bool,
) -> DepthFrame {
    let mut frame = cam.blank_frame(stamp, body_pose);
    let k = frame.intrinsics;
    let w = k.width as usize;
    let origin = Point3::from(body_pose.translation.vector);
    let rotation = body_pose.rotation;
    let range_m = cam.range_m;
    let start = MarchStart {
        t_m: 0.0,
        radius_m: world.safe_step_m(&origin),
    };
    let job = TileJob {
        cam,
        world,
        origin,
        noise_seed,
        width: w,
        cones,
    };
    let bands = frame
        .depth_m
        .par_chunks_mut(w * TILE_PX)
        .zip(frame.intensity.par_chunks_mut(w * TILE_PX));
    bands.enumerate().for_each(|(index, (depth, intensity))| {
        let row0 = index * TILE_PX;
        let rows = depth.len() / w;
        let mut band = Band {
            row0,
            depth,
            intensity,
        };
        let mut rays = Vec::with_capacity(TILE_PX * TILE_PX);
        for col0 in (0..w).step_by(TILE_PX) {
            let cols = (w - col0).min(TILE_PX);
            rays.clear();
            for row in row0..row0 + rows {
                for col in col0..col0 + cols {
                    let unit_depth = k.pixel_ray(col as u32, row as u32);
                    let cos_axis = 1.0 / unit_depth.norm();
                    rays.push(PixelRay {
                        dir: rotation * (unit_depth * cos_axis),
                        cos_axis,
                        t_max_m: range_m / cos_axis,
                    });
                }
            }
            job.render_tile(&rays, cols, (col0, 0), start, &mut band);
        }
    });
    frame
}
