//! Time the stages of a SOGMM fit (mean shift, k-means++, EM) on the synthetic
//! 160×120 room frame for several seeds, single-threaded: a timing profile of
//! `fit_points` (thesis Fig. 6.1). Medians of `reps` runs per seed.
//!
//! ```sh
//! RAYON_NUM_THREADS=1 cargo run --release -p troupe-algorithms --example sogmm_stages -- \
//!     [sigma=0.02] [seeds=5] [reps=3]
//! ```

use std::time::Instant;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use troupe_algorithms::sogmm::{
    EmConfig, MeanShiftConfig, SogmmConfig, fit_em, fit_points, frame_points, init_from_partition,
    kmeans_plusplus, mean_shift_modes, synthetic,
};

fn arg<T: std::str::FromStr>(i: usize, default: T) -> T {
    std::env::args()
        .nth(i)
        .and_then(|s| s.parse().ok())
        .unwrap_or(default)
}

/// FNV-1a over the bits of every parameter: equal when two fits are bit-identical.
fn fit_bits(gmm: &troupe_algorithms::mixture::Gmm4) -> u64 {
    let values = gmm
        .weights()
        .iter()
        .copied()
        .chain(gmm.means().iter().flat_map(|m| m.iter().copied()))
        .chain(gmm.covariances().iter().flat_map(|c| c.iter().copied()));
    values.fold(0xcbf2_9ce4_8422_2325, |h, v| {
        (h ^ v.to_bits()).wrapping_mul(0x0100_0000_01b3)
    })
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let sigma: f64 = arg(1, 0.02);
    let seeds: u64 = arg(2, 5);
    let reps: usize = arg(3, 3);
    let intr = synthetic::intrinsics(160, 120);
    let pose = synthetic::room_pose();
    let (d, g) = synthetic::Scene::room_corner().render(&intr, &pose);
    let fp = frame_points(&d, &g, &intr, &pose)?;
    println!("{} points, σ = {sigma}", fp.len());
    println!(
        "{:>4} {:>5} {:>5} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>6} {:>6} {:>16}",
        "seed",
        "M",
        "iters",
        "ms_shift",
        "kmeans_ms",
        "init_ms",
        "em_ms",
        "fit_ms",
        "ms/iter",
        "evals",
        "kept",
        "fit_bits"
    );
    for seed in 0..seeds {
        let (mut t_ms, mut t_km, mut t_init, mut t_em, mut t_fit) =
            (vec![], vec![], vec![], vec![], vec![]);
        let mut iters = 0;
        let mut m = 0;
        let (mut evals, mut kept) = (0.0, 0.0);
        let mut bits = 0u64;
        for _ in 0..reps {
            let t = Instant::now();
            let modes = mean_shift_modes(&fp.depth_intensity, sigma, &MeanShiftConfig::default());
            t_ms.push(t.elapsed().as_secs_f64());
            let t = Instant::now();
            let seeding = kmeans_plusplus(
                &fp.points,
                modes.len().max(1),
                &mut ChaCha8Rng::seed_from_u64(seed),
            );
            t_km.push(t.elapsed().as_secs_f64());
            let t = Instant::now();
            let init =
                init_from_partition(&fp.points, &seeding.assignment, seeding.centres.len(), 1e-6)?;
            t_init.push(t.elapsed().as_secs_f64());
            let t = Instant::now();
            let (_, report) = fit_em(&fp.points, &init, &EmConfig::default())?;
            t_em.push(t.elapsed().as_secs_f64());
            let t = Instant::now();
            let fit = fit_points(
                &fp.points,
                &fp.depth_intensity,
                &SogmmConfig {
                    bandwidth: sigma,
                    seed,
                    ..SogmmConfig::default()
                },
            )?;
            t_fit.push(t.elapsed().as_secs_f64());
            iters = fit.report.em.iterations;
            m = fit.gmm.len();
            evals = fit.report.em.mean_components_per_point;
            kept = fit.report.em.mean_kept_per_point;
            bits = fit_bits(&fit.gmm);
            let _ = report;
        }
        let em = median(t_em);
        println!(
            "{seed:>4} {m:>5} {iters:>5} {:>9.1} {:>9.1} {:>9.1} {:>9.1} {:>9.1} {:>9.2} {evals:>6.1} {kept:>6.1} {bits:016x}",
            median(t_ms) * 1e3,
            median(t_km) * 1e3,
            median(t_init) * 1e3,
            em * 1e3,
            median(t_fit) * 1e3,
            em * 1e3 / iters.max(1) as f64
        );
    }
    Ok(())
}
