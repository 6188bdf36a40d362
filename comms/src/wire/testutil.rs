//! Deterministic generators of valid payloads and a reference GMM likelihood
//! (tests only).

// Small fixed-size matrix code reads best with explicit indices.
#![allow(clippy::needless_range_loop)]

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::check;
use super::*;

pub(crate) fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// Standard normal by Box–Muller.
pub(crate) fn normal(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = 1.0 - rng.random::<f64>(); // (0, 1]
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// A random rotation (Gram–Schmidt of a Gaussian matrix; rows orthonormal).
fn rotation<const D: usize>(rng: &mut ChaCha8Rng) -> [[f64; D]; D] {
    let mut q = [[0.0; D]; D];
    for i in 0..D {
        loop {
            let mut v = [0.0; D];
            for x in &mut v {
                *x = normal(rng);
            }
            for row in q.iter().take(i) {
                let d: f64 = (0..D).map(|k| v[k] * row[k]).sum();
                for k in 0..D {
                    v[k] -= d * row[k];
                }
            }
            let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            if n > 1e-3 {
                q[i] = v.map(|x| x / n);
                break;
            }
        }
    }
    q
}

/// `Rᵀ diag(σ²) R` with σ log-uniform in `[sigma_min, sigma_max]`.
pub(crate) fn covariance<const D: usize>(
    rng: &mut ChaCha8Rng,
    sigma_min: f64,
    sigma_max: f64,
) -> [[f64; D]; D] {
    let r = rotation::<D>(rng);
    let s: [f64; D] = std::array::from_fn(|_| {
        (sigma_min.ln() + rng.random::<f64>() * (sigma_max / sigma_min).ln()).exp()
    });
    let mut c = [[0.0; D]; D];
    for i in 0..D {
        for j in 0..D {
            c[i][j] = (0..D).map(|k| r[k][i] * s[k] * s[k] * r[k][j]).sum();
        }
    }
    c
}

fn weights(rng: &mut ChaCha8Rng, n: usize) -> Vec<f32> {
    let raw: Vec<f64> = (0..n).map(|_| 0.05 + rng.random::<f64>()).collect();
    let total: f64 = raw.iter().sum();
    raw.iter().map(|w| (w / total) as f32).collect()
}

/// A position in the 4 m box of the mixtures' means: x in [0, 4), y in [-2, 2) and
/// z in [0, 2) metres, drawn in that order.
fn box_position(rng: &mut ChaCha8Rng) -> [f32; 3] {
    [
        (rng.random::<f64>() * 4.0) as f32,
        (rng.random::<f64>() * 4.0 - 2.0) as f32,
        (rng.random::<f64>() * 2.0) as f32,
    ]
}

/// A valid 4D mixture: means in a 4 m box (intensity in [0, 1]), σ in
/// `[sigma_min, sigma_max]` (the intensity axis shares the range).
pub(crate) fn mixture4(seed: u64, n: usize, sigma_min: f64, sigma_max: f64) -> Vec<Component4> {
    let mut rng = rng(seed);
    let w = weights(&mut rng, n);
    w.into_iter()
        .map(|weight| {
            let [x, y, z] = box_position(&mut rng);
            let mean = [x, y, z, rng.random::<f32>()];
            let mut cov = [0.0f32; 10];
            check::pack_symmetric(&covariance::<4>(&mut rng, sigma_min, sigma_max), &mut cov);
            Component4 {
                mean,
                covariance: cov,
                weight,
            }
        })
        .collect()
}

/// A valid 3D mixture (see [`mixture4`]).
pub(crate) fn mixture3(seed: u64, n: usize, sigma_min: f64, sigma_max: f64) -> Vec<Component3> {
    let mut rng = rng(seed);
    let w = weights(&mut rng, n);
    w.into_iter()
        .map(|weight| {
            let mean = box_position(&mut rng);
            let mut cov = [0.0f32; 6];
            check::pack_symmetric(&covariance::<3>(&mut rng, sigma_min, sigma_max), &mut cov);
            Component3 {
                mean,
                covariance: cov,
                weight,
            }
        })
        .collect()
}

pub(crate) fn pose() -> SensorPose {
    let h = std::f32::consts::FRAC_1_SQRT_2;
    SensorPose {
        position_m: [1.0, 2.0, 1.5],
        orientation_xyzw: [0.0, 0.0, h, h],
    }
}

pub(crate) fn keyframe(mixture: Mixture) -> Envelope {
    Envelope::new(
        3,
        2,
        1000,
        5_000_000_000,
        Payload::Keyframe(Keyframe {
            keyframe_id: 17,
            sensor_pose: pose(),
            support_size: 19_200,
            mixture,
        }),
    )
}

pub(crate) fn plan(seed: u64, knots: usize) -> Plan {
    let mut rng = rng(seed);
    let mut t = 0.0f32;
    Plan {
        plan_id: rng.random(),
        priority: rng.random(),
        start_ns: rng.random(),
        knots: (0..knots)
            .map(|_| {
                t += rng.random::<f32>() * 0.2;
                PlanKnot {
                    t_s: t,
                    position_m: [rng.random(), rng.random(), rng.random()],
                    yaw_rad: rng.random::<f32>() * 6.0 - 3.0,
                }
            })
            .collect(),
    }
}

pub(crate) fn grid(seed: u64, n: usize) -> GridChangeSet {
    let mut rng = rng(seed);
    let dims = GridDims {
        width: 200,
        height: 200,
        length: 50,
    };
    let mut g = GridChangeSet {
        dims,
        origin_m: [-10.0, -10.0, -1.0],
        changes: (0..n)
            .map(|_| CellChange {
                index: rng.random_range(0..dims.cells() as u32),
                log_odds: rng.random::<f32>() * 8.0 - 4.0,
            })
            .collect(),
    };
    g.normalise();
    g
}

/// `ln N(x; μ, Σ)` in `f64`.
fn log_normal<const D: usize>(x: &[f64; D], mean: &[f32], cov: &[f32]) -> f64 {
    let l = check::cholesky(&check::unpack_symmetric::<D>(cov)).expect("valid covariance");
    let mut y = [0.0; D];
    for i in 0..D {
        let mut s = x[i] - f64::from(mean[i]);
        for k in 0..i {
            s -= l[i][k] * y[k];
        }
        y[i] = s / l[i][i];
    }
    let maha: f64 = y.iter().map(|v| v * v).sum();
    let ln_det: f64 = (0..D).map(|i| 2.0 * l[i][i].ln()).sum();
    -0.5 * (D as f64 * (std::f64::consts::TAU).ln() + ln_det + maha)
}

/// Mean log-likelihood of points under a mixture (log-sum-exp in `f64`).
pub(crate) fn mean_log_likelihood<const D: usize>(
    components: &[(f32, &[f32], &[f32])],
    points: &[[f64; D]],
) -> f64 {
    let mut total = 0.0;
    for x in points {
        let terms: Vec<f64> = components
            .iter()
            .map(|(w, m, c)| f64::from(*w).ln() + log_normal::<D>(x, m, c))
            .collect();
        let max = terms.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        total += max + terms.iter().map(|t| (t - max).exp()).sum::<f64>().ln();
    }
    total / points.len() as f64
}

/// Samples from a mixture.
pub(crate) fn sample<const D: usize>(
    components: &[(f32, &[f32], &[f32])],
    n: usize,
    seed: u64,
) -> Vec<[f64; D]> {
    let mut rng = rng(seed);
    (0..n)
        .map(|_| {
            let mut u: f64 = rng.random();
            let mut pick = components.len() - 1;
            for (i, (w, _, _)) in components.iter().enumerate() {
                u -= f64::from(*w);
                if u <= 0.0 {
                    pick = i;
                    break;
                }
            }
            let (_, m, c) = components[pick];
            let l = check::cholesky(&check::unpack_symmetric::<D>(c)).expect("valid covariance");
            let z: [f64; D] = std::array::from_fn(|_| normal(&mut rng));
            std::array::from_fn(|i| f64::from(m[i]) + (0..=i).map(|k| l[i][k] * z[k]).sum::<f64>())
        })
        .collect()
}
