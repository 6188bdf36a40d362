//! Distance between two ellipsoids (thesis Proposition 1, Eqs. 7.2–7.5) and its
//! approximate gradient (Eq. 7.7), in 2D and 3D.
//!
//! An ellipsoid is `E(b, B) = {x : (x − b)ᵀ B (x − b) ≤ 1}` with `B ≻ 0` (§7.1.1);
//! `E₁(b, B)` is the robot and `E₂(c, C)` a surface ellipsoid.
//!
//! # From the 2q × 2q eigenproblems to two secular equations
//!
//! Proposition 1 takes `λ`, the minimal eigenvalue of
//! `M₁ = [[C̃, −I], [−c̃c̃ᵀ, C̃]]` with `C̃ = B^{1/2} C⁻¹ B^{1/2}` and
//! `c̃ = C̃^{1/2} B^{1/2}(c − b)` (Eq. 7.2: `B^{-1/2}Q̂Λ_Q^{1/2}Q̂ᵀ = B^{-1/2} C̃^{-1/2}`),
//! then `μ`, the minimal eigenvalue of `M₂ = [[B⁻¹, −I], [−b̃b̃ᵀ, B⁻¹]]`. `M₁` and `M₂`
//! are not symmetric, but their spectra follow from the symmetric diagonal block:
//!
//! 1. `M₁ (x₁, x₂) = λ (x₁, x₂)` gives `x₂ = (C̃ − λI)x₁` and
//!    `(C̃ − λI)² x₁ = c̃ (c̃ᵀx₁)`, so for `λ` outside the spectrum of `C̃`,
//!    `det(M₁ − λI) = det(C̃ − λI)² · (1 − c̃ᵀ(C̃ − λI)⁻² c̃)`.
//! 2. With `C̃ = V diag(γ) Vᵀ` (γ ascending, the only eigen solve per pair, q × q) and
//!    `ĉ = Vᵀc̃`, i.e. `ĉᵢ = √γᵢ (Vᵀ c′)ᵢ` with `c′ = B^{1/2}(c − b)`, the real
//!    eigenvalues are the roots of the secular equation `Σᵢ ĉᵢ² / (γᵢ − λ)² = 1`.
//!    Left of `γ₁` the left side rises from 0 to ∞, so it has exactly one root there;
//!    that is the minimal eigenvalue (the dense reference in the tests confirms that no
//!    complex eigenvalue has a smaller real part). At `λ = 0` the left side equals
//!    `(c − b)ᵀ C (c − b)`, so `λ < 0` exactly when `b` lies outside `E₂`
//!    (\[157, Thm. 2\]); otherwise the robot centre is inside the surface ellipsoid and
//!    the pair collides.
//! 3. Write `s = −λ > 0`. Then `F(s) = Σ ĉᵢ²/(γᵢ + s)²` decreases and
//!    `ψ(s) = F(s)^{-1/2} − 1` is increasing and concave (it is the trust-region secular
//!    function of Moré and Sorensen), so Newton's method from a point left of the root
//!    climbs monotonically to it. The root lies in
//!    `[max(0, maxᵢ(|ĉᵢ| − γᵢ), ‖ĉ‖ − γ_q), ‖ĉ‖ − γ₁]`; Newton starts at the left end and
//!    every step is kept inside the bracket, bisecting if a step leaves it
//!    ([`secular_root`]).
//! 4. In the scaled frame `u = B^{1/2}(x − b)` the robot is the unit ball and the point
//!    of `E₂` closest in the robot's metric is `u* = s (C̃ + sI)⁻¹ c′`. Back in the world
//!    frame `y* = b + B^{-1/2}u* = b + λα` (α of Eq. 7.3).
//! 5. `M₂` has the same structure with `C̃ → B⁻¹` (eigenbasis `B̂`, eigenvalues `aᵢ²`,
//!    the squared semi-axes, known since initialisation) and `c̃ → b̃ = B^{-1/2}(y* − b)`,
//!    whose coordinates are `aᵢ p̂ᵢ` with `p̂ = B̂ᵀ(y* − b)`. Its root `ν = −μ` is the
//!    multiplier of the projection of `y*` onto `E₁`, and Eq. 7.5 becomes, per axis,
//!    `d*ᵢ = −ν p̂ᵢ / (aᵢ² + ν)`: the vector from `y*` to its closest point on `E₁`.
//!
//! So a pair costs one q × q symmetric eigen solve (of `C̃`) and two scalar root finds;
//! no 2q × 2q eigenproblem, inverse or matrix square root of a full matrix is formed.
//!
//! # When the estimate is exact
//!
//! Eq. 7.4 is the distance from `y*`, the point of `E₂` nearest to `b` *in the metric of
//! `B`*, to `E₁`. Since `y* ∈ E₂`, it is never below the true distance. It equals the
//! true distance when `y*` is the true closest point: when the robot is a ball (the
//! `B`-metric is Euclidean), when `E₂` shrinks to a point (the limit of §7.1.3 where
//! every point has its own component), and in symmetric configurations; for nearly
//! touching pairs the gap vanishes to first order. Likewise Eq. 7.7 is the exact gradient
//! of the distance in those cases, and an approximation otherwise.

