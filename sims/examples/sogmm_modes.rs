//! Dumps the 2D (depth, intensity) mean-shift data of frames and the number of modes
//! `M` troupe's two mean shifts find on them, for `scripts/sogmm_meanshift_vs_sklearn.py`
//! to compare with scikit-learn's `MeanShift(bandwidth=σ, bin_seeding=True)`.
//!
//! Frames: the synthetic room corner (`sogmm::synthetic`) at 160×120 from three views
//! and at 40×30 from the first (the frame the unit test pins), and, with `--sequence
//! DIR`, every `--every`-th frame of a recorded sequence (e.g. a cave flight from the
//! `record_cave` example: the cave world and camera of `troupe run`), decimated by 2
//! as the mapper does. For each frame and σ it writes `OUT/<frame>_sigma<σ>.f64`
//! (little-endian row-major N×2 f64) and prints one JSON line: frame, σ, N, `M` of the
//! reference and of the blurring mean shift, and the reference's wall seconds.
//!
//! ```sh
//! cargo run --release -p troupe-sims --example sogmm_modes -- OUT 0.02 0.03 \
//!     [--sequence DIR [--every 40]]
//! ```

use std::error::Error;
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use nalgebra::Isometry3;
use troupe_actors::mapper::decimate;
use troupe_algorithms::sogmm::{
    MeanShiftConfig, MeanShiftKind, frame_points, mean_shift_modes, synthetic,
};
use troupe_sims::sequence::Sequence;

/// A named frame's (depth, intensity) data.
type NamedData = (String, Vec<[f64; 2]>);

/// Every frame asked for.
fn frames(sequence: Option<&PathBuf>, every: usize) -> Result<Vec<NamedData>, Box<dyn Error>> {
    let views = synthetic::room_views();
    let scene = synthetic::Scene::room_corner();
    let mut out = Vec::new();
    let mut synth =
        |name: String, w: u32, h: u32, pose: &Isometry3<f64>| -> Result<(), Box<dyn Error>> {
            let intr = synthetic::intrinsics(w, h);
            let (d, g) = scene.render(&intr, pose);
            let fp = frame_points(&d, &g, &intr, pose)?;
            out.push((name, fp.depth_intensity));
            Ok(())
        };
    synth("room40x30_0".into(), 40, 30, &views[0])?;
    for (k, pose) in views.iter().enumerate() {
        synth(format!("room160x120_{k}"), 160, 120, pose)?;
    }
    if let Some(dir) = sequence {
        let seq = Sequence::open(dir)?;
        for i in (0..seq.len()).step_by(every.max(1)) {
            let frame = decimate(&seq.frame(i)?, 2);
            let fp = frame_points(
                &frame.depth_m,
                &frame.intensity,
                &frame.intrinsics,
                &frame.pose,
            )?;
            if !fp.is_empty() {
                out.push((format!("cave_{i}"), fp.depth_intensity));
            }
        }
    }
    Ok(out)
}

fn run() -> Result<(), Box<dyn Error>> {
    let usage = "usage: sogmm_modes OUT SIGMA... [--sequence DIR [--every N]]";
    let mut args = std::env::args().skip(1);
    let out = PathBuf::from(args.next().ok_or(usage)?);
    let (mut sigmas, mut sequence, mut every) = (Vec::new(), None, 40usize);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--sequence" => sequence = Some(PathBuf::from(args.next().ok_or(usage)?)),
            "--every" => {
                let n = args.next().ok_or(usage)?;
                every = n.parse().map_err(|e| format!("--every `{n}`: {e}"))?;
            }
            s => sigmas.push(s.parse::<f64>().map_err(|e| format!("σ `{s}`: {e}"))?),
        }
    }
    if sigmas.is_empty() || sigmas.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
        return Err("give one or more bandwidths σ > 0".into());
    }
    std::fs::create_dir_all(&out).map_err(|e| format!("{}: {e}", out.display()))?;
    for (name, data) in frames(sequence.as_ref(), every)? {
        for &sigma in &sigmas {
            let start = Instant::now();
            let reference = mean_shift_modes(&data, sigma, &MeanShiftConfig::default());
            let reference_s = start.elapsed().as_secs_f64();
            let blurring =
                mean_shift_modes(&data, sigma, &MeanShiftConfig::of(MeanShiftKind::Blurring));
            let path = out.join(format!("{name}_sigma{sigma}.f64"));
            let bytes: Vec<u8> = data
                .iter()
                .flat_map(|p| p.iter().flat_map(|v| v.to_le_bytes()))
                .collect();
            std::fs::write(&path, bytes).map_err(|e| format!("{}: {e}", path.display()))?;
            let line = format!(
                "{{\"frame\":\"{name}\",\"sigma\":{sigma},\"n\":{},\"data\":\"{}\",\"m_reference\":{},\"m_blurring\":{},\"reference_s\":{reference_s:.4}}}",
                data.len(),
                path.display(),
                reference.len(),
                blurring.len(),
            );
            let mut stdout = std::io::stdout().lock();
            writeln!(stdout, "{line}")?;
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
