//! The robot body as an ellipsoid `E₁(b, B)` (thesis §7.1.1: "the robot body model"),
//! either from configuration (semi-axes and an orientation in the body frame) or as the
//! minimum-volume enclosing ellipsoid (MVEE) of given points (Khachiyan's algorithm),
//! and its placement at a world pose.
//!
//! # Khachiyan's algorithm
//!
//! For points `p₁ … pₙ ∈ ℝᵈ`, lift them to `qᵢ = (pᵢ, 1)` and keep weights `u` on the
//! simplex (start uniform). Each iteration forms `X = Σ uᵢ qᵢqᵢᵀ`, finds the point with
//! the largest `Mⱼ = qⱼᵀ X⁻¹ qⱼ`, and moves weight towards it (or, Wolfe–Atwood, away
//! from the supporting point of smallest `Mⱼ`) with step
//! `(Mⱼ − d − 1) / ((d + 1)(Mⱼ − 1))`. At the optimum `max Mⱼ = d + 1`. The ellipsoid is
//! `c = Σ uᵢ pᵢ`, `A = (Σ uᵢ pᵢpᵢᵀ − ccᵀ)⁻¹ / d`; we then scale `A` so that the farthest
//! point lies exactly on the boundary, which guarantees that every point is inside while
//! the volume stays within `(1 + ε)^{d/2}` of the optimum for the stopping tolerance ε.

use nalgebra::{DMatrix, DVector, Isometry3, Matrix3, Rotation3, SMatrix, SVector, Vector3};
use serde::{Deserialize, Serialize};

use super::ellipsoid::{Ellipsoid, Ellipsoid3};

/// Why a body ellipsoid could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BodyError {
    /// A semi-axis is not a positive finite number.
    #[error("semi-axes must be finite and > 0, got {0:?}")]
    SemiAxes([f64; 3]),
    /// The orientation is not finite.
    #[error("orientation must be finite, got {0:?}")]
    Orientation([f64; 3]),
    /// Fewer than `d + 1` points, a non-finite coordinate, or all points in a
    /// hyperplane: no ellipsoid of positive volume encloses them tightly.
    #[error(
        "the body points must be finite and span the space (at least d + 1 points not in a plane)"
    )]
    DegeneratePoints,
}

/// The `[robot.collision.body]` table: an ellipsoid from semi-axes and a body-frame
/// orientation, or, when `points_m` is not empty, the MVEE of those body-frame points.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BodyConfig {
    /// Semi-axes along the rotated body x, y, z axes, metres.
    pub semi_axes_m: [f64; 3],
    /// Orientation of the ellipsoid in the body frame: roll, pitch, yaw, radians.
    pub orientation_rpy_rad: [f64; 3],
    /// Centre of the ellipsoid in the body frame, metres.
    pub center_m: [f64; 3],
    /// Body-frame points to enclose (e.g. rotor tips, sensor corners); overrides the
    /// semi-axes, orientation and centre when not empty.
    pub points_m: Vec<[f64; 3]>,
}

impl Default for BodyConfig {
    /// A 0.3 × 0.3 × 0.15 m (semi-axes) body, centred and aligned with the body frame.
    fn default() -> Self {
        BodyConfig {
            semi_axes_m: [0.3, 0.3, 0.15],
            orientation_rpy_rad: [0.0; 3],
            center_m: [0.0; 3],
            points_m: Vec::new(),
        }
    }
}

impl BodyConfig {
    /// The body ellipsoid in the body frame.
    pub fn ellipsoid(&self) -> Result<Ellipsoid3, BodyError> {
        if !self.points_m.is_empty() {
            let points: Vec<Vector3<f64>> =
                self.points_m.iter().map(|p| Vector3::from(*p)).collect();
            return min_volume_enclosing_ellipsoid(&points, 1e-7);
        }
        if !self.semi_axes_m.iter().all(|a| a.is_finite() && *a > 0.0) {
            return Err(BodyError::SemiAxes(self.semi_axes_m));
        }
        let [roll, pitch, yaw] = self.orientation_rpy_rad;
        if ![roll, pitch, yaw].iter().all(|a| a.is_finite())
            || !self.center_m.iter().all(|a| a.is_finite())
        {
            return Err(BodyError::Orientation(self.orientation_rpy_rad));
        }
        let axes = Rotation3::from_euler_angles(roll, pitch, yaw).into_inner();
        Ellipsoid3::from_axes(
            Vector3::from(self.center_m),
            axes,
            Vector3::from(self.semi_axes_m),
        )
        .ok_or(BodyError::SemiAxes(self.semi_axes_m))
    }
}

