//! Gaussian mixtures, the shared language of troupe's maps: the joint 4D model [`Gmm4`] (x, y, z, intensity; thesis Eq. 6.1), its
//! spatial marginal [`Gmm3`] (Eq. 6.11), the intensity conditional
//! [`IntensityConditional`] (Eqs. 6.12–6.13), log-likelihoods through Cholesky factors
//! (App. A, Eq. A.3) and sampling (§6.1.5).
//!
//! Covariances are never inverted: every Mahalanobis distance is a forward substitution
//! with the lower Cholesky factor `L` (`Σ = L Lᵀ`), and `ln |Σ| = 2 Σ ln L_jj`.

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use rand::Rng;
use rayon::prelude::*;

mod merge;

pub use merge::{merge_gmm, merge_gmm3, merge_gmm4, merge_weights};

/// Why a mixture is not valid.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum MixtureError {
    /// A mixture needs at least one component.
    #[error("mixture has no components")]
    EmptyModel,
    /// Weights, means and covariances differ in number.
    #[error("{weights} weights, {means} means, {covariances} covariances")]
    LengthMismatch {
        /// Number of weights.
        weights: usize,
        /// Number of means.
        means: usize,
        /// Number of covariances.
        covariances: usize,
    },
    /// A weight is negative or not finite.
    #[error("weight {weight} of component {component} is negative or not finite")]
    InvalidWeight {
        /// Component index.
        component: usize,
        /// The weight.
        weight: f64,
    },
    /// Weights do not sum to one (within [`WEIGHT_SUM_TOLERANCE`]).
    #[error("weights sum to {sum}, not 1")]
    WeightsDoNotSumToOne {
        /// Their sum.
        sum: f64,
    },
    /// A covariance is not symmetric positive definite (or a mean is not finite).
    #[error("covariance of component {component} is not symmetric positive definite")]
    NotPositiveDefinite {
        /// Component index.
        component: usize,
    },
    /// Parts to merge are not valid (non-finite or negative support, no parts).
    #[error("invalid merge: {0}")]
    InvalidMerge(&'static str),
}

/// `ln(2π)`.
pub(crate) const LN_2PI: f64 = 1.837_877_066_409_345_5;

/// Largest allowed `|Σ w − 1|` for a valid mixture.
pub const WEIGHT_SUM_TOLERANCE: f64 = 1e-9;

/// Relative asymmetry `|Σ − Σᵀ|_max / |Σ|_max` accepted for a covariance.
const SYMMETRY_TOLERANCE: f64 = 1e-9;

/// Points per rayon task in the batched evaluations (results are per point, so the
/// split does not change any value).
const BATCH: usize = 1024;

/// One `D`-dimensional component (`D ≤ 4`) in the form the hot loops use: mean, packed
/// lower Cholesky factor, the reciprocals of its diagonal and the log normaliser
/// `−(D/2) ln 2π − Σ ln L_jj` (Eq. A.3, without the weight).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Chol<const D: usize> {
    pub(crate) mean: [f64; D],
    /// The lower triangle row by row (`L_ij` at `i (i + 1) / 2 + j`, `j ≤ i`), in an
    /// array sized for the largest `D` (4), so that a 4D factor keeps its packed size.
    l: [f64; PACKED_MAX],
    inv_diag: [f64; D],
    pub(crate) log_norm: f64,
}

/// Entries of the packed lower triangle of a 4×4 factor, the largest [`Chol`] holds.
const PACKED_MAX: usize = 10;

/// Where row `i` of a packed lower triangle starts.
#[inline(always)]
const fn row(i: usize) -> usize {
    i * (i + 1) / 2
}

/// The `(i, j)` of packed entry `k` of a `D`×`D` lower triangle, `None` past its end.
fn packed_entry<const D: usize>(k: usize) -> Option<(usize, usize)> {
    let i = (0..D).find(|&i| k < row(i + 1))?;
    Some((i, k - row(i)))
}

/// A 3D component (the spatial marginal, the gates and the global map use it).
pub(crate) type Chol3 = Chol<3>;