use nalgebra::{SMatrix, SVector};

/// A 2D ellipse.
pub type Ellipsoid2 = Ellipsoid<2>;
/// A 3D ellipsoid.
pub type Ellipsoid3 = Ellipsoid<3>;
/// Proximity of a 2D pair.
pub type Proximity2 = Proximity<2>;
/// Proximity of a 3D pair.
pub type Proximity3 = Proximity<3>;

/// A solid ellipsoid `E(c, C) = {x : (x − c)ᵀ C (x − c) ≤ 1}` in `D` dimensions
/// (§7.1.1), stored with the per-ellipsoid quantities that Proposition 1 caches at
/// initialisation (§7.2.1): the eigen decomposition `C = Ĉ Λ_C Ĉᵀ` (as principal axes
/// and semi-axes `aᵢ = Λᵢ^{-1/2}`), `C^{1/2}` and `C⁻¹`.
///
/// The eigenpairs are ordered by decreasing semi-axis, so the last principal axis is the
/// eigenvector of the minimum eigenvalue of the shape matrix `C⁻¹` (the surface normal
/// of a flat surface ellipsoid, §7.1.4).
#[derive(Clone, Debug, PartialEq)]
pub struct Ellipsoid<const D: usize> {
    center: SVector<f64, D>,
    axes: SMatrix<f64, D, D>,
    semi_axes: SVector<f64, D>,
    shape_sqrt: SMatrix<f64, D, D>,
    shape_inv: SMatrix<f64, D, D>,
}

impl<const D: usize> Ellipsoid<D> {
    /// Builds an ellipsoid from its centre, principal axes (orthonormal columns) and
    /// semi-axis lengths, i.e. `C = R diag(a)⁻² Rᵀ` (§7.1.1).
    ///
    /// Returns `None` when a value is not finite, a semi-axis is not positive, or the
    /// columns of `axes` are not orthonormal to 1e-9.
    #[must_use]
    pub fn from_axes(
        center: SVector<f64, D>,
        axes: SMatrix<f64, D, D>,
        semi_axes: SVector<f64, D>,
    ) -> Option<Self> {
        let orthonormal =
            (axes.transpose() * axes - SMatrix::<f64, D, D>::identity()).amax() <= 1e-9;
        if !orthonormal || !all_finite(center.as_slice()) || !all_finite(axes.as_slice()) {
            return None;
        }
        if !semi_axes.iter().all(|&a| positive(a)) {
            return None;
        }
        let mut order: [usize; D] = std::array::from_fn(|i| i);
        order.sort_by(|&i, &j| semi_axes[j].total_cmp(&semi_axes[i]));
        let axes = SMatrix::<f64, D, D>::from_fn(|r, c| axes[(r, order[c])]);
        let semi_axes = SVector::<f64, D>::from_fn(|i, _| semi_axes[order[i]]);
        Some(Self::from_sorted_parts(center, axes, semi_axes))
    }