/// The body ellipsoid (given in the body frame) placed at the world `pose`: centre
/// `pose · c`, principal axes `R Ĉ` (no new eigen solve).
#[must_use]
pub fn place(body: &Ellipsoid3, pose: &Isometry3<f64>) -> Option<Ellipsoid3> {
    let center = pose * nalgebra::Point3::from(*body.center());
    let axes: Matrix3<f64> = pose.rotation.to_rotation_matrix().into_inner() * body.axes();
    Ellipsoid3::from_axes(center.coords, axes, *body.semi_axes())
}

/// Volume of a `D`-dimensional ellipsoid: `V_D · Π aᵢ` (π a b in 2D, 4/3 π a b c in 3D).
#[must_use]
pub fn volume<const D: usize>(e: &Ellipsoid<D>) -> f64 {
    let unit_ball = match D {
        1 => 2.0,
        2 => std::f64::consts::PI,
        3 => 4.0 / 3.0 * std::f64::consts::PI,
        _ => {
            // V_d = π^{d/2} / Γ(d/2 + 1) by the recursion V_d = 2π/d · V_{d−2}.
            let mut v = if D.is_multiple_of(2) { 1.0 } else { 2.0 };
            let mut d = if D.is_multiple_of(2) { 2 } else { 3 };
            while d <= D {
                v *= std::f64::consts::TAU / d as f64;
                d += 2;
            }
            v
        }
    };
    unit_ball * e.semi_axes().iter().product::<f64>()
}

