//! The `troupe` command line.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context as _;
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use troupe_actors::mapper::MapModel;
use troupe_sims::report::write_run;
use troupe_sims::scenario::Scenario;
use troupe_sims::study::{
    RunRow, Study, Variant, finished_run, run_variants, save_finished_run, write_study,
};
use troupe_sims::team::Team;

/// troupe: teams of robots that explore and map unknown places over weak links.
#[derive(Debug, Parser)]
#[command(name = "troupe", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run a team of simulated robots in one process (sim time, deterministic) and
    /// write a report to `OUT/<scenario name>/`.
    Run(RunArgs),
    /// Run a study: every combination of the study's levels under every seed, in
    /// parallel; writes `OUT/<study>/results.csv` (one row per run), `aggregate.csv`
    /// (means and 95% intervals over seeds), plots, and each run's report under
    /// `OUT/<study>/runs/`.
    Sweep(SweepArgs),
    /// Build a map from a recorded sequence (TUM RGB-D layout: camera.toml, depth.txt,
    /// rgb.txt, groundtruth.txt, depth/ and rgb/ PNGs); write `map.troupe` (the
    /// keyframe mixtures) and `map.ply` (points sampled from it, with intensity) to
    /// OUT, and print one JSON line of statistics.
    Map(MapArgs),
    /// Run a scenario's team as separate `troupe-robot` processes on this machine,
    /// talking over zenoh on loopback (robot i listens on BASE_PORT + i and connects
    /// to the others); writes the robot files, each robot's `summary.json` and
    /// `trajectory.csv`, and `launch.json` (exit codes, closest approach) to
    /// `OUT/<scenario name>/`. Ctrl-C stops every robot cleanly.
    Launch(LaunchArgs),
}

#[derive(Debug, clap::Args)]
struct LaunchArgs {
    /// Scenario file (TOML): world, robots, robot configuration.
    scenario: PathBuf,
    /// Wall seconds each robot runs; without it, until Ctrl-C.
    #[arg(long, value_name = "SECONDS")]
    duration_s: Option<f64>,
    /// Port of robot 0; robot i uses BASE_PORT + i.
    #[arg(long, default_value_t = 7447)]
    base_port: u16,
    /// Directory that receives the launch directory.
    #[arg(long, default_value = "runs/launch")]
    out: PathBuf,
}

#[derive(Debug, clap::Args)]
struct SweepArgs {
    /// Study file (TOML), e.g. `sims/studies/link_constraint.toml`.
    study: PathBuf,
    /// Runs at once (default: the number of CPU cores).
    #[arg(long)]
    jobs: Option<usize>,
    /// Directory that receives the study directory.
    #[arg(long, default_value = "runs")]
    out: PathBuf,
    /// List the runs and exit without running them.
    #[arg(long)]
    dry_run: bool,
    /// Reuse runs that an earlier sweep into the same directory finished with the
    /// same scenario (their `runs/<run>/study_row.json`); fly only the rest.
    #[arg(long)]
    resume: bool,
}

#[derive(Debug, clap::Args)]
struct MapArgs {
    /// The sequence directory.
    sequence_dir: PathBuf,
    /// Map model of each keyframe: `sogmm` (self-organizing, thesis §6) or `windowed`
    /// (fixed-size occupied + free-space GMMs, paper §IV-A).
    #[arg(long, default_value = "sogmm")]
    model: MapModel,
    /// SOGMM mean-shift bandwidth σ (smaller: more components, finer map).
    #[arg(long, default_value_t = 0.02)]
    bandwidth: f64,
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

#[derive(Debug, clap::Args)]
struct RunArgs {
    /// Scenario file (TOML). Without it, the built-in default runs: two robots
    /// exploring a procedural cave for 120 simulated seconds.
    scenario: Option<PathBuf>,
    /// Override the scenario's run seed.
    #[arg(long)]
    seed: Option<u64>,
    /// Override the simulated duration, seconds.
    #[arg(long, value_name = "SECONDS")]
    duration_s: Option<f64>,
    /// Override the number of robots.
    #[arg(long)]
    robots: Option<u32>,
    /// Override the run name (the output directory under OUT).
    #[arg(long)]
    name: Option<String>,
    /// Directory that receives run directories.
    #[arg(long, default_value = "runs")]
    out: PathBuf,
    /// Never show a progress bar (it is shown only on a terminal anyway).
    #[arg(long)]
    no_progress: bool,
}

fn launch(args: LaunchArgs) -> anyhow::Result<()> {
    if args.duration_s.is_some_and(|d| !(d.is_finite() && d > 0.0)) {
        anyhow::bail!("--duration-s must be a finite number > 0");
    }
    let scenario = Scenario::load(&args.scenario)?;
    let dir = args.out.join(&scenario.name);
    let exe = std::env::current_exe()
        .context("locating troupe")?
        .with_file_name(format!("troupe-robot{}", std::env::consts::EXE_SUFFIX));
    if !exe.is_file() {
        anyhow::bail!(
            "{} not found: build it with `cargo build --release -p troupe-sims --bins`",
            exe.display()
        );
    }
    println!(
        "launching {} robots of {} as processes (ports {}..), outputs in {}",
        scenario.robots,
        args.scenario.display(),
        args.base_port,
        dir.display()
    );
    let report =
        troupe_sims::launch::launch(&args.scenario, &dir, args.base_port, args.duration_s, &exe)?;
    let failed = report.exit_codes.iter().filter(|c| **c != Some(0)).count();
    println!(
        "{} robots finished ({} failed); closest approach {}",
        report.exit_codes.len(),
        failed,
        report
            .min_inter_robot_distance_m
            .map_or("n/a".into(), |d| format!("{d:.2} m"))
    );
    if failed > 0 {
        anyhow::bail!("{failed} robot processes failed");
    }
    Ok(())
}

fn main() -> ExitCode {
    troupe_sims::init_logging();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Run(args) => run(args),
        Command::Sweep(args) => sweep(args),
        Command::Map(args) => map(args),
        Command::Launch(args) => launch(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::FAILURE
        }
    }
}

