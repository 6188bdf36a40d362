//! Expectation–maximisation for a full-covariance 4D mixture in log space through
//! Cholesky factors (thesis App. A, Eqs. A.1–A.3).
//!
//! **E-step.** `ln γ_nb = ln π_b + ln N(x_n | μ_b, Σ_b) − ln Σ_a π_a N(x_n | μ_a, Σ_a)`
//! (Eq. A.2), with `ln N` from the lower Cholesky factor `L` (Eq. A.3, evaluated as
//! `|L⁻¹ (x − μ)|²` with `L⁻¹` formed once per iteration) and the last term by
//! log-sum-exp.
//!
//! **M-step.** `N_b = Σ_n γ_nb`, `π_b = N_b / N`, `μ_b = Σ γ x / N_b`,
//! `Σ_b = Σ γ (x − μ_b)(x − μ_b)ᵀ / N_b + ε I`. The sums are taken in one pass, centred
//! on the previous mean (shifted moments, stable because the mean moves little per
//! iteration). `ε = reg_covar` (default `1e-6`: a 1 mm / 0.001-intensity floor on the
//! standard deviations, as scikit-learn's default) keeps every covariance positive
//! definite; as in scikit-learn, `10 f64::EPSILON` is added to each `N_b`.
//!
//! **Convergence.** Stop when the mean log-likelihood of the points changes by less than
//! `tolerance` (default `1e-3` nats per point) between iterations, or after
//! `max_iterations` (default 100). The value compared is the one of the E-step, i.e. of
//! the parameters before that iteration's M-step (scikit-learn's convention).
//!
//! **Restricted E-step** ([`EStep::Restricted`], the default). A component `m` whose
//! joint log-density `ℓ_m(x) = ln π_m + ln N(x | μ_m, Σ_m)` is below
//! `max_b ℓ_b(x) − ln 10¹⁰` has responsibility below `1e-10` and is skipped. To find
//! the others without visiting all `M`: the spatial Mahalanobis distance lower-bounds the
//! 4D one (a marginal's quadratic form never exceeds the joint's), so
//! `ℓ_m(x) ≤ c_m − ½ d²_xyz,m(x)` with `c_m = ln π_m + ln N_max`, and `ℓ_m(x) ≥ T` is
//! only possible inside the ellipsoid `d²_xyz,m ≤ 2 (c_m − T)`, whose axis-aligned box
//! has half-widths `sqrt(2 (c_m − T) Σ_m,ii)`. Each iteration picks a threshold `T`
//! (the 0.5 % quantile of the points' "anchor" log-densities minus `ln 10¹⁰`; the anchor
//! of a point is its most responsible component of the previous iteration, or its
//! k-means++ centre at the start), lists every component in the grid cells its box
//! overlaps (then narrows each cell's list for the run of points in it, see
//! `run_blocks`), and evaluates a point on its run's list only when its anchor proves
//! `max_b ℓ_b(x) − ln 10¹⁰ ≥ ℓ_anchor(x) − ln 10¹⁰ ≥ T`; the other points
//! (about 0.5 %) are evaluated over all components. Every component left out therefore has
//! responsibility below `1e-10` relative to the best one, so each responsibility is
//! within `M · 1e-10` of the dense value and each point's log-likelihood within
//! `M · 1e-10` nats.
//!
//! Determinism: points are processed in a fixed order (sorted by grid cell) in fixed
//! chunks; each chunk accumulates its own sums, and the chunk sums are added in chunk
//! order, so the result does not depend on the number of rayon threads.

use std::ops::Range;

use nalgebra::{Matrix4, Vector4};
use rayon::prelude::*;

use super::SogmmError;
use super::grid::{CellLists, PointGrid};
use crate::mixture::{Gmm4, LN_2PI, MixtureError};

/// `ln 10¹⁰`: components below the best one by more than this are skipped by the
/// restricted E-step (responsibility < 1e-10 relative).
pub const LOG_TRUNCATION: f64 = 23.025_850_929_940_457;

/// Quantile of the anchor log-densities that sets the restricted E-step's threshold.
const ANCHOR_QUANTILE: f64 = 0.005;

/// Points per accumulation chunk (fixed: part of the summation order).
const CHUNK: usize = 2048;

/// Components per rayon task in the per-iteration work outside the pass (factoring,
/// summing the chunks); any value gives the same bits.
const COMPONENTS_PER_TASK: usize = 64;

/// Runs of points per rayon task when their candidate blocks are built; any value
/// gives the same blocks.
const RUNS_PER_TASK: usize = 128;

/// How the E-step visits components.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EStep {
    /// Every point against every component: the exact reference.
    Dense,
    /// Only the components that can reach responsibility 1e-10 relative to the best one
    /// (see the module doc).
    Restricted,
}

