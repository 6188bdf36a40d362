//! EM for a full-covariance 3D mixture with the Mahalanobis gate of thesis §3.2.1
//! (Eq. 3.3): a point takes part in the update of component `m` only when
//! `sqrt((x − μ¹_m)ᵀ (Λ¹_m)⁻¹ (x − μ¹_m)) < λ`, with `μ¹_m, Λ¹_m` the *initial*
//! parameters; a point outside every component's gate is discarded for the whole fit.
//!
//! The gate is computed once, from the starting mixture, as a sparse point → component
//! list ([`Gate`]); every E-step then evaluates only the listed components, which is
//! where the saving comes from (the paper's §IV-A motivation: `N·M` responsibilities
//! per iteration otherwise).
//!
//! E-step in log space through Cholesky factors (the same arithmetic as the SOGMM EM,
//! thesis App. A, Eqs. A.2–A.3, restricted to the gated components); M-step with the
//! moments shifted by the previous means, `+ reg_covar · I` on every covariance.
//! Convergence: change of the mean log-likelihood of the kept points below
//! `tolerance`, or `max_iterations`. Sequential and deterministic.

use nalgebra::{Matrix3, Vector3, Vector4};
use rand::Rng;

use crate::mixture::{Chol3, log_sum_exp};
use crate::sogmm::kmeans_plusplus;

/// Settings of one gated EM fit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GatedEmConfig {
    /// Mahalanobis gate λ of Eq. 3.3 (in standard deviations); `f64::INFINITY` keeps
    /// every point for every component (plain EM).
    pub gate: f64,
    /// `ε` added to every covariance diagonal, m² (1e-6: a 1 mm floor).
    pub reg_covar: f64,
    /// Convergence threshold on the change of the mean log-likelihood, nats per point.
    pub tolerance: f64,
    /// Iteration cap.
    pub max_iterations: usize,
    /// Components whose responsibility mass (effective number of points) ends below
    /// this are dropped and the other weights renormalised.
    pub min_component_points: f64,
}

impl Default for GatedEmConfig {
    /// λ = 3, `reg_covar = 1e-6`, `tolerance = 1e-3`, 100 iterations, components of
    /// fewer than 3 effective points dropped.
    fn default() -> Self {
        Self {
            gate: 3.0,
            reg_covar: 1e-6,
            tolerance: 1e-3,
            max_iterations: 100,
            min_component_points: 3.0,
        }
    }
}

/// A 3D mixture in plain form (weights sum to 1, covariances positive definite), with
/// the number of points it was fitted to.
#[derive(Clone, Debug, PartialEq)]
pub struct GatedFit {
    /// Weights.
    pub weights: Vec<f64>,
    /// Means, metres.
    pub means: Vec<Vector3<f64>>,
    /// Covariances, m².
    pub covariances: Vec<Matrix3<f64>>,
    /// Points inside at least one gate: the support size `N_i` of Eq. 3.4.
    pub support: usize,
    /// Points outside every gate (discarded by Eq. 3.3).
    pub discarded: usize,
    /// EM iterations run.
    pub iterations: usize,
    /// Whether the tolerance rule stopped the loop.
    pub converged: bool,
    /// For every kept component, the responsibility-weighted mean and covariance of
    /// the points' fourth coordinate (intensity) jointly with x, y, z: filled by
    /// [`fit_gated_em`] when it is given 4D points.
    pub joint: Vec<(Vector4<f64>, nalgebra::Matrix4<f64>)>,
}

/// Which components each point may inform (Eq. 3.3), as compressed rows.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Gate {
    /// `offsets[i]..offsets[i + 1]` indexes `components` for point `i`.
    pub offsets: Vec<u32>,
    /// Component indices, ascending within a point.
    pub components: Vec<u32>,
}

impl Gate {
    /// The components point `i` may inform.
    #[must_use]
    pub fn of(&self, i: usize) -> &[u32] {
        &self.components[self.offsets[i] as usize..self.offsets[i + 1] as usize]
    }

    /// Points with at least one component.
    #[must_use]
    pub fn kept(&self) -> usize {
        self.offsets.windows(2).filter(|w| w[1] > w[0]).count()
    }
}

/// The gate of Eq. 3.3: for every point, the components `m` with
/// `d_M(x, μ_m, Λ_m) < λ` under the given (initial) parameters.
#[must_use]
pub(crate) fn gate(points: &[Vector3<f64>], chol: &[Chol3], lambda: f64) -> Gate {
    let lambda2 = lambda * lambda;
    let mut offsets = Vec::with_capacity(points.len() + 1);
    let mut components = Vec::new();
    offsets.push(0);
    for p in points {
        let x = [p[0], p[1], p[2]];
        for (m, c) in chol.iter().enumerate() {
            if c.mahalanobis2(&x) < lambda2 {
                components.push(m as u32);
            }
        }
        offsets.push(components.len() as u32);
    }
    Gate {
        offsets,
        components,
    }
}