impl<const D: usize> Chol<D> {
    /// Factor `cov`; `None` if it is not positive definite (or not finite).
    pub(crate) fn new(mean: &SVector<f64, D>, cov: &SMatrix<f64, D, D>) -> Option<Self> {
        if !cov.iter().all(|v| v.is_finite()) || !mean.iter().all(|v| v.is_finite()) {
            return None;
        }
        const { assert!(D <= 4, "a Chol holds factors of at most 4 dimensions") };
        let l = cov.cholesky()?.l();
        let diag: [f64; D] = std::array::from_fn(|i| l[(i, i)]);
        if diag.iter().any(|d| !d.is_finite() || *d <= 0.0) {
            return None;
        }
        let log_det_half: f64 = diag.iter().map(|d| d.ln()).sum();
        Some(Self {
            mean: (*mean).into(),
            l: std::array::from_fn(|k| packed_entry::<D>(k).map_or(0.0, |ij| l[ij])),
            inv_diag: diag.map(|d| 1.0 / d),
            log_norm: -(D as f64 / 2.0) * LN_2PI - log_det_half,
        })
    }

    /// Squared Mahalanobis distance `|L⁻¹ (x − μ)|²` by forward substitution (Eq. A.3).
    #[inline(always)]
    pub(crate) fn mahalanobis2(&self, x: &[f64; D]) -> f64 {
        let mut y = [0.0; D];
        for i in 0..D {
            let mut r = x[i] - self.mean[i];
            for (l, yj) in self.l[row(i)..row(i) + i].iter().zip(&y[..i]) {
                r -= l * yj;
            }
            y[i] = r * self.inv_diag[i];
        }
        y.iter().fold(0.0, |sum, v| sum + v * v)
    }

    /// `μ + L z`.
    #[inline]
    fn transform(&self, z: [f64; D]) -> SVector<f64, D> {
        SVector::from_fn(|i, _| {
            let mut v = self.mean[i];
            for (l, zj) in self.l[row(i)..=row(i) + i].iter().zip(&z[..=i]) {
                v += l * zj;
            }
            v
        })
    }
}

/// `ln Σ exp(v)` over a slice, stable (max shifted). `−∞` for an empty slice.
#[inline]
pub(crate) fn log_sum_exp(values: &[f64]) -> f64 {
    let max = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !max.is_finite() {
        return max;
    }
    let s: f64 = values.iter().map(|v| (v - max).exp()).sum();
    max + s.ln()
}

fn check_weights(weights: &[f64]) -> Result<(), MixtureError> {
    if weights.is_empty() {
        return Err(MixtureError::EmptyModel);
    }
    for (component, w) in weights.iter().enumerate() {
        if !w.is_finite() || *w < 0.0 {
            return Err(MixtureError::InvalidWeight {
                component,
                weight: *w,
            });
        }
    }
    let sum: f64 = weights.iter().sum();
    if (sum - 1.0).abs() > WEIGHT_SUM_TOLERANCE {
        return Err(MixtureError::WeightsDoNotSumToOne { sum });
    }
    Ok(())
}

/// The invariants [`Gmm::new`] checks (matching lengths, valid weights, symmetric
/// positive-definite covariances), with each covariance factored.
fn checked_factors<const D: usize>(
    weights: &[f64],
    means: &[SVector<f64, D>],
    covariances: &[SMatrix<f64, D, D>],
) -> Result<Vec<Chol<D>>, MixtureError> {
    if means.len() != weights.len() || covariances.len() != weights.len() {
        return Err(MixtureError::LengthMismatch {
            weights: weights.len(),
            means: means.len(),
            covariances: covariances.len(),
        });
    }
    check_weights(weights)?;
    means
        .iter()
        .zip(covariances)
        .enumerate()
        .map(|(component, (mean, cov))| {
            if asymmetry(cov) > SYMMETRY_TOLERANCE {
                return Err(MixtureError::NotPositiveDefinite { component });
            }
            Chol::new(mean, cov).ok_or(MixtureError::NotPositiveDefinite { component })
        })
        .collect()
}

fn asymmetry<const D: usize>(m: &SMatrix<f64, D, D>) -> f64 {
    let scale = m.amax().max(f64::MIN_POSITIVE);
    (m - m.transpose()).amax() / scale
}

/// A Gaussian mixture in `D` dimensions: weights `π_m`, means `μ_m ∈ ℝᴰ`, full
/// covariances `Σ_m ∈ ℝᴰˣᴰ`, with the Cholesky factors and log-determinants cached at
/// construction. Used as [`Gmm4`] (the joint model, thesis Eq. 6.1) and [`Gmm3`] (its
/// spatial marginal, Eq. 6.11).
///
/// Invariants (checked by [`Gmm::new`]): at least one component, weights finite,
/// non-negative and summing to 1 within [`WEIGHT_SUM_TOLERANCE`], means finite,
/// covariances symmetric and positive definite.
#[derive(Clone, Debug)]
pub struct Gmm<const D: usize> {
    weights: Vec<f64>,
    means: Vec<SVector<f64, D>>,
    covariances: Vec<SMatrix<f64, D, D>>,
    chol: Vec<Chol<D>>,
    log_weights: Vec<f64>,
}