/// EM settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EmConfig {
    /// `ε` added to every covariance diagonal.
    pub reg_covar: f64,
    /// Convergence threshold on the change of the mean log-likelihood, nats per point.
    pub tolerance: f64,
    /// Iteration cap.
    pub max_iterations: usize,
    /// E-step variant.
    pub e_step: EStep,
}

impl Default for EmConfig {
    /// `reg_covar = 1e-6`, `tolerance = 1e-3`, `max_iterations = 100`, restricted E-step.
    fn default() -> Self {
        Self {
            reg_covar: 1e-6,
            tolerance: 1e-3,
            max_iterations: 100,
            e_step: EStep::Restricted,
        }
    }
}

/// What an EM run did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EmReport {
    /// Iterations (E-step + M-step pairs) run.
    pub iterations: usize,
    /// Whether the tolerance rule stopped the loop.
    pub converged: bool,
    /// Mean log-likelihood of the points at each E-step.
    pub log_likelihood_trace: Vec<f64>,
    /// Average number of components evaluated per point and iteration.
    pub mean_components_per_point: f64,
    /// Average number of components with a non-negligible responsibility per point and
    /// iteration (all of them for the dense E-step).
    pub mean_kept_per_point: f64,
    /// Point evaluations that fell back to all components (restricted E-step).
    pub dense_fallbacks: usize,
}

/// Mixture parameters during EM (unchecked; validated into a [`Gmm4`] at the end).
#[derive(Clone, Debug)]
struct Params {
    weights: Vec<f64>,
    means: Vec<Vector4<f64>>,
    covs: Vec<Matrix4<f64>>,
}

/// Per-chunk sums of the fused E/M pass.
struct Partial {
    n: Vec<f64>,
    s1: Vec<[f64; 4]>,
    s2: Vec<[f64; 10]>,
    ll: f64,
    evaluated: usize,
    kept: usize,
    fallbacks: usize,
}

impl Partial {
    fn new(m: usize) -> Self {
        Self {
            n: vec![0.0; m],
            s1: vec![[0.0; 4]; m],
            s2: vec![[0.0; 10]; m],
            ll: 0.0,
            evaluated: 0,
            kept: 0,
            fallbacks: 0,
        }
    }

    /// The sum of `parts` added in their order (so the same bits on any number of
    /// threads); the components are summed side by side.
    fn sum(parts: &[&Partial], m: usize) -> Self {
        let mut total = Partial::new(m);
        total
            .n
            .par_iter_mut()
            .zip(total.s1.par_iter_mut())
            .zip(total.s2.par_iter_mut())
            .enumerate()
            .with_min_len(COMPONENTS_PER_TASK)
            .for_each(|(k, ((n, s1), s2))| {
                for p in parts {
                    *n += p.n[k];
                    for (a, b) in s1.iter_mut().zip(&p.s1[k]) {
                        *a += b;
                    }
                    for (a, b) in s2.iter_mut().zip(&p.s2[k]) {
                        *a += b;
                    }
                }
            });
        for p in parts {
            total.ll += p.ll;
            total.evaluated += p.evaluated;
            total.kept += p.kept;
            total.fallbacks += p.fallbacks;
        }
        total
    }

    #[inline(always)]
    fn accumulate(&mut self, m: usize, r: f64, d: [f64; 4]) {
        self.n[m] += r;
        let s1 = &mut self.s1[m];
        let rd = [r * d[0], r * d[1], r * d[2], r * d[3]];
        for k in 0..4 {
            s1[k] += rd[k];
        }
        let s2 = &mut self.s2[m];
        s2[0] += rd[0] * d[0];
        s2[1] += rd[1] * d[0];
        s2[2] += rd[1] * d[1];
        s2[3] += rd[2] * d[0];
        s2[4] += rd[2] * d[1];
        s2[5] += rd[2] * d[2];
        s2[6] += rd[3] * d[0];
        s2[7] += rd[3] * d[1];
        s2[8] += rd[3] * d[2];
        s2[9] += rd[3] * d[3];
    }
}

/// One component as the E-step evaluates it: its mean, the inverse `U = L⁻¹` of the
/// lower Cholesky factor of its covariance (packed rows) and `c = ln π + ln N_max`, so
/// that `ℓ(x) = ln π + ln N(x | μ, Σ) = c − ½ |U (x − μ)|²` (Eq. A.3). The four rows of
/// `U (x − μ)` are independent products, unlike forward substitution through `L`.
#[derive(Clone, Copy, Debug)]
struct Whitened {
    mean: [f64; 4],
    u: [f64; 10],
    logc: f64,
}

