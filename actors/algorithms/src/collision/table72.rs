//! The 2D experiment of thesis §7.2.3 (Fig. 7.2, Table 7.2): a circle of radius 1 m
//! sampled with 1000 points, a robot ellipse with semi-axes (0.3, 0.1) m rotated by 45°,
//! its centre on a 200 × 200 grid over [−2, 2]² m. The distance field of Eq. 7.6 over
//! the surface ellipsoids of a 2D GMM fitted to the points is compared (RMSE) with the
//! ground truth: the exact distance from the robot ellipse to the nearest point.
//!
//! The GMM follows \[76\] in 2D: the number of components `M` is the number of modes of
//! flat-kernel mean shift with bandwidth σ, seeded at every point (non-blurring: the data
//! stay fixed, Eq. 6.6 with the kernel of Eq. 6.7), modes merged greedily by decreasing
//! support when closer than σ; the points are assigned to their nearest mode, and EM
//! with full covariances refines the mixture. The blurring variant that the SOGMM core
//! uses on (depth, intensity) data ([`crate::sogmm::mean_shift_modes`]) is not
//! usable here: blurring shrinks the ring onto a single point for σ ≥ 0.2 m.

use nalgebra::{Matrix2, Rotation2, Vector2};

use super::ellipsoid::Ellipsoid2;
use super::surface::SurfaceEllipsoids;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// `n` points sampled uniformly on the circle of radius `r` (seeded).
pub fn circle_points(n: usize, r: f64, seed: u64) -> Vec<Vector2<f64>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            let t = rng.random_range(0.0..std::f64::consts::TAU);
            Vector2::new(r * t.cos(), r * t.sin())
        })
        .collect()
}

/// Modes of flat-kernel (non-blurring) mean shift with bandwidth `sigma` seeded at every
/// point, merged greedily by decreasing support (points within `sigma` of the mode).
pub fn mean_shift_modes_2d(points: &[Vector2<f64>], sigma: f64) -> Vec<Vector2<f64>> {
    let s2 = sigma * sigma;
    let mut found: Vec<(usize, Vector2<f64>)> = points
        .iter()
        .map(|&seed| {
            let mut x = seed;
            let mut support = 0;
            for _ in 0..300 {
                let (sum, count) = points
                    .iter()
                    .filter(|p| (*p - x).norm_squared() <= s2)
                    .fold((Vector2::zeros(), 0usize), |(s, c), p| (s + p, c + 1));
                support = count;
                if count == 0 {
                    break;
                }
                let next = sum / count as f64;
                let moved = (next - x).norm();
                x = next;
                if moved <= 1e-3 * sigma {
                    break;
                }
            }
            (support, x)
        })
        .collect();
    found.sort_by_key(|f| std::cmp::Reverse(f.0));
    let mut modes: Vec<Vector2<f64>> = Vec::new();
    for (_, x) in found {
        if modes.iter().all(|m| (m - x).norm() > sigma) {
            modes.push(x);
        }
    }
    modes
}

/// A fitted 2D mixture.
pub struct Gmm2 {
    pub weights: Vec<f64>,
    pub means: Vec<Vector2<f64>>,
    pub covariances: Vec<Matrix2<f64>>,
}

/// Variance added to each covariance diagonal (m²): keeps components of collinear points
/// positive definite, as the regularisation of the SOGMM EM does.
const REG_M2: f64 = 1e-8;

fn gaussian_log(x: &Vector2<f64>, mean: &Vector2<f64>, cov: &Matrix2<f64>) -> f64 {
    let det = cov.determinant();
    let d = x - mean;
    let inv = Matrix2::new(cov[(1, 1)], -cov[(0, 1)], -cov[(1, 0)], cov[(0, 0)]) / det;
    -0.5 * d.dot(&(inv * d)) - 0.5 * det.ln() - std::f64::consts::TAU.ln()
}

