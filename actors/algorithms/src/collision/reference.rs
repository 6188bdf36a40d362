//! Test support: generators of valid inputs, the dense reference for Proposition 1
//! (the thesis's formulas with full 2q × 2q general eigen solves) and an independent
//! exact ellipsoid–ellipsoid distance by convex optimisation.

use nalgebra::{DMatrix, DVector, SMatrix, SVector};
use rand::Rng;

use super::ellipsoid::Ellipsoid;

/// A standard normal sample (Box–Muller).
pub fn normal<R: Rng>(rng: &mut R) -> f64 {
    let u: f64 = 1.0 - rng.random::<f64>();
    let v: f64 = rng.random();
    (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
}

/// A Haar-distributed rotation in SO(D): Gram–Schmidt of a Gaussian matrix (the QR
/// method with the sign fix of Mezzadri), then a column flip onto det = +1.
pub fn random_rotation<const D: usize, R: Rng>(rng: &mut R) -> SMatrix<f64, D, D> {
    loop {
        let g = SMatrix::<f64, D, D>::from_fn(|_, _| normal(rng));
        let mut q = g;
        let mut ok = true;
        for j in 0..D {
            let mut col: SVector<f64, D> = g.column(j).into_owned();
            for i in 0..j {
                let qi: SVector<f64, D> = q.column(i).into_owned();
                col -= qi * qi.dot(&col);
            }
            let n = col.norm();
            if n < 1e-8 {
                ok = false;
                break;
            }
            q.set_column(j, &(col / n));
        }
        if !ok {
            continue;
        }
        if DMatrix::from_column_slice(D, D, q.as_slice()).determinant() < 0.0 {
            let c: SVector<f64, D> = -q.column(0).into_owned();
            q.set_column(0, &c);
        }
        return q;
    }
}

/// A random point uniform in `[-half, half]^D`.
pub fn random_point<const D: usize, R: Rng>(rng: &mut R, half: f64) -> SVector<f64, D> {
    SVector::from_fn(|_, _| rng.random_range(-half..=half))
}

/// Semi-axes uniform in `[lo, hi]`.
pub fn random_axes<const D: usize, R: Rng>(rng: &mut R, lo: f64, hi: f64) -> SVector<f64, D> {
    SVector::from_fn(|_, _| rng.random_range(lo..=hi))
}

/// An ellipsoid of the §7.2.1 distribution: semi-axes uniform in [0.1, 0.5] m, centre
/// uniform in [−10, 10] m per axis, Haar rotation; built from its shape matrix (the
/// initialisation path).
pub fn random_ellipsoid_721<const D: usize, R: Rng>(rng: &mut R) -> Ellipsoid<D> {
    let center = random_point::<D, _>(rng, 10.0);
    let shape = random_shape::<D, _>(rng, 0.1, 0.5);
    Ellipsoid::from_shape(center, &shape).expect("valid SPD shape")
}

/// A shape matrix `R diag(a)⁻² Rᵀ` with semi-axes uniform in `[lo, hi]`.
pub fn random_shape<const D: usize, R: Rng>(rng: &mut R, lo: f64, hi: f64) -> SMatrix<f64, D, D> {
    let r = random_rotation::<D, _>(rng);
    let a = random_axes::<D, _>(rng, lo, hi);
    let m = r * SMatrix::from_diagonal(&a.map(|x| 1.0 / (x * x))) * r.transpose();
    (m + m.transpose()) * 0.5
}

/// A well-conditioned SPD matrix (eigenvalues in `[lo, hi]`), e.g. a covariance.
pub fn random_spd<const D: usize, R: Rng>(rng: &mut R, lo: f64, hi: f64) -> SMatrix<f64, D, D> {
    let r = random_rotation::<D, _>(rng);
    let l = SVector::<f64, D>::from_fn(|_, _| rng.random_range(lo..=hi));
    let m = r * SMatrix::from_diagonal(&l) * r.transpose();
    (m + m.transpose()) * 0.5
}

fn to_dyn<const D: usize>(m: &SMatrix<f64, D, D>) -> DMatrix<f64> {
    DMatrix::from_column_slice(D, D, m.as_slice())
}

fn to_dvec<const D: usize>(v: &SVector<f64, D>) -> DVector<f64> {
    DVector::from_column_slice(v.as_slice())
}

/// Output of the dense reference.
#[derive(Debug, Clone)]
pub struct Dense {
    pub lambda: f64,
    pub mu: f64,
    pub separation: DVector<f64>,
    pub distance: f64,
}

/// `f(B) = B̂ f(Λ) B̂ᵀ` through nalgebra's dense symmetric eigen solver.
fn spectral(m: &DMatrix<f64>, f: impl Fn(f64) -> f64) -> DMatrix<f64> {
    let e = m.clone().symmetric_eigen();
    let d = DMatrix::from_diagonal(&e.eigenvalues.map(f));
    &e.eigenvectors * d * e.eigenvectors.transpose()
}

/// Real part of the eigenvalue of lowest real part (footnote 2 of Proposition 1).
/// `None` if the Schur iteration does not converge.
fn min_real_eigenvalue(m: DMatrix<f64>) -> Option<f64> {
    let schur = nalgebra::linalg::Schur::try_new(m, f64::EPSILON, 20_000)?;
    Some(
        schur
            .complex_eigenvalues()
            .iter()
            .map(|z| z.re)
            .fold(f64::INFINITY, f64::min),
    )
}

/// Proposition 1 exactly as written (Eqs. 7.2–7.5): matrix square roots and inverses by
/// dense symmetric eigen solves, `λ` and `μ` by general eigen solves of the full
/// non-symmetric `2q × 2q` matrices `M₁`, `M₂`, linear systems by LU. `None` if a system
/// is singular (touching or intersecting pairs).
pub fn dense_proposition1<const D: usize>(
    robot: &Ellipsoid<D>,
    surface: &Ellipsoid<D>,
) -> Option<Dense> {
    let q = D;
    let b = to_dvec(robot.center());
    let c = to_dvec(surface.center());
    let bm = to_dyn(&robot.shape());
    let cm = to_dyn(&surface.shape());
    let b_half = spectral(&bm, f64::sqrt);
    let b_mhalf = spectral(&bm, |x| 1.0 / x.sqrt());
    let b_inv = spectral(&bm, |x| 1.0 / x);
    let c_inv = spectral(&cm, |x| 1.0 / x);
    let c_tilde = &b_half * &c_inv * &b_half;
    let y = &c - &b;
    // Eq. 7.2 with Q̂ Λ_Q Q̂ᵀ = B^{-1/2} C B^{-1/2}.
    let qm = &b_mhalf * &cm * &b_mhalf;
    let q_half = spectral(&((&qm + qm.transpose()) * 0.5), f64::sqrt);
    let c_t = (&b_mhalf * q_half).lu().solve(&y)?;
    let ident = DMatrix::<f64>::identity(q, q);
    let mut m1 = DMatrix::<f64>::zeros(2 * q, 2 * q);
    m1.view_mut((0, 0), (q, q)).copy_from(&c_tilde);
    // Balanced as LAPACK's dgeev would: diag(I, I/k) M₁ diag(I, kI), k = ‖c̃‖, has the
    // same eigenvalues and equal off-diagonal block norms.
    let k1 = c_t.norm();
    m1.view_mut((0, q), (q, q)).copy_from(&(-&ident * k1));
    m1.view_mut((q, 0), (q, q))
        .copy_from(&(-(&c_t * c_t.transpose()) / k1));
    m1.view_mut((q, q), (q, q)).copy_from(&c_tilde);
    let lambda = min_real_eigenvalue(m1)?;
    // Eq. 7.3.
    let alpha = (&b_mhalf * (&ident * lambda - &c_tilde) * &b_half)
        .lu()
        .solve(&y)?;
    let b_t = &b_mhalf * &alpha * (-lambda);
    let mut m2 = DMatrix::<f64>::zeros(2 * q, 2 * q);
    m2.view_mut((0, 0), (q, q)).copy_from(&b_inv);
    let k2 = b_t.norm();
    m2.view_mut((0, q), (q, q)).copy_from(&(-&ident * k2));
    m2.view_mut((q, 0), (q, q))
        .copy_from(&(-(&b_t * b_t.transpose()) / k2));
    m2.view_mut((q, q), (q, q)).copy_from(&b_inv);
    let mu = min_real_eigenvalue(m2)?;
    // Eq. 7.5.
    let separation = (&ident * mu - &b_inv)
        .lu()
        .solve(&(&alpha * (-mu * lambda)))?;
    let distance = separation.norm();
    Some(Dense {
        lambda,
        mu,
        separation,
        distance,
    })
}

/// Projection onto the ellipsoid `(x − c)ᵀ M (x − c) ≤ 1`, with the multiplier found
/// by plain bisection (independent of the Newton solver under test).
pub struct Projector {
    center: DVector<f64>,
    vectors: DMatrix<f64>,
    values: DVector<f64>,
}

impl Projector {
    pub fn new(center: DVector<f64>, shape: &DMatrix<f64>) -> Self {
        let e = shape.clone().symmetric_eigen();
        Self {
            center,
            vectors: e.eigenvectors,
            values: e.eigenvalues,
        }
    }

    /// Closest point of the ellipsoid to `p`.
    pub fn project(&self, p: &DVector<f64>) -> DVector<f64> {
        let x = self.vectors.tr_mul(&(p - &self.center));
        let beta = &self.values;
        let f = |nu: f64| -> f64 {
            x.iter()
                .zip(beta.iter())
                .map(|(xi, bi)| bi * xi * xi / ((1.0 + nu * bi) * (1.0 + nu * bi)))
                .sum()
        };
        if f(0.0) <= 1.0 {
            return p.clone();
        }
        let mut lo = 0.0;
        let mut hi = 1.0;
        while f(hi) > 1.0 {
            hi *= 2.0;
        }
        loop {
            let mid = 0.5 * (lo + hi);
            if mid <= lo || mid >= hi {
                break;
            }
            if f(mid) > 1.0 { lo = mid } else { hi = mid }
        }
        let nu = 0.5 * (lo + hi);
        let z = DVector::from_fn(x.len(), |i, _| x[i] / (1.0 + nu * beta[i]));
        &self.center + &self.vectors * z
    }
}

/// Exact distance between two disjoint ellipsoids by alternating projections, stopped
/// when the separating-hyperplane lower bound `n·(b − c) − √(nᵀB⁻¹n) − √(nᵀC⁻¹n)`
/// (support functions along `n = (x − y)/‖x − y‖`) certifies the gap to within `tol`.
/// Returns `(upper, lower)`; `None` if the sets intersect or it does not converge.
pub fn exact_distance<const D: usize>(
    a: &Ellipsoid<D>,
    b: &Ellipsoid<D>,
    tol: f64,
) -> Option<(f64, f64)> {
    let ca = to_dvec(a.center());
    let cb = to_dvec(b.center());
    let pa = Projector::new(ca.clone(), &to_dyn(&a.shape()));
    let pb = Projector::new(cb.clone(), &to_dyn(&b.shape()));
    let ia = to_dyn(a.shape_inverse());
    let ib = to_dyn(b.shape_inverse());
    let mut x = ca.clone();
    for _ in 0..200_000 {
        let y = pb.project(&x);
        x = pa.project(&y);
        let diff = &x - &y;
        let upper = diff.norm();
        if upper < 1e-14 {
            return None;
        }
        let n = diff / upper;
        let lower = n.dot(&(&ca - &cb)) - n.dot(&(&ia * &n)).sqrt() - n.dot(&(&ib * &n)).sqrt();
        if upper - lower <= tol {
            return Some((upper, lower));
        }
    }
    None
}