impl Whitened {
    /// `None` if `cov` is not positive definite (or anything is not finite).
    fn new(weight: f64, mean: &Vector4<f64>, cov: &Matrix4<f64>) -> Option<Self> {
        if !cov.iter().all(|v| v.is_finite()) || !mean.iter().all(|v| v.is_finite()) {
            return None;
        }
        let l = cov.cholesky()?.l();
        let diag = [l[(0, 0)], l[(1, 1)], l[(2, 2)], l[(3, 3)]];
        if diag.iter().any(|d| !d.is_finite() || *d <= 0.0) {
            return None;
        }
        let u = l.solve_lower_triangular(&Matrix4::identity())?;
        if !u.iter().all(|v| v.is_finite()) {
            return None;
        }
        let log_det_half: f64 = diag.iter().map(|d| d.ln()).sum();
        Some(Self {
            mean: [mean[0], mean[1], mean[2], mean[3]],
            u: [
                u[(0, 0)],
                u[(1, 0)],
                u[(1, 1)],
                u[(2, 0)],
                u[(2, 1)],
                u[(2, 2)],
                u[(3, 0)],
                u[(3, 1)],
                u[(3, 2)],
                u[(3, 3)],
            ],
            logc: weight.ln() - 2.0 * LN_2PI - log_det_half,
        })
    }

    /// `ℓ(x) = c − ½ |U (x − μ)|²`.
    #[inline(always)]
    fn log_density(&self, x: &[f64; 4]) -> f64 {
        let u = &self.u;
        let d0 = x[0] - self.mean[0];
        let d1 = x[1] - self.mean[1];
        let d2 = x[2] - self.mean[2];
        let d3 = x[3] - self.mean[3];
        let y0 = u[0] * d0;
        let y1 = u[1] * d0 + u[2] * d1;
        let y2 = u[3] * d0 + u[4] * d1 + u[5] * d2;
        let y3 = u[6] * d0 + u[7] * d1 + u[8] * d2 + u[9] * d3;
        self.logc - 0.5 * (y0 * y0 + y1 * y1 + y2 * y2 + y3 * y3)
    }
}

/// Every component's [`Whitened`] form, side by side; the error names the first
/// component (in index order) whose covariance is not positive definite.
fn factor(params: &Params) -> Result<Vec<Whitened>, SogmmError> {
    let factored: Vec<Option<Whitened>> = (0..params.weights.len())
        .into_par_iter()
        .with_min_len(COMPONENTS_PER_TASK)
        .map(|k| Whitened::new(params.weights[k], &params.means[k], &params.covs[k]))
        .collect();
    factored
        .into_iter()
        .enumerate()
        .map(|(component, w)| {
            w.ok_or(SogmmError::Mixture(MixtureError::NotPositiveDefinite {
                component,
            }))
        })
        .collect()
}

/// M-step from hard labels: the starting mixture of EM after k-means++ (KInit, Fig. 6.1).
/// `assignment[i] < m` is the cluster of point `i`; covariances get `+ reg_covar · I`.
pub fn init_from_partition(
    points: &[Vector4<f64>],
    assignment: &[u32],
    m: usize,
    reg_covar: f64,
) -> Result<Gmm4, SogmmError> {
    if points.is_empty() || m == 0 {
        return Err(SogmmError::TooFewPoints {
            points: points.len(),
            needed: 1,
        });
    }
    let mut count = vec![0.0f64; m];
    let mut sum = vec![Vector4::zeros(); m];
    for (p, &a) in points.iter().zip(assignment) {
        let a = a as usize;
        if a >= m {
            return Err(SogmmError::InvalidInput("assignment out of range"));
        }
        count[a] += 1.0;
        sum[a] += p;
    }
    let means: Vec<Vector4<f64>> = sum
        .iter()
        .zip(&count)
        .map(|(s, c)| s / (c + 10.0 * f64::EPSILON))
        .collect();
    let mut covs = vec![Matrix4::zeros(); m];
    for (p, &a) in points.iter().zip(assignment) {
        let d = p - means[a as usize];
        covs[a as usize] += d * d.transpose();
    }
    let n = points.len() as f64;
    for (cov, c) in covs.iter_mut().zip(&count) {
        *cov /= c + 10.0 * f64::EPSILON;
        *cov += Matrix4::identity() * reg_covar;
    }
    let mut weights: Vec<f64> = count.iter().map(|c| c / n).collect();
    let total: f64 = weights.iter().sum();
    weights.iter_mut().for_each(|w| *w /= total);
    Ok(Gmm4::new(weights, means, covs)?)
}

/// Run EM from `init` on `points` (see the module doc for the E-step variants, the
/// regularisation and the convergence rule). Deterministic.
pub fn fit_em(
    points: &[Vector4<f64>],
    init: &Gmm4,
    config: &EmConfig,
) -> Result<(Gmm4, EmReport), SogmmError> {
    fit_em_anchored(points, init, None, config)
}

