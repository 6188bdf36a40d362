#![allow(missing_docs)]
//! SOGMM fit of one synthetic 160×120 frame (room corner, box, textured floor) at
//! σ = 0.02 and 0.03 and of the same view at 320×240, with the reference mean shift
//! (the default), and its steps (both mean shifts). Run single-threaded for the issue's
//! target: `RAYON_NUM_THREADS=1 cargo bench --bench sogmm`.

use criterion::{Criterion, criterion_group, criterion_main};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;

use troupe_algorithms::sogmm::{
    EStep, EmConfig, FramePoints, MeanShiftConfig, MeanShiftKind, SogmmConfig, fit_em, fit_points,
    frame_points, init_from_partition, kmeans_plusplus, mean_shift_modes, synthetic,
};

fn room_frame() -> FramePoints {
    room_frame_of(160, 120)
}

fn room_frame_of(w: u32, h: u32) -> FramePoints {
    let intr = synthetic::intrinsics(w, h);
    let pose = synthetic::room_pose();
    let (d, g) = synthetic::Scene::room_corner().render(&intr, &pose);
    frame_points(&d, &g, &intr, &pose).expect("synthetic frame is valid")
}

fn bench_fit(c: &mut Criterion) {
    let fp = room_frame();
    let mut group = c.benchmark_group("sogmm_fit_160x120");
    group.sample_size(10);
    // σ = 0.02 on five k-means++ seeds (the target is every seed), σ = 0.03 on one.
    let cases = (0..5u64)
        .map(|seed| (0.02, seed))
        .chain(std::iter::once((0.03, 0)));
    for (sigma, seed) in cases {
        let config = SogmmConfig {
            bandwidth: sigma,
            seed,
            ..SogmmConfig::default()
        };
        let fit = fit_points(&fp.points, &fp.depth_intensity, &config).expect("fit");
        eprintln!(
            "σ = {sigma}, seed {seed}: M = {}, EM iterations = {} (converged: {}), components visited per point = {:.1}",
            fit.gmm.len(),
            fit.report.em.iterations,
            fit.report.em.converged,
            fit.report.em.mean_components_per_point
        );
        let name = if seed == 0 {
            format!("fit_sigma_{sigma}")
        } else {
            format!("fit_sigma_{sigma}_seed_{seed}")
        };
        group.bench_function(name, |b| {
            b.iter(|| fit_points(black_box(&fp.points), &fp.depth_intensity, &config).expect("fit"))
        });
    }
    group.finish();
    let big = room_frame_of(320, 240);
    let mut group = c.benchmark_group("sogmm_fit_320x240");
    group.sample_size(10);
    let fit = fit_points(&big.points, &big.depth_intensity, &SogmmConfig::default()).expect("fit");
    eprintln!(
        "320×240, σ = 0.02: M = {}, EM iterations = {}",
        fit.gmm.len(),
        fit.report.em.iterations
    );
    group.bench_function("fit_sigma_0.02", |b| {
        b.iter(|| {
            fit_points(
                black_box(&big.points),
                &big.depth_intensity,
                &SogmmConfig::default(),
            )
            .expect("fit")
        })
    });
    group.finish();
}

fn bench_steps(c: &mut Criterion) {
    let fp = room_frame();
    let mut group = c.benchmark_group("sogmm_steps_160x120_sigma_0.02");
    group.sample_size(10);
    for kind in [MeanShiftKind::Reference, MeanShiftKind::Blurring] {
        group.bench_function(format!("mean_shift_{kind}"), |b| {
            b.iter(|| {
                mean_shift_modes(
                    black_box(&fp.depth_intensity),
                    0.02,
                    &MeanShiftConfig::of(kind),
                )
            })
        });
    }
    let m = mean_shift_modes(&fp.depth_intensity, 0.02, &MeanShiftConfig::default()).len();
    group.bench_function("kmeans_plusplus", |b| {
        b.iter(|| kmeans_plusplus(black_box(&fp.points), m, &mut ChaCha8Rng::seed_from_u64(0)))
    });
    let seeding = kmeans_plusplus(&fp.points, m, &mut ChaCha8Rng::seed_from_u64(0));
    let init = init_from_partition(&fp.points, &seeding.assignment, seeding.centres.len(), 1e-6)
        .expect("init");
    // Ten EM iterations with each E-step: the dense one is the exact reference.
    for e_step in [EStep::Restricted, EStep::Dense] {
        let config = EmConfig {
            e_step,
            tolerance: 0.0,
            max_iterations: 10,
            ..EmConfig::default()
        };
        group.bench_function(format!("em_10_iterations_{e_step:?}"), |b| {
            b.iter(|| fit_em(black_box(&fp.points), &init, &config).expect("em"))
        });
    }
    group.finish();
}

criterion_group!(benches, bench_fit, bench_steps);
criterion_main!(benches);
