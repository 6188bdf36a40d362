//! Rays per second into the local occupancy grid, on simulated 160×120 frames of the
//! default cave — one side of `scripts/bench_grid_vs_octomap.py`, which times
//! OctoMap on the very same points.
//!
//! Run: `cargo run --release -p troupe-sims --example grid_insertion -- OUT.bin`
//! (writes the points it used to OUT.bin: per frame a u32 point count, the sensor
//! origin as 3 × f64, then the end points as 3 × f64 each, little endian).

use std::io::Write;
use std::time::Instant;

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use troupe_actors::grid::{LocalGrid, LogOddsParams};
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
    for (i, pair) in route.windows(2).step_by(7).take(10).enumerate() {
        let yaw = (pair[1].y - pair[0].y).atan2(pair[1].x - pair[0].x);
        let pose = Isometry3::from_parts(
            Translation3::from(pair[0].coords),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw),
        );
        let image = camera.render(&world, &pose, i as u64);
        let origin = Point3::from(pose.translation.vector);
        let mut ends = Vec::new();
        for row in 0..image.height {
            for col in 0..image.width {
                let d = f64::from(image.depth_at(col, row));
                if d > 0.0 {
                    let (u, v) = CameraParams::pixel_centre(col, row);
                    ends.push(camera.back_project(&pose, u, v, d));
                }
            }
        }
        let mut times = Vec::with_capacity(REPEATS);
        for _ in 0..REPEATS {
            let mut grid = LocalGrid::centred(
                &origin,
                &Vector3::new(20.0, 20.0, 12.0),
                RESOLUTION_M,
                LogOddsParams::default(),
            );
            let start = Instant::now();
            for end in &ends {
                grid.insert_ray(&origin, end, true, None);
            }
            times.push(start.elapsed().as_secs_f64());
            std::hint::black_box(&grid);
        }
        times.sort_by(f64::total_cmp);
        per_frame.push(times[REPEATS / 2]);
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
    let seconds: f64 = per_frame.iter().sum();
    per_frame.sort_by(f64::total_cmp);
    println!(
        "{{\"frames\": {}, \"rays\": {}, \"resolution_m\": {}, \"median_frame_s\": {:.6}, \"rays_per_s\": {:.0}}}",
        per_frame.len(),
        rays_total,
        RESOLUTION_M,
        per_frame[per_frame.len() / 2],
        rays_total as f64 / seconds
    );
    if let Some(path) = out {
        std::fs::File::create(&path)?.write_all(&file)?;
    }
    Ok(())
}