/// [`fit_em`] with the starting anchor of every point given (e.g. its k-means++ cluster;
/// any component is valid, see the module doc); `None` uses the nearest mean in 4D.
pub(crate) fn fit_em_anchored(
    points: &[Vector4<f64>],
    init: &Gmm4,
    anchors: Option<&[u32]>,
    config: &EmConfig,
) -> Result<(Gmm4, EmReport), SogmmError> {
    if points.is_empty() {
        return Err(SogmmError::TooFewPoints {
            points: 0,
            needed: 1,
        });
    }
    let m = init.len();
    let mut params = Params {
        weights: init.weights().to_vec(),
        means: init.means().to_vec(),
        covs: init.covariances().to_vec(),
    };
    let (grid, order) = sorted_grid(points, init);
    let xs: Vec<[f64; 4]> = order
        .iter()
        .map(|&i| {
            let p = points[i as usize];
            [p[0], p[1], p[2], p[3]]
        })
        .collect();
    let cells: Vec<u32> = order.iter().map(|&i| grid.point_cell[i as usize]).collect();
    let runs = cell_runs(&xs, &cells);
    let mut anchors: Vec<u32> = match anchors {
        Some(a) if a.len() == points.len() && a.iter().all(|&k| (k as usize) < m) => {
            order.iter().map(|&i| a[i as usize]).collect()
        }
        _ => nearest_means(&xs, init.means()),
    };

    let mut report = EmReport::default();
    let mut prev_ll = f64::NEG_INFINITY;
    let mut evaluated_total = 0usize;
    let mut kept_total = 0usize;
    for _ in 0..config.max_iterations {
        let comps = factor(&params)?;
        let (blocks, anchor_ll, threshold) = match config.e_step {
            EStep::Dense => (None, vec![], f64::NEG_INFINITY),
            EStep::Restricted => {
                let anchor_ll: Vec<f64> = xs
                    .par_iter()
                    .zip(&anchors)
                    .map(|(x, &a)| comps[a as usize].log_density(x))
                    .collect();
                let threshold = quantile(&anchor_ll, ANCHOR_QUANTILE) - LOG_TRUNCATION;
                let boxes: Vec<Option<([f64; 3], [f64; 3])>> = (0..m)
                    .map(|k| reach_box(&params.means[k], &params.covs[k], comps[k].logc, threshold))
                    .collect();
                let lists = grid.component_lists(&boxes);
                let blocks = run_blocks(&runs, &lists, &anchor_ll, threshold, &params, &comps);
                (Some(blocks), anchor_ll, threshold)
            }
        };
        let all = Blocks::new(&comps, vec![0, m], (0..m as u32).collect());
        let ctx = PassCtx {
            xs: &xs,
            all: &all,
            runs: &runs,
            means: &params.means,
            blocks: blocks.as_ref(),
            anchor_ll: &anchor_ll,
            threshold,
        };
        let (total, new_anchors) = fused_pass(&ctx, m);
        anchors = new_anchors;
        let ll = total.ll / xs.len() as f64;
        report.log_likelihood_trace.push(ll);
        report.iterations += 1;
        evaluated_total += total.evaluated;
        kept_total += total.kept;
        report.dense_fallbacks += total.fallbacks;
        m_step(&mut params, &total, xs.len(), config.reg_covar);
        if (ll - prev_ll).abs() < config.tolerance {
            report.converged = true;
            break;
        }
        prev_ll = ll;
    }
    let denom = (xs.len() * report.iterations.max(1)) as f64;
    report.mean_components_per_point = evaluated_total as f64 / denom;
    report.mean_kept_per_point = kept_total as f64 / denom;
    let total_w: f64 = params.weights.iter().sum();
    params.weights.iter_mut().for_each(|w| *w /= total_w);
    let gmm = Gmm4::new(params.weights, params.means, params.covs)?;
    Ok((gmm, report))
}

