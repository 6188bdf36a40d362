//! Local grid costs on a 160×120 frame of the synthetic room (thesis §3.2.3, paper
//! IV-B), 0.2 m cells, 20 m × 20 m × 12 m window:
//!
//! - `insert/per_ray`: every ray updates every cell it crosses (one thread);
//! - `insert/per_scan_1_thread` and `insert/per_scan`: each cell once per scan
//!   (OctoMap's `insertPointCloud` semantics), on one thread and on rayon's pool;
//! - `insert/per_end_voxel`: each cell once per scan, one ray per distinct end voxel
//!   to its centre (`UpdateRule::PerEndVoxel`, OctoMap's `discretize`; one thread);
//! - `window_move/rebuild_{rule}_{size}`: move the window 1 m along x, 0.4 m along
//!   y and 0.2 m along z and rebuild the novel boxes from the stored components of
//!   four SOGMM keyframes fitted to 160×120 frames, for the default 20 m window and
//!   an 8 m one (the counts of candidates, traced components and rays are printed).
//!
//! - `distance/unsafe` and `distance/frontier`: the two distance fields of a grid
//!   snapshot (exact Euclidean transforms, DESIGN §6) on the default window after
//!   eight frames of the room, one every 45° of yaw.
//!
//! Throughput is in rays (in cells for `distance`). Grids are cloned outside the
//! timed part.
#![allow(missing_docs)]

use std::hint::black_box;
use std::time::Duration;

use criterion::{BatchSize, Criterion, Throughput, criterion_group, criterion_main};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use troupe_algorithms::frame::DepthFrame;
use troupe_algorithms::grid::FrontierSet;
use troupe_algorithms::grid::distance::unsafe_distance;
use troupe_algorithms::grid::frontier::frontier_mask;
use troupe_algorithms::grid::{
    ComponentStore, EndVoxelScratch, KeyframeSource, LocalGrid, LogOddsParams, ScanScratch,
    UpdateRule,
};
use troupe_algorithms::keyframe::Keyframe;
use troupe_algorithms::sogmm::synthetic::{Scene, intrinsics, room_pose};
use troupe_algorithms::sogmm::{SogmmConfig, fit_depth_frame};
use troupe_core::Time;

const RESOLUTION_M: f64 = 0.2;

fn window(centre: &Point3<f64>) -> LocalGrid {
    LocalGrid::centred(
        centre,
        &Vector3::new(20.0, 20.0, 12.0),
        RESOLUTION_M,
        LogOddsParams::default(),
    )
}

/// A 160×120 frame of the room from `pose`.
fn frame(pose: Isometry3<f64>) -> DepthFrame {
    let k = intrinsics(160, 120);
    let (depth_m, intensity) = Scene::room_corner().render(&k, &pose);
    DepthFrame {
        stamp: Time::ZERO,
        pose,
        intrinsics: k,
        depth_m,
        intensity,
    }
}

/// The end points of a frame's valid pixels.
fn end_points(frame: &DepthFrame) -> Vec<Point3<f64>> {
    let k = &frame.intrinsics;
    let mut ends = Vec::new();
    for row in 0..k.height {
        for col in 0..k.width {
            let d = f64::from(frame.depth_m[(row * k.width + col) as usize]);
            if d > 0.0 {
                ends.push(frame.pose * k.back_project(col, row, d));
            }
        }
    }
    ends
}

fn insert(c: &mut Criterion) {
    let f = frame(room_pose());
    let origin = Point3::from(f.pose.translation.vector);
    let ends = end_points(&f);
    let empty = window(&origin);
    let mut group = c.benchmark_group("grid/insert");
    group.throughput(Throughput::Elements(ends.len() as u64));
    group.bench_function("per_ray", |b| {
        b.iter_batched_ref(
            || empty.clone(),
            |grid| {
                for e in &ends {
                    grid.insert_ray(&origin, e, true, None);
                }
                black_box(grid.values()[0])
            },
            BatchSize::LargeInput,
        );
    });
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a one-thread pool");
    let mut scratch = ScanScratch::default();
    group.bench_function("per_scan_1_thread", |b| {
        b.iter_batched_ref(
            || empty.clone(),
            |grid| {
                one.install(|| scratch.insert_scan(grid, &origin, &ends, true, None));
                black_box(grid.values()[0])
            },
            BatchSize::LargeInput,
        );
    });
    group.bench_function("per_scan", |b| {
        b.iter_batched_ref(
            || empty.clone(),
            |grid| {
                scratch.insert_scan(grid, &origin, &ends, true, None);
                black_box(grid.values()[0])
            },
            BatchSize::LargeInput,
        );
    });
    let mut voxels = EndVoxelScratch::default();
    group.bench_function("per_end_voxel", |b| {
        b.iter_batched_ref(
            || empty.clone(),
            |grid| black_box(voxels.insert_scan(grid, &origin, &ends, true, None)),
            BatchSize::LargeInput,
        );
    });
    group.finish();
}

