//! Per-pair cost of the ellipsoid collision core on the §7.2.1 distribution
//! (thesis Table 7.1): initialisation of both ellipsoids from their shape matrices,
//! distance + gradient (Proposition 1, Eq. 7.7), and collision probability
//! (Eqs. 7.8–7.9), single-threaded. Inputs are generated outside the timed part.
#![allow(missing_docs)]

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{Matrix3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use troupe_algorithms::collision::ellipsoid::{Ellipsoid3, Proximity3};

const PAIRS: usize = 4096;

fn normal(rng: &mut ChaCha8Rng) -> f64 {
    let u: f64 = 1.0 - rng.random::<f64>();
    let v: f64 = rng.random();
    (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
}

/// Haar rotation: Gram–Schmidt of a Gaussian matrix, flipped onto det = +1.
fn rotation(rng: &mut ChaCha8Rng) -> Matrix3<f64> {
    let g = Matrix3::from_fn(|_, _| normal(rng));
    let mut q = g;
    for j in 0..3 {
        let mut col: Vector3<f64> = g.column(j).into_owned();
        for i in 0..j {
            let qi: Vector3<f64> = q.column(i).into_owned();
            col -= qi * qi.dot(&col);
        }
        q.set_column(j, &col.normalize());
    }
    if q.determinant() < 0.0 {
        let c: Vector3<f64> = -q.column(0).into_owned();
        q.set_column(0, &c);
    }
    q
}

/// Centre uniform in [−10, 10]³ m, semi-axes uniform in [0.1, 0.5] m, Haar rotation.
fn shape_721(rng: &mut ChaCha8Rng) -> (Vector3<f64>, Matrix3<f64>) {
    let c = Vector3::from_fn(|_, _| rng.random_range(-10.0..=10.0));
    let a = Vector3::from_fn(|_, _| rng.random_range(0.1..=0.5));
    let r = rotation(rng);
    let m = r * Matrix3::from_diagonal(&a.map(|x| 1.0 / (x * x))) * r.transpose();
    (c, (m + m.transpose()) * 0.5)
}

struct Inputs {
    shapes: Vec<[(Vector3<f64>, Matrix3<f64>); 2]>,
    pairs: Vec<(Ellipsoid3, Ellipsoid3)>,
    proximities: Vec<Proximity3>,
    covariance: Matrix3<f64>,
}

fn inputs() -> Inputs {
    let mut rng = ChaCha8Rng::seed_from_u64(721);
    let shapes: Vec<_> = (0..PAIRS)
        .map(|_| [shape_721(&mut rng), shape_721(&mut rng)])
        .collect();
    let pairs: Vec<_> = shapes
        .iter()
        .map(|[(b, bm), (c, cm)]| {
            (
                Ellipsoid3::from_shape(*b, bm).expect("SPD"),
                Ellipsoid3::from_shape(*c, cm).expect("SPD"),
            )
        })
        .collect();
    let proximities = pairs
        .iter()
        .map(|(r, s)| Proximity3::between(r, s))
        .collect();
    Inputs {
        shapes,
        pairs,
        proximities,
        covariance: Matrix3::identity() * 0.01,
    }
}

fn bench(c: &mut Criterion) {
    let inp = inputs();
    let mut group = c.benchmark_group("ellipsoid_pair_721");
    group
        .measurement_time(Duration::from_secs(3))
        .warm_up_time(Duration::from_secs(1));
    let mut i = 0;
    group.bench_function("init", |b| {
        b.iter(|| {
            i = (i + 1) % PAIRS;
            let [(bc, bm), (cc, cm)] = &inp.shapes[i];
            black_box((
                Ellipsoid3::from_shape(*bc, bm),
                Ellipsoid3::from_shape(*cc, cm),
            ))
        })
    });
    group.bench_function("distance_gradient", |b| {
        b.iter(|| {
            i = (i + 1) % PAIRS;
            let (r, s) = &inp.pairs[i];
            let p = Proximity3::between(black_box(r), black_box(s));
            black_box((p.distance(), p.gradient()))
        })
    });
    group.bench_function("collision_probability", |b| {
        b.iter(|| {
            i = (i + 1) % PAIRS;
            black_box(inp.proximities[i].collision_probability(black_box(&inp.covariance)))
        })
    });
    group.bench_function("total", |b| {
        b.iter(|| {
            i = (i + 1) % PAIRS;
            let [(bc, bm), (cc, cm)] = &inp.shapes[i];
            let (Some(r), Some(s)) = (
                Ellipsoid3::from_shape(*bc, bm),
                Ellipsoid3::from_shape(*cc, cm),
            ) else {
                return None;
            };
            let p = Proximity3::between(&r, &s);
            Some(black_box((
                p.distance(),
                p.gradient(),
                p.collision_probability(&inp.covariance),
            )))
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