    /// Builds an ellipsoid from its centre and shape matrix `C` (symmetric positive
    /// definite): the initialisation step of §7.2.1, one symmetric `D × D` eigen solve.
    ///
    /// Returns `None` when `C` is not finite, not symmetric to 1e-9 relative, or not
    /// positive definite.
    #[must_use]
    pub fn from_shape(center: SVector<f64, D>, shape: &SMatrix<f64, D, D>) -> Option<Self> {
        if !all_finite(center.as_slice()) || !all_finite(shape.as_slice()) {
            return None;
        }
        let (eigenvalues, vectors) = positive_definite_eigen(shape)?;
        // Ascending shape eigenvalues = descending semi-axes.
        let semi_axes = eigenvalues.map(|l| 1.0 / l.sqrt());
        Some(Self::from_sorted_parts(center, vectors, semi_axes))
    }

    /// The `l`-th isocontour of a Gaussian `N(mean, covariance)` (§7.1.1): shape
    /// `Σ⁻¹ / l²`, semi-axes `l·σᵢ` along the eigenvectors of `Σ`. `l = 3` covers 99.7 %.
    ///
    /// Returns `None` when `covariance` is not symmetric positive definite or `level` is
    /// not positive and finite.
    #[must_use]
    pub fn from_gaussian(
        mean: SVector<f64, D>,
        covariance: &SMatrix<f64, D, D>,
        level: f64,
    ) -> Option<Self> {
        if !positive(level) || !all_finite(covariance.as_slice()) {
            return None;
        }
        let (variances, vectors) = positive_definite_eigen(covariance)?;
        // Descending semi-axes: reverse the ascending variances.
        let axes = SMatrix::<f64, D, D>::from_fn(|r, c| vectors[(r, D - 1 - c)]);
        let semi_axes = SVector::<f64, D>::from_fn(|i, _| level * variances[D - 1 - i].sqrt());
        Some(Self::from_sorted_parts(mean, axes, semi_axes))
    }

    fn from_sorted_parts(
        center: SVector<f64, D>,
        axes: SMatrix<f64, D, D>,
        semi_axes: SVector<f64, D>,
    ) -> Self {
        let inv_a = semi_axes.map(|a| 1.0 / a);
        let sq_a = semi_axes.component_mul(&semi_axes);
        let shape_sqrt = scaled_outer(&axes, &inv_a);
        let shape_inv = scaled_outer(&axes, &sq_a);
        Self {
            center,
            axes,
            semi_axes,
            shape_sqrt,
            shape_inv,
        }
    }

    /// The same ellipsoid moved to `center` (no new eigen solve): how a robot body is
    /// placed at each query position.
    #[must_use]
    pub fn with_center(&self, center: SVector<f64, D>) -> Self {
        Self {
            center,
            ..self.clone()
        }
    }

    /// The centre `c`.
    #[must_use]
    pub fn center(&self) -> &SVector<f64, D> {
        &self.center
    }

    /// Principal axes `Ĉ` as orthonormal columns, by decreasing semi-axis.
    #[must_use]
    pub fn axes(&self) -> &SMatrix<f64, D, D> {
        &self.axes
    }

    /// Semi-axis lengths `aᵢ = Λ_C^{-1/2}`, decreasing.
    #[must_use]
    pub fn semi_axes(&self) -> &SVector<f64, D> {
        &self.semi_axes
    }

    /// The largest semi-axis: the radius of a ball around the centre that holds the
    /// ellipsoid.
    #[must_use]
    pub fn bounding_radius(&self) -> f64 {
        self.semi_axes[0]
    }