/// Minimum-volume enclosing ellipsoid of `points` by Khachiyan's algorithm (module
/// docs) with Wolfe–Atwood away steps, stopped when every `Mⱼ ≤ (d + 1)(1 + tolerance)`
/// and every supporting `Mⱼ ≥ (d + 1)(1 − tolerance)` (or after 100 000 iterations),
/// then scaled so that every point is inside.
pub fn min_volume_enclosing_ellipsoid<const D: usize>(
    points: &[SVector<f64, D>],
    tolerance: f64,
) -> Result<Ellipsoid<D>, BodyError> {
    let n = points.len();
    if n < D + 1 || points.iter().any(|p| p.iter().any(|x| !x.is_finite())) {
        return Err(BodyError::DegeneratePoints);
    }
    // Centre the data for conditioning.
    let mean = points.iter().fold(SVector::<f64, D>::zeros(), |a, p| a + p) / n as f64;
    let q = DMatrix::from_fn(
        D + 1,
        n,
        |r, c| {
            if r < D { points[c][r] - mean[r] } else { 1.0 }
        },
    );
    let mut u = DVector::from_element(n, 1.0 / n as f64);
    let tolerance = if tolerance > 0.0 { tolerance } else { 1e-7 };
    let d1 = (D + 1) as f64;
    let mut m = vec![0.0; n];
    for _ in 0..100_000 {
        let mut x = DMatrix::<f64>::zeros(D + 1, D + 1);
        for (j, &w) in u.iter().enumerate() {
            let col = q.column(j);
            x += w * col * col.transpose();
        }
        let Some(x_inv) = x.try_inverse() else {
            return Err(BodyError::DegeneratePoints);
        };
        for (j, mj) in m.iter_mut().enumerate() {
            let col = q.column(j);
            *mj = (col.transpose() * &x_inv * col)[(0, 0)];
        }
        if m.iter().any(|v| !v.is_finite()) {
            return Err(BodyError::DegeneratePoints);
        }
        // Toward-step on the farthest point, or away-step on the nearest support point
        // (Wolfe–Atwood), whichever violates optimality more.
        let (far, far_m) = (0..n)
            .map(|j| (j, m[j]))
            .fold((0, f64::NEG_INFINITY), |a, b| if b.1 > a.1 { b } else { a });
        let (near, near_m) = (0..n)
            .filter(|&j| u[j] > 0.0)
            .map(|j| (j, m[j]))
            .fold((0, f64::INFINITY), |a, b| if b.1 < a.1 { b } else { a });
        if far_m <= d1 * (1.0 + tolerance) && near_m >= d1 * (1.0 - tolerance) {
            break;
        }
        let (j, mj) = if far_m - d1 >= d1 - near_m {
            (far, far_m)
        } else {
            (near, near_m)
        };
        let mut step = (mj - d1) / (d1 * (mj - 1.0));
        if step < 0.0 {
            // Keep u_j ≥ 0.
            step = step.max(-u[j] / (1.0 - u[j]).max(f64::MIN_POSITIVE));
        }
        u *= 1.0 - step;
        u[j] += step;
        u[j] = u[j].max(0.0);
    }
    let mut c = SVector::<f64, D>::zeros();
    let mut second = SMatrix::<f64, D, D>::zeros();
    for (i, p) in points.iter().enumerate() {
        let p = p - mean;
        c += u[i] * p;
        second += u[i] * p * p.transpose();
    }
    let scatter = second - c * c.transpose();
    let Some(inv) = scatter.try_inverse() else {
        return Err(BodyError::DegeneratePoints);
    };
    let mut shape = inv / D as f64;
    shape = 0.5 * (shape + shape.transpose());
    let reach = points
        .iter()
        .map(|p| {
            let d = p - mean - c;
            d.dot(&(shape * d))
        })
        .fold(0.0, f64::max);
    if !(reach.is_finite() && reach > 0.0) {
        return Err(BodyError::DegeneratePoints);
    }
    shape /= reach;
    Ellipsoid::from_shape(c + mean, &shape).ok_or(BodyError::DegeneratePoints)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Vector2, Vector3};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn box_corners_give_the_sqrt_d_scaled_box() {
        let h = Vector3::new(0.4, 0.25, 0.1);
        let corners: Vec<Vector3<f64>> = (0..8)
            .map(|i| {
                Vector3::new(
                    if i & 1 == 0 { -h.x } else { h.x },
                    if i & 2 == 0 { -h.y } else { h.y },
                    if i & 4 == 0 { -h.z } else { h.z },
                ) + Vector3::new(1.0, -2.0, 0.5)
            })
            .collect();
        let e = min_volume_enclosing_ellipsoid(&corners, 1e-9).unwrap();
        let expected = 3f64.sqrt() * h;
        let mut axes: Vec<f64> = e.semi_axes().iter().copied().collect();
        axes.sort_by(|a, b| b.total_cmp(a));
        for (a, b) in axes.iter().zip([expected.x, expected.y, expected.z]) {
            assert!((a - b).abs() < 1e-6, "{axes:?} vs {expected}");
        }
        assert!((e.center() - Vector3::new(1.0, -2.0, 0.5)).norm() < 1e-9);
        for p in &corners {
            assert!(e.level(p) <= 1.0 + 1e-12);
        }
    }

    #[test]
    fn square_corners_give_the_circumscribed_circle() {
        let pts = [
            Vector2::new(1.0, 1.0),
            Vector2::new(-1.0, 1.0),
            Vector2::new(1.0, -1.0),
            Vector2::new(-1.0, -1.0),
            Vector2::new(0.2, 0.1),
        ];
        let e = min_volume_enclosing_ellipsoid(&pts, 1e-10).unwrap();
        let r = std::f64::consts::SQRT_2;
        assert!((e.semi_axes() - Vector2::new(r, r)).amax() < 1e-6);
        assert!((volume(&e) - std::f64::consts::PI * 2.0).abs() < 1e-5);
    }

    #[test]
    fn random_points_are_inside_and_points_on_an_ellipsoid_recover_it() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for _ in 0..20 {
            let pts: Vec<Vector3<f64>> = (0..40)
                .map(|_| {
                    Vector3::new(
                        rng.random_range(-1.0..1.0),
                        rng.random_range(-0.5..0.5),
                        rng.random_range(-0.2..0.3),
                    )
                })
                .collect();
            let e = min_volume_enclosing_ellipsoid(&pts, 1e-8).unwrap();
            assert!(pts.iter().all(|p| e.level(p) <= 1.0 + 1e-9));
            // Touches at least d + 1 points (the optimum's support).
            let touching = pts.iter().filter(|p| e.level(p) > 1.0 - 1e-3).count();
            assert!(touching >= 4, "{touching}");
        }
        // Points spread on a known ellipsoid surface: the MVEE is that ellipsoid.
        let truth = Ellipsoid3::from_axes(
            Vector3::new(0.5, 0.0, -1.0),
            Rotation3::from_euler_angles(0.3, -0.2, 1.0).into_inner(),
            Vector3::new(0.5, 0.3, 0.2),
        )
        .unwrap();
        let pts: Vec<Vector3<f64>> = (0..200)
            .map(|_| {
                let v = Vector3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0f64),
                )
                .normalize();
                truth.center() + truth.axes() * v.component_mul(truth.semi_axes())
            })
            .collect();
        let e = min_volume_enclosing_ellipsoid(&pts, 1e-10).unwrap();
        let ratio = volume(&e) / volume(&truth);
        assert!((1.0..1.001).contains(&ratio), "{ratio}");
        assert!((e.center() - truth.center()).norm() < 1e-3);
    }

    #[test]
    fn degenerate_inputs_are_errors() {
        let flat: Vec<Vector3<f64>> = (0..10)
            .map(|i| Vector3::new(i as f64, (i * i) as f64, 0.0))
            .collect();
        assert_eq!(
            min_volume_enclosing_ellipsoid(&flat, 1e-7),
            Err(BodyError::DegeneratePoints)
        );
        let few = [Vector3::new(0.0, 0.0, 0.0), Vector3::new(1.0, 0.0, 0.0)];
        assert!(min_volume_enclosing_ellipsoid(&few, 1e-7).is_err());
        let nan = [
            Vector2::new(f64::NAN, 0.0),
            Vector2::new(1.0, 0.0),
            Vector2::new(0.0, 1.0),
        ];
        assert!(min_volume_enclosing_ellipsoid(&nan, 1e-7).is_err());
        let bad = BodyConfig {
            semi_axes_m: [0.3, -1.0, 0.1],
            ..BodyConfig::default()
        };
        assert!(bad.ellipsoid().is_err());
    }

    #[test]
    fn configured_body_is_rotated_and_placed() {
        let body = BodyConfig {
            semi_axes_m: [0.3, 0.1, 0.05],
            orientation_rpy_rad: [0.0, 0.0, std::f64::consts::FRAC_PI_2],
            ..BodyConfig::default()
        }
        .ellipsoid()
        .unwrap();
        // Long axis along body y after the 90° yaw.
        assert!(body.contains(&Vector3::new(0.0, 0.29, 0.0)));
        assert!(!body.contains(&Vector3::new(0.29, 0.0, 0.0)));
        let pose = Isometry3::new(
            Vector3::new(5.0, 0.0, 1.0),
            Vector3::new(0.0, 0.0, std::f64::consts::FRAC_PI_2),
        );
        let placed = place(&body, &pose).unwrap();
        // Body y → world −x after a further 90° yaw.
        assert!(placed.contains(&Vector3::new(5.0 - 0.29, 0.0, 1.0)));
        assert!(!placed.contains(&Vector3::new(5.0, 0.29, 1.0)));
        let from_points = BodyConfig {
            points_m: vec![
                [0.2, 0.2, 0.05],
                [-0.2, 0.2, 0.05],
                [0.2, -0.2, 0.05],
                [-0.2, -0.2, 0.05],
                [0.0, 0.0, -0.1],
            ],
            ..BodyConfig::default()
        }
        .ellipsoid()
        .unwrap();
        assert!(from_points.contains(&Vector3::new(0.19, 0.19, 0.05)));
    }
}