/// Grid over the spatial part of the points (cell side from the starting model) and the
/// processing order: points sorted by cell, stable.
fn sorted_grid(points: &[Vector4<f64>], init: &Gmm4) -> (PointGrid, Vec<u32>) {
    let xyz: Vec<[f64; 3]> = points.iter().map(|p| [p[0], p[1], p[2]]).collect();
    // Cell side: 1.5 × the median over components of the 3σ half-width along the widest
    // axis; clamped to [extent/512, extent/8]. Larger cells hold more components that do
    // not matter, smaller ones cost more lists; 1.5 was the fastest of 0.5–3 on the
    // 160×120 room frame at σ = 0.02. The side does not change which components are
    // kept, only the order in which points are summed (so the last bits of a fit).
    let mut widths: Vec<f64> = init
        .covariances()
        .iter()
        .map(|c| 3.0 * c[(0, 0)].max(c[(1, 1)]).max(c[(2, 2)]).sqrt())
        .collect();
    let median = if widths.is_empty() {
        1.0
    } else {
        quantile(&widths.split_off(0), 0.5)
    };
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in &xyz {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let extent = (0..3)
        .map(|a| hi[a] - lo[a])
        .fold(0.0f64, f64::max)
        .max(1e-6);
    let h = (1.5 * median).clamp(extent / 512.0, extent / 8.0);
    let grid = PointGrid::new(&xyz, h);
    let mut order: Vec<u32> = (0..points.len() as u32).collect();
    order.sort_by_key(|&i| grid.point_cell[i as usize]);
    (grid, order)
}

fn nearest_means(xs: &[[f64; 4]], means: &[Vector4<f64>]) -> Vec<u32> {
    xs.par_chunks(CHUNK)
        .flat_map_iter(|chunk| {
            chunk
                .iter()
                .map(|x| {
                    let mut best = (f64::INFINITY, 0u32);
                    for (k, mu) in means.iter().enumerate() {
                        let d: f64 = (0..4).map(|a| (x[a] - mu[a]).powi(2)).sum();
                        if d < best.0 {
                            best = (d, k as u32);
                        }
                    }
                    best.1
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

/// The `q`-quantile (nearest rank, lower) of finite values; `−∞` if there are none.
fn quantile(values: &[f64], q: f64) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return f64::NEG_INFINITY;
    }
    let k = ((v.len() - 1) as f64 * q).floor() as usize;
    let (_, kth, _) = v.select_nth_unstable_by(k, f64::total_cmp);
    *kth
}

/// Axis-aligned box of the spatial ellipsoid where `ℓ_m` can reach `threshold`
/// (half-widths `sqrt(2 (c_m − T) Σ_ii)`); `None` if `c_m ≤ T` (never reaches it).
fn reach_box(
    mean: &Vector4<f64>,
    cov: &Matrix4<f64>,
    logc: f64,
    threshold: f64,
) -> Option<([f64; 3], [f64; 3])> {
    let k2 = 2.0 * (logc - threshold);
    if k2.is_nan() || k2 <= 0.0 {
        return None;
    }
    let mut lo = [0.0; 3];
    let mut hi = [0.0; 3];
    for a in 0..3 {
        let r = (k2 * cov[(a, a)]).sqrt();
        lo[a] = mean[a] - r;
        hi[a] = mean[a] + r;
    }
    Some((lo, hi))
}

struct PassCtx<'a> {
    xs: &'a [[f64; 4]],
    /// Every component, for the dense E-step and the fallback points.
    all: &'a Blocks,
    runs: &'a [Run],
    means: &'a [Vector4<f64>],
    /// One block per run of [`Self::runs`] (restricted E-step).
    blocks: Option<&'a Blocks>,
    anchor_ll: &'a [f64],
    threshold: f64,
}

/// E-step and M-step sums in one pass over the points, chunked; chunk sums added in
/// chunk order. Returns the totals and each point's most responsible component.
fn fused_pass(ctx: &PassCtx<'_>, m: usize) -> (Partial, Vec<u32>) {
    let n = ctx.xs.len();
    let arch = pulp::Arch::new();
    let chunks: Vec<(Partial, Vec<u32>)> = (0..n.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            let range = c * CHUNK..((c + 1) * CHUNK).min(n);
            arch.dispatch(ChunkPass { ctx, m, range })
        })
        .collect();
    let parts: Vec<&Partial> = chunks.iter().map(|(p, _)| p).collect();
    let total = Partial::sum(&parts, m);
    let anchors = chunks.iter().flat_map(|(_, a)| a.iter().copied()).collect();
    (total, anchors)
}

/// A run of sorted points that share a grid cell, with the box of their positions.
struct Run {
    points: Range<usize>,
    cell: u32,
    lo: [f64; 3],
    hi: [f64; 3],
}

/// The runs of equal cells in the sorted points.
fn cell_runs(xs: &[[f64; 4]], cells: &[u32]) -> Vec<Run> {
    let mut runs = Vec::new();
    let mut start = 0;
    for i in 1..=cells.len() {
        if i == cells.len() || cells[i] != cells[start] {
            let mut lo = [f64::INFINITY; 3];
            let mut hi = [f64::NEG_INFINITY; 3];
            for x in &xs[start..i] {
                for a in 0..3 {
                    lo[a] = lo[a].min(x[a]);
                    hi[a] = hi[a].max(x[a]);
                }
            }
            runs.push(Run {
                points: start..i,
                cell: cells[start],
                lo,
                hi,
            });
            start = i;
        }
    }
    runs
}

/// One block of candidate components per run: the run's cell list, narrowed to the
/// components that can reach the run's own threshold
/// `T_r = max(T, min_run (ℓ_anchor − ln 10¹⁰))` somewhere in the box of the run's
/// points: per axis, the gap `g` from the mean to the box must satisfy
/// `g² ≤ 2 (c_m − T_r) Σ_m,aa` (the reach box of the module doc, with a relative slack
/// of 1e-9 against rounding). Every point of the run that is not a fallback has
/// `max_b ℓ_b − ln 10¹⁰ ≥ T_r`, so a component left out is below its cut exactly as
/// with the cell's list: the kept components, their order and so the fit are the same.
fn run_blocks(
    runs: &[Run],
    lists: &CellLists,
    anchor_ll: &[f64],
    threshold: f64,
    params: &Params,
    comps: &[Whitened],
) -> Blocks {
    let narrowed: Vec<(Vec<u32>, Vec<usize>)> = runs
        .par_chunks(RUNS_PER_TASK)
        .map(|chunk| {
            let mut ids: Vec<u32> = Vec::new();
            let mut ends = Vec::with_capacity(chunk.len());
            for run in chunk {
                let t_run = anchor_ll[run.points.clone()]
                    .iter()
                    .fold(f64::INFINITY, |t, &l| t.min(l - LOG_TRUNCATION))
                    .max(threshold);
                ids.extend(lists.get(run.cell).iter().copied().filter(|&k| {
                    let k = k as usize;
                    let k2 = 2.0 * (comps[k].logc - t_run) * (1.0 + 1e-9);
                    let (mean, cov) = (&params.means[k], &params.covs[k]);
                    k2 > 0.0
                        && (0..3).all(|a| {
                            let g = (run.lo[a] - mean[a]).max(mean[a] - run.hi[a]).max(0.0);
                            g * g <= k2 * cov[(a, a)]
                        })
                }));
                ends.push(ids.len());
            }
            (ids, ends)
        })
        .collect();
    let mut start = Vec::with_capacity(runs.len() + 1);
    start.push(0);
    let mut ids: Vec<u32> = Vec::with_capacity(narrowed.iter().map(|(i, _)| i.len()).sum());
    for (chunk_ids, ends) in &narrowed {
        let offset = ids.len();
        start.extend(ends.iter().map(|e| offset + e));
        ids.extend_from_slice(chunk_ids);
    }
    Blocks::new(comps, start, ids)
}

/// Blocks of components in structure-of-arrays layout (one slice per parameter, blocks
/// one after another), so that [`Blocks::eval`] runs the arithmetic of
/// [`Whitened::log_density`] over a block in a loop the compiler vectorises, with the
/// same result bit for bit (no reassociation, no fused multiply-add).
struct Blocks {
    /// Block `b` is `start[b]..start[b + 1]`.
    start: Vec<usize>,
    ids: Vec<u32>,
    mean: [Vec<f64>; 4],
    u: [Vec<f64>; 10],
    logc: Vec<f64>,
}

impl Blocks {
    /// Blocks `start[b]..start[b + 1]` of the components `ids` (in that order).
    fn new(comps: &[Whitened], start: Vec<usize>, ids: Vec<u32>) -> Self {
        let n = ids.len();
        let mut mean: [Vec<f64>; 4] = std::array::from_fn(|_| Vec::with_capacity(n));
        let mut u: [Vec<f64>; 10] = std::array::from_fn(|_| Vec::with_capacity(n));
        let mut logc = Vec::with_capacity(n);
        for &k in &ids {
            let c = &comps[k as usize];
            for (v, x) in mean.iter_mut().zip(c.mean) {
                v.push(x);
            }
            for (v, x) in u.iter_mut().zip(c.u) {
                v.push(x);
            }
            logc.push(c.logc);
        }
        Self {
            start,
            ids,
            mean,
            u,
            logc,
        }
    }

    /// The component ids of block `b`.
    #[inline(always)]
    fn ids(&self, b: usize) -> &[u32] {
        &self.ids[self.start[b]..self.start[b + 1]]
    }

    /// `out[j] = ℓ_{ids[j]}(x)` over block `b`, exactly as [`Whitened::log_density`].
    #[inline(always)]
    fn eval(&self, b: usize, x: &[f64; 4], out: &mut Vec<f64>) {
        let r = self.start[b]..self.start[b + 1];
        let k = r.len();
        out.clear();
        out.resize(k, 0.0);
        let out = &mut out[..k];
        let m: [&[f64]; 4] = std::array::from_fn(|i| &self.mean[i][r.clone()]);
        let u: [&[f64]; 10] = std::array::from_fn(|i| &self.u[i][r.clone()]);
        let logc = &self.logc[r];
        for j in 0..k {
            let d0 = x[0] - m[0][j];
            let d1 = x[1] - m[1][j];
            let d2 = x[2] - m[2][j];
            let d3 = x[3] - m[3][j];
            let y0 = u[0][j] * d0;
            let y1 = u[1][j] * d0 + u[2][j] * d1;
            let y2 = u[3][j] * d0 + u[4][j] * d1 + u[5][j] * d2;
            let y3 = u[6][j] * d0 + u[7][j] * d1 + u[8][j] * d2 + u[9][j] * d3;
            out[j] = logc[j] - 0.5 * (y0 * y0 + y1 * y1 + y2 * y2 + y3 * y3);
        }
    }
}

/// [`chunk_pass`] compiled for the widest vector instructions the processor has (pulp's
/// runtime dispatch: AVX2 where present, else the baseline). The arithmetic is the same
/// in every version (Rust neither reassociates nor fuses floating-point operations), so
/// the fit is bit-identical on any of them.
struct ChunkPass<'a, 'b> {
    ctx: &'a PassCtx<'b>,
    m: usize,
    range: Range<usize>,
}

impl pulp::WithSimd for ChunkPass<'_, '_> {
    type Output = (Partial, Vec<u32>);

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> Self::Output {
        chunk_pass(self.ctx, self.m, self.range)
    }
}

#[inline(always)]
fn chunk_pass(ctx: &PassCtx<'_>, m: usize, range: Range<usize>) -> (Partial, Vec<u32>) {
    let mut part = Partial::new(m);
    let mut anchors = Vec::with_capacity(range.len());
    let mut lls: Vec<f64> = Vec::with_capacity(m);
    // ℓ − max, then exp(ℓ − max), and the ids of the kept components; apart from `lls`
    // so that the compaction's stores never alias its loads.
    let mut es: Vec<f64> = vec![0.0; m];
    let mut kept_ids: Vec<u32> = vec![0; m];
    let mut log_sum = LogSum::default();
    // The run of the chunk's first point; runs are in point order.
    let mut run = ctx.runs.partition_point(|r| r.points.end <= range.start);
    for i in range {
        while ctx.runs[run].points.end <= i {
            run += 1;
        }
        let x = &ctx.xs[i];
        let (blocks, b, truncate) = match ctx.blocks {
            None => (ctx.all, 0, false),
            Some(blocks) => {
                if ctx.anchor_ll[i] - LOG_TRUNCATION >= ctx.threshold {
                    (blocks, run, true)
                } else {
                    part.fallbacks += 1;
                    (ctx.all, 0, true)
                }
            }
        };
        let ids = blocks.ids(b);
        part.evaluated += ids.len();
        blocks.eval(b, x, &mut lls);
        let (max, arg) = max_first(&lls);
        let cut = if truncate {
            max - LOG_TRUNCATION
        } else {
            f64::NEG_INFINITY
        };
        // Keep ℓ − max of the components at or above the cut (in block order, without
        // branches), then one exponential each: e = exp(ℓ − max), γ = e / Σ e.
        let kept = keep_at_or_above(&lls, ids, max, cut, &mut es, &mut kept_ids);
        let es = &mut es[..kept];
        for e in es.iter_mut() {
            *e = exp_nonpositive(*e);
        }
        let s: f64 = es.iter().sum();
        part.ll += max;
        log_sum.push(s);
        part.kept += kept;
        anchors.push(ids[arg]);
        let inv_s = 1.0 / s;
        for (&k, &e) in kept_ids.iter().zip(es.iter()) {
            let r = e * inv_s;
            let mu = &ctx.means[k as usize];
            let d = [x[0] - mu[0], x[1] - mu[1], x[2] - mu[2], x[3] - mu[3]];
            part.accumulate(k as usize, r, d);
        }
    }
    // Σ (max + ln Σ e) over the points: the maxima above, the logarithms here.
    part.ll += log_sum.ln();
    (part, anchors)
}

/// Writes `ℓ − max` and the id of every value of `lls` at or above `cut` to the front
/// of `es` and `kept_ids` (in order; both at least as long as `lls`) and returns how
/// many. Branch-free: every value is written, and the count advances only past the kept.
#[inline(always)]
fn keep_at_or_above(
    lls: &[f64],
    ids: &[u32],
    max: f64,
    cut: f64,
    es: &mut [f64],
    kept_ids: &mut [u32],
) -> usize {
    let n = lls.len();
    let (ids, es, kept_ids) = (&ids[..n], &mut es[..n], &mut kept_ids[..n]);
    let mut kept = 0;
    for j in 0..n {
        let l = lls[j];
        // kept ≤ j < n
        es[kept] = l - max;
        kept_ids[kept] = ids[j];
        kept += usize::from(l >= cut);
    }
    kept
}

/// `Σ ln sᵢ` of values `sᵢ ≥ 1` with one logarithm: their product, kept as a mantissa
/// in `[1, 2)` (rescaled by a power of two after every factor, which is exact) and a
/// sum of binary exponents. The product rounds once per factor (relative error below
/// `n · 2⁻⁵³` for `n` factors), so the sum is within `n · 1.1·10⁻¹⁶` nats of the sum of
/// the logarithms. A value outside the normal positive range a product can take (a
/// degenerate point: 0, subnormal, huge, infinite or NaN) adds its own logarithm
/// instead, as a sum of logarithms would.
pub(crate) struct LogSum {
    mantissa: f64,
    exponent: i64,
    degenerate: f64,
}

impl Default for LogSum {
    /// The empty sum: the product 1.
    fn default() -> Self {
        Self {
            mantissa: 1.0,
            exponent: 0,
            degenerate: 0.0,
        }
    }
}

impl LogSum {
    const EXPONENT_MASK: u64 = 0x7ff << 52;

    #[inline(always)]
    pub(crate) fn push(&mut self, s: f64) {
        if !(s.is_normal() && s > 0.0 && s < f64::MAX / 2.0) {
            self.degenerate += s.ln();
            return;
        }
        let product = self.mantissa * s;
        let bits = product.to_bits();
        self.exponent += ((bits & Self::EXPONENT_MASK) >> 52) as i64 - 1023;
        self.mantissa = f64::from_bits((bits & !Self::EXPONENT_MASK) | (1023 << 52));
    }

    pub(crate) fn ln(&self) -> f64 {
        self.mantissa.ln() + self.exponent as f64 * std::f64::consts::LN_2 + self.degenerate
    }
}

/// The largest value and the first index holding it (`(−∞, 0)` if empty); values must
/// not be NaN. Four running maxima with the index of each lane's first maximum, so that
/// the loop vectorises; the index is then the smallest among the lanes that hold the
/// maximum, as a left-to-right scan with `>` would pick.
#[inline(always)]
pub(crate) fn max_first(values: &[f64]) -> (f64, usize) {
    let mut acc = [f64::NEG_INFINITY; 4];
    let mut at = [0u64; 4];
    let quads = values.chunks_exact(4);
    let rest = quads.remainder();
    for (q, quad) in quads.enumerate() {
        for t in 0..4 {
            let better = quad[t] > acc[t];
            acc[t] = if better { quad[t] } else { acc[t] };
            at[t] = if better { (4 * q + t) as u64 } else { at[t] };
        }
    }
    // All −∞ (or none): the first index.
    let (mut max, mut arg) = (f64::NEG_INFINITY, 0);
    for t in 0..4 {
        if acc[t] > max || (acc[t] == max && (at[t] as usize) < arg) {
            (max, arg) = (acc[t], at[t] as usize);
        }
    }
    let base = values.len() - rest.len();
    for (j, &v) in rest.iter().enumerate() {
        if v > max {
            (max, arg) = (v, base + j);
        }
    }
    (max, arg)
}

/// `eˣ` for `x ≤ 0`, to within a few units in the last place (0 below −708, where `eˣ`
/// underflows): `x = k ln 2 + r` with `|r| ≤ ½ ln 2` (Cody–Waite, `ln 2` in two parts),
/// `eʳ` by its Taylor polynomial to degree 12 (truncation below 3·10⁻¹⁶ relative),
/// `2ᵏ` from the exponent bits. Branch-free, so a loop over it vectorises, and the same
/// bits on every processor and C library (unlike `f64::exp`).
#[inline(always)]
pub(crate) fn exp_nonpositive(x: f64) -> f64 {
    const SHIFTER: f64 = 6_755_399_441_055_744.0; // 1.5 · 2⁵²: adding it rounds to an integer
    const LN2_HI: f64 = 6.931_471_803_691_238e-1; // 32 significant bits: k · LN2_HI is exact
    const LN2_LO: f64 = 1.908_214_929_270_587_7e-10;
    let xc = if x >= -708.0 { x } else { -708.0 };
    let t = xc * std::f64::consts::LOG2_E + SHIFTER;
    let k = t - SHIFTER;
    let r = (xc - k * LN2_HI) - k * LN2_LO;
    let mut p = 1.0 / 479_001_600.0; // 1/12!
    for c in [
        1.0 / 39_916_800.0,
        1.0 / 3_628_800.0,
        1.0 / 362_880.0,
        1.0 / 40_320.0,
        1.0 / 5_040.0,
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        0.5,
        1.0,
        1.0,
    ] {
        p = p * r + c;
    }
    // t's low bits hold k (two's complement): 2ᵏ has biased exponent k + 1023.
    let scale = f64::from_bits(
        t.to_bits()
            .wrapping_sub(SHIFTER.to_bits())
            .wrapping_add(1023)
            << 52,
    );
    if x >= -708.0 { p * scale } else { 0.0 }
}

fn m_step(params: &mut Params, total: &Partial, n_points: usize, reg: f64) {
    let n = n_points as f64;
    for k in 0..params.weights.len() {
        let nk = total.n[k] + 10.0 * f64::EPSILON;
        let d = Vector4::new(
            total.s1[k][0],
            total.s1[k][1],
            total.s1[k][2],
            total.s1[k][3],
        ) / nk;
        let s = &total.s2[k];
        let mut cov = Matrix4::new(
            s[0], s[1], s[3], s[6], //
            s[1], s[2], s[4], s[7], //
            s[3], s[4], s[5], s[8], //
            s[6], s[7], s[8], s[9],
        ) / nk;
        cov -= d * d.transpose();
        for a in 0..4 {
            cov[(a, a)] += reg;
        }
        params.means[k] += d;
        params.covs[k] = cov;
        params.weights[k] = nk / n;
    }
}
