//! One robot of the default scenario (procedural cave, CPU camera, standard robot)
//! simulated for one second: every actor's work for 15 camera frames, 15 depth frames
//! into the grid, keyframes, a planning round, the ground-truth coverage. Building the
//! team (world, coverage grid) is outside the timing.
// criterion_group! and criterion_main! generate undocumented functions.
#![allow(missing_docs)]

use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use troupe_sims::camera::{CameraBackend, CameraParams};
use troupe_sims::scenario::Scenario;
use troupe_sims::team::Team;

fn scenario(duration_s: f64) -> Scenario {
    let defaults = Scenario::default();
    Scenario {
        robots: 1,
        duration_s,
        camera: CameraParams {
            backend: CameraBackend::Cpu,
            ..defaults.camera.clone()
        },
        ..defaults
    }
}

fn bench_robot_step(c: &mut Criterion) {
    let mut group = c.benchmark_group("robot_step");
    group.sample_size(10);
    // The first second holds the start-up (the first keyframe, the first rounds); the
    // next one is the steady state, measured as the difference of 2 s and 1 s runs.
    for duration_s in [1.0, 2.0] {
        let s = scenario(duration_s);
        group.bench_function(format!("default_cave_1_robot_{duration_s}s"), |b| {
            b.iter_batched(
                || Team::new(&s).expect("the default scenario assembles"),
                |team| team.run(|_| {}),
                BatchSize::PerIteration,
            );
        });
    }
    group.finish();
}

criterion_group!(benches, bench_robot_step);
criterion_main!(benches);
