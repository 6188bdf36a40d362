//! Tests of the SOGMM core: numeric kernels against explicit references, properties of
//! each step, and the end-to-end fit on ray-cast synthetic frames.

use nalgebra::{
    Isometry3, Matrix3, Matrix4, Point3, Translation3, UnitQuaternion, Vector3, Vector4,
};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::em::LOG_TRUNCATION;
use super::*;
use crate::frame::FrameError;
use crate::mixture::LN_2PI;
use crate::mixture::MixtureError;

// ---------------------------------------------------------------- support

/// Valid points of the synthetic room frame (room corner, box, textured floor).
fn room_frame(w: u32, h: u32) -> FramePoints {
    let intr = synthetic::intrinsics(w, h);
    let pose = synthetic::room_pose();
    let (d, g) = synthetic::Scene::room_corner().render(&intr, &pose);
    frame_points(&d, &g, &intr, &pose).unwrap()
}

/// Valid points of one uniform wall seen from the origin.
fn plane_frame(w: u32, h: u32) -> FramePoints {
    let intr = synthetic::intrinsics(w, h);
    let pose = Isometry3::identity();
    let (d, g) = synthetic::Scene::single_plane().render(&intr, &pose);
    frame_points(&d, &g, &intr, &pose).unwrap()
}

/// A random well-conditioned SPD matrix: `Q diag(λ) Qᵀ`, `λ ∈ [0.05, 1] · scale`.
fn random_spd4(rng: &mut ChaCha8Rng, scale: f64) -> Matrix4<f64> {
    let a = Matrix4::from_fn(|_, _| rng.random::<f64>() - 0.5);
    let q = a.qr().q();
    let lambda = Matrix4::from_diagonal(&Vector4::from_fn(|_, _| {
        scale * (0.05 + 0.95 * rng.random::<f64>())
    }));
    let m = q * lambda * q.transpose();
    (m + m.transpose()) * 0.5
}

fn random_gmm4(rng: &mut ChaCha8Rng, m: usize) -> Gmm4 {
    let mut w: Vec<f64> = (0..m).map(|_| 0.1 + rng.random::<f64>()).collect();
    let s: f64 = w.iter().sum();
    w.iter_mut().for_each(|v| *v /= s);
    let means = (0..m)
        .map(|_| Vector4::from_fn(|_, _| 2.0 * rng.random::<f64>() - 1.0))
        .collect();
    let covs = (0..m).map(|_| random_spd4(rng, 0.3)).collect();
    Gmm4::new(w, means, covs).unwrap()
}

/// Explicit Gaussian density (tests only: inverse and determinant).
fn explicit_density4(gmm: &Gmm4, x: &Vector4<f64>) -> f64 {
    let mut p = 0.0;
    for m in 0..gmm.len() {
        let cov = gmm.covariances()[m];
        let d = x - gmm.means()[m];
        let q = (d.transpose() * cov.try_inverse().unwrap() * d)[0];
        p += gmm.weights()[m] * (-0.5 * q).exp()
            / ((2.0 * std::f64::consts::PI).powi(4) * cov.determinant()).sqrt();
    }
    p
}

// ---------------------------------------------------------------- gmm.rs

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn log_likelihood_matches_explicit_density(seed in any::<u64>(), m in 1usize..6) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let gmm = random_gmm4(&mut rng, m);
        gmm.validate().unwrap();
        for _ in 0..8 {
            let x = Vector4::from_fn(|_, _| 2.0 * rng.random::<f64>() - 1.0);
            let reference = explicit_density4(&gmm, &x).ln();
            prop_assert!((gmm.log_likelihood(&x) - reference).abs() < 1e-9 * reference.abs().max(1.0));
        }
        for k in 0..m {
            let det = gmm.covariances()[k].determinant();
            prop_assert!((gmm.ln_determinant(k) - det.ln()).abs() < 1e-9);
        }
    }

    /// Eq. 6.11: the marginal density equals the joint integrated over intensity.
    #[test]
    fn marginal_equals_integrated_joint(seed in any::<u64>(), m in 1usize..4) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let gmm = random_gmm4(&mut rng, m);
        let g3 = gmm.marginal_spatial();
        let x = Vector3::from_fn(|_, _| rng.random::<f64>() - 0.5);
        let (lo, hi, n) = (-8.0, 8.0, 8000);
        let dg = (hi - lo) / n as f64;
        let integral: f64 = (0..n)
            .map(|i| explicit_density4(&gmm, &Vector4::new(x[0], x[1], x[2], lo + (i as f64 + 0.5) * dg)) * dg)
            .sum();
        prop_assert!((g3.log_likelihood(&x) - integral.ln()).abs() < 1e-6);
    }

    /// Eqs. 6.12–6.13: conditional mean and variance equal the moments of p(g | x)
    /// computed by quadrature of the joint.
    #[test]
    fn conditional_matches_quadrature(seed in any::<u64>(), m in 1usize..4) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let gmm = random_gmm4(&mut rng, m);
        let cond = gmm.intensity_conditional();
        let x = Vector3::from_fn(|_, _| rng.random::<f64>() - 0.5);
        let (lo, hi, n) = (-8.0, 8.0, 8000);
        let dg = (hi - lo) / n as f64;
        let (mut z, mut m1, mut m2) = (0.0, 0.0, 0.0);
        for i in 0..n {
            let g = lo + (i as f64 + 0.5) * dg;
            let p = explicit_density4(&gmm, &Vector4::new(x[0], x[1], x[2], g));
            z += p;
            m1 += p * g;
            m2 += p * g * g;
        }
        let mean = m1 / z;
        let var = m2 / z - mean * mean;
        let est = cond.estimate(&x);
        prop_assert!((est.mean - mean).abs() < 1e-6, "{} vs {}", est.mean, mean);
        prop_assert!((est.variance - var).abs() < 1e-6, "{} vs {}", est.variance, var);
        let batch = cond.estimate_batch(&[x, x]);
        prop_assert_eq!(batch[1], est);
    }
}