/// A Gaussian mixture over (x, y, z, intensity) (thesis Eq. 6.1): weights `π_m`, means
/// `μ_m ∈ ℝ⁴`, full covariances `Σ_m ∈ ℝ⁴ˣ⁴`, with the Cholesky factors and
/// log-determinants cached at construction.
///
/// Invariants (checked by [`Gmm::new`]): at least one component, weights finite,
/// non-negative and summing to 1 within [`WEIGHT_SUM_TOLERANCE`], means finite,
/// covariances symmetric and positive definite.
pub type Gmm4 = Gmm<4>;

/// A Gaussian mixture over (x, y, z): the spatial marginal of a [`Gmm4`] (Eq. 6.11),
/// used to sample the reconstructed surface (§6.1.5) and, later, the relevant-subset
/// test (Eq. 6.9). Same invariants as [`Gmm4`].
pub type Gmm3 = Gmm<3>;

impl<const D: usize> PartialEq for Gmm<D> {
    /// Equal parameters (the caches follow from them).
    fn eq(&self, other: &Self) -> bool {
        self.weights == other.weights
            && self.means == other.means
            && self.covariances == other.covariances
    }
}

impl<const D: usize> Gmm<D> {
    /// A validated mixture; fails on any broken invariant (see the type doc).
    pub fn new(
        weights: Vec<f64>,
        means: Vec<SVector<f64, D>>,
        covariances: Vec<SMatrix<f64, D, D>>,
    ) -> Result<Self, MixtureError> {
        let chol = checked_factors(&weights, &means, &covariances)?;
        let log_weights = weights.iter().map(|w| w.ln()).collect();
        Ok(Self {
            weights,
            means,
            covariances,
            chol,
            log_weights,
        })
    }

    /// Number of components `M`.
    #[must_use]
    pub fn len(&self) -> usize {
        self.weights.len()
    }

    /// Never true for a constructed mixture (kept for the `len` convention).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.weights.is_empty()
    }

    /// Weights `π_m`.
    #[must_use]
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// Means `μ_m` (x, y, z in metres, then intensity in a [`Gmm4`]).
    #[must_use]
    pub fn means(&self) -> &[SVector<f64, D>] {
        &self.means
    }

    /// Covariances `Σ_m` (m² in the spatial block).
    #[must_use]
    pub fn covariances(&self) -> &[SMatrix<f64, D, D>] {
        &self.covariances
    }

    /// `ln |Σ_m|` from the cached Cholesky factor (`2 Σ ln L_jj`).
    #[must_use]
    pub fn ln_determinant(&self, m: usize) -> f64 {
        -2.0 * (self.chol[m].log_norm + (D as f64 / 2.0) * LN_2PI)
    }

    /// Re-check every invariant of the type doc (weights sum to 1, covariances PD).
    pub fn validate(&self) -> Result<(), MixtureError> {
        Self::new(
            self.weights.clone(),
            self.means.clone(),
            self.covariances.clone(),
        )
        .map(|_| ())
    }

    /// Append the components of `other` and replace every weight by `weights` (first
    /// this model's components, then `other`'s): the merge of a local model into the
    /// global one, "appending the parameters and re-normalizing the weights" (thesis
    /// §6.1.4.2). The cached Cholesky factors are reused, so the cost is linear in the
    /// number of components with a small constant. On error (wrong length, weights not
    /// summing to 1, see [`Gmm::new`]) `self` is left unchanged.
    pub fn append_reweighted(
        &mut self,
        other: &Self,
        weights: Vec<f64>,
    ) -> Result<(), MixtureError> {
        let n = self.len() + other.len();
        if weights.len() != n {
            return Err(MixtureError::LengthMismatch {
                weights: weights.len(),
                means: n,
                covariances: n,
            });
        }
        check_weights(&weights)?;
        self.means.extend_from_slice(&other.means);
        self.covariances.extend_from_slice(&other.covariances);
        self.chol.extend_from_slice(&other.chol);
        self.log_weights = weights.iter().map(|w| w.ln()).collect();
        self.weights = weights;
        Ok(())
    }

    /// `ln π_m + ln N(x | μ_m, Σ_m)` (Eq. A.2 numerator, Eq. A.3).
    #[must_use]
    pub fn log_component(&self, m: usize, x: &SVector<f64, D>) -> f64 {
        let c = &self.chol[m];
        self.log_weights[m] + c.log_norm - 0.5 * c.mahalanobis2(&(*x).into())
    }

    /// `ln p(x) = ln Σ_m π_m N(x | μ_m, Σ_m)` by log-sum-exp over all components (exact,
    /// dense).
    #[must_use]
    pub fn log_likelihood(&self, x: &SVector<f64, D>) -> f64 {
        let xs: [f64; D] = (*x).into();
        let mut buf = Vec::with_capacity(self.len());
        buf.extend(
            self.chol
                .iter()
                .zip(&self.log_weights)
                .map(|(c, lw)| lw + c.log_norm - 0.5 * c.mahalanobis2(&xs)),
        );
        log_sum_exp(&buf)
    }

    /// [`Gmm::log_likelihood`] of many points, in parallel (values do not depend on the
    /// thread count).
    #[must_use]
    pub fn log_likelihoods(&self, xs: &[SVector<f64, D>]) -> Vec<f64> {
        xs.par_chunks(BATCH)
            .flat_map_iter(|chunk| chunk.iter().map(|x| self.log_likelihood(x)))
            .collect()
    }

    /// Mean of [`Gmm::log_likelihoods`], summed in point order.
    #[must_use]
    pub fn mean_log_likelihood(&self, xs: &[SVector<f64, D>]) -> f64 {
        if xs.is_empty() {
            return f64::NAN;
        }
        self.log_likelihoods(xs).iter().sum::<f64>() / xs.len() as f64
    }
}