fn window_move(c: &mut Criterion) {
    let config = SogmmConfig {
        bandwidth: 0.03,
        ..SogmmConfig::default()
    };
    let base = room_pose();
    let keyframes: Vec<Keyframe> = (0..4)
        .map(|i| {
            let offset = Vector3::new(-0.3 * f64::from(i), 0.2 * f64::from(i), 0.0);
            let pose = Isometry3::from_parts(
                Translation3::from(base.translation.vector + offset),
                UnitQuaternion::from_euler_angles(0.0, 0.25, 0.3 * f64::from(i) - 0.3),
            );
            let f = frame(pose);
            let fit = fit_depth_frame(&f, &config).expect("the room frame fits");
            Keyframe {
                id: i,
                stamp: Time::ZERO,
                pose,
                support_size: f.valid_pixels() as u32,
                gmm: fit.gmm,
            }
        })
        .collect();
    let origin = Point3::from(base.translation.vector);
    let to = origin + Vector3::new(1.0, 0.4, 0.2);
    let mut group = c.benchmark_group("grid/window_move");
    // The default 20 m window (its novel slabs lie beyond the room: nothing to trace)
    // and an 8 m one whose novel slabs cut through the room.
    for (size, size_m) in [("20m", [20.0, 20.0, 12.0]), ("8m", [8.0, 8.0, 4.0])] {
        for (rule_name, rule) in [
            ("per_ray", UpdateRule::PerRay),
            ("per_scan", UpdateRule::PerScan),
            ("per_end_voxel", UpdateRule::PerEndVoxel),
        ] {
            let name = format!("rebuild_{rule_name}_{size}");
            let mut store = ComponentStore::new(19_200, 16, 4.0).with_rule(rule);
            let mut grid = LocalGrid::centred(
                &origin,
                &Vector3::from(size_m),
                RESOLUTION_M,
                LogOddsParams::default(),
            );
            for kf in &keyframes {
                let k = store
                    .insert(KeyframeSource::Own, kf)
                    .expect("a finite keyframe");
                store.trace_keyframe(&mut grid, k);
            }
            let mut probe = grid.clone();
            let novel = probe.shift_to(&to);
            let stats = store.rebuild(&mut probe, &novel);
            eprintln!(
                "{name}: {} components, {} candidates, {} traced, {} rays, novel cells {} of {}",
                store.component_count(),
                stats.candidates,
                stats.traced,
                stats.rays,
                novel.iter().map(|b| b.cell_count()).sum::<usize>(),
                grid.values().len()
            );
            group.bench_function(name, |b| {
                b.iter_batched_ref(
                    || grid.clone(),
                    |g| {
                        let novel = g.shift_to(&to);
                        black_box(store.rebuild(g, &novel))
                    },
                    BatchSize::LargeInput,
                );
            });
        }
    }
    group.finish();
}

fn distance(c: &mut Criterion) {
    let base = room_pose();
    let origin = Point3::from(base.translation.vector);
    let mut grid = window(&origin);
    for i in 0..8 {
        let yaw =
            UnitQuaternion::from_euler_angles(0.0, 0.0, f64::from(i) * std::f64::consts::FRAC_PI_4);
        let f = frame(Isometry3::from_parts(base.translation, yaw * base.rotation));
        for e in end_points(&f) {
            grid.insert_ray(&origin, &e, true, None);
        }
    }
    let mut group = c.benchmark_group("grid/distance");
    group.throughput(Throughput::Elements(grid.values().len() as u64));
    group.bench_function("unsafe", |b| b.iter(|| black_box(unsafe_distance(&grid))));
    group.bench_function("frontier", |b| b.iter(|| black_box(FrontierSet::of(&grid))));
    group.bench_function("frontier_mask", |b| {
        b.iter(|| black_box(frontier_mask(&grid)))
    });
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .sample_size(20)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(4));
    targets = insert, window_move, distance
}
criterion_main!(benches);