    /// `C^{1/2}` (cached at initialisation).
    #[must_use]
    pub fn shape_sqrt(&self) -> &SMatrix<f64, D, D> {
        &self.shape_sqrt
    }

    /// `C⁻¹`, the shape matrix in the sense of \[80\] (cached at initialisation).
    #[must_use]
    pub fn shape_inverse(&self) -> &SMatrix<f64, D, D> {
        &self.shape_inv
    }

    /// The quadratic-form matrix `C = Ĉ Λ_C Ĉᵀ`.
    #[must_use]
    pub fn shape(&self) -> SMatrix<f64, D, D> {
        scaled_outer(&self.axes, &self.semi_axes.map(|a| 1.0 / (a * a)))
    }

    /// The unit eigenvector of the minimum eigenvalue of the shape matrix `C⁻¹` (the
    /// shortest principal axis), signed to point towards `point` (§7.1.4, Fig. 7.1).
    #[must_use]
    pub fn normal_towards(&self, point: &SVector<f64, D>) -> SVector<f64, D> {
        let n: SVector<f64, D> = self.axes.column(D - 1).into_owned();
        if n.dot(&(point - self.center)) < 0.0 {
            -n
        } else {
            n
        }
    }

    /// `(x − c)ᵀ C (x − c)`: below 1 inside, 1 on the boundary.
    #[must_use]
    pub fn level(&self, point: &SVector<f64, D>) -> f64 {
        let local = self.axes.tr_mul(&(point - self.center));
        local
            .iter()
            .zip(self.semi_axes.iter())
            .map(|(x, a)| (x / a) * (x / a))
            .sum()
    }

    /// Whether `point` lies in the solid ellipsoid.
    #[must_use]
    pub fn contains(&self, point: &SVector<f64, D>) -> bool {
        self.level(point) <= 1.0
    }
}

/// How a pair of ellipsoids relates (Proposition 1 and its footnote 3).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PairStatus {
    /// Disjoint: `λ < 0`, `μ < 0`, positive distance.
    Separated,
    /// The ellipsoids touch or intersect: `y*` lies in the robot ellipsoid; distance 0.
    Intersecting,
    /// The robot centre lies in the surface ellipsoid (`λ ≥ 0`); distance 0 and
    /// collision probability 1.
    CenterInside,
}

/// Distance estimate between a robot ellipsoid `E₁(b, B)` and a surface ellipsoid
/// `E₂(c, C)`: Proposition 1 (Eq. 7.4), the witness vector `d*` (Eq. 7.5) and the
/// gradient of Eq. 7.7, plus what Eqs. 7.8–7.9 reuse (see
/// [`collision_probability`](Self::collision_probability)).
#[derive(Clone, Debug, PartialEq)]
pub struct Proximity<const D: usize> {
    pub(super) status: PairStatus,
    pub(super) distance: f64,
    pub(super) separation: SVector<f64, D>,
    pub(super) surface_point: SVector<f64, D>,
    pub(super) lambda: f64,
    pub(super) mu: f64,
    /// `W = B^{1/2} V`, so that `Ā = B^{1/2}(λI − C̃)⁻² B^{1/2} = W diag(1/(γᵢ − λ)²) Wᵀ`.
    pub(super) pair_basis: SMatrix<f64, D, D>,
    /// `γ`, the eigenvalues of `C̃`, ascending.
    pub(super) pair_eigenvalues: SVector<f64, D>,
    /// `Wᵀ(c − b) = Vᵀ c′`.
    pub(super) pair_offset: SVector<f64, D>,
}