#[test]
fn new_rejects_invalid_models() {
    let mean = vec![Vector4::zeros()];
    let eye = vec![Matrix4::identity()];
    assert!(Gmm4::new(vec![1.0], mean.clone(), eye.clone()).is_ok());
    assert!(matches!(
        Gmm4::new(vec![0.9], mean.clone(), eye.clone()),
        Err(MixtureError::WeightsDoNotSumToOne { .. })
    ));
    assert!(matches!(
        Gmm4::new(vec![f64::NAN], mean.clone(), eye.clone()),
        Err(MixtureError::InvalidWeight { .. })
    ));
    assert!(matches!(
        Gmm4::new(vec![], vec![], vec![]),
        Err(MixtureError::EmptyModel)
    ));
    let mut not_pd = Matrix4::identity();
    not_pd[(2, 2)] = -1e-3;
    assert!(matches!(
        Gmm4::new(vec![1.0], mean.clone(), vec![not_pd]),
        Err(MixtureError::NotPositiveDefinite { component: 0 })
    ));
    let mut asym = Matrix4::identity();
    asym[(0, 1)] = 0.5;
    assert!(matches!(
        Gmm4::new(vec![1.0], mean.clone(), vec![asym]),
        Err(MixtureError::NotPositiveDefinite { .. })
    ));
    assert!(matches!(
        Gmm4::new(vec![0.5, 0.5], mean, eye),
        Err(MixtureError::LengthMismatch { .. })
    ));
}

#[test]
fn marginal_is_the_leading_block() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let gmm = random_gmm4(&mut rng, 3);
    let g3 = gmm.marginal_spatial();
    for k in 0..3 {
        assert_eq!(g3.means()[k], gmm.means()[k].xyz());
        assert_eq!(
            g3.covariances()[k],
            gmm.covariances()[k].fixed_view::<3, 3>(0, 0).into_owned()
        );
        assert_eq!(g3.weights()[k], gmm.weights()[k]);
    }
}

#[test]
fn sampling_matches_weights_and_moments() {
    let cov = Matrix3::new(0.04, 0.01, 0.0, 0.01, 0.02, 0.005, 0.0, 0.005, 0.01);
    let g3 = Gmm3::new(
        vec![0.25, 0.75],
        vec![Vector3::new(-5.0, 0.0, 0.0), Vector3::new(5.0, 1.0, 2.0)],
        vec![cov, cov],
    )
    .unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let n = 200_000;
    let xs = g3.sample(n, &mut rng);
    let right: Vec<&Vector3<f64>> = xs.iter().filter(|x| x[0] > 0.0).collect();
    let frac = right.len() as f64 / n as f64;
    assert!((frac - 0.75).abs() < 0.005, "fraction {frac}");
    let mean = right.iter().fold(Vector3::zeros(), |a, x| a + **x) / right.len() as f64;
    assert!((mean - Vector3::new(5.0, 1.0, 2.0)).amax() < 3e-3, "{mean}");
    let c = right.iter().fold(Matrix3::zeros(), |a, x| {
        a + (**x - mean) * (**x - mean).transpose()
    }) / right.len() as f64;
    assert!((c - cov).amax() < 1.5e-3, "{c}");
    // Same rng state ⇒ same samples.
    let mut r1 = ChaCha8Rng::seed_from_u64(5);
    let mut r2 = ChaCha8Rng::seed_from_u64(5);
    assert_eq!(g3.sample(100, &mut r1), g3.sample(100, &mut r2));
}

// ---------------------------------------------------------------- points.rs

