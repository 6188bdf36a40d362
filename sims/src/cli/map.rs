//! `troupe map SEQUENCE_DIR`: a map built from a recorded sequence.

use std::path::PathBuf;

use anyhow::Context as _;
use troupe_algorithms::model::MapModel;
use troupe_algorithms::sogmm::MeanShiftKind;

use super::progress_bar;

#[derive(Debug, clap::Args)]
pub(crate) struct MapArgs {
    /// The sequence directory.
    sequence_dir: PathBuf,
    /// Map model of each keyframe: `sogmm` (self-organizing, thesis §6) or `windowed`
    /// (fixed-size occupied + free-space GMMs, paper §IV-A).
    #[arg(long, default_value = "sogmm")]
    model: MapModel,
    /// SOGMM mean-shift bandwidth σ (smaller: more components, finer map).
    #[arg(long, default_value_t = 0.02)]
    bandwidth: f64,
    /// SOGMM mean shift choosing the number of components: `reference` (the authors'
    /// published implementation) or `blurring` (the thesis text's, coarser).
    #[arg(long, value_name = "KIND", default_value_t = MeanShiftKind::Reference)]
    mean_shift: MeanShiftKind,
    /// Use every N-th frame of the sequence.
    #[arg(long, value_name = "N", default_value_t = 1)]
    stride: usize,
    /// Fit every N-th pixel in each image direction.
    #[arg(long, value_name = "N", default_value_t = 2)]
    pixel_stride: u32,
    /// Keyframe overlap threshold: a frame becomes a keyframe when less than this
    /// fraction of its view is covered by an earlier keyframe.
    #[arg(long, default_value_t = 0.5)]
    overlap: f64,
    /// Points sampled from the map into the PLY file.
    #[arg(long, value_name = "N", default_value_t = 200_000)]
    ply_points: usize,
    /// Seed of the fits and of the PLY sampling.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Output directory (created if needed); default `maps/<sequence directory name>`.
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Never show a progress bar (it is shown only on a terminal anyway).
    #[arg(long)]
    no_progress: bool,
}

pub(crate) fn run(args: MapArgs) -> anyhow::Result<()> {
    use crate::sequence::{MapBuildOptions, Sequence, build_map};
    use rand::SeedableRng;
    use troupe_algorithms::mapfile::{sample_surface, write_atomically, write_ply};

    if !(args.bandwidth.is_finite() && args.bandwidth > 0.0) {
        anyhow::bail!("--bandwidth must be a number > 0, got {}", args.bandwidth);
    }
    if args.stride == 0 || args.pixel_stride == 0 {
        anyhow::bail!("--stride and --pixel-stride must be at least 1");
    }
    if !(0.0..=1.0).contains(&args.overlap) {
        anyhow::bail!("--overlap must be in [0, 1], got {}", args.overlap);
    }
    let sequence = Sequence::open(&args.sequence_dir)?;
    let options = MapBuildOptions {
        model: args.model,
        bandwidth: args.bandwidth,
        mean_shift: args.mean_shift,
        frame_stride: args.stride,
        pixel_stride: args.pixel_stride,
        overlap_threshold: args.overlap,
        seed: args.seed,
        ..MapBuildOptions::default()
    };
    let frames = sequence.len().div_ceil(args.stride) as u64;
    let bar = progress_bar(frames, args.no_progress);
    let (gmm_map, stats) = build_map(&sequence, &options, |done, total| {
        bar.set_position(done as u64);
        bar.set_message(format!("{done}/{total} frames"));
    })?;
    bar.finish_and_clear();
    let merged = gmm_map.merged_occupied().with_context(|| {
        format!(
            "no keyframe of {} could be fitted ({} frames, {} failed fits)",
            args.sequence_dir.display(),
            stats.frames,
            stats.failed_fits
        )
    })?;
    let out = args.out.clone().unwrap_or_else(|| {
        let name = args
            .sequence_dir
            .file_name()
            .map_or_else(|| "sequence".into(), |n| n.to_string_lossy().into_owned());
        PathBuf::from("maps").join(name)
    });
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(args.seed);
    let points = sample_surface(&merged, args.ply_points, &mut rng);
    let mut ply = Vec::with_capacity(256 + 19 * points.len());
    write_ply(&mut ply, &points).context("encoding the PLY point cloud")?;
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    gmm_map.save(&out.join("map.troupe"))?;
    write_atomically(&out.join("map.ply"), &ply)?;
    println!("{}", serde_json::to_string(&stats)?);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::{Command, parse};

    #[test]
    fn map_flags_parse() {
        match parse(&["map", "seq"]).expect("map").command {
            Command::Map(a) => {
                assert_eq!(a.sequence_dir, PathBuf::from("seq"));
                assert_eq!(a.model, MapModel::Sogmm);
                assert_eq!(a.mean_shift, MeanShiftKind::Reference);
                assert_eq!((a.stride, a.pixel_stride, a.ply_points), (1, 2, 200_000));
                assert_eq!(a.out, None);
            }
            other => panic!("{other:?}"),
        }
        match parse(&[
            "map",
            "seq",
            "--model",
            "windowed",
            "--bandwidth",
            "0.05",
            "--mean-shift",
            "blurring",
            "--stride",
            "3",
            "--out",
            "o",
        ])
        .expect("map")
        .command
        {
            Command::Map(a) => {
                assert_eq!(a.model, MapModel::Windowed);
                assert_eq!(a.mean_shift, MeanShiftKind::Blurring);
                assert_eq!((a.bandwidth, a.stride), (0.05, 3));
                assert_eq!(a.out, Some(PathBuf::from("o")));
            }
            other => panic!("{other:?}"),
        }
        assert!(parse(&["map"]).is_err(), "the sequence is required");
        assert!(parse(&["map", "seq", "--model", "octree"]).is_err());
    }
}
