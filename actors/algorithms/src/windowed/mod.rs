//! The windowed fixed-size GMM the paper flew with (paper §IV-A, thesis §3.2.1–3.2.2):
//! one frame becomes an **occupied** mixture `G(x)` and a **free-space** mixture `F(x)`.
//!
//! 1. [`split_frame`]: every pixel's ray from the sensor. A return whose distance from
//!    the sensor is at most `r_d` is an occupied point; a return beyond `r_d` — and, by
//!    default, a pixel with no return at all (the camera saw nothing within its range) —
//!    is a free-space point: its ray direction, normalised and projected to `r_d`
//!    (Fig. 3.1d). Points go to one of `W = windows[0] × windows[1]` rectangular image
//!    windows by pixel position (Fig. 3.1d, paper Fig. 3c–d).
//! 2. [`gated_em`]: per window, `n` components (k-means++ start, then EM with the
//!    Mahalanobis gate λ of Eq. 3.3 around the initial components).
//! 3. [`crate::mixture::merge_gmm4`]: the windows' mixtures are merged by Eq. 3.5 with their
//!    support sizes `N_w` (points inside some gate).
//!
//! The occupied mixture is returned as a [`Gmm4`] over (x, y, z, intensity): the
//! spatial part is the gated 3D EM fit, and each component's intensity mean, variance
//! and covariance with x, y, z are the responsibility-weighted moments of the window's
//! intensities under the final spatial responsibilities (so [`Gmm4::marginal_spatial`]
//! gives back the 3D fit and the intensity conditional of Eqs. 6.12–6.13 works on it).
//!
//! Windows are fitted in parallel with rayon; each has its own seed derived from
//! [`WindowedConfig::seed`] and its index, and the parts are merged in window order, so
//! the result does not depend on the thread count.
//!
//! ```
//! use nalgebra::Isometry3;
//! use troupe_algorithms::sogmm::synthetic;
//! use troupe_algorithms::windowed::{WindowedConfig, fit_windowed};
//!
//! let intr = synthetic::intrinsics(80, 60);
//! let pose = synthetic::room_pose();
//! let (depth, intensity) = synthetic::Scene::room_corner().render(&intr, &pose);
//! let fit = fit_windowed(&depth, &intensity, &intr, &pose, &WindowedConfig::default()).unwrap();
//! assert!(fit.occupied.len() <= 100); // 10 windows × 10 components at most
//! ```

pub mod gated_em;
#[cfg(test)]
mod tests;

use nalgebra::{Isometry3, Point3, Vector3, Vector4};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::camera::PinholeIntrinsics;
use crate::frame::DepthFrame;
use crate::mixture::{merge_gmm3, merge_gmm4};
use crate::sogmm::{Gmm3, Gmm4, SogmmError};
pub use gated_em::{GatedEmConfig, GatedFit, fit_gated_em};

/// Settings of the windowed fit. The defaults are the paper's (§VI: 10 windows of 10
/// components for both mixtures).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WindowedConfig {
    /// Image windows across (columns) and down (rows); `W` is their product.
    pub windows: [u32; 2],
    /// Components per window for the occupied mixture (`n`).
    pub occupied_components: usize,
    /// Components per window for the free-space mixture (`n_f`).
    pub free_components: usize,
    /// Maximum range `r_d`, metres: returns farther from the sensor are free space.
    /// `None` uses the camera's `max_depth_m`.
    pub range_m: Option<f64>,
    /// Treat pixels with no return as free space along their ray (true for a camera
    /// whose zero depth means "nothing within range", as the simulated one; set false
    /// for sensors whose zero means "invalid").
    pub no_return_is_free: bool,
    /// Windows with fewer points than this are left out (their points are not
    /// represented; too few to fit `n` components meaningfully).
    pub min_window_points: usize,
    /// The EM of each window (gate λ, regularisation, convergence).
    pub em: GatedEmConfig,
    /// Seed of the k-means++ draws (each window derives its own).
    pub seed: u64,
}

impl Default for WindowedConfig {
    /// 5 × 2 windows, 10 + 10 components per window, `r_d` = camera range, no-return
    /// pixels are free, windows of fewer than 20 points skipped, default EM, seed 0.
    fn default() -> Self {
        Self {
            windows: [5, 2],
            occupied_components: 10,
            free_components: 10,
            range_m: None,
            no_return_is_free: true,
            min_window_points: 20,
            em: GatedEmConfig::default(),
            seed: 0,
        }
    }
}

