//! A simulated flight through a synthetic corridor, mapped incrementally (thesis
//! §6.1.4): prints per-frame time against the global map size every 25 frames, and at
//! the end times the relevant-subset step (Eq. 6.9) through the spatial hash against the
//! same step over all components.
//!
//! ```sh
//! cargo run --release -p troupe-algorithms --example incremental_flight -- \
//!     [frames=300] [width=80] [height=60] [sigma=0.03] [length_m=40]
//! ```
//! Set `RAYON_NUM_THREADS=1` for single-threaded numbers.

use std::time::Instant;

use nalgebra::Point3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use troupe_algorithms::global_map::{GlobalMap, GlobalMapConfig};
use troupe_algorithms::sogmm::{SogmmConfig, frame_points, synthetic};

fn arg<T: std::str::FromStr>(i: usize, default: T) -> T {
    std::env::args()
        .nth(i)
        .and_then(|s| s.parse().ok())
        .unwrap_or(default)
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let frames: usize = arg(1, 300);
    let width: u32 = arg(2, 80);
    let height: u32 = arg(3, 60);
    let sigma: f64 = arg(4, 0.03);
    let length_m: f64 = arg(5, 40.0);
    let scene = synthetic::Scene::corridor(length_m);
    let intr = synthetic::intrinsics(width, height);
    let config = GlobalMapConfig {
        sogmm: SogmmConfig {
            bandwidth: sigma,
            ..SogmmConfig::default()
        },
        ..GlobalMapConfig::default()
    };
    let mut map = GlobalMap::new(config)?;
    println!(
        "{frames} frames {width}×{height}, σ = {sigma}, corridor {length_m} m, hash α = {} m, φ = {}",
        config.cell_m, config.relevance_threshold
    );
    println!(
        "{:>5} {:>7} {:>9} {:>7} {:>8} {:>8} {:>9} {:>9} {:>9}",
        "frame", "K", "support", "cached", "|B|", "relevant", "frame_ms", "subset_ms", "fit_ms"
    );
    let mut window_ms = Vec::new();
    let mut last = None;
    for i in 0..frames {
        let pose = synthetic::flight_pose(i, frames, length_m);
        let (d, g) = scene.render(&intr, &pose);
        let fp = frame_points(&d, &g, &intr, &pose)?;
        let t = Instant::now();
        let up = map.insert_frame(&fp)?;
        let ms = t.elapsed().as_secs_f64() * 1e3;
        window_ms.push(ms);
        if (i + 1) % 25 == 0 || i == 0 {
            println!(
                "{:>5} {:>7} {:>9.0} {:>7} {:>8} {:>8} {:>9.1} {:>9.2} {:>9.1}   window: median {:.1} ms, mean {:.1} ms, max {:.1} ms",
                i + 1,
                map.len(),
                map.total_support(),
                map.cached_points(),
                up.queried_components,
                up.relevant_points,
                ms,
                up.relevant_s * 1e3,
                up.fit_s * 1e3,
                median(&mut window_ms),
                window_ms.iter().sum::<f64>() / window_ms.len() as f64,
                window_ms.iter().copied().fold(0.0, f64::max)
            );
            window_ms.clear();
        }
        last = Some(fp);
    }
    let Some(fp) = last else { return Ok(()) };
    // The relevant-subset step on the last frame: hash vs all components.
    let reps = 5;
    let mut hash_s = Vec::new();
    let mut all_s = Vec::new();
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for _ in 0..reps {
        let t = Instant::now();
        a = map.relevant(&fp.points);
        hash_s.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        b = map.relevant_all(&fp.points);
        all_s.push(t.elapsed().as_secs_f64());
    }
    let (h, f) = (median(&mut hash_s), median(&mut all_s));
    let differ = a.iter().zip(&b).filter(|(x, y)| x != y).count();
    println!(
        "relevant subset of the last frame ({} points, K = {}): hash {:.2} ms, all components {:.1} ms, ratio {:.1}×; {} of {} points classified differently ({} relevant via hash, {} via all)",
        fp.len(),
        map.len(),
        h * 1e3,
        f * 1e3,
        f / h,
        differ,
        fp.len(),
        a.iter().filter(|x| **x).count(),
        b.iter().filter(|x| **x).count()
    );
    if let Some(gmm) = map.gmm() {
        // Reconstruction error of the global map (§6.2.4) against the exact surfaces.
        let samples = gmm
            .marginal_spatial()
            .sample(50_000, &mut ChaCha8Rng::seed_from_u64(1));
        let d: Vec<f64> = samples
            .iter()
            .map(|s| scene.distance(&Point3::from(*s)))
            .collect();
        println!(
            "global map: MRE {:.4} m, precision within 1 cm {:.3} (50 000 samples vs the exact scene)",
            d.iter().sum::<f64>() / d.len() as f64,
            d.iter().filter(|x| **x <= 0.01).count() as f64 / d.len() as f64
        );
    }
    println!(
        "hash: {} cells, {} entries; map {} components, {} parameter bytes, {} local fits",
        map.hash().cells(),
        map.hash().entries(),
        map.len(),
        map.parameter_bytes(),
        map.fits()
    );
    Ok(())
}