impl<const D: usize> Proximity<D> {
    /// Evaluates Proposition 1 for the robot `robot = E₁(b, B)` and the surface
    /// ellipsoid `surface = E₂(c, C)` through the secular equations derived in the
    /// [module docs](self): one `D × D` symmetric eigen solve and two bracketed Newton
    /// root finds.
    #[must_use]
    pub fn between(robot: &Ellipsoid<D>, surface: &Ellipsoid<D>) -> Self {
        let y = surface.center - robot.center;
        // C̃ = B^{1/2} C⁻¹ B^{1/2}.
        let c_tilde = robot.shape_sqrt * surface.shape_inv * robot.shape_sqrt;
        let (gamma, v) = symmetric_eigen(&c_tilde);
        let pair_basis = robot.shape_sqrt * v;
        let pair_offset = pair_basis.tr_mul(&y);
        let mut out = Self {
            status: PairStatus::CenterInside,
            distance: 0.0,
            separation: SVector::zeros(),
            surface_point: robot.center,
            lambda: 0.0,
            mu: 0.0,
            pair_basis,
            pair_eigenvalues: gamma,
            pair_offset,
        };
        if surface.level(&robot.center) <= 1.0 {
            return out;
        }
        // Secular equation of M₁: Σ ĉᵢ²/(γᵢ + s)² = 1, ĉᵢ² = γᵢ c′ᵢ², λ = −s.
        let weights = SVector::<f64, D>::from_fn(|i, _| gamma[i] * pair_offset[i] * pair_offset[i]);
        let s = secular_root(&weights, &gamma);
        out.lambda = -s;
        // u* = s (C̃ + sI)⁻¹ c′ (scaled frame); y* − b = B^{-1/2} u* = λα.
        let u_star = SVector::<f64, D>::from_fn(|i, _| s * pair_offset[i] / (gamma[i] + s));
        // B^{-1/2} = B̂ diag(a) B̂ᵀ, applied without forming it.
        let p = robot.axes
            * robot
                .axes
                .tr_mul(&(v * u_star))
                .component_mul(&robot.semi_axes);
        out.surface_point = robot.center + p;
        // Closest point of E₁ to y*: the secular equation of M₂ in the basis B̂.
        let p_hat = robot.axes.tr_mul(&p);
        let sq_a = robot.semi_axes.component_mul(&robot.semi_axes);
        let level: f64 = p_hat
            .iter()
            .zip(robot.semi_axes.iter())
            .map(|(x, a)| (x / a) * (x / a))
            .sum();
        if level <= 1.0 {
            out.status = PairStatus::Intersecting;
            return out;
        }
        let weights = SVector::<f64, D>::from_fn(|i, _| sq_a[i] * p_hat[i] * p_hat[i]);
        let nu = secular_root(&weights, &sq_a);
        out.mu = -nu;
        // Eq. 7.5 per axis: d*ᵢ = −ν p̂ᵢ/(aᵢ² + ν).
        let d_hat = SVector::<f64, D>::from_fn(|i, _| -nu * p_hat[i] / (sq_a[i] + nu));
        out.separation = robot.axes * d_hat;
        out.distance = out.separation.norm();
        out.status = PairStatus::Separated;
        out
    }

    /// How the pair relates.
    #[must_use]
    pub fn status(&self) -> PairStatus {
        self.status
    }

    /// The distance estimate `d(E₁, E₂) = ‖d*‖` of Eq. 7.4; 0 when the pair touches or
    /// intersects.
    #[must_use]
    pub fn distance(&self) -> f64 {
        self.distance
    }

    /// `d*` of Eq. 7.5: from the witness point `y*` on the surface ellipsoid to its
    /// closest point on the robot ellipsoid; zero unless [`PairStatus::Separated`].
    #[must_use]
    pub fn separation(&self) -> &SVector<f64, D> {
        &self.separation
    }

    /// The gradient estimate of Eq. 7.7, `d*/‖d*‖`, with respect to the robot centre;
    /// the zero vector unless [`PairStatus::Separated`].
    #[must_use]
    pub fn gradient(&self) -> SVector<f64, D> {
        if self.distance > 0.0 {
            self.separation / self.distance
        } else {
            SVector::zeros()
        }
    }