impl WindowedConfig {
    /// Check the numbers; the error names the field.
    pub fn validate(&self) -> Result<(), SogmmError> {
        if self.windows[0] == 0 || self.windows[1] == 0 {
            return Err(SogmmError::InvalidInput("windows must be at least 1 × 1"));
        }
        if self.occupied_components == 0 || self.free_components == 0 {
            return Err(SogmmError::InvalidInput(
                "components per window must be at least 1",
            ));
        }
        if let Some(r) = self.range_m
            && !(r.is_finite() && r > 0.0)
        {
            return Err(SogmmError::InvalidInput(
                "range_m must be a finite number > 0",
            ));
        }
        if self.em.gate.is_nan() || self.em.gate <= 0.0 {
            return Err(SogmmError::InvalidInput("gate λ must be > 0"));
        }
        if !(self.em.reg_covar.is_finite() && self.em.reg_covar > 0.0) {
            return Err(SogmmError::InvalidInput("reg_covar must be > 0"));
        }
        Ok(())
    }
}

/// A frame's points sorted into windows (step 1 of the module doc).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct WindowedPoints {
    /// Occupied points `(x, y, z, intensity)` in the world frame, per window.
    pub occupied: Vec<Vec<Vector4<f64>>>,
    /// Free-space points (rays projected to `r_d`) in the world frame, per window.
    pub free: Vec<Vec<Vector3<f64>>>,
}

/// Window index of pixel `(col, row)`: windows tile the image in row-major order.
#[must_use]
pub fn window_of(intrinsics: &PinholeIntrinsics, windows: [u32; 2], col: u32, row: u32) -> usize {
    let wx = (u64::from(col) * u64::from(windows[0]) / u64::from(intrinsics.width.max(1))) as usize;
    let wy =
        (u64::from(row) * u64::from(windows[1]) / u64::from(intrinsics.height.max(1))) as usize;
    wy * windows[0] as usize + wx
}

/// Step 1 of the module doc: occupied and free-space points per window.
pub fn split_frame(
    depth_m: &[f32],
    intensity: &[f32],
    intrinsics: &PinholeIntrinsics,
    pose: &Isometry3<f64>,
    config: &WindowedConfig,
) -> Result<WindowedPoints, SogmmError> {
    config.validate()?;
    crate::frame::check_buffers(intrinsics, depth_m, intensity)?;
    let w = intrinsics.width as usize;
    let r_d = config.range_m.unwrap_or(intrinsics.max_depth_m);
    if !(r_d.is_finite() && r_d > 0.0) {
        return Err(SogmmError::InvalidInput(
            "maximum range r_d must be a finite number > 0",
        ));
    }
    let n_windows = (config.windows[0] * config.windows[1]) as usize;
    let mut out = WindowedPoints {
        occupied: vec![Vec::new(); n_windows],
        free: vec![Vec::new(); n_windows],
    };
    for row in 0..intrinsics.height {
        for col in 0..intrinsics.width {
            let i = row as usize * w + col as usize;
            let win = window_of(intrinsics, config.windows, col, row);
            let d = f64::from(depth_m[i]);
            if !d.is_finite() || d < 0.0 {
                continue;
            }
            let has_return = d > 0.0 && d <= intrinsics.max_depth_m;
            if has_return {
                let body = intrinsics.back_project(col, row, d);
                let range = body.coords.norm();
                if range <= r_d {
                    let g = f64::from(intensity[i]);
                    if g.is_finite() {
                        let p = pose * body;
                        out.occupied[win].push(Vector4::new(p.x, p.y, p.z, g));
                    }
                    continue;
                }
            } else if !config.no_return_is_free {
                continue;
            }
            let dir = intrinsics.pixel_ray(col, row).normalize();
            let p = pose * Point3::from(dir * r_d);
            out.free[win].push(p.coords);
        }
    }
    Ok(out)
}

/// What a windowed fit did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct WindowedReport {
    /// Occupied points of the frame (before the gate).
    pub occupied_points: usize,
    /// Free-space points of the frame (before the gate).
    pub free_points: usize,
    /// Points discarded by the gate (Eq. 3.3), both mixtures.
    pub gated_out: usize,
    /// Windows fitted (occupied + free).
    pub windows_fitted: usize,
    /// Most EM iterations of any window.
    pub max_iterations: usize,
}

