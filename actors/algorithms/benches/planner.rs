//! Planner cost on a fixed synthetic scene (a 3.5 m room with a doorway, the
//! 160 × 120 forward camera of thesis §4.2.1, default round settings):
//! primitives generated (minimum-duration line search, Eq. 4.4) and checked
//! (acceleration/jerk limits, clearance of the primitive and its stopping primitive)
//! per second; CSQMI beams per second (one subsampled camera view); and one planning
//! round (every child of the root state, scored) with the minimal and the large
//! library (thesis Table 4.2). Scenes are built outside the timed part.
#![allow(missing_docs)]

use std::hint::black_box;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use nalgebra::Vector3;
use troupe_algorithms::planner::csqmi::view_information;
use troupe_algorithms::planner::primitives::FlatState;
use troupe_algorithms::planner::problem::PlanningProblem;
use troupe_algorithms::planner::round::{LibraryChoice, RoundConfig, pose_of};
use troupe_algorithms::planner::scenes;

fn bench_planner(c: &mut Criterion) {
    let snapshot = scenes::room_with_doorway(3.5, 1.5, 0.5);
    let camera = scenes::forward_camera();
    let root = FlatState::at_rest(Vector3::zeros(), 0.3);

    let mut group = c.benchmark_group("planner");
    group
        .sample_size(20)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(3));

    // Primitives generated and checked: every action of the large library.
    let config = RoundConfig {
        library: LibraryChoice::Large,
        ..RoundConfig::default()
    };
    let problem = PlanningProblem::new(&config, &snapshot, &camera);
    let actions = problem.actions().to_vec();
    group.throughput(Throughput::Elements(actions.len() as u64));
    group.bench_function("primitives_generated_and_checked", |b| {
        b.iter(|| {
            actions
                .iter()
                .filter(|&&(action, fixed)| {
                    config
                        .primitive(&root, action, fixed)
                        .and_then(|p| config.safe_with_stop(&p, &snapshot))
                        .is_some()
                })
                .count()
        });
    });

    // CSQMI: one view of the camera subsampled by the default pixel stride.
    let stride = config.view.pixel_stride.max(1);
    let beams = ((stride / 2..camera.width).step_by(stride as usize).count()
        * (stride / 2..camera.height).step_by(stride as usize).count()) as u64;
    let pose = pose_of(&root);
    group.throughput(Throughput::Elements(beams));
    group.bench_function("csqmi_view", |b| {
        b.iter(|| view_information(&snapshot.grid, black_box(&pose), &camera, &config.view));
    });

    // One planning round per library.
    for library in [LibraryChoice::Minimal, LibraryChoice::Large] {
        let config = RoundConfig {
            library,
            ..RoundConfig::default()
        };
        let problem = PlanningProblem::new(&config, &snapshot, &camera);
        group.throughput(Throughput::Elements(problem.actions().len() as u64));
        group.bench_with_input(
            BenchmarkId::new("round", format!("{library:?}").to_lowercase()),
            &root,
            |b, root| b.iter(|| problem.children(black_box(root)).len()),
        );
    }
    group.finish();
}

criterion_group!(benches, bench_planner);
criterion_main!(benches);