/// SOGMM-style 2D fit (module docs): `M` from mean shift at bandwidth `sigma`, nearest-
/// mode partition, then `iterations` EM steps.
pub fn fit_gmm2(points: &[Vector2<f64>], sigma: f64, iterations: usize) -> Gmm2 {
    let modes = mean_shift_modes_2d(points, sigma);
    let m = modes.len();
    let n = points.len();
    // Responsibilities, initialised hard from the nearest mode.
    let mut resp = vec![0.0; n * m];
    for (i, p) in points.iter().enumerate() {
        let best = (0..m)
            .min_by(|&a, &b| {
                let da = (p - modes[a]).norm_squared();
                let db = (p - modes[b]).norm_squared();
                da.total_cmp(&db)
            })
            .unwrap_or(0);
        resp[i * m + best] = 1.0;
    }
    let mut gmm = Gmm2 {
        weights: vec![0.0; m],
        means: vec![Vector2::zeros(); m],
        covariances: vec![Matrix2::identity(); m],
    };
    for it in 0..=iterations {
        // M step.
        for k in 0..m {
            let nk: f64 = (0..n).map(|i| resp[i * m + k]).sum();
            if nk <= 0.0 {
                gmm.weights[k] = 0.0;
                continue;
            }
            let mean =
                (0..n).fold(Vector2::zeros(), |acc, i| acc + resp[i * m + k] * points[i]) / nk;
            let cov = (0..n).fold(Matrix2::zeros(), |acc, i| {
                let d = points[i] - mean;
                acc + resp[i * m + k] * d * d.transpose()
            }) / nk
                + Matrix2::identity() * REG_M2;
            gmm.weights[k] = nk / n as f64;
            gmm.means[k] = mean;
            gmm.covariances[k] = cov;
        }
        if it == iterations {
            break;
        }
        // E step.
        for (i, p) in points.iter().enumerate() {
            let logs: Vec<f64> = (0..m)
                .map(|k| {
                    if gmm.weights[k] > 0.0 {
                        gmm.weights[k].ln() + gaussian_log(p, &gmm.means[k], &gmm.covariances[k])
                    } else {
                        f64::NEG_INFINITY
                    }
                })
                .collect();
            let top = logs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let sum: f64 = logs.iter().map(|l| (l - top).exp()).sum();
            for k in 0..m {
                resp[i * m + k] = (logs[k] - top).exp() / sum;
            }
        }
    }
    // Drop emptied components.
    let keep: Vec<usize> = (0..m).filter(|&k| gmm.weights[k] > 0.0).collect();
    Gmm2 {
        weights: keep.iter().map(|&k| gmm.weights[k]).collect(),
        means: keep.iter().map(|&k| gmm.means[k]).collect(),
        covariances: keep.iter().map(|&k| gmm.covariances[k]).collect(),
    }
}

/// Exact Euclidean distance from `p` to the solid axis-aligned ellipse with semi-axes
/// `a`, `b` centred at the origin (0 inside): the closest boundary point is
/// `(a²x/(t+a²), b²y/(t+b²))` with `t ≥ 0` the root of
/// `(ax/(t+a²))² + (by/(t+b²))² = 1`, found by bisection (the left side decreases).
pub fn point_ellipse_distance(p: Vector2<f64>, a: f64, b: f64) -> f64 {
    let (x, y) = (p.x.abs(), p.y.abs());
    if (x / a).powi(2) + (y / b).powi(2) <= 1.0 {
        return 0.0;
    }
    let f = |t: f64| (a * x / (t + a * a)).powi(2) + (b * y / (t + b * b)).powi(2) - 1.0;
    let (mut lo, mut hi) = (0.0, (a * x).hypot(b * y));
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if f(mid) > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= 1e-15 * hi.max(1.0) {
            break;
        }
    }
    let t = 0.5 * (lo + hi);
    let q = Vector2::new(a * a * x / (t + a * a), b * b * y / (t + b * b));
    (Vector2::new(x, y) - q).norm()
}

/// The robot of §7.2.3: semi-axes (0.3, 0.1) m, major axis at 45° from +x.
pub fn robot_ellipse(center: Vector2<f64>) -> Option<Ellipsoid2> {
    let rot = Rotation2::new(std::f64::consts::FRAC_PI_4).into_inner();
    Ellipsoid2::from_axes(center, rot, Vector2::new(0.3, 0.1))
}

/// Ground truth at robot centre `c`: distance from the robot ellipse to the nearest
/// point of `points` (exact point–ellipse distances; points that cannot beat the
/// inscribed-circle bound are skipped).
pub fn ground_truth(c: Vector2<f64>, points: &[Vector2<f64>]) -> f64 {
    let (a, b) = (0.3, 0.1);
    let rot = Rotation2::new(-std::f64::consts::FRAC_PI_4);
    let upper = points
        .iter()
        .map(|p| ((p - c).norm() - b).max(0.0))
        .fold(f64::INFINITY, f64::min);
    points
        .iter()
        .filter(|p| (*p - c).norm() - a <= upper)
        .map(|p| point_ellipse_distance(rot * (p - c), a, b))
        .fold(f64::INFINITY, f64::min)
}

/// Seed of the sampled circle.
pub const SEED: u64 = 7;

/// One row of Table 7.2 (proposed method).
pub struct Row {
    pub sigma: f64,
    pub components: usize,
    pub rmse_m: f64,
    /// Largest amount by which the estimate falls below the ground truth (m).
    pub worst_underestimate_m: f64,
}

/// Runs the experiment for bandwidth `sigma` with surface ellipsoids at isocontour
/// `level` (§7.1.1) on a `cells × cells` grid.
pub fn run(sigma: f64, level: f64, cells: usize, truth: &[f64]) -> Option<Row> {
    let points = circle_points(1000, 1.0, SEED);
    let gmm = fit_gmm2(&points, sigma, 100);
    let surface = SurfaceEllipsoids::<2>::from_gaussians(
        gmm.means
            .iter()
            .copied()
            .zip(gmm.covariances.iter().copied()),
        level,
    )?;
    let mut sq = 0.0;
    let mut worst: f64 = 0.0;
    for (i, c) in grid_centres(cells).into_iter().enumerate() {
        let robot = robot_ellipse(c)?;
        let (d, _) = surface.distance(&robot)?;
        let e = d - truth[i];
        sq += e * e;
        worst = worst.max(-e);
    }
    Some(Row {
        sigma,
        components: gmm.means.len(),
        rmse_m: (sq / truth.len() as f64).sqrt(),
        worst_underestimate_m: worst,
    })
}