/// The two mixtures of one frame.
#[derive(Clone, Debug)]
pub struct WindowedFit {
    /// Occupied mixture `G(x)` over (x, y, z, intensity).
    pub occupied: Gmm4,
    /// Its support size `N` (points inside some gate), the weight of this frame when
    /// merged with others by Eq. 3.5.
    pub occupied_support: usize,
    /// Free-space mixture `F(x)`; `None` when the frame had no free-space points (e.g.
    /// every ray hit something within `r_d`).
    pub free: Option<Gmm3>,
    /// Support size of `F`.
    pub free_support: usize,
    /// What the fit did.
    pub report: WindowedReport,
}

/// Per-window seed: SplitMix64 of the base seed, the window and the mixture kind.
fn window_seed(seed: u64, window: usize, kind: u64) -> u64 {
    let mut z = seed
        .wrapping_add((window as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15))
        .wrapping_add(kind.wrapping_mul(0xd1b5_4a32_d192_ed03));
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

fn fit_windows(
    windows: &[Vec<Vector4<f64>>],
    components: usize,
    kind: u64,
    config: &WindowedConfig,
) -> Vec<Option<GatedFit>> {
    windows
        .par_iter()
        .enumerate()
        .map(|(w, pts)| {
            if pts.len() < config.min_window_points.max(1) {
                return None;
            }
            let mut rng = ChaCha8Rng::seed_from_u64(window_seed(config.seed, w, kind));
            fit_gated_em(pts, components, &mut rng, &config.em)
        })
        .collect()
}

/// Fit the occupied and free-space mixtures of one frame (module doc, steps 1–3).
/// Errors on a malformed frame or config, and with [`SogmmError::TooFewPoints`] when no
/// window has enough occupied points.
pub fn fit_windowed(
    depth_m: &[f32],
    intensity: &[f32],
    intrinsics: &PinholeIntrinsics,
    pose: &Isometry3<f64>,
    config: &WindowedConfig,
) -> Result<WindowedFit, SogmmError> {
    let pts = split_frame(depth_m, intensity, intrinsics, pose, config)?;
    let free4: Vec<Vec<Vector4<f64>>> = pts
        .free
        .iter()
        .map(|w| w.iter().map(|p| Vector4::new(p.x, p.y, p.z, 0.0)).collect())
        .collect();
    let occ = fit_windows(&pts.occupied, config.occupied_components, 0, config);
    let free = fit_windows(&free4, config.free_components, 1, config);
    let mut report = WindowedReport {
        occupied_points: pts.occupied.iter().map(Vec::len).sum(),
        free_points: pts.free.iter().map(Vec::len).sum(),
        ..WindowedReport::default()
    };
    for f in occ.iter().chain(&free).flatten() {
        report.gated_out += f.discarded;
        report.windows_fitted += 1;
        report.max_iterations = report.max_iterations.max(f.iterations);
    }

    let occ_parts: Vec<(f64, Gmm4)> = occ
        .iter()
        .flatten()
        .map(|f| {
            let (means, covs): (Vec<_>, Vec<_>) = f.joint.iter().copied().unzip();
            Gmm4::new(f.weights.clone(), means, covs).map(|g| (f.support as f64, g))
        })
        .collect::<Result<_, _>>()?;
    if occ_parts.is_empty() {
        return Err(SogmmError::TooFewPoints {
            points: report.occupied_points,
            needed: config.min_window_points,
        });
    }
    let occupied_support = occ_parts.iter().map(|(n, _)| *n as usize).sum();
    let occupied = merge_gmm4(&occ_parts.iter().map(|(n, g)| (*n, g)).collect::<Vec<_>>())?;

    let free_parts: Vec<(f64, Gmm3)> = free
        .iter()
        .flatten()
        .map(|f| {
            Gmm3::new(f.weights.clone(), f.means.clone(), f.covariances.clone())
                .map(|g| (f.support as f64, g))
        })
        .collect::<Result<_, _>>()?;
    let free_support = free_parts.iter().map(|(n, _)| *n as usize).sum();
    let free = if free_parts.is_empty() {
        None
    } else {
        Some(merge_gmm3(
            &free_parts.iter().map(|(n, g)| (*n, g)).collect::<Vec<_>>(),
        )?)
    };
    Ok(WindowedFit {
        occupied,
        occupied_support,
        free,
        free_support,
        report,
    })
}

/// [`fit_windowed`] on a [`DepthFrame`] (its pose, intrinsics, depth and intensity).
pub fn fit_windowed_frame(
    frame: &DepthFrame,
    config: &WindowedConfig,
) -> Result<WindowedFit, SogmmError> {
    fit_windowed(
        &frame.depth_m,
        &frame.intensity,
        &frame.intrinsics,
        &frame.pose,
        config,
    )
}
