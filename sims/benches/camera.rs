//! Rendering and coverage costs of one 160x120 frame in the default cave, on the CPU and
//! (when a Vulkan adapter is found, e.g. Mesa's lavapipe) on the GPU camera.
// criterion_group! and criterion_main! generate undocumented functions.
#![allow(missing_docs)]

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use std::hint::black_box;
use troupe_core::Time;
use troupe_sims::camera::{CameraParams, GpuCamera};
use troupe_sims::coverage::CoverageGrid;
use troupe_sims::world::World;
use troupe_sims::world::{CaveParams, CaveWorld};

fn start_pose(cave: &CaveWorld) -> Isometry3<f64> {
    let route = cave.centreline_route(0, 1);
    let (a, b) = (route[0], route[1]);
    let yaw = (b.y - a.y).atan2(b.x - a.x);
    Isometry3::from_parts(
        Translation3::from(a.coords),
        UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
    )
}

fn bench_camera(c: &mut Criterion) {
    let cave = CaveWorld::generate(&CaveParams::default(), 0);
    let cam = CameraParams::default();
    let pose = start_pose(&cave);
    c.bench_function("render_160x120_cave", |b| {
        b.iter(|| cam.render(black_box(&cave), Time::ZERO, black_box(&pose), 0));
    });
    // The default scenario's camera: every second pixel, all the standard robot reads.
    let strided = CameraParams {
        render_stride: 2,
        ..cam.clone()
    };
    c.bench_function("render_160x120_cave_stride2", |b| {
        b.iter(|| strided.render(black_box(&cave), Time::ZERO, black_box(&pose), 0));
    });
    let scene = cave.gpu_scene();
    match scene.map(|s| GpuCamera::new(&cam, &s)) {
        Some(Ok(mut gpu)) => {
            eprintln!("GPU camera on {}", gpu.context().adapter_name());
            c.bench_function("render_160x120_cave_gpu", |b| {
                b.iter(|| gpu.render(Time::ZERO, black_box(&pose), 0));
            });
        }
        Some(Err(e)) => eprintln!("render_160x120_cave_gpu skipped: {e}"),
        None => eprintln!("render_160x120_cave_gpu skipped: the cave has no GPU scene"),
    }
    let frame = cam.render(&cave, Time::ZERO, &pose, 0);
    let fresh = CoverageGrid::new(&cave, 0.25);
    c.bench_function("coverage_observe_160x120_stride1_cell0.25", |b| {
        b.iter_batched_ref(
            || fresh.clone(),
            |cov| cov.observe(black_box(&frame), 1),
            criterion::BatchSize::LargeInput,
        );
    });
    c.bench_function("coverage_grid_new_cave_cell0.5", |b| {
        b.iter(|| CoverageGrid::new(black_box(&cave), 0.5));
    });
}

criterion_group!(benches, bench_camera);
criterion_main!(benches);
