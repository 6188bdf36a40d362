#![allow(missing_docs)]
//! Does faer pay off in the SOGMM E-step? The E-step's core is the joint log-density
//! `ℓ_k(x) = c_k − ½ |U_k (x − μ_k)|²` of points against components (thesis Eq. A.3;
//! `U = L⁻¹`, `c = ln π + ln N_max`). This bench computes it for the two shapes the fit
//! meets, on the 160×120 room frame at σ = 0.02 (M = 775, the k-means++ start):
//!
//! - `dense_2048x775`: one chunk of the fused pass against every component (the dense
//!   E-step, and the restricted one's fallback points);
//! - `cell_64x40`: a run of 64 points of one grid cell against 40 candidates (the
//!   restricted E-step's block; on this frame a run holds ~30–90 points and ~37
//!   candidates).
//!
//! Kernels: `loop` is the arithmetic of `sogmm::em` (components in SoA, a loop the
//! compiler vectorises; pulp picks AVX2 where present); `faer` expands the quadratic
//! form into one matrix product, `Y = [x 1] · [U_k | −U_k μ_k]ᵀ` (N × 5 by 5 × 4K,
//! `faer::linalg::matmul`, `Par::Seq`), then `ℓ = c − ½ Σ y²` over each group of four
//! columns, column by column, into a component-major result; `faer_product_only` times the product alone. Run:
//! `RAYON_NUM_THREADS=1 cargo bench -p troupe-algorithms --features faer
//! --bench sogmm_faer`. It also prints the largest difference between the two results:
//! the expansion subtracts `U μ` from `U x`, two large nearly equal numbers.

use criterion::{Criterion, criterion_group, criterion_main};
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, Par};
use nalgebra::Matrix4;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;

use troupe_algorithms::sogmm::{
    MeanShiftConfig, frame_points, init_from_partition, kmeans_plusplus, mean_shift_modes,
    synthetic,
};

/// Components in SoA: mean (4), U packed by rows (10), c.
struct Soa {
    mean: [Vec<f64>; 4],
    u: [Vec<f64>; 10],
    logc: Vec<f64>,
}

/// Points (N × 4), the components' SoA and, for faer, the 5 × 4K right-hand side.
struct Case {
    xs: Vec<[f64; 4]>,
    soa: Soa,
    x1: Mat<f64>,
    rhs: Mat<f64>,
}

fn case(n_points: usize, n_comps: usize, stride: usize) -> Case {
    let intr = synthetic::intrinsics(160, 120);
    let pose = synthetic::room_pose();
    let (d, g) = synthetic::Scene::room_corner().render(&intr, &pose);
    let fp = frame_points(&d, &g, &intr, &pose).expect("synthetic frame is valid");
    let m = mean_shift_modes(&fp.depth_intensity, 0.02, &MeanShiftConfig::default()).len();
    let seeding = kmeans_plusplus(&fp.points, m, &mut ChaCha8Rng::seed_from_u64(0));
    let gmm = init_from_partition(&fp.points, &seeding.assignment, seeding.centres.len(), 1e-6)
        .expect("init");
    // Points: a contiguous stretch (neighbours, as in a cell); components: every
    // `stride`-th, starting near the points.
    let xs: Vec<[f64; 4]> = fp.points[..n_points]
        .iter()
        .map(|p| [p[0], p[1], p[2], p[3]])
        .collect();
    let mut soa = Soa {
        mean: Default::default(),
        u: Default::default(),
        logc: vec![],
    };
    let mut rhs = Mat::<f64>::zeros(5, 4 * n_comps);
    for j in 0..n_comps {
        let k = (j * stride) % gmm.len();
        let l = gmm.covariances()[k]
            .cholesky()
            .expect("positive definite")
            .l();
        let u: Matrix4<f64> = l
            .solve_lower_triangular(&Matrix4::identity())
            .expect("invertible");
        let mu = gmm.means()[k];
        let log_det_half: f64 = (0..4).map(|a| l[(a, a)].ln()).sum();
        soa.logc
            .push(gmm.weights()[k].ln() - 2.0 * (2.0 * std::f64::consts::PI).ln() - log_det_half);
        for a in 0..4 {
            soa.mean[a].push(mu[a]);
        }
        let packed = [
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
        ];
        for (v, x) in soa.u.iter_mut().zip(packed) {
            v.push(x);
        }
        let umu = u * mu;
        for r in 0..4 {
            for a in 0..4 {
                rhs[(a, 4 * j + r)] = u[(r, a)];
            }
            rhs[(4, 4 * j + r)] = -umu[r];
        }
    }
    let x1 = Mat::<f64>::from_fn(n_points, 5, |i, a| if a < 4 { xs[i][a] } else { 1.0 });
    Case { xs, soa, x1, rhs }
}

