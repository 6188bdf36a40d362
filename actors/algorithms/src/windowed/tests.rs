#![allow(clippy::unwrap_used)]

use nalgebra::{Isometry3, Matrix3, Vector3, Vector4};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::gated_em::gate;
use super::*;
use crate::mixture::Chol3;
use crate::sogmm::synthetic;

fn room() -> (Vec<f32>, Vec<f32>, PinholeIntrinsics, Isometry3<f64>) {
    let intr = synthetic::intrinsics(160, 120);
    let pose = synthetic::room_pose();
    let (d, g) = synthetic::Scene::room_corner().render(&intr, &pose);
    (d, g, intr, pose)
}

fn is_pd3(c: &Matrix3<f64>) -> bool {
    (c - c.transpose()).amax() <= 1e-12 * c.amax() && c.cholesky().is_some()
}

#[test]
fn room_fit_is_a_valid_fixed_size_mixture_pair() {
    let (d, g, intr, pose) = room();
    // r_d = 4 m: the far part of the back wall becomes free space.
    let config = WindowedConfig {
        range_m: Some(4.0),
        ..WindowedConfig::default()
    };
    let fit = fit_windowed(&d, &g, &intr, &pose, &config).unwrap();
    assert!(
        fit.occupied.len() <= 100 && fit.occupied.len() >= 50,
        "{}",
        fit.occupied.len()
    );
    fit.occupied.validate().unwrap();
    assert!((fit.occupied.weights().iter().sum::<f64>() - 1.0).abs() < 1e-12);
    let free = fit.free.as_ref().expect("rays beyond 4 m");
    assert!(free.len() <= 100);
    assert!((free.weights().iter().sum::<f64>() - 1.0).abs() < 1e-12);
    assert!(free.covariances().iter().all(is_pd3));
    assert_eq!(
        fit.occupied_support + fit.free_support + fit.report.gated_out,
        fit.report.occupied_points + fit.report.free_points
    );
    // Free-space means lie on (or, being averages over a sphere cap, just inside) the
    // sphere of radius r_d around the sensor.
    let origin = pose.translation.vector;
    for m in free.means() {
        let r = (m - origin).norm();
        assert!(r <= 4.0 + 1e-9 && r > 3.8, "free mean at {r} m");
    }
}

#[test]
fn occupied_mixture_lies_on_the_surfaces() {
    let (d, g, intr, pose) = room();
    let fit = fit_windowed(&d, &g, &intr, &pose, &WindowedConfig::default()).unwrap();
    let scene = synthetic::Scene::room_corner();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let samples = fit.occupied.marginal_spatial().sample(20_000, &mut rng);
    let mean_error_m = samples
        .iter()
        .map(|p| scene.distance(&nalgebra::Point3::from(*p)))
        .sum::<f64>()
        / samples.len() as f64;
    // 100 components over a whole room: each spans ~0.5 m of surface, so resampled
    // points spread off curved/cornered parts by a few cm (paper Fig. 3e is as coarse).
    assert!(
        mean_error_m < 0.05,
        "mean distance to the surface {mean_error_m} m"
    );
    // Intensity is modelled: the conditional reproduces the rendered intensities on
    // average better than their global mean does.
    let fp = crate::sogmm::frame_points(&d, &g, &intr, &pose).unwrap();
    let cond = fit.occupied.intensity_conditional();
    let xs: Vec<Vector3<f64>> = fp.points.iter().map(|p| p.xyz()).collect();
    let est = cond.estimate_batch(&xs);
    let gmean = fp.points.iter().map(|p| p[3]).sum::<f64>() / xs.len() as f64;
    let (mut e_model, mut e_flat) = (0.0, 0.0);
    for (p, e) in fp.points.iter().zip(&est) {
        e_model += (p[3] - e.mean).powi(2);
        e_flat += (p[3] - gmean).powi(2);
    }
    assert!(e_model < 0.7 * e_flat, "{e_model} vs {e_flat}");
}

#[test]
fn the_fit_is_deterministic_and_independent_of_threads() {
    let (d, g, intr, pose) = room();
    let config = WindowedConfig {
        range_m: Some(4.0),
        seed: 3,
        ..WindowedConfig::default()
    };
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| fit_windowed(&d, &g, &intr, &pose, &config).unwrap());
    let two = rayon::ThreadPoolBuilder::new()
        .num_threads(3)
        .build()
        .unwrap()
        .install(|| fit_windowed(&d, &g, &intr, &pose, &config).unwrap());
    assert_eq!(one.occupied, two.occupied);
    let (f1, f2) = (one.free.unwrap(), two.free.unwrap());
    assert_eq!(f1.means(), f2.means());
    assert_eq!(f1.weights(), f2.weights());
    let other = fit_windowed(&d, &g, &intr, &pose, &WindowedConfig { seed: 4, ..config }).unwrap();
    assert_ne!(one.occupied, other.occupied, "the seed matters");
}

