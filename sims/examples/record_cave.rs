//! Record a flight along the centre line of a procedural cave as a sequence in the TUM
//! RGB-D layout (`troupe_sims::sequence`), to try `troupe map` on:
//!
//! ```sh
//! cargo run --release -p troupe-sims --example record_cave -- /tmp/cave_seq 300
//! cargo run --release -p troupe-sims --bin troupe -- map /tmp/cave_seq --out /tmp/cave_map
//! ```
//!
//! Arguments: output directory, number of frames (default 300), cave seed (default 1).
//! The camera (160×120, D435-like field of view, 5 m range, no noise) flies at
//! 0.5 m/s, 10 frames per second, looking along the route.

use std::error::Error;
use std::path::PathBuf;
use std::process::ExitCode;

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
use troupe_sims::camera::CameraParams;
use troupe_sims::sequence::record_camera;
use troupe_sims::world::{CaveParams, CaveWorld};

/// Poses every `step_m` along the polyline, yawed along it (level camera).
fn poses_along(route: &[Point3<f64>], step_m: f64, count: usize) -> Vec<Isometry3<f64>> {
    let mut out = Vec::with_capacity(count);
    let mut carried = 0.0;
    for w in route.windows(2) {
        let d = w[1] - w[0];
        let len = d.norm();
        if len < 1e-9 {
            continue;
        }
        let yaw = d.y.atan2(d.x);
        let mut s = carried;
        while s < len && out.len() < count {
            let p = w[0] + d * (s / len);
            out.push(Isometry3::from_parts(
                Translation3::from(p.coords),
                UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
            ));
            s += step_m;
        }
        carried = s - len;
    }
    out
}

fn run() -> Result<(), Box<dyn Error>> {
    let mut args = std::env::args().skip(1);
    let dir = PathBuf::from(
        args.next()
            .ok_or("usage: record_cave DIR [FRAMES] [SEED]")?,
    );
    let frames: usize = match args.next() {
        Some(s) => s.parse().map_err(|e| format!("FRAMES `{s}`: {e}"))?,
        None => 300,
    };
    let seed: u64 = match args.next() {
        Some(s) => s.parse().map_err(|e| format!("SEED `{s}`: {e}"))?,
        None => 1,
    };
    let world = CaveWorld::generate(&CaveParams::default(), seed);
    let route = world.centreline_route(0, 1);
    let poses = poses_along(&route, 0.05, frames);
    let path: Vec<(f64, Isometry3<f64>)> = poses
        .into_iter()
        .enumerate()
        .map(|(i, p)| (0.1 * i as f64, p))
        .collect();
    let out = record_camera(&dir, &world, &CameraParams::default(), &path, seed)?;
    println!("{} frames in {}", path.len(), out.display());
    Ok(())
}

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", troupe_core::ErrorChain(e.as_ref()));
            ExitCode::FAILURE
        }
    }
}