#[test]
fn pixel_convention_and_invalid_pixels() {
    let intr = PinholeIntrinsicsExt::tiny();
    // 4×2 image; pixel (col 3, row 0) is right of and above the centre.
    let mut depth = vec![2.0f32; 8];
    depth[0] = 0.0; // no return
    depth[1] = 100.0; // beyond max depth
    depth[2] = f32::NAN;
    let intensity: Vec<f32> = (0..8).map(|i| i as f32 / 10.0).collect();
    let pose = Isometry3::from_parts(
        Translation3::new(1.0, 2.0, 3.0),
        UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2),
    );
    let fp = frame_points(&depth, &intensity, &intr, &pose).unwrap();
    assert_eq!(fp.pixels, vec![3, 4, 5, 6, 7]);
    let body = intr.back_project(3, 0, 2.0);
    // u = 3.5 > cx = 2 → body −y; v = 0.5 < cy = 1 → body +z.
    assert!(
        (body - Point3::new(2.0, -(3.5 - 2.0) / 2.0 * 2.0, (1.0 - 0.5) / 2.0 * 2.0)).norm() < 1e-12
    );
    let world = pose * body;
    assert!((fp.points[0].xyz() - world.coords).norm() < 1e-12);
    assert_eq!(fp.points[0][3], f64::from(0.3f32));
    assert_eq!(fp.depth_intensity[0], [2.0, f64::from(0.3f32)]);
    assert!(matches!(
        frame_points(&depth[..7], &intensity, &intr, &pose),
        Err(SogmmError::Frame(FrameError::BufferSize { .. }))
    ));
}

struct PinholeIntrinsicsExt;
impl PinholeIntrinsicsExt {
    fn tiny() -> crate::camera::PinholeIntrinsics {
        crate::camera::PinholeIntrinsics {
            width: 4,
            height: 2,
            fx: 2.0,
            fy: 2.0,
            cx: 2.0,
            cy: 1.0,
            max_depth_m: 10.0,
        }
    }
}

#[test]
fn synthetic_render_lies_on_the_scene() {
    let intr = synthetic::intrinsics(40, 30);
    let pose = synthetic::room_pose();
    let scene = synthetic::Scene::room_corner();
    let (d, g) = scene.render(&intr, &pose);
    let fp = frame_points(&d, &g, &intr, &pose).unwrap();
    assert_eq!(fp.len(), 1200, "the room is closed: every pixel hits");
    for p in &fp.points {
        // f32 depth quantisation: ≤ 1e-6 relative.
        assert!(scene.distance(&Point3::from(p.xyz())) < 1e-5);
    }
}

// ---------------------------------------------------------------- mean_shift.rs

/// Reference: the blurring update over all pairs (O(N²)), same stopping and merging.
fn naive_gbms_modes(data: &[[f64; 2]], sigma: f64, tol: f64, max_iter: usize) -> usize {
    let mut pts = data.to_vec();
    for _ in 0..max_iter {
        let next: Vec<[f64; 2]> = pts
            .iter()
            .map(|p| {
                let (mut s, mut n) = ([0.0, 0.0], 0.0);
                for q in &pts {
                    if (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2) <= sigma * sigma {
                        s[0] += q[0];
                        s[1] += q[1];
                        n += 1.0;
                    }
                }
                [s[0] / n, s[1] / n]
            })
            .collect();
        let shift = pts
            .iter()
            .zip(&next)
            .map(|(a, b)| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt())
            .fold(0.0, f64::max);
        pts = next;
        if shift <= tol * sigma {
            break;
        }
    }
    // Modes: clusters of final points closer than σ/2 (they coincide up to rounding).
    let mut modes: Vec<[f64; 2]> = Vec::new();
    for p in pts {
        if !modes
            .iter()
            .any(|m| (m[0] - p[0]).powi(2) + (m[1] - p[1]).powi(2) <= (0.5 * sigma).powi(2))
        {
            modes.push(p);
        }
    }
    modes.len()
}

fn blobs(rng: &mut ChaCha8Rng, centres: &[[f64; 2]], per: usize, spread: f64) -> Vec<[f64; 2]> {
    let mut out = Vec::new();
    for c in centres {
        for _ in 0..per {
            out.push([
                c[0] + spread * (rng.random::<f64>() - 0.5),
                c[1] + spread * (rng.random::<f64>() - 0.5),
            ]);
        }
    }
    out
}

/// 40 points in each of 12 blobs 0.15 wide, centred at random in 4 × 1, from `seed`.
fn twelve_blobs(seed: u64) -> Vec<[f64; 2]> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let centres: Vec<[f64; 2]> = (0..12)
        .map(|_| [4.0 * rng.random::<f64>(), rng.random::<f64>()])
        .collect();
    blobs(&mut rng, &centres, 40, 0.15)
}

#[test]
fn mean_shift_separates_blobs() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let data = blobs(&mut rng, &[[1.0, 0.2], [1.5, 0.2], [1.0, 0.8]], 200, 0.05);
    let modes = mean_shift_modes(&data, 0.1, &MeanShiftConfig::default());
    assert_eq!(modes.len(), 3);
    assert!(modes.converged);
    assert_eq!(modes.support.iter().sum::<usize>(), 600);
    assert!(modes.support.iter().all(|s| *s == 200));
    // One tight blob (diameter < σ) is one mode at its centroid.
    let one = blobs(&mut rng, &[[2.0, 0.5]], 100, 0.02);
    let modes = mean_shift_modes(&one, 0.1, &MeanShiftConfig::default());
    assert_eq!(modes.len(), 1);
    let c = one.iter().fold([0.0, 0.0], |a, p| {
        [a[0] + p[0] / 100.0, a[1] + p[1] / 100.0]
    });
    assert!((modes.modes[0][0] - c[0]).abs() < 1e-12 && (modes.modes[0][1] - c[1]).abs() < 1e-12);
}