/// Cell centres of the `cells × cells` grid over [−2, 2]², row-major.
pub fn grid_centres(cells: usize) -> Vec<Vector2<f64>> {
    let step = 4.0 / cells as f64;
    (0..cells * cells)
        .map(|i| {
            let (r, c) = (i / cells, i % cells);
            Vector2::new(
                -2.0 + (c as f64 + 0.5) * step,
                -2.0 + (r as f64 + 0.5) * step,
            )
        })
        .collect()
}

/// Ground truth over the grid.
pub fn truth_field(cells: usize) -> Vec<f64> {
    let points = circle_points(1000, 1.0, SEED);
    grid_centres(cells)
        .into_iter()
        .map(|c| ground_truth(c, &points))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Table 7.2, proposed method: (σ, M, RMSE in m).
    const THESIS: [(f64, usize, f64); 5] = [
        (0.1, 40, 0.007),
        (0.2, 19, 0.030),
        (0.3, 14, 0.055),
        (0.4, 12, 0.072),
        (0.5, 7, 0.186),
    ];

    /// Reproduces Table 7.2 with surface ellipsoids at the 3-σ isocontour (§7.1.1).
    ///
    /// Tolerances: the thesis does not give its sample, its isocontour level or its EM
    /// settings, and `M` comes from a greedy merge whose outcome depends on the sample
    /// (our seed gives 38, 21, 13, 10, 6 against 40, 19, 14, 12, 7). The RMSE is
    /// dominated by the straight ellipse tips overshooting the arc (sagitta ∝ (arc
    /// length)² ∝ 1/M²), so a difference of a couple of components changes it by tens of
    /// percent: we ask for `M` within ±5 and every RMSE within a factor 2 of the table,
    /// 0.007 m at σ = 0.1 within [0.0045, 0.011] m, and the RMSE increasing with σ as in
    /// the table. Run with `--nocapture` to print the table.
    #[test]
    fn table_7_2_distance_field_rmse() {
        let truth = truth_field(200);
        let mut previous = 0.0;
        println!("σ (m) | M (thesis) | RMSE m (thesis) | worst underestimate m");
        for (sigma, m_thesis, rmse_thesis) in THESIS {
            let row = run(sigma, 3.0, 200, &truth).expect("valid fit");
            println!(
                "{:.1} | {} ({m_thesis}) | {:.4} ({rmse_thesis:.3}) | {:.4}",
                row.sigma, row.components, row.rmse_m, row.worst_underestimate_m
            );
            assert!(
                row.components.abs_diff(m_thesis) <= 5,
                "σ = {sigma}: M = {}",
                row.components
            );
            assert!(
                row.rmse_m > rmse_thesis / 2.0 && row.rmse_m < rmse_thesis * 2.0,
                "σ = {sigma}: RMSE {}",
                row.rmse_m
            );
            assert!(row.rmse_m > previous, "RMSE must grow with σ");
            previous = row.rmse_m;
            if sigma == 0.1 {
                assert!((0.0045..0.011).contains(&row.rmse_m), "RMSE {}", row.rmse_m);
            }
        }
    }

    #[test]
    fn point_ellipse_distance_matches_dense_boundary_sampling() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for _ in 0..200 {
            let p = Vector2::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
            let exact = point_ellipse_distance(p, 0.3, 0.1);
            let inside = (p.x / 0.3).powi(2) + (p.y / 0.1).powi(2) <= 1.0;
            let sampled = (0..100_000)
                .map(|i| {
                    let t = std::f64::consts::TAU * i as f64 / 100_000.0;
                    (p - Vector2::new(0.3 * t.cos(), 0.1 * t.sin())).norm()
                })
                .fold(f64::INFINITY, f64::min);
            if inside {
                assert_eq!(exact, 0.0);
            } else {
                // Boundary samples are 1e-5 m apart: the sampled minimum is above the
                // exact one by less than that.
                assert!(
                    exact <= sampled + 1e-12 && sampled - exact < 1e-5,
                    "{p}: {exact} vs {sampled}"
                );
            }
        }
    }

    #[test]
    fn mean_shift_on_two_clusters_finds_two_modes() {
        let mut points = circle_points(100, 0.05, 1);
        points.extend(
            circle_points(100, 0.05, 2)
                .into_iter()
                .map(|p| p + Vector2::new(1.0, 0.0)),
        );
        let modes = mean_shift_modes_2d(&points, 0.2);
        assert_eq!(modes.len(), 2);
        let gmm = fit_gmm2(&points, 0.2, 20);
        assert_eq!(gmm.means.len(), 2);
        assert!((gmm.weights.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        let mut xs: Vec<f64> = gmm.means.iter().map(|m| m.x).collect();
        xs.sort_by(f64::total_cmp);
        assert!(xs[0].abs() < 0.01 && (xs[1] - 1.0).abs() < 0.01, "{xs:?}");
    }
}