struct Loop<'a> {
    case: &'a Case,
    out: &'a mut [f64],
}

impl pulp::WithSimd for Loop<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        let soa = &self.case.soa;
        let k = soa.logc.len();
        let m: [&[f64]; 4] = std::array::from_fn(|i| &soa.mean[i][..k]);
        let u: [&[f64]; 10] = std::array::from_fn(|i| &soa.u[i][..k]);
        let logc = &soa.logc[..k];
        for (x, out) in self.case.xs.iter().zip(self.out.chunks_exact_mut(k)) {
            let out = &mut out[..k];
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
}

fn by_loop(case: &Case, out: &mut [f64]) {
    pulp::Arch::new().dispatch(Loop { case, out });
}

fn by_faer(case: &Case, y: &mut Mat<f64>, q: &mut [f64], out: &mut [f64]) {
    matmul(
        y.as_mut(),
        Accum::Replace,
        &case.x1,
        &case.rhs,
        1.0,
        Par::Seq,
    );
    let k = case.soa.logc.len();
    // Column by column (faer's matrices are column-major): q = Σ_r y_r² per point.
    for j in 0..k {
        q.fill(0.0);
        for r in 0..4 {
            let col = y
                .col(4 * j + r)
                .try_as_col_major()
                .expect("a Mat's columns are contiguous")
                .as_slice();
            for (q, v) in q.iter_mut().zip(col) {
                *q += v * v;
            }
        }
        // Component-major output (contiguous writes).
        for (o, q) in out[j * q.len()..(j + 1) * q.len()].iter_mut().zip(q.iter()) {
            *o = case.soa.logc[j] - 0.5 * q;
        }
    }
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("sogmm_estep_kernel");
    group.sample_size(20);
    for (name, n, k, stride) in [("dense_2048x775", 2048, 775, 1), ("cell_64x40", 64, 40, 1)] {
        let case = case(n, k, stride);
        let mut a = vec![0.0; n * k];
        let mut b = vec![0.0; n * k];
        let mut y = Mat::<f64>::zeros(n, 4 * k);
        let mut q = vec![0.0; n];
        by_loop(&case, &mut a);
        by_faer(&case, &mut y, &mut q, &mut b);
        // Differences where it matters: components within ln 10¹⁰ of each point's best.
        let mut worst = 0.0f64;
        for (i, ra) in a.chunks_exact(k).enumerate() {
            let max = ra.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            for (j, x) in ra.iter().enumerate() {
                if *x >= max - 23.03 {
                    worst = worst.max((x - b[j * n + i]).abs());
                }
            }
        }
        eprintln!("{name}: largest |ℓ_loop − ℓ_faer| among kept components: {worst:.3e} nats");
        group.bench_function(format!("{name}/loop"), |bch| {
            bch.iter(|| by_loop(black_box(&case), &mut a))
        });
        group.bench_function(format!("{name}/faer"), |bch| {
            bch.iter(|| by_faer(black_box(&case), &mut y, &mut q, &mut b))
        });
        // The matrix product alone: a floor for any faer-based E-step of this shape.
        group.bench_function(format!("{name}/faer_product_only"), |bch| {
            bch.iter(|| {
                matmul(
                    y.as_mut(),
                    Accum::Replace,
                    black_box(&case.x1),
                    &case.rhs,
                    1.0,
                    Par::Seq,
                )
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