    /// `y* = b + λα`: the point of the surface ellipsoid nearest to the robot centre in
    /// the robot's metric (the robot centre itself when [`PairStatus::CenterInside`]).
    #[must_use]
    pub fn surface_point(&self) -> &SVector<f64, D> {
        &self.surface_point
    }

    /// The point of the robot ellipsoid closest to [`surface_point`](Self::surface_point).
    #[must_use]
    pub fn robot_point(&self) -> SVector<f64, D> {
        self.surface_point + self.separation
    }

    /// `λ`, the minimal eigenvalue of `M₁` (Proposition 1); `None` when the robot centre
    /// is inside the surface ellipsoid (then `λ ≥ 0` and is not computed).
    #[must_use]
    pub fn lambda(&self) -> Option<f64> {
        (self.status != PairStatus::CenterInside).then_some(self.lambda)
    }

    /// `μ`, the minimal eigenvalue of `M₂` (Proposition 1); `None` unless
    /// [`PairStatus::Separated`].
    #[must_use]
    pub fn mu(&self) -> Option<f64> {
        (self.status == PairStatus::Separated).then_some(self.mu)
    }
}

/// The root `s > 0` of the secular equation `Σᵢ wᵢ / (gᵢ + s)² = 1`, for `wᵢ ≥ 0`,
/// `gᵢ > 0` and `Σᵢ wᵢ / gᵢ² > 1` (so the root is positive and unique on `s > −min g`).
///
/// Newton's method on `ψ(s) = F(s)^{-1/2} − 1`, which is increasing and concave, from
/// the lower end of the bracket `[max(0, maxᵢ(√wᵢ − gᵢ), √Σw − max g), √Σw − min g]`;
/// steps that leave the bracket are replaced by bisection (module docs, step 3).
#[must_use]
pub fn secular_root<const D: usize>(w: &SVector<f64, D>, g: &SVector<f64, D>) -> f64 {
    let norm = w.sum().sqrt();
    let mut lo = (norm - g.max()).max(0.0);
    for i in 0..D {
        lo = lo.max(w[i].sqrt() - g[i]);
    }
    let mut hi = (norm - g.min()).max(lo);
    let mut s = lo;
    for _ in 0..100 {
        let mut f = 0.0;
        let mut f3 = 0.0;
        for i in 0..D {
            let r = 1.0 / (g[i] + s);
            let t = w[i] * r * r;
            f += t;
            f3 += t * r;
        }
        if f > 1.0 {
            lo = s;
        } else if f < 1.0 {
            hi = s;
        } else {
            return s;
        }
        // Newton step on ψ: Δ = (F^{3/2} − F) / Σ wᵢ/(gᵢ+s)³.
        let step = (f * f.sqrt() - f) / f3;
        let mut next = s + step;
        if !(next > lo && next < hi) {
            next = 0.5 * (lo + hi);
        }
        if (next - s).abs() <= 2.0 * f64::EPSILON * s.abs().max(f64::MIN_POSITIVE)
            || hi - lo <= 2.0 * f64::EPSILON * hi
        {
            return next;
        }
        s = next;
    }
    s
}

