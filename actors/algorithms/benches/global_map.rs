#![allow(missing_docs)]
//! The relevant-subset step of the incremental map (thesis §6.1.4.1, Eq. 6.9) at the end
//! of a simulated 300-frame flight through the synthetic corridor (80×60 frames,
//! σ = 0.03): through the spatial hash (§6.1.4.3) against the same test over all
//! components. Building the map takes a while (setup, not timed). Single-threaded:
//! `RAYON_NUM_THREADS=1 cargo bench -p troupe-algorithms --bench global_map`.

use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;

use troupe_algorithms::global_map::{GlobalMap, GlobalMapConfig};
use troupe_algorithms::sogmm::{FramePoints, SogmmConfig, frame_points, synthetic};

const FRAMES: usize = 300;
const LENGTH_M: f64 = 40.0;

fn flight_map() -> (GlobalMap, FramePoints) {
    let scene = synthetic::Scene::corridor(LENGTH_M);
    let intr = synthetic::intrinsics(80, 60);
    let mut map = GlobalMap::new(GlobalMapConfig {
        sogmm: SogmmConfig {
            bandwidth: 0.03,
            ..SogmmConfig::default()
        },
        ..GlobalMapConfig::default()
    })
    .expect("valid settings");
    let mut last = FramePoints::default();
    for i in 0..FRAMES {
        let pose = synthetic::flight_pose(i, FRAMES, LENGTH_M);
        let (d, g) = scene.render(&intr, &pose);
        last = frame_points(&d, &g, &intr, &pose).expect("synthetic frame is valid");
        map.insert_frame(&last).expect("insert");
    }
    (map, last)
}

fn bench_relevant(c: &mut Criterion) {
    let (map, frame) = flight_map();
    eprintln!(
        "map after {FRAMES} frames: {} components, {} hash entries; last frame {} points",
        map.len(),
        map.hash().entries(),
        frame.len()
    );
    let mut group = c.benchmark_group("relevant_subset_end_of_flight");
    group.sample_size(10);
    group.bench_function("spatial_hash", |b| {
        b.iter(|| map.relevant(black_box(&frame.points)))
    });
    group.bench_function("all_components", |b| {
        b.iter(|| map.relevant_all(black_box(&frame.points)))
    });
    group.finish();
}

criterion_group!(benches, bench_relevant);
criterion_main!(benches);