impl Gmm<4> {
    /// The spatial marginal `p(x, y, z)` (Eq. 6.11): same weights, the first three mean
    /// entries and the top-left 3×3 covariance block.
    #[must_use]
    pub fn marginal_spatial(&self) -> Gmm3 {
        let means: Vec<Vector3<f64>> = self.means.iter().map(|m| m.xyz()).collect();
        let covs: Vec<Matrix3<f64>> = self
            .covariances
            .iter()
            .map(|c| c.fixed_view::<3, 3>(0, 0).into_owned())
            .collect();
        let chol = means
            .iter()
            .zip(&covs)
            .map(|(m, c)| {
                // A principal block of a PD matrix is PD; the factor exists.
                Chol3::new(m, c).unwrap_or_else(unreachable_block)
            })
            .collect();
        Gmm3 {
            weights: self.weights.clone(),
            log_weights: self.log_weights.clone(),
            means,
            covariances: covs,
            chol,
        }
    }

    /// The intensity conditional `p(g | x, y, z)` (Eq. 6.12), ready for batched queries.
    #[must_use]
    pub fn intensity_conditional(&self) -> IntensityConditional {
        IntensityConditional::new(self)
    }
}

#[cold]
fn unreachable_block() -> Chol3 {
    // Only reachable if a validated 4×4 PD covariance had a non-PD leading block, which
    // cannot happen; return a harmless, far-away unit component rather than panic.
    Chol3 {
        mean: [f64::MAX; 3],
        l: [1.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0],
        inv_diag: [1.0; 3],
        log_norm: f64::NEG_INFINITY,
    }
}

impl Gmm<3> {
    /// Draw `n` points (§6.1.5): component by its weight, then `μ + L z` with `z` standard
    /// normal from the Box–Muller transform. Deterministic for a given `rng` state.
    pub fn sample<R: Rng + ?Sized>(&self, n: usize, rng: &mut R) -> Vec<Vector3<f64>> {
        let mut cumulative = Vec::with_capacity(self.len());
        let mut acc = 0.0;
        for w in &self.weights {
            acc += w;
            cumulative.push(acc);
        }
        let total = acc;
        let last = self.len() - 1;
        (0..n)
            .map(|_| {
                let u = rng.random::<f64>() * total;
                let m = cumulative.partition_point(|c| *c <= u).min(last);
                let (z0, z1) = box_muller(rng);
                let (z2, _) = box_muller(rng);
                self.chol[m].transform([z0, z1, z2])
            })
            .collect()
    }
}

/// Two independent standard normal draws from two uniforms (Box–Muller).
pub(crate) fn box_muller<R: Rng + ?Sized>(rng: &mut R) -> (f64, f64) {
    // 1 − U lies in (0, 1], so the logarithm is finite.
    let u1 = 1.0 - rng.random::<f64>();
    let u2 = rng.random::<f64>();
    let r = (-2.0 * u1.ln()).sqrt();
    let (s, c) = (std::f64::consts::TAU * u2).sin_cos();
    (r * c, r * s)
}