/// Eigen decomposition of a symmetric `D × D` matrix by cyclic Jacobi rotations:
/// eigenvalues ascending, eigenvectors as the columns of the second value. Exact in one
/// rotation for `D = 2`; two to four sweeps for `D = 3`. Stops when the off-diagonal
/// norm is below half an ulp of the diagonal norm, so eigenvalues are accurate to a few
/// ulps of the matrix norm.
#[must_use]
#[allow(clippy::needless_range_loop)] // index arithmetic on rows and columns p, q, k
pub fn symmetric_eigen<const D: usize>(
    m: &SMatrix<f64, D, D>,
) -> (SVector<f64, D>, SMatrix<f64, D, D>) {
    let mut a: [[f64; D]; D] = std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)]));
    let mut v: [[f64; D]; D] =
        std::array::from_fn(|i| std::array::from_fn(|j| f64::from(u8::from(i == j))));
    for _sweep in 0..32 {
        let mut off = 0.0;
        let mut diag = 0.0;
        for i in 0..D {
            diag += a[i][i] * a[i][i];
            for j in (i + 1)..D {
                off += a[i][j] * a[i][j];
            }
        }
        if off <= 0.25 * f64::EPSILON * f64::EPSILON * diag {
            break;
        }
        for p in 0..D {
            for q in (p + 1)..D {
                let apq = a[p][q];
                // Below half an ulp of both diagonal entries a rotation changes nothing
                // they hold: drop the entry instead of paying for the rotation.
                if apq.abs() <= 0.5 * f64::EPSILON * a[p][p].abs().min(a[q][q].abs()) {
                    a[p][q] = 0.0;
                    a[q][p] = 0.0;
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * apq);
                // tan of the rotation angle, the smaller root (|t| ≤ 1); for huge θ,
                // t = 1/(2θ) avoids overflowing θ².
                let t = if theta.abs() < 1e150 {
                    theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt())
                } else {
                    0.5 / theta
                };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                // A ← Jᵀ A J on rows and columns p, q (symmetric: update one side and
                // mirror), V ← V J.
                let (app, aqq) = (a[p][p], a[q][q]);
                a[p][p] = app - t * apq;
                a[q][q] = aqq + t * apq;
                a[p][q] = 0.0;
                a[q][p] = 0.0;
                for k in 0..D {
                    if k != p && k != q {
                        let (akp, akq) = (a[k][p], a[k][q]);
                        let np = c * akp - s * akq;
                        let nq = s * akp + c * akq;
                        a[k][p] = np;
                        a[p][k] = np;
                        a[k][q] = nq;
                        a[q][k] = nq;
                    }
                    let (vkp, vkq) = (v[k][p], v[k][q]);
                    v[k][p] = c * vkp - s * vkq;
                    v[k][q] = s * vkp + c * vkq;
                }
            }
        }
    }
    let mut order: [usize; D] = std::array::from_fn(|i| i);
    order.sort_unstable_by(|&i, &j| a[i][i].total_cmp(&a[j][j]));
    let values = SVector::<f64, D>::from_fn(|i, _| a[order[i]][order[i]]);
    let vectors = SMatrix::<f64, D, D>::from_fn(|r, c| v[r][order[c]]);
    (values, vectors)
}

/// `R diag(d) Rᵀ`, symmetrised.
fn scaled_outer<const D: usize>(r: &SMatrix<f64, D, D>, d: &SVector<f64, D>) -> SMatrix<f64, D, D> {
    let mut rd = *r;
    for (mut col, &di) in rd.column_iter_mut().zip(d.iter()) {
        col *= di;
    }
    let m = rd * r.transpose();
    (m + m.transpose()) * 0.5
}

/// [`symmetric_eigen`] of `m` if it is symmetric to 1e-9 relative and positive
/// definite (its largest entry and its smallest eigenvalue positive and finite).
fn positive_definite_eigen<const D: usize>(
    m: &SMatrix<f64, D, D>,
) -> Option<(SVector<f64, D>, SMatrix<f64, D, D>)> {
    let scale = m.amax();
    if !positive(scale) || (m - m.transpose()).amax() > 1e-9 * scale {
        return None;
    }
    let (eigenvalues, vectors) = symmetric_eigen(m);
    positive(eigenvalues[0]).then_some((eigenvalues, vectors))
}

/// Positive and finite (false for NaN).
fn positive(x: f64) -> bool {
    x > 0.0 && x.is_finite()
}

fn all_finite(values: &[f64]) -> bool {
    values.iter().all(|x| x.is_finite())
}
