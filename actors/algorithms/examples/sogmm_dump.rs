//! Dumps what `scripts/sogmm_vs_sklearn.py` needs to compare our EM with
//! scikit-learn's `GaussianMixture` on the same data, and runs our EM on it.
//!
//! For each synthetic 160×120 frame (the room corner of `sogmm::synthetic` seen from
//! three poses) and the given σ: the 4D points, the number of components `M` from the
//! mean shift (thesis Eqs. 6.5–6.7) and the k-means++ partition (steps 1a–1c, seed 0)
//! are written to `OUT/frame<k>_sigma<σ>.{points.f64,assign.u32}` (little-endian,
//! row-major N×4 f64, and N u32); then EM runs from that partition (the SOGMM fit's own
//! EM, App. A) and one JSON line per frame is printed with `M`, the mean
//! log-likelihood of the points under the result (dense evaluation), the EM wall time
//! and iterations. Run with `RAYON_NUM_THREADS=1` for single-threaded timings.
//!
//! `cargo run --release -p troupe-algorithms --example sogmm_dump -- OUT SIGMA...`

use std::error::Error;
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use troupe_algorithms::sogmm::{
    EmConfig, MeanShiftConfig, fit_em, frame_points, init_from_partition, kmeans_plusplus,
    mean_shift_modes, synthetic,
};

fn run() -> Result<(), Box<dyn Error>> {
    let mut args = std::env::args().skip(1);
    let out = PathBuf::from(args.next().ok_or("usage: sogmm_dump OUT SIGMA...")?);
    let sigmas: Vec<f64> = args
        .map(|s| s.parse::<f64>().map_err(|e| format!("σ `{s}`: {e}")))
        .collect::<Result<_, _>>()?;
    if sigmas.is_empty() || sigmas.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
        return Err("give one or more bandwidths σ > 0".into());
    }
    std::fs::create_dir_all(&out).map_err(|e| format!("{}: {e}", out.display()))?;
    let intr = synthetic::intrinsics(160, 120);
    let scene = synthetic::Scene::room_corner();
    for sigma in sigmas {
        for (k, pose) in synthetic::room_views().iter().enumerate() {
            let (d, g) = scene.render(&intr, pose);
            let fp = frame_points(&d, &g, &intr, pose)?;
            let modes = mean_shift_modes(&fp.depth_intensity, sigma, &MeanShiftConfig::default());
            let m = modes.len().clamp(1, fp.len());
            let seeding = kmeans_plusplus(&fp.points, m, &mut ChaCha8Rng::seed_from_u64(0));
            let em = EmConfig::default();
            let init = init_from_partition(
                &fp.points,
                &seeding.assignment,
                seeding.centres.len(),
                em.reg_covar,
            )?;
            let start = Instant::now();
            let (gmm, report) = fit_em(&fp.points, &init, &em)?;
            let em_s = start.elapsed().as_secs_f64();
            let ll = gmm.mean_log_likelihood(&fp.points);

            let stem = format!("frame{k}_sigma{sigma}");
            let mut points = Vec::with_capacity(fp.len() * 32);
            for p in &fp.points {
                for v in p.iter() {
                    points.extend_from_slice(&v.to_le_bytes());
                }
            }
            let assign: Vec<u8> = seeding
                .assignment
                .iter()
                .flat_map(|a| a.to_le_bytes())
                .collect();
            let points_path = out.join(format!("{stem}.points.f64"));
            let assign_path = out.join(format!("{stem}.assign.u32"));
            std::fs::write(&points_path, points)?;
            std::fs::write(&assign_path, assign)?;
            println!(
                "{{\"frame\":{k},\"sigma\":{sigma},\"n\":{},\"m\":{},\"ll\":{ll},\"em_s\":{em_s},\"iterations\":{},\"converged\":{},\"points\":\"{}\",\"assign\":\"{}\"}}",
                fp.len(),
                seeding.centres.len(),
                report.iterations,
                report.converged,
                points_path.display(),
                assign_path.display()
            );
            std::io::stdout().flush()?;
        }
    }
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
