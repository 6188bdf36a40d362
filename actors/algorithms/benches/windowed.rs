#![allow(missing_docs)]
//! Windowed fixed-size GMM (paper §IV-A, thesis §3.2) on one synthetic 160×120 frame
//! (room corner), the paper's 10 windows × 10 components, with the Mahalanobis gate
//! λ = 3 and without it (plain EM per window), and with one window of 100 components
//! (the windowless fit the paper compares against, Fig. 6). Single-threaded:
//! `RAYON_NUM_THREADS=1 cargo bench -p troupe-algorithms --bench windowed`.

use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;

use troupe_algorithms::sogmm::synthetic;
use troupe_algorithms::windowed::{GatedEmConfig, WindowedConfig, fit_windowed};

fn bench(c: &mut Criterion) {
    let intr = synthetic::intrinsics(160, 120);
    let pose = synthetic::room_pose();
    let (d, g) = synthetic::Scene::room_corner().render(&intr, &pose);
    let mut group = c.benchmark_group("windowed_fit_160x120");
    group.sample_size(10);
    let variants = [
        ("10x10_gate_3", WindowedConfig::default()),
        (
            "10x10_no_gate",
            WindowedConfig {
                em: GatedEmConfig {
                    gate: f64::INFINITY,
                    ..GatedEmConfig::default()
                },
                ..WindowedConfig::default()
            },
        ),
        (
            "1x100_gate_3",
            WindowedConfig {
                windows: [1, 1],
                occupied_components: 100,
                free_components: 100,
                ..WindowedConfig::default()
            },
        ),
    ];
    for (name, config) in variants {
        let fit = fit_windowed(&d, &g, &intr, &pose, &config).expect("fit");
        eprintln!(
            "{name}: {} occupied components, {} points gated out of {}, at most {} EM iterations",
            fit.occupied.len(),
            fit.report.gated_out,
            fit.report.occupied_points + fit.report.free_points,
            fit.report.max_iterations
        );
        group.bench_function(name, |b| {
            b.iter(|| fit_windowed(black_box(&d), &g, &intr, &pose, &config).expect("fit"))
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