#[test]
fn the_gate_matches_a_brute_force_mahalanobis_check() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    use rand::Rng;
    let comps: Vec<(Vector3<f64>, Matrix3<f64>)> = (0..6)
        .map(|k| {
            let a = Matrix3::from_fn(|_, _| rng.random::<f64>() - 0.5);
            (
                Vector3::new(k as f64 * 0.7, rng.random::<f64>(), 0.0),
                a * a.transpose() * 0.3 + Matrix3::identity() * 0.01,
            )
        })
        .collect();
    let chol: Vec<Chol3> = comps
        .iter()
        .map(|(m, c)| Chol3::new(m, c).unwrap())
        .collect();
    let points: Vec<Vector3<f64>> = (0..500)
        .map(|_| {
            Vector3::new(
                rng.random::<f64>() * 5.0 - 0.5,
                rng.random::<f64>() * 2.0 - 0.5,
                rng.random::<f64>() - 0.5,
            )
        })
        .collect();
    for lambda in [0.5, 1.0, 3.0] {
        let gt = gate(&points, &chol, lambda);
        for (i, p) in points.iter().enumerate() {
            let expect: Vec<u32> = comps
                .iter()
                .enumerate()
                .filter(|(_, (m, c))| {
                    let d = p - m;
                    (d.transpose() * c.try_inverse().unwrap() * d)[0].sqrt() < lambda
                })
                .map(|(k, _)| k as u32)
                .collect();
            assert_eq!(gt.of(i), expect.as_slice(), "point {i}, λ = {lambda}");
        }
    }
    // A wider gate keeps a superset.
    let (narrow, wide) = (gate(&points, &chol, 1.0), gate(&points, &chol, 3.0));
    assert!(narrow.kept() <= wide.kept());
}

#[test]
fn on_separated_blobs_the_gate_agrees_with_plain_em() {
    // Two tight blobs in one window.
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    use rand::Rng;
    let mut pts = Vec::new();
    for c in [0.0, 1.0] {
        for _ in 0..400 {
            pts.push(Vector4::new(
                c + 0.02 * (rng.random::<f64>() - 0.5),
                0.02 * (rng.random::<f64>() - 0.5),
                0.02 * (rng.random::<f64>() - 0.5),
                0.5,
            ));
        }
    }
    let plain = GatedEmConfig {
        gate: f64::INFINITY,
        ..GatedEmConfig::default()
    };
    let fit_plain = fit_gated_em(&pts, 2, &mut ChaCha8Rng::seed_from_u64(2), &plain).unwrap();
    assert_eq!((fit_plain.support, fit_plain.discarded), (800, 0));
    let fit_gated = fit_gated_em(
        &pts,
        2,
        &mut ChaCha8Rng::seed_from_u64(2),
        &GatedEmConfig::default(),
    )
    .unwrap();
    // On well-separated blobs the gate changes nothing of substance.
    for (a, b) in fit_plain.means.iter().zip(&fit_gated.means) {
        assert!((a - b).norm() < 1e-6, "{a} {b}");
    }
    // Every kept component's joint covariance is PD and its intensity mean is 0.5.
    for (mean, cov) in &fit_gated.joint {
        assert!((mean[3] - 0.5).abs() < 1e-9);
        assert!(cov.cholesky().is_some());
    }
    assert!((fit_gated.weights.iter().sum::<f64>() - 1.0).abs() < 1e-12);
}

#[test]
fn windows_tile_the_image() {
    let intr = synthetic::intrinsics(160, 120);
    let mut counts = [0usize; 10];
    for row in 0..120 {
        for col in 0..160 {
            counts[window_of(&intr, [5, 2], col, row)] += 1;
        }
    }
    assert!(counts.iter().all(|&c| c == 32 * 60), "{counts:?}");
    assert_eq!(window_of(&intr, [5, 2], 159, 119), 9);
}

#[test]
fn bad_input_is_an_error_not_a_panic() {
    let (d, g, intr, pose) = room();
    assert!(fit_windowed(&d[1..], &g, &intr, &pose, &WindowedConfig::default()).is_err());
    let bad = WindowedConfig {
        windows: [0, 2],
        ..WindowedConfig::default()
    };
    assert!(fit_windowed(&d, &g, &intr, &pose, &bad).is_err());
    let bad = WindowedConfig {
        range_m: Some(f64::NAN),
        ..WindowedConfig::default()
    };
    assert!(fit_windowed(&d, &g, &intr, &pose, &bad).is_err());
    // Nothing within range: no occupied mixture.
    let empty = vec![0.0f32; d.len()];
    assert!(matches!(
        fit_windowed(&empty, &g, &intr, &pose, &WindowedConfig::default()),
        Err(SogmmError::TooFewPoints { .. })
    ));
}