fn progress_bar(len: u64, hidden: bool) -> ProgressBar {
    if hidden || !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(len);
    bar.set_style(
        ProgressStyle::with_template("{spinner} [{elapsed_precise}] {wide_bar} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar
}

fn map(args: MapArgs) -> anyhow::Result<()> {
    use rand::SeedableRng;
    use troupe_actors::mapper::mapfile::{sample_surface, write_atomically, write_ply};
    use troupe_sims::sequence::{MapBuildOptions, Sequence, build_map};

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

fn run(args: RunArgs) -> anyhow::Result<()> {
    let mut scenario = match &args.scenario {
        Some(path) => Scenario::load(path)?,
        None => Scenario::default(),
    };
    let source = args
        .scenario
        .clone()
        .unwrap_or_else(|| PathBuf::from("<built-in default>"));
    if let Some(seed) = args.seed {
        scenario.seed = seed;
    }
    if let Some(d) = args.duration_s {
        scenario.duration_s = d;
    }
    if let Some(n) = args.robots {
        scenario.robots = n;
    }
    if let Some(name) = args.name {
        scenario.name = name;
    }
    scenario.validate(&source)?;
    let team = Team::new(&scenario)
        .with_context(|| format!("assembling the robots of {}", source.display()))?;
    let bar = progress_bar(
        (scenario.duration_s * 10.0).round() as u64,
        args.no_progress,
    );
    let duration_s = scenario.duration_s;
    let output = team.run(|t| {
        bar.set_position((t * 10.0).round() as u64);
        bar.set_message(format!("{t:.0}/{duration_s:.0} sim s"));
    });
    bar.finish_and_clear();
    let dir = write_run(&args.out, &scenario.name, &output)
        .with_context(|| format!("writing the report under {}", args.out.display()))?;
    let s = &output.summary;
    println!(
        "{}: {} robots, {:.0} sim s in {:.1} wall s ({:.1}× real time); coverage {:.1}% ({:.0} of {:.0} m³), collisions {}",
        s.scenario,
        s.robots,
        s.duration_s,
        output.timing.wall_s,
        output.timing.sim_seconds_per_wall_second,
        100.0 * s.coverage.final_fraction,
        s.coverage.explored_volume_m3,
        s.world.free_volume_m3,
        s.collisions
    );
    println!("report: {}", dir.display());
    Ok(())
}

fn sweep(args: SweepArgs) -> anyhow::Result<()> {
    let study = Study::load(&args.study)?;
    let variants = study.variants()?;
    if args.dry_run {
        for v in &variants {
            println!("{}", v.name);
        }
        return Ok(());
    }
    let jobs = args.jobs.unwrap_or_else(|| {
        std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get)
    });
    let root = args.out.join(&study.name);
    let runs_dir = root.join("runs");
    let total = variants.len();
    eprintln!(
        "{}: {total} runs ({} seeds), {jobs} at a time",
        study.name,
        study.seeds.len()
    );
    let mut rows: Vec<Option<RunRow>> = variants
        .iter()
        .map(|v| {
            args.resume
                .then(|| finished_run(&runs_dir.join(&v.name), v, &study.coverage_levels))
                .flatten()
        })
        .collect();
    let to_fly: Vec<Variant> = variants
        .iter()
        .zip(&rows)
        .filter(|(_, row)| row.is_none())
        .map(|(v, _)| v.clone())
        .collect();
    let reused = total - to_fly.len();
    if args.resume {
        eprintln!(
            "resuming: {reused} of {total} runs reused from {}",
            runs_dir.display()
        );
    }
    let started = std::time::Instant::now();
    let mut finished = reused;
    let mut write_errors = Vec::new();
    let flown = run_variants(
        &to_fly,
        &study.coverage_levels,
        jobs,
        |variant, output, row| {
            finished += 1;
            let saved = write_run(&runs_dir, &variant.name, output)
                .and_then(|dir| save_finished_run(&dir, variant, row));
            if let Err(e) = saved {
                write_errors.push(format!("{}: {e}", variant.name));
            }
            eprintln!(
                "[{finished}/{total}] {}: coverage {:.1}%, collisions {}, map bytes offered {} sent {}, {:.0} wall s",
                variant.name,
                100.0 * row.final_coverage,
                row.collisions,
                row.map_bytes_offered,
                row.map_bytes_sent,
                row.wall_s
            );
        },
    )?;
    let mut flown = flown.into_iter();
    for row in &mut rows {
        if row.is_none() {
            *row = flown.next();
        }
    }
    let rows: Vec<RunRow> = rows.into_iter().flatten().collect();
    if let Some(e) = write_errors.first() {
        anyhow::bail!("writing a run report under {}: {e}", runs_dir.display());
    }
    let written = write_study(&root, &study, &rows)
        .with_context(|| format!("writing the study outputs under {}", root.display()))?;
    println!(
        "{}: {total} runs in {:.0} wall s; outputs: {}",
        study.name,
        started.elapsed().as_secs_f64(),
        written.join(", ")
    );
    Ok(())
}