#[test]
fn mean_shift_grid_matches_all_pairs_reference() {
    for seed in 0..4 {
        let data = twelve_blobs(seed);
        for sigma in [0.03, 0.06] {
            let blurring = MeanShiftConfig::of(MeanShiftKind::Blurring);
            let fast = mean_shift_modes(&data, sigma, &blurring);
            let slow = naive_gbms_modes(&data, sigma, 1e-3, 100);
            assert_eq!(fast.len(), slow, "seed {seed} σ {sigma}");
        }
    }
}

/// Reference: scikit-learn's `MeanShift(bandwidth=σ, bin_seeding=True)` written out
/// over all pairs (O(N²) per step): bin seeds, per-seed shifts, sort by support then
/// coordinates (both decreasing), greedy suppression within σ. Returns the modes.
fn naive_sklearn_modes(data: &[[f64; 2]], sigma: f64) -> Vec<[f64; 2]> {
    let mut bins: Vec<[f64; 2]> = Vec::new();
    for p in data {
        let b = [
            (p[0] / sigma).round_ties_even(),
            (p[1] / sigma).round_ties_even(),
        ];
        if !bins.contains(&b) {
            bins.push(b);
        }
    }
    let seeds: Vec<[f64; 2]> = if bins.len() == data.len() {
        data.to_vec()
    } else {
        bins.iter().map(|b| [b[0] * sigma, b[1] * sigma]).collect()
    };
    let within = |c: [f64; 2]| -> Vec<[f64; 2]> {
        data.iter()
            .copied()
            .filter(|q| (q[0] - c[0]).powi(2) + (q[1] - c[1]).powi(2) <= sigma * sigma)
            .collect()
    };
    let mut found: Vec<([f64; 2], usize)> = Vec::new();
    for seed in seeds {
        let mut mean = seed;
        let mut iterations = 0;
        loop {
            let near = within(mean);
            if near.is_empty() {
                break;
            }
            let old = mean;
            let n = near.len() as f64;
            mean = [
                near.iter().map(|q| q[0]).sum::<f64>() / n,
                near.iter().map(|q| q[1]).sum::<f64>() / n,
            ];
            let shift = ((mean[0] - old[0]).powi(2) + (mean[1] - old[1]).powi(2)).sqrt();
            if shift <= 1e-3 * sigma || iterations == 300 {
                found.push((mean, near.len()));
                break;
            }
            iterations += 1;
        }
    }
    found.sort_by(|a, b| {
        b.1.cmp(&a.1)
            .then(b.0[0].total_cmp(&a.0[0]))
            .then(b.0[1].total_cmp(&a.0[1]))
    });
    let mut kept: Vec<[f64; 2]> = Vec::new();
    for (c, _) in found {
        if !kept
            .iter()
            .any(|k| (k[0] - c[0]).powi(2) + (k[1] - c[1]).powi(2) <= sigma * sigma)
        {
            kept.push(c);
        }
    }
    kept
}

#[test]
fn reference_mean_shift_matches_all_pairs_sklearn_algorithm() {
    for seed in 0..4 {
        let data = twelve_blobs(seed);
        for sigma in [0.03, 0.06] {
            let fast = mean_shift_modes(&data, sigma, &MeanShiftConfig::default());
            let slow = naive_sklearn_modes(&data, sigma);
            assert_eq!(fast.len(), slow.len(), "seed {seed} σ {sigma}");
            for (a, b) in fast.modes.iter().zip(&slow) {
                assert!(
                    (a[0] - b[0]).abs() < 1e-12 && (a[1] - b[1]).abs() < 1e-12,
                    "seed {seed} σ {sigma}: {a:?} vs {b:?}"
                );
            }
            assert!(fast.converged);
        }
    }
}

/// `M` on a small frame, pinned: the 40×30 room frame at σ = 0.02 and 0.03 gives the
/// cluster counts of scikit-learn 1.7's `MeanShift(bandwidth=σ, bin_seeding=True)` on
/// the same (depth, intensity) data (`scripts/sogmm_meanshift_vs_sklearn.py` checks
/// larger frames), and more modes than the blurring variant.
#[test]
fn reference_mean_shift_pins_m_on_a_small_frame() {
    let fp = room_frame(40, 30);
    let reference =
        |sigma| mean_shift_modes(&fp.depth_intensity, sigma, &MeanShiftConfig::default());
    let blurring = |sigma| {
        mean_shift_modes(
            &fp.depth_intensity,
            sigma,
            &MeanShiftConfig::of(MeanShiftKind::Blurring),
        )
    };
    assert_eq!(
        (reference(0.02).len(), reference(0.03).len()),
        PINNED_M_40X30
    );
    assert!(blurring(0.02).len() < reference(0.02).len());
    // The same modes with any number of threads.
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| reference(0.02));
    assert_eq!(one, reference(0.02));
}

const PINNED_M_40X30: (usize, usize) = (383, 279);