/// Per-component sums of one pass, shifted by a centre per component.
struct Moments {
    n: Vec<f64>,
    s1: Vec<Vector3<f64>>,
    s2: Vec<Matrix3<f64>>,
}

impl Moments {
    fn new(m: usize) -> Self {
        Self {
            n: vec![0.0; m],
            s1: vec![Vector3::zeros(); m],
            s2: vec![Matrix3::zeros(); m],
        }
    }
}

/// Factor every component; `None` if one is not positive definite.
fn factor(means: &[Vector3<f64>], covs: &[Matrix3<f64>]) -> Option<Vec<Chol3>> {
    means
        .iter()
        .zip(covs)
        .map(|(m, c)| Chol3::new(m, c))
        .collect()
}

/// Responsibilities of point `x` over its gated components into `out` (as
/// `(component, γ)`), returning `ln Σ_m π_m N(x | μ_m, Λ_m)` over those components.
fn responsibilities(
    x: &[f64; 3],
    comps: &[u32],
    chol: &[Chol3],
    log_weights: &[f64],
    buf: &mut Vec<f64>,
    out: &mut Vec<(usize, f64)>,
) -> f64 {
    buf.clear();
    buf.extend(comps.iter().map(|&m| {
        let c = &chol[m as usize];
        log_weights[m as usize] + c.log_norm - 0.5 * c.mahalanobis2(x)
    }));
    let lse = log_sum_exp(buf);
    out.clear();
    if lse.is_finite() {
        out.extend(
            comps
                .iter()
                .zip(buf.iter())
                .map(|(&m, l)| (m as usize, (l - lse).exp())),
        );
    }
    lse
}

/// The M-step of a hard partition: per component its point count, mean and
/// covariance (regularised by `reg_covar`).
fn partition_start(
    xyz: &[Vector3<f64>],
    assignment: &[u32],
    m: usize,
    reg_covar: f64,
) -> (Vec<f64>, Vec<Vector3<f64>>, Vec<Matrix3<f64>>) {
    let mut count = vec![0.0f64; m];
    let mut means = vec![Vector3::zeros(); m];
    for (p, &a) in xyz.iter().zip(assignment) {
        count[a as usize] += 1.0;
        means[a as usize] += p;
    }
    for (mean, c) in means.iter_mut().zip(&count) {
        *mean /= c.max(f64::MIN_POSITIVE);
    }
    let mut covs = vec![Matrix3::zeros(); m];
    for (p, &a) in xyz.iter().zip(assignment) {
        let d = p - means[a as usize];
        covs[a as usize] += d * d.transpose();
    }
    for (cov, c) in covs.iter_mut().zip(&count) {
        *cov /= c.max(f64::MIN_POSITIVE);
        *cov += Matrix3::identity() * reg_covar;
    }
    (count, means, covs)
}

/// EM over the `kept` points, each informing only its gated components, until the
/// mean log-likelihood changes by less than the tolerance or the iterations run out:
/// `(iterations, converged)`, `None` if a covariance stops being positive definite.
fn run_em(
    xyz: &[Vector3<f64>],
    kept: &[usize],
    gate: &Gate,
    means: &mut [Vector3<f64>],
    covs: &mut [Matrix3<f64>],
    weights: &mut [f64],
    config: &GatedEmConfig,
) -> Option<(usize, bool)> {
    let m = means.len();
    let n_kept = kept.len() as f64;
    let mut buf = Vec::with_capacity(m);
    let mut resp = Vec::with_capacity(m);
    let mut prev_ll = f64::NEG_INFINITY;
    let mut iterations = 0;
    for _ in 0..config.max_iterations {
        let chol = factor(means, covs)?;
        let log_weights: Vec<f64> = weights.iter().map(|w| w.ln()).collect();
        let mut mom = Moments::new(m);
        let mut ll = 0.0;
        for &i in kept {
            let p = &xyz[i];
            let x = [p[0], p[1], p[2]];
            ll += responsibilities(&x, gate.of(i), &chol, &log_weights, &mut buf, &mut resp);
            for &(k, r) in &resp {
                let d = p - means[k];
                mom.n[k] += r;
                mom.s1[k] += r * d;
                mom.s2[k] += r * d * d.transpose();
            }
        }
        iterations += 1;
        let ll = ll / n_kept;
        // M-step (shifted moments: Σ γ (x − c)(x − c)ᵀ / N − δ δᵀ with δ = Σ γ (x − c) / N).
        for k in 0..m {
            let nk = mom.n[k] + 10.0 * f64::EPSILON;
            let delta = mom.s1[k] / nk;
            means[k] += delta;
            let cov = mom.s2[k] / nk - delta * delta.transpose();
            covs[k] = 0.5 * (cov + cov.transpose()) + Matrix3::identity() * config.reg_covar;
            weights[k] = (mom.n[k] / n_kept).max(f64::MIN_POSITIVE);
        }
        if (ll - prev_ll).abs() < config.tolerance {
            return Some((iterations, true));
        }
        prev_ll = ll;
    }
    Some((iterations, false))
}

