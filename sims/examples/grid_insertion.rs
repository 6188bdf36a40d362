//! Rays per second into the local occupancy grid, on simulated 160×120 frames of the
//! default cave — one side of `scripts/bench_grid_vs_octomap.py`, which times
//! OctoMap on the very same points. Four ways, each the median of repeats per frame:
//!
//! - `baseline`: the first implementation (the `RayWalk` iterator, one update per ray
//!   and cell), kept here as the "before" of the speed work;
//! - `per_ray`: `LocalGrid::insert_ray` (same semantics, tight walk loop);
//! - `per_scan`: `ScanScratch::insert_scan` (each cell once per frame, hits first —
//!   OctoMap's own semantics — rays walked in parallel on rayon's pool);
//! - `per_end_voxel`: `EndVoxelScratch::insert_scan` (`UpdateRule::PerEndVoxel`: as
//!   `per_scan`, one ray per distinct end voxel to its centre — OctoMap's
//!   `discretize` — on one thread); `end_voxels` counts the rays it traced.
//!
//! Every rate counts the input points (pixels with a return), not traced rays.
//!
//! Run: `cargo run --release -p troupe-sims --example grid_insertion -- OUT.bin`
//! (writes the points it used to OUT.bin: per frame a u32 point count, the sensor
//! origin as 3 × f64, then the end points as 3 × f64 each, little endian).

use std::io::Write;
use std::time::Instant;

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use troupe_algorithms::grid::{EndVoxelScratch, LocalGrid, LogOddsParams, ScanScratch};
use troupe_core::Time;
use troupe_sims::camera::CameraParams;
use troupe_sims::world::{CaveParams, CaveWorld};

const RESOLUTION_M: f64 = 0.2;
const REPEATS: usize = 15;

fn main() -> anyhow::Result<()> {
    let out = std::env::args().nth(1);
    let world = CaveWorld::generate(&CaveParams::default(), 7);
    let camera = CameraParams::default();
    let route = world.centreline_route(0, 1);
    let mut file = Vec::new();
    let mut per_frame = Vec::new();
    let mut rays_total = 0usize;
    let mut end_voxels_total = 0usize;
    for (i, pair) in route.windows(2).step_by(7).take(10).enumerate() {
        let yaw = (pair[1].y - pair[0].y).atan2(pair[1].x - pair[0].x);
        let pose = Isometry3::from_parts(
            Translation3::from(pair[0].coords),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw),
        );
        let frame = camera.render(&world, Time::ZERO, &pose, i as u64);
        let origin = Point3::from(pose.translation.vector);
        let k = frame.intrinsics;
        let mut ends = Vec::new();
        for row in 0..k.height {
            for col in 0..k.width {
                let d = f64::from(frame.depth_m[(row * k.width + col) as usize]);
                if d > 0.0 {
                    ends.push(pose * k.back_project(col, row, d));
                }
            }
        }
        let empty = LocalGrid::centred(
            &origin,
            &Vector3::new(20.0, 20.0, 12.0),
            RESOLUTION_M,
            LogOddsParams::default(),
        );
        let mut scratch = ScanScratch::default();
        let mut voxel_scratch = EndVoxelScratch::default();
        let time = |insert: &mut dyn FnMut(&mut LocalGrid)| -> f64 {
            let mut times = Vec::with_capacity(REPEATS);
            for _ in 0..REPEATS {
                let mut grid = empty.clone();
                let start = Instant::now();
                insert(&mut grid);
                times.push(start.elapsed().as_secs_f64());
                std::hint::black_box(&grid);
            }
            times.sort_by(f64::total_cmp);
            times[REPEATS / 2]
        };
        let baseline = time(&mut |grid| {
            for end in &ends {
                baseline_insert(grid, &origin, end);
            }
        });
        let per_ray = time(&mut |grid| {
            for end in &ends {
                grid.insert_ray(&origin, end, true, None);
            }
        });
        let per_scan = time(&mut |grid| scratch.insert_scan(grid, &origin, &ends, true, None));
        let mut end_voxels = 0;
        let per_end_voxel = time(&mut |grid| {
            end_voxels = voxel_scratch.insert_scan(grid, &origin, &ends, true, None);
        });
        end_voxels_total += end_voxels;
        per_frame.push([baseline, per_ray, per_scan, per_end_voxel]);
        rays_total += ends.len();
        file.extend_from_slice(&(ends.len() as u32).to_le_bytes());
        for v in origin.coords.iter() {
            file.extend_from_slice(&v.to_le_bytes());
        }
        for p in &ends {
            for v in p.coords.iter() {
                file.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    let mut fields = vec![
        format!("\"frames\": {}", per_frame.len()),
        format!("\"rays\": {rays_total}"),
        format!("\"resolution_m\": {RESOLUTION_M}"),
        format!("\"threads\": {}", rayon::current_num_threads()),
        format!("\"end_voxels\": {end_voxels_total}"),
    ];
    let names = ["baseline", "per_ray", "per_scan", "per_end_voxel"];
    for (i, name) in names.iter().enumerate() {
        let mut frames: Vec<f64> = per_frame.iter().map(|f| f[i]).collect();
        let seconds: f64 = frames.iter().sum();
        frames.sort_by(f64::total_cmp);
        fields.push(format!(
            "\"{name}_median_frame_s\": {:.6}",
            frames[frames.len() / 2]
        ));
        fields.push(format!(
            "\"{name}_rays_per_s\": {:.0}",
            rays_total as f64 / seconds
        ));
    }
    println!("{{{}}}", fields.join(", "));
    if let Some(path) = out {
        std::fs::File::create(&path)?.write_all(&file)?;
    }
    Ok(())
}

/// The first `insert_ray` (through the `RayWalk` iterator), for the "before" rate.
fn baseline_insert(grid: &mut LocalGrid, origin: &Point3<f64>, end: &Point3<f64>) {
    let Some(walk) = grid.walk(origin, end) else {
        return;
    };
    let p = *grid.params();
    for step in walk {
        if let Some(i) = step.index {
            grid.update(i, if step.is_end { p.hit } else { p.miss });
        }
    }
}
