//! Self-organizing Gaussian mixtures (SOGMM, thesis ch. 6 and App. A): a 4D
//! (x, y, z, intensity) mixture fitted to one depth + intensity frame, with its size `M`
//! chosen by the data.
//!
//! The pipeline of Fig. 6.1, one module per step:
//!
//! 1. [`points`]: frame → world-frame 4D points and 2D (depth, intensity) data.
//! 2. [`mean_shift`]: `M` = number of modes of a flat-kernel mean shift of bandwidth σ
//!    on the 2D data (Eqs. 6.5–6.7): by default the non-blurring one from bin seeds of
//!    the authors' published implementation, or the thesis text's blurring one
//!    ([`MeanShiftKind`]).
//! 3. [`kmeanspp`]: k-means++ steps 1a–1c on the 4D points → hard partition (KInit).
//! 4. [`em`]: EM with full covariances in log space via Cholesky (Eqs. A.2–A.3), with an
//!    exact dense E-step and a restricted one that skips components whose
//!    responsibility is provably below 1e-10 relative.
//! 5. [`crate::mixture`]: the model types [`Gmm4`] and [`Gmm3`], log-likelihoods, the spatial
//!    marginal, sampling, and the intensity conditional (Eqs. 6.12–6.13).
//!
//! [`fit_frame`] / [`fit_points`] run the whole pipeline; a fit is deterministic for a
//! given [`SogmmConfig::seed`] and does not depend on the rayon thread count.
//! [`synthetic`] ray-casts analytic test scenes and [`metrics`] scores reconstructions
//! (§6.2.4).
//!
//! ```
//! use nalgebra::Isometry3;
//! use troupe_algorithms::sogmm::{fit_frame, synthetic, SogmmConfig};
//!
//! let scene = synthetic::Scene::single_plane();
//! let intr = synthetic::intrinsics(40, 30);
//! let pose = Isometry3::identity();
//! let (depth, intensity) = scene.render(&intr, &pose);
//! let fit = fit_frame(&depth, &intensity, &intr, &pose, &SogmmConfig::default()).unwrap();
//! assert!(fit.gmm.len() >= 1);
//! let cloud = fit.gmm.marginal_spatial();
//! assert_eq!(cloud.len(), fit.gmm.len());
//! ```

pub mod em;
mod grid;
pub mod kmeanspp;
pub mod mean_shift;
pub mod metrics;
pub mod points;
pub mod synthetic;
#[cfg(test)]
mod tests;

use nalgebra::{Isometry3, Vector4};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

pub use crate::mixture::{Gmm3, Gmm4, IntensityConditional, IntensityEstimate};
pub use em::{EStep, EmConfig, EmReport, fit_em, init_from_partition};
pub use kmeanspp::{Seeding, kmeans_plusplus};
pub use mean_shift::{MeanShiftConfig, MeanShiftKind, MeanShiftModes, mean_shift_modes};
pub use points::{FramePoints, frame_points};

use crate::camera::PinholeIntrinsics;

/// Errors of the SOGMM fit.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SogmmError {
    /// The mixture is not valid (weights, covariances).
    #[error("invalid mixture")]
    Mixture(#[from] crate::mixture::MixtureError),
    /// The frame's buffers do not fit its intrinsics.
    #[error("unusable frame")]
    Frame(#[from] crate::frame::FrameError),
    /// Not enough valid points to fit.
    #[error("{points} valid points, at least {needed} needed")]
    TooFewPoints {
        /// Valid points.
        points: usize,
        /// Required.
        needed: usize,
    },
    /// Some other invalid argument.
    #[error("invalid input: {0}")]
    InvalidInput(&'static str),
}

/// Settings of a SOGMM fit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SogmmConfig {
    /// Mean-shift bandwidth σ on (depth m, intensity) (§6.1.3); smaller → more components.
    pub bandwidth: f64,
    /// Seed of the k-means++ draw (ChaCha8).
    pub seed: u64,
    /// Mean-shift settings.
    pub mean_shift: MeanShiftConfig,
    /// EM settings.
    pub em: EmConfig,
}

impl Default for SogmmConfig {
    /// σ = 0.02, seed 0, the reference mean shift, default EM.
    fn default() -> Self {
        Self {
            bandwidth: 0.02,
            seed: 0,
            mean_shift: MeanShiftConfig::default(),
            em: EmConfig::default(),
        }
    }
}

/// What a fit did, for logs and benchmarks.
#[derive(Clone, Debug, PartialEq)]
pub struct FitReport {
    /// Valid points fitted.
    pub points: usize,
    /// Modes found by the mean shift (`M`).
    pub modes: usize,
    /// Mean-shift iterations.
    pub mean_shift_iterations: usize,
    /// Components seeded (equals `modes` unless the points had fewer distinct values).
    pub components: usize,
    /// The EM run.
    pub em: EmReport,
}

/// A fitted frame.
#[derive(Clone, Debug)]
pub struct SogmmFit {
    /// The mixture.
    pub gmm: Gmm4,
    /// What the fit did.
    pub report: FitReport,
}

/// Fit a SOGMM to 4D points with the given mean-shift data (Fig. 6.1): mean shift → `M`,
/// k-means++ (seeded with `config.seed`) → hard partition → EM.
pub fn fit_points(
    points: &[Vector4<f64>],
    depth_intensity: &[[f64; 2]],
    config: &SogmmConfig,
) -> Result<SogmmFit, SogmmError> {
    if points.is_empty() {
        return Err(SogmmError::TooFewPoints {
            points: 0,
            needed: 1,
        });
    }
    if !config.bandwidth.is_finite() || config.bandwidth <= 0.0 {
        return Err(SogmmError::InvalidInput(
            "bandwidth must be positive and finite",
        ));
    }
    if points.iter().any(|p| !p.iter().all(|v| v.is_finite())) {
        return Err(SogmmError::InvalidInput("points must be finite"));
    }
    let modes = mean_shift_modes(depth_intensity, config.bandwidth, &config.mean_shift);
    let m = modes.len().clamp(1, points.len());
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let seeding = kmeans_plusplus(points, m, &mut rng);
    let init = init_from_partition(
        points,
        &seeding.assignment,
        seeding.centres.len(),
        config.em.reg_covar,
    )?;
    let (gmm, em) = em::fit_em_anchored(points, &init, Some(&seeding.assignment), &config.em)?;
    Ok(SogmmFit {
        gmm,
        report: FitReport {
            points: points.len(),
            modes: modes.len(),
            mean_shift_iterations: modes.iterations,
            components: seeding.centres.len(),
            em,
        },
    })
}

/// [`fit_frame`] on a [`DepthFrame`](crate::frame::DepthFrame) (its pose, intrinsics,
/// depth and intensity).
pub fn fit_depth_frame(
    frame: &crate::frame::DepthFrame,
    config: &SogmmConfig,
) -> Result<SogmmFit, SogmmError> {
    fit_frame(
        &frame.depth_m,
        &frame.intensity,
        &frame.intrinsics,
        &frame.pose,
        config,
    )
}

/// [`frame_points`] then [`fit_points`].
pub fn fit_frame(
    depth_m: &[f32],
    intensity: &[f32],
    intrinsics: &PinholeIntrinsics,
    pose: &Isometry3<f64>,
    config: &SogmmConfig,
) -> Result<SogmmFit, SogmmError> {
    let frame = frame_points(depth_m, intensity, intrinsics, pose)?;
    fit_points(&frame.points, &frame.depth_intensity, config)
}