/// Fit `components` Gaussians to `points` (x, y, z in the first three coordinates; the
/// fourth, e.g. intensity, is carried into [`GatedFit::joint`] but not fitted): k-means++
/// seeding (steps 1a–1c, on x, y, z) → hard-partition start → gate (Eq. 3.3) → EM.
/// `None` when there are no points or `components == 0`. Deterministic for a given
/// `rng` state.
pub fn fit_gated_em<R: Rng + ?Sized>(
    points: &[Vector4<f64>],
    components: usize,
    rng: &mut R,
    config: &GatedEmConfig,
) -> Option<GatedFit> {
    if points.is_empty() || components == 0 {
        return None;
    }
    let flat: Vec<Vector4<f64>> = points
        .iter()
        .map(|p| Vector4::new(p[0], p[1], p[2], 0.0))
        .collect();
    let seeding = kmeans_plusplus(&flat, components.min(points.len()), rng);
    let m = seeding.centres.len().max(1);
    let xyz: Vec<Vector3<f64>> = points.iter().map(|p| p.xyz()).collect();

    // Start: the M-step of the hard partition.
    let (count, mut means, mut covs) =
        partition_start(&xyz, &seeding.assignment, m, config.reg_covar);
    let n_total = xyz.len() as f64;
    let mut weights: Vec<f64> = count.iter().map(|c| c / n_total).collect();

    let chol0 = factor(&means, &covs)?;
    let gate = gate(&xyz, &chol0, config.gate);
    let kept: Vec<usize> = (0..xyz.len()).filter(|&i| !gate.of(i).is_empty()).collect();
    if kept.is_empty() {
        return None;
    }
    let n_kept = kept.len() as f64;
    // Weights of the start restricted to the kept points.
    {
        let mut kept_count = vec![0.0f64; m];
        for &i in &kept {
            kept_count[seeding.assignment[i] as usize] += 1.0;
        }
        for (w, c) in weights.iter_mut().zip(&kept_count) {
            *w = (c / n_kept).max(f64::MIN_POSITIVE);
        }
    }

    let (iterations, converged) = run_em(
        &xyz,
        &kept,
        &gate,
        &mut means,
        &mut covs,
        &mut weights,
        config,
    )?;

    let mut buf = Vec::with_capacity(m);
    let mut resp = Vec::with_capacity(m);
    // Final pass: responsibility mass per component and the joint 4D moments.
    let chol = factor(&means, &covs)?;
    let log_weights: Vec<f64> = weights.iter().map(|w| w.ln()).collect();
    let g_centre = kept.iter().map(|&i| points[i][3]).sum::<f64>() / n_kept;
    let centres: Vec<Vector4<f64>> = means
        .iter()
        .map(|mu| Vector4::new(mu[0], mu[1], mu[2], g_centre))
        .collect();
    let mut n4 = vec![0.0f64; m];
    let mut s1 = vec![Vector4::zeros(); m];
    let mut s2 = vec![nalgebra::Matrix4::zeros(); m];
    for &i in &kept {
        let p = &xyz[i];
        responsibilities(
            &[p[0], p[1], p[2]],
            gate.of(i),
            &chol,
            &log_weights,
            &mut buf,
            &mut resp,
        );
        for &(k, r) in &resp {
            let d = points[i] - centres[k];
            n4[k] += r;
            s1[k] += r * d;
            s2[k] += r * d * d.transpose();
        }
    }
    let mut fit = GatedFit {
        weights: Vec::with_capacity(m),
        means: Vec::with_capacity(m),
        covariances: Vec::with_capacity(m),
        support: kept.len(),
        discarded: xyz.len() - kept.len(),
        iterations,
        converged,
        joint: Vec::with_capacity(m),
    };
    let total: f64 = (0..m)
        .filter(|&k| n4[k] >= config.min_component_points)
        .map(|k| n4[k])
        .sum();
    if total <= 0.0 {
        return None;
    }
    for k in 0..m {
        if n4[k] < config.min_component_points {
            continue;
        }
        let delta = s1[k] / n4[k];
        let mean4 = centres[k] + delta;
        let cov4 = s2[k] / n4[k] - delta * delta.transpose();
        let cov4 =
            0.5 * (cov4 + cov4.transpose()) + nalgebra::Matrix4::identity() * config.reg_covar;
        fit.weights.push(n4[k] / total);
        fit.means.push(mean4.xyz());
        fit.covariances
            .push(cov4.fixed_view::<3, 3>(0, 0).into_owned());
        fit.joint.push((mean4, cov4));
    }
    Some(fit)
}