/// Expected intensity and its variance at a point (Eqs. 6.12–6.13).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IntensityEstimate {
    /// `λ(x) = Σ_m w_m(x) λ_m(x)` (Eq. 6.13).
    pub mean: f64,
    /// `Σ_m w_m(x) (ν_m² + λ_m(x)²) − λ(x)²`, the variance of the mixture of Eq. 6.12.
    pub variance: f64,
}

/// The conditional `p(g | x)` of a [`Gmm4`] (Eq. 6.12), with per-component regression
/// vectors `b_m = Σ_xx⁻¹ Σ_xg` and conditional variances
/// `ν_m² = Σ_gg − Σ_gx Σ_xx⁻¹ Σ_xg` precomputed by Cholesky solves.
#[derive(Clone, Debug)]
pub struct IntensityConditional {
    spatial: Vec<Chol3>,
    log_weights: Vec<f64>,
    mean_g: Vec<f64>,
    regression: Vec<[f64; 3]>,
    cond_var: Vec<f64>,
}

impl IntensityConditional {
    /// Precompute from a joint model.
    #[must_use]
    pub fn new(gmm: &Gmm4) -> Self {
        let n = gmm.len();
        let mut spatial = Vec::with_capacity(n);
        let mut regression = Vec::with_capacity(n);
        let mut cond_var = Vec::with_capacity(n);
        for (mean, cov) in gmm.means.iter().zip(&gmm.covariances) {
            let sxx = cov.fixed_view::<3, 3>(0, 0).into_owned();
            let sxg: Vector3<f64> = cov.fixed_view::<3, 1>(0, 3).into_owned();
            let sgg = cov[(3, 3)];
            match sxx.cholesky() {
                Some(ch) => {
                    let b = ch.solve(&sxg);
                    spatial.push(Chol3::new(&mean.xyz(), &sxx).unwrap_or_else(unreachable_block));
                    regression.push([b[0], b[1], b[2]]);
                    cond_var.push((sgg - sxg.dot(&b)).max(0.0));
                }
                None => {
                    spatial.push(unreachable_block());
                    regression.push([0.0; 3]);
                    cond_var.push(sgg);
                }
            }
        }
        Self {
            spatial,
            log_weights: gmm.log_weights.clone(),
            mean_g: gmm.means.iter().map(|m| m[3]).collect(),
            regression,
            cond_var,
        }
    }

    /// Expected intensity and variance at one point (dense over all components).
    #[must_use]
    pub fn estimate(&self, x: &Vector3<f64>) -> IntensityEstimate {
        let mut buf = Vec::with_capacity(self.log_weights.len());
        self.estimate_with(x, &mut buf)
    }

    fn estimate_with(&self, x: &Vector3<f64>, buf: &mut Vec<f64>) -> IntensityEstimate {
        let xs = [x[0], x[1], x[2]];
        buf.clear();
        buf.extend(
            self.spatial
                .iter()
                .zip(&self.log_weights)
                .map(|(c, lw)| lw + c.log_norm - 0.5 * c.mahalanobis2(&xs)),
        );
        let max = buf.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let (mut wsum, mut m1, mut m2) = (0.0, 0.0, 0.0);
        for (m, lw) in buf.iter().enumerate() {
            // Far from every component (max = −∞) fall back to the prior weights.
            let w = if max.is_finite() {
                (lw - max).exp()
            } else {
                self.log_weights[m].exp()
            };
            if w == 0.0 {
                continue;
            }
            let c = &self.spatial[m];
            let b = &self.regression[m];
            let lambda = self.mean_g[m]
                + b[0] * (xs[0] - c.mean[0])
                + b[1] * (xs[1] - c.mean[1])
                + b[2] * (xs[2] - c.mean[2]);
            wsum += w;
            m1 += w * lambda;
            m2 += w * (self.cond_var[m] + lambda * lambda);
        }
        let mean = m1 / wsum;
        IntensityEstimate {
            mean,
            variance: (m2 / wsum - mean * mean).max(0.0),
        }
    }

    /// [`IntensityConditional::estimate`] for a batch of points, in parallel batches
    /// (§6.1.5); each value depends only on its point.
    #[must_use]
    pub fn estimate_batch(&self, xs: &[Vector3<f64>]) -> Vec<IntensityEstimate> {
        xs.par_chunks(BATCH)
            .flat_map_iter(|chunk| {
                let mut buf = Vec::with_capacity(self.log_weights.len());
                chunk
                    .iter()
                    .map(move |x| self.estimate_with(x, &mut buf))
                    .collect::<Vec<_>>()
            })
            .collect()
    }
}