/// `M` of the reference mean shift equals the cluster count of scikit-learn's
/// `MeanShift(bandwidth=σ, bin_seeding=True)` (the real one, from `.venv-sogmm`, which
/// `.ci/run` installs; skipped without it) on the three 160×120 views of the room
/// corner at σ = 0.02, within 1 % (the bound; measured: equal).
#[test]
fn reference_mean_shift_m_matches_scikit_learn() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let python = root.join(".venv-sogmm/bin/python");
    if !python.exists() {
        eprintln!("skipped: {} missing (see .ci/run)", python.display());
        return;
    }
    let dir = std::env::temp_dir().join(format!("troupe-ms-sklearn-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let intr = synthetic::intrinsics(160, 120);
    let views = synthetic::room_views();
    let sigma = 0.02;
    for (k, pose) in views.iter().enumerate() {
        let (d, g) = synthetic::Scene::room_corner().render(&intr, pose);
        let fp = frame_points(&d, &g, &intr, pose).unwrap();
        let path = dir.join(format!("view{k}.f64"));
        let bytes: Vec<u8> = fp
            .depth_intensity
            .iter()
            .flat_map(|p| p.iter().flat_map(|v| v.to_le_bytes()))
            .collect();
        std::fs::write(&path, bytes).unwrap();
        let out = std::process::Command::new(&python)
            .args([
                "-c",
                "import sys, numpy as np; from sklearn.cluster import MeanShift; \
                 x = np.fromfile(sys.argv[1], dtype='<f8').reshape(-1, 2); \
                 print(len(MeanShift(bandwidth=float(sys.argv[2]), bin_seeding=True).fit(x).cluster_centers_))",
            ])
            .arg(&path)
            .arg(sigma.to_string())
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let theirs: usize = String::from_utf8_lossy(&out.stdout).trim().parse().unwrap();
        let ours = mean_shift_modes(&fp.depth_intensity, sigma, &MeanShiftConfig::default()).len();
        assert!(
            ours.abs_diff(theirs) * 100 <= theirs,
            "view {k}: troupe M {ours}, scikit-learn {theirs}"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn mean_shift_survives_extreme_and_non_finite_values() {
    let mut data = vec![[1.0, 0.5]; 10];
    data.extend([
        [1e300, 1e300],
        [-1e300, 0.5],
        [f64::MAX, -f64::MAX],
        [f64::NAN, 0.5],
        [1.0, f64::INFINITY],
    ]);
    for kind in [MeanShiftKind::Reference, MeanShiftKind::Blurring] {
        for sigma in [0.02, 1e-300] {
            let modes = mean_shift_modes(&data, sigma, &MeanShiftConfig::of(kind));
            // The ten equal points are the strongest mode; NaN/∞ are ignored and the far
            // finite points are modes of their own at most (whose bins may overflow).
            assert_eq!(modes.modes[0], [1.0, 0.5], "{kind} σ {sigma}: {modes:?}");
            assert_eq!(modes.support[0], 10, "{kind} σ {sigma}: {modes:?}");
            assert!(modes.len() <= 4, "{kind} σ {sigma}: {modes:?}");
        }
    }
    assert!(mean_shift_modes(&[], 0.02, &MeanShiftConfig::default()).is_empty());
}

#[test]
fn mean_shift_variant_names_round_trip() {
    for kind in [MeanShiftKind::Reference, MeanShiftKind::Blurring] {
        assert_eq!(kind.name().parse::<MeanShiftKind>().unwrap(), kind);
    }
    let e = "gaussian".parse::<MeanShiftKind>().unwrap_err();
    assert_eq!(e.key, "mean_shift");
    assert!(e.to_string().contains("gaussian"), "{e}");
}

// ---------------------------------------------------------------- kmeanspp.rs

#[test]
fn kmeanspp_is_deterministic_distinct_and_assigns_nearest() {
    let fp = room_frame(40, 30);
    let run = |seed| kmeans_plusplus(&fp.points, 50, &mut ChaCha8Rng::seed_from_u64(seed));
    let a = run(7);
    assert_eq!(a, run(7));
    assert_ne!(a.centres, run(8).centres);
    assert_eq!(a.centres.len(), 50);
    let mut sorted = a.centres.clone();
    sorted.sort_unstable();
    sorted.dedup();
    assert_eq!(sorted.len(), 50, "centres are distinct points");
    for (p, &k) in fp.points.iter().zip(&a.assignment) {
        let d = (p - fp.points[a.centres[k as usize]]).norm_squared();
        for &c in &a.centres {
            assert!(d <= (p - fp.points[c]).norm_squared());
        }
    }
    // Fewer distinct points than centres: stops early.
    let dup = vec![Vector4::new(1.0, 2.0, 3.0, 0.5); 10];
    assert_eq!(
        kmeans_plusplus(&dup, 4, &mut ChaCha8Rng::seed_from_u64(0))
            .centres
            .len(),
        1
    );
}

// ---------------------------------------------------------------- em.rs

fn kinit(fp: &FramePoints, sigma: f64, seed: u64) -> (Gmm4, Seeding) {
    let m = mean_shift_modes(&fp.depth_intensity, sigma, &MeanShiftConfig::default()).len();
    let seeding = kmeans_plusplus(&fp.points, m, &mut ChaCha8Rng::seed_from_u64(seed));
    let init =
        init_from_partition(&fp.points, &seeding.assignment, seeding.centres.len(), 1e-6).unwrap();
    (init, seeding)
}

#[test]
fn dense_em_never_decreases_log_likelihood() {
    let fp = room_frame(80, 60);
    let (init, _) = kinit(&fp, 0.03, 1);
    let config = EmConfig {
        e_step: EStep::Dense,
        tolerance: 1e-6,
        max_iterations: 60,
        ..EmConfig::default()
    };
    let (gmm, report) = fit_em(&fp.points, &init, &config).unwrap();
    gmm.validate().unwrap();
    let trace = &report.log_likelihood_trace;
    assert!(trace.len() > 10);
    for w in trace.windows(2) {
        // The ε I regularisation makes the M-step a near-maximiser only; allow 1e-9 nats.
        assert!(w[1] >= w[0] - 1e-9, "decrease {} → {}", w[0], w[1]);
    }
    // The trace is the mean log-likelihood of the parameters of each E-step.
    assert!(trace[trace.len() - 1] > trace[0] + 0.5);
}

#[test]
fn restricted_e_step_matches_dense() {
    let fp = room_frame(80, 60);
    let (init, _) = kinit(&fp, 0.02, 2);
    let m = init.len();
    // One iteration from the same start: the M-step sums differ only by the dropped
    // responsibilities (< 1e-10 each relative to the best component).
    let one = |e_step| {
        fit_em(
            &fp.points,
            &init,
            &EmConfig {
                e_step,
                max_iterations: 1,
                ..EmConfig::default()
            },
        )
        .unwrap()
    };
    let (d1, dr) = one(EStep::Dense);
    let (r1, rr) = one(EStep::Restricted);
    assert!(
        rr.mean_components_per_point < 0.5 * m as f64,
        "restriction visits {} of {m}",
        rr.mean_components_per_point
    );
    let ll_bound = m as f64 * (-LOG_TRUNCATION).exp();
    assert!((dr.log_likelihood_trace[0] - rr.log_likelihood_trace[0]).abs() <= ll_bound);
    for k in 0..m {
        assert!((d1.weights()[k] - r1.weights()[k]).abs() < 1e-9);
        assert!(
            (d1.means()[k] - r1.means()[k]).amax() < 1e-6,
            "component {k}"
        );
        assert!(
            (d1.covariances()[k] - r1.covariances()[k]).amax() < 1e-8,
            "component {k}"
        );
    }
    // Five iterations: still rounding-level apart.
    let five = |e_step| {
        fit_em(
            &fp.points,
            &init,
            &EmConfig {
                e_step,
                max_iterations: 5,
                tolerance: 0.0,
                ..EmConfig::default()
            },
        )
        .unwrap()
    };
    let ((d5, d5r), (r5, r5r)) = (five(EStep::Dense), five(EStep::Restricted));
    for (a, b) in d5r
        .log_likelihood_trace
        .iter()
        .zip(&r5r.log_likelihood_trace)
    {
        assert!((a - b).abs() < 1e-7, "{a} vs {b}");
    }
    let mean_gap = (0..m)
        .map(|k| (d5.means()[k] - r5.means()[k]).amax())
        .fold(0.0, f64::max);
    // Components with little support move most (their means divide by a small N_k).
    assert!(mean_gap < 1e-5, "means {mean_gap}");
    // Whole runs (tens of iterations): EM amplifies the tiny differences along its slow
    // directions, so the two only agree to within the convergence tolerance.
    let full = |e_step| {
        fit_em(
            &fp.points,
            &init,
            &EmConfig {
                e_step,
                ..EmConfig::default()
            },
        )
        .unwrap()
    };
    let (dg, dr) = full(EStep::Dense);
    let (rg, rr) = full(EStep::Restricted);
    let (a, b) = (
        dg.mean_log_likelihood(&fp.points),
        rg.mean_log_likelihood(&fp.points),
    );
    eprintln!(
        "one iteration: Δll {:.2e}; five: Δll {:.2e}, max Δmean {mean_gap:.2e}; full runs ({} / {} iterations): {a} vs {b}",
        (dr1_ll(&fp, &init) - rr1_ll(&fp, &init)).abs(),
        (d5r.log_likelihood_trace[4] - r5r.log_likelihood_trace[4]).abs(),
        dr.iterations,
        rr.iterations
    );
    assert!((a - b).abs() < EmConfig::default().tolerance, "{a} vs {b}");
}

fn dr1_ll(fp: &FramePoints, init: &Gmm4) -> f64 {
    fit_em(
        &fp.points,
        init,
        &EmConfig {
            e_step: EStep::Dense,
            max_iterations: 1,
            ..EmConfig::default()
        },
    )
    .unwrap()
    .1
    .log_likelihood_trace[0]
}

fn rr1_ll(fp: &FramePoints, init: &Gmm4) -> f64 {
    fit_em(
        &fp.points,
        init,
        &EmConfig {
            max_iterations: 1,
            ..EmConfig::default()
        },
    )
    .unwrap()
    .1
    .log_likelihood_trace[0]
}

// ---------------------------------------------------------------- the whole fit

#[test]
fn every_fit_is_a_valid_mixture() {
    let fp = room_frame(80, 60);
    for (sigma, seed) in [(0.02, 0), (0.03, 1), (0.05, 2)] {
        let fit = fit_points(
            &fp.points,
            &fp.depth_intensity,
            &SogmmConfig {
                bandwidth: sigma,
                seed,
                ..SogmmConfig::default()
            },
        )
        .unwrap();
        fit.gmm.validate().unwrap();
        let s: f64 = fit.gmm.weights().iter().sum();
        assert!((s - 1.0).abs() < 1e-12);
        for c in fit.gmm.covariances() {
            assert!(c.cholesky().is_some());
            assert!(c.symmetric_eigenvalues().min() > 0.0);
        }
        assert_eq!(fit.gmm.len(), fit.report.components);
        assert!(fit.report.em.iterations <= EmConfig::default().max_iterations);
    }
}

#[test]
fn same_seed_gives_bit_identical_mixture_on_any_thread_count() {
    let fp = room_frame(80, 60);
    let config = SogmmConfig {
        bandwidth: 0.03,
        seed: 42,
        ..SogmmConfig::default()
    };
    let run = |threads| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| fit_points(&fp.points, &fp.depth_intensity, &config).unwrap())
    };
    let a = run(1);
    let b = run(1);
    assert_eq!(a.gmm, b.gmm);
    // 4800 points: three chunks of the fused E/M pass, spread over the threads.
    for threads in [2, 3] {
        let c = run(threads);
        assert_eq!(a.gmm, c.gmm);
        assert_eq!(a.report, c.report);
    }
    let other = fit_points(
        &fp.points,
        &fp.depth_intensity,
        &SogmmConfig { seed: 43, ..config },
    )
    .unwrap();
    assert_ne!(a.gmm, other.gmm);
}

#[test]
fn smaller_bandwidth_gives_more_components() {
    let fp = room_frame(160, 120);
    let counts: Vec<usize> = [0.01, 0.02, 0.03, 0.05, 0.08]
        .iter()
        .map(|s| mean_shift_modes(&fp.depth_intensity, *s, &MeanShiftConfig::default()).len())
        .collect();
    for w in counts.windows(2) {
        assert!(w[0] > w[1], "{counts:?}");
    }
}

#[test]
fn simple_scene_gets_fewer_components_than_cluttered() {
    let (room, plane) = (room_frame(160, 120), plane_frame(160, 120));
    for sigma in [0.02, 0.03, 0.05] {
        let m_room =
            mean_shift_modes(&room.depth_intensity, sigma, &MeanShiftConfig::default()).len();
        let m_plane =
            mean_shift_modes(&plane.depth_intensity, sigma, &MeanShiftConfig::default()).len();
        assert!(
            2 * m_plane < m_room,
            "σ {sigma}: plane {m_plane}, room {m_room}"
        );
    }
}

/// §6.2.4 on the synthetic 160×120 room frame, with both mean shifts: resample as many points as the frame has
/// from the spatial marginal, regress their intensity (Eq. 6.13), and score them.
///
/// Thresholds: the thesis reports MRE ≈ 0.005 m and precision ≥ 0.95 at σ = 0.02–0.03 on
/// noisy real data (Fig. 6.11); this frame is noise-free, so against the exact surface we
/// require at least as much. Against a discrete ground-truth cloud (the frame ray-cast
/// at 4× resolution, like the thesis' 1 cm voxel cloud) the nearest-neighbour distance
/// includes the cloud's own spacing (up to ~1 cm at 5 m), so the bounds are looser there.
#[test]
fn reconstruction_quality_on_synthetic_frame() {
    let (w, h) = (160, 120);
    let intr = synthetic::intrinsics(w, h);
    let pose = synthetic::room_pose();
    let scene = synthetic::Scene::room_corner();
    let fp = room_frame(w, h);
    let dense_intr = synthetic::scaled(&intr, 4);
    let (dd, dg) = scene.render(&dense_intr, &pose);
    let truth = frame_points(&dd, &dg, &dense_intr, &pose).unwrap();
    let cases = [0.02, 0.03]
        .into_iter()
        .flat_map(|s| [(s, MeanShiftKind::Reference), (s, MeanShiftKind::Blurring)]);
    let mut exact_mre = Vec::new();
    for (sigma, kind) in cases {
        let fit = fit_points(
            &fp.points,
            &fp.depth_intensity,
            &SogmmConfig {
                bandwidth: sigma,
                mean_shift: MeanShiftConfig::of(kind),
                ..SogmmConfig::default()
            },
        )
        .unwrap();
        let samples = fit
            .gmm
            .marginal_spatial()
            .sample(fp.len(), &mut ChaCha8Rng::seed_from_u64(9));
        let est = fit.gmm.intensity_conditional().estimate_batch(&samples);
        let predicted: Vec<Vector4<f64>> = samples
            .iter()
            .zip(&est)
            .map(|(s, e)| Vector4::new(s.x, s.y, s.z, e.mean))
            .collect();
        let exact: Vec<f64> = samples
            .iter()
            .map(|s| scene.distance(&Point3::from(*s)))
            .collect();
        let mre_exact = exact.iter().sum::<f64>() / exact.len() as f64;
        let precision_exact =
            exact.iter().filter(|d| **d <= 0.01).count() as f64 / exact.len() as f64;
        let cloud = metrics::reconstruction_metrics(&predicted, &truth.points, 0.01);
        eprintln!(
            "σ {sigma} {kind}: M {} EM iterations {}; exact surface: MRE {mre_exact:.4} m, precision {precision_exact:.3}; \
             4× cloud: MRE {:.4} m, precision {:.3}, recall {:.3}, PSNR {:.1} dB",
            fit.gmm.len(),
            fit.report.em.iterations,
            cloud.mre_m,
            cloud.precision,
            cloud.recall,
            cloud.psnr_db
        );
        exact_mre.push(mre_exact);
        assert!(mre_exact <= 0.005, "exact MRE {mre_exact}");
        assert!(precision_exact >= 0.95, "exact precision {precision_exact}");
        assert!(cloud.mre_m <= 0.009, "cloud MRE {}", cloud.mre_m);
        assert!(
            cloud.precision >= 0.90,
            "cloud precision {}",
            cloud.precision
        );
        // Checkerboard and box edges are intensity steps that a mixture smooths; the
        // thesis reaches ≈ 30 dB on real scenes.
        assert!(cloud.psnr_db >= 22.0, "PSNR {}", cloud.psnr_db);
    }
    // The reference mean shift's finer mixtures are no less accurate than the blurring
    // one's at the same σ (measured: 0.0018 vs 0.0023 m at σ = 0.02).
    for pair in exact_mre.chunks(2) {
        assert!(
            pair[0] <= pair[1],
            "reference vs blurring exact MRE {pair:?}"
        );
    }
}

#[test]
fn fit_rejects_bad_input() {
    assert!(matches!(
        fit_points(&[], &[], &SogmmConfig::default()),
        Err(SogmmError::TooFewPoints { .. })
    ));
    let fp = plane_frame(20, 15);
    let bad = SogmmConfig {
        bandwidth: 0.0,
        ..SogmmConfig::default()
    };
    assert!(matches!(
        fit_points(&fp.points, &fp.depth_intensity, &bad),
        Err(SogmmError::InvalidInput(_))
    ));
    let mut pts = fp.points.clone();
    pts[0][3] = f64::NAN;
    assert!(fit_points(&pts, &fp.depth_intensity, &SogmmConfig::default()).is_err());
}

#[test]
fn ln_2pi_constant() {
    assert!((LN_2PI - (2.0 * std::f64::consts::PI).ln()).abs() < 1e-15);
}

#[test]
fn exp_of_the_e_step_matches_the_c_library() {
    // Relative error against f64::exp over the whole range the E-step meets (and below).
    let mut worst = 0.0f64;
    for i in 0..=200_000 {
        let x = -708.0 * f64::from(i) / 200_000.0;
        let (ours, libm) = (super::em::exp_nonpositive(x), x.exp());
        worst = worst.max((ours - libm).abs() / libm);
    }
    assert!(worst < 1e-15, "worst relative error {worst:e}");
    assert_eq!(super::em::exp_nonpositive(0.0), 1.0);
    assert_eq!(super::em::exp_nonpositive(-709.0), 0.0);
    assert_eq!(super::em::exp_nonpositive(f64::NEG_INFINITY), 0.0);
}

#[test]
fn max_first_agrees_with_a_left_to_right_scan() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for len in 0..40 {
        for _ in 0..50 {
            // Few distinct values, so ties are common; −∞ among them.
            let values: Vec<f64> = (0..len)
                .map(|_| match rng.random_range(0..5) {
                    0 => f64::NEG_INFINITY,
                    v => f64::from(v),
                })
                .collect();
            let mut scan = (f64::NEG_INFINITY, 0);
            for (j, &v) in values.iter().enumerate() {
                if v > scan.0 {
                    scan = (v, j);
                }
            }
            assert_eq!(super::em::max_first(&values), scan, "{values:?}");
        }
    }
}

#[test]
fn log_sum_is_the_sum_of_the_logarithms() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let values: Vec<f64> = (0..5000).map(|_| rng.random_range(1.0..800.0)).collect();
    let mut log_sum = super::em::LogSum::default();
    values.iter().for_each(|&s| log_sum.push(s));
    let direct: f64 = values.iter().map(|s| s.ln()).sum();
    // The product is ~10^12000: far beyond f64, kept as mantissa and exponent.
    assert!(
        (log_sum.ln() - direct).abs() < 1e-9 * direct,
        "{} vs {direct}",
        log_sum.ln()
    );
    assert_eq!(super::em::LogSum::default().ln(), 0.0);
    // A degenerate value gives what its logarithm would.
    let mut with_zero = super::em::LogSum::default();
    with_zero.push(2.0);
    with_zero.push(0.0);
    assert_eq!(with_zero.ln(), f64::NEG_INFINITY);
    let mut with_nan = super::em::LogSum::default();
    with_nan.push(f64::NAN);
    with_nan.push(3.0);
    assert!(with_nan.ln().is_nan());
}
