//! Collision probability of a robot ellipsoid whose centre is Gaussian,
//! `b ~ N(μ_B, Σ_B)`, against one surface ellipsoid (Corollary 1, Eqs. 7.8–7.9).
//!
//! With `y = c − b` and `Ā = B^{1/2}(λI − C̃)⁻² B^{1/2}`, the pair touches or intersects
//! iff `v = yᵀĀy ≤ 1/λ²` (Eq. 7.8). Taking `Ā` and `λ` at the mean (the conservative
//! assumption of \[183\]), `v` is a quadratic form in a Gaussian with
//! `E[v] = tr(ĀΣ) + mᵀĀm` and `V[v] = 2 tr((ĀΣ)²) + 4 mᵀĀΣĀm`, `m = c − μ_B`, and
//! Eq. 7.9 bounds `P(v ≤ 1/λ²) ≤ η√V / (E + η√V − 1/λ²)`.
//!
//! `Ā` comes for free from the distance computation: in the eigenbasis `V` of `C̃`,
//! `Ā = W diag(hᵢ) Wᵀ` with `W = B^{1/2}V` and `hᵢ = 1/(γᵢ − λ)²`, so with
//! `G = WᵀΣW` and `ŷ = Wᵀm`: `tr(ĀΣ) = Σ hᵢGᵢᵢ`, `tr((ĀΣ)²) = Σᵢⱼ hᵢhⱼGᵢⱼ²`,
//! `mᵀĀm = Σ hᵢŷᵢ²` and `mᵀĀΣĀm = (hŷ)ᵀG(hŷ)`. No Cholesky factor is needed.
//!
//! # The η rule (§7.1.4)
//!
//! `η` starts at 0.25 and grows by 0.5 until the denominator of Eq. 7.9 is positive;
//! the step count is computed in closed form. Whenever the rule had to raise `η` the
//! bound exceeds 1 and is reported as 1. Two edge cases follow the deterministic check:
//! with `V[v] = 0` the probability is 0 or 1 by the sign of `E[v] − 1/λ²`, and a robot
//! centre inside the surface ellipsoid (`λ ≥ 0`) gives 1.
//!
//! As a function of isotropic noise `σ`, Eq. 7.9 rises from 0 and, for noise much
//! larger than the clearance, levels off (it tends to a constant below 1 and may dip
//! slightly before that); it is increasing over the range where the noise is
//! comparable to the distance, which is where it matters.

use nalgebra::SMatrix;

use super::ellipsoid::{PairStatus, Proximity};

/// First value of `η` in Eq. 7.9 (\[183\], footnote 5).
pub const ETA_START: f64 = 0.25;
/// Increment of `η` while the denominator of Eq. 7.9 is not positive (§7.1.4).
pub const ETA_STEP: f64 = 0.5;

/// The collision probability bound of Eq. 7.9 and the quantities behind it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CollisionProbability {
    /// The bound, clipped to `[0, 1]`.
    pub probability: f64,
    /// The `η` used; `None` when Eq. 7.9 was not needed (robot centre inside the surface
    /// ellipsoid, or zero variance).
    pub eta: Option<f64>,
    /// `E[v]`.
    pub mean: f64,
    /// `V[v]`.
    pub variance: f64,
    /// `1/λ²`, the collision threshold on `v` (Eq. 7.8); infinite when `λ ≥ 0`.
    pub threshold: f64,
}

impl<const D: usize> Proximity<D> {
    /// Upper bound on the probability that the robot ellipsoid, with its centre
    /// distributed as `N(b, position_covariance)` around the centre used to build this
    /// pair, touches the surface ellipsoid: Eqs. 7.8–7.9 with the η rule of §7.1.4.
    #[must_use]
    pub fn collision_probability(
        &self,
        position_covariance: &SMatrix<f64, D, D>,
    ) -> CollisionProbability {
        if self.status == PairStatus::CenterInside {
            return CollisionProbability {
                probability: 1.0,
                eta: None,
                mean: 0.0,
                variance: 0.0,
                threshold: f64::INFINITY,
            };
        }
        let s = -self.lambda;
        let h = self.pair_eigenvalues.map(|g| {
            let r = 1.0 / (g + s);
            r * r
        });
        let w = &self.pair_basis;
        let g = w.tr_mul(&(position_covariance * w));
        let y = &self.pair_offset;
        let hy = h.component_mul(y);
        let mut trace = 0.0;
        let mut trace_sq = 0.0;
        for i in 0..D {
            trace += h[i] * g[(i, i)];
            for j in 0..D {
                trace_sq += h[i] * h[j] * g[(i, j)] * g[(i, j)];
            }
        }
        let mean = trace + hy.dot(y);
        let variance = 2.0 * trace_sq + 4.0 * hy.dot(&(g * hy));
        let threshold = 1.0 / (s * s);
        let (probability, eta) = bound(mean, variance, threshold);
        CollisionProbability {
            probability,
            eta,
            mean,
            variance,
            threshold,
        }
    }
}

/// Eq. 7.9 with the η rule: returns the clipped bound and the `η` used.
fn bound(mean: f64, variance: f64, threshold: f64) -> (f64, Option<f64>) {
    let sd = variance.max(0.0).sqrt();
    let gap = mean - threshold;
    if sd.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return (if gap > 0.0 { 0.0 } else { 1.0 }, None);
    }
    let mut eta = ETA_START;
    if gap + eta * sd <= 0.0 {
        // Smallest k with gap + (0.25 + 0.5k)·sd > 0, then guard against rounding.
        let k = ((-gap / sd - ETA_START) / ETA_STEP).floor() + 1.0;
        eta = ETA_START + ETA_STEP * k.max(1.0);
        while gap + eta * sd <= 0.0 && eta.is_finite() {
            eta += ETA_STEP;
        }
        if !eta.is_finite() {
            return (1.0, None);
        }
    }
    let p = eta * sd / (gap + eta * sd);
    (p.clamp(0.0, 1.0), Some(eta))
}
