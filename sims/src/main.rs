//! The `troupe` command line.

use std::io::{IsTerminal, Write as _};
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context as _;
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use troupe_actors::mapper::MapModel;
use troupe_actors::mapper::sogmm::MeanShiftKind;
use troupe_record::{Clock, Recorder, SharedRecorder};
use troupe_sims::launch::LaunchOptions;
use troupe_sims::process::{RobotProcess, run_until_signal, shutdown_signal};
use troupe_sims::recording::{
    RUN_RECORDING, RecordingFile, record_options, record_outputs, record_world,
};
use troupe_sims::report::write_run;
use troupe_sims::router::{Router, settings};
use troupe_sims::scenario::Scenario;
use troupe_sims::study::{
    RunRow, Shard, Study, Variant, finished_run, merge_finished_runs, run_variants,
    save_finished_run, write_study,
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
    /// `OUT/<study>/runs/`. Across machines: `--shard K/N` on each, then `--merge`.
    Sweep(SweepArgs),
    /// Build a map from a recorded sequence (TUM RGB-D layout: camera.toml, depth.txt,
    /// rgb.txt, groundtruth.txt, depth/ and rgb/ PNGs); write `map.troupe` (the
    /// keyframe mixtures) and `map.ply` (points sampled from it, with intensity) to
    /// OUT, and print one JSON line of statistics.
    Map(MapArgs),
    /// Run a scenario's team as separate `troupe robot` processes on this machine,
    /// talking over zenoh on loopback (robot i listens on BASE_PORT + i and connects
    /// to the others; with `--router`, through one zenoh router on BASE_PORT);
    /// writes the robot files, each robot's `summary.json` and `trajectory.csv`, and
    /// `launch.json` (exit codes, closest approach) to `OUT/<scenario name>/`. Ctrl-C
    /// stops every robot cleanly.
    Launch(LaunchArgs),
    /// Run one robot of a team in this process: its simulated vehicle and camera in
    /// the scenario's world (or, with `sequence` in the robot file, a recorded
    /// sequence replayed as its sensor), the standard actors on the wall clock, the
    /// link over zenoh. Writes `summary.json` and `trajectory.csv` on exit (end of
    /// `duration_s`, Ctrl-C or SIGTERM).
    Robot(RobotArgs),
    /// Run a zenoh router until Ctrl-C or SIGTERM: robots in client mode
    /// (`[zenoh] mode = "client"`, `connect = ["tcp/<this host>:7447"]`) reach each
    /// other through it instead of connecting to every other robot.
    Router(RouterArgs),
    /// Write a team's credentials for mutual TLS with access control
    /// (`docs/security.md`): a CA, one certificate and key per robot, for the base
    /// station and for a router, each named by its link id (`robot<i>`), and the
    /// `[zenoh]` tables that use them (`<member>.zenoh.toml`).
    Keys(KeysArgs),
    /// Run the base station: join the team over zenoh without flying, collect every
    /// robot's keyframes, odometry and plans, print one status line per robot per
    /// second, and on exit (end of `duration_s`, Ctrl-C or SIGTERM) write
    /// `merged_map.ply`, `merged_map.troupe`, `maps/robot<i>.troupe|.ply` and
    /// `summary.json`.
    Base(BaseArgs),
    /// Read a recording (`run.mcap` of `troupe run`, a robot process or the base
    /// station): print its channels (schema, messages) and time span, and with
    /// `--plots DIR` draw a run's plots again from the recording alone.
    Replay(ReplayArgs),
}

#[derive(Debug, clap::Args)]
struct ReplayArgs {
    /// The MCAP recording, e.g. `runs/default/run.mcap`.
    recording: PathBuf,
    /// Draw the run's plots (coverage, link bytes, speed, nearest robot,
    /// trajectories) from the recording's samples into this directory.
    #[arg(long, value_name = "DIR")]
    plots: Option<PathBuf>,
    /// Print the summary as one JSON object instead of a table.
    #[arg(long)]
    json: bool,
}

#[derive(Debug, clap::Args)]
struct BaseArgs {
    /// The base file (TOML): `scenario`, `base_id`, `duration_s`, `out`,
    /// `ply_points`, `[zenoh]`.
    #[arg(long)]
    config: PathBuf,
    /// Override the file's `duration_s` (wall seconds).
    #[arg(long, value_name = "SECONDS")]
    duration_s: Option<f64>,
}

#[derive(Debug, clap::Args)]
struct RobotArgs {
    /// The robot file (TOML): `robot`, `scenario`, `duration_s`, `out`, `sequence`,
    /// `[zenoh]`.
    #[arg(long)]
    config: PathBuf,
    /// Override the file's `duration_s` (wall seconds).
    #[arg(long, value_name = "SECONDS")]
    duration_s: Option<f64>,
}

#[derive(Debug, clap::Args)]
struct RouterArgs {
    /// Endpoint to listen on (repeat for several); default `tcp/0.0.0.0:7447`
    /// without `--config`.
    #[arg(long, value_name = "ENDPOINT")]
    listen: Vec<String>,
    /// Another router to connect to (repeat for several).
    #[arg(long, value_name = "ENDPOINT")]
    connect: Vec<String>,
    /// A file with the router's `[zenoh]` table (TLS, users, access control; e.g.
    /// `router.zenoh.toml` of `troupe keys`); `--listen`/`--connect` add endpoints.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Listen off loopback without authentication (anyone who reaches the port
    /// can join the team and pose as any robot).
    #[arg(long)]
    insecure: bool,
}

#[derive(Debug, clap::Args)]
struct KeysArgs {
    /// The team's scenario (its number of robots); or give `--team-size`.
    #[arg(required_unless_present = "team_size", conflicts_with = "team_size")]
    scenario: Option<PathBuf>,
    /// Robots in the team (ids 0..N; the base station is id N).
    #[arg(long, value_name = "N")]
    team_size: Option<u32>,
    /// Directory that receives the files.
    #[arg(long, default_value = "keys")]
    out: PathBuf,
}

#[derive(Debug, clap::Args)]
struct LaunchArgs {
    /// Scenario file (TOML): world, robots, robot configuration.
    scenario: PathBuf,
    /// Wall seconds each robot runs; without it, until Ctrl-C.
    #[arg(long, value_name = "SECONDS")]
    duration_s: Option<f64>,
    /// Port of robot 0; robot i uses BASE_PORT + i (with `--router`: the router's).
    #[arg(long, default_value_t = 7447)]
    base_port: u16,
    /// Start one zenoh router on BASE_PORT and run the robots as its clients.
    #[arg(long)]
    router: bool,
    /// Mutual TLS with zenoh's access control: write the team's keys with `troupe
    /// keys` into the launch directory's `keys/` and robot files that use them.
    #[arg(long)]
    tls: bool,
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
    /// List the runs (of this shard) and exit without running them.
    #[arg(long)]
    dry_run: bool,
    /// Reuse runs that an earlier sweep into the same directory finished with the
    /// same scenario (their `runs/<run>/study_row.json`); fly only the rest.
    #[arg(long)]
    resume: bool,
    /// Fly only shard K of N (0 <= K < N): the runs whose position in the study's
    /// run list (`--dry-run` order) is K modulo N, whatever `--jobs`. Writes their
    /// reports under `OUT/<study>/runs/` but not the study's tables: collect those
    /// with `--merge` once every shard is done.
    #[arg(long, value_name = "K/N", conflicts_with = "merge")]
    shard: Option<Shard>,
    /// Fly nothing: rebuild `results.csv`, `aggregate.csv` and the plots in
    /// `OUT/<study>/` from the finished runs (`study_row.json`) found under these
    /// directories (e.g. the `OUT/<study>` of every shard). Refuses runs of another
    /// version of the study; lists the runs still missing and then fails.
    #[arg(
        long,
        value_name = "DIR",
        num_args = 1..,
        conflicts_with_all = ["jobs", "dry_run", "resume"]
    )]
    merge: Vec<PathBuf>,
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
    /// Do not write `run.mcap` (as `[metrics] record = false`).
    #[arg(long)]
    no_record: bool,
}

fn launch(args: LaunchArgs) -> anyhow::Result<()> {
    if args.duration_s.is_some_and(|d| !(d.is_finite() && d > 0.0)) {
        anyhow::bail!("--duration-s must be a finite number > 0");
    }
    let scenario = Scenario::load(&args.scenario)?;
    let dir = args.out.join(&scenario.name);
    let troupe = std::env::current_exe().context("locating troupe")?;
    println!(
        "launching {} robots of {} as processes ({} port {}), outputs in {}",
        scenario.robots,
        args.scenario.display(),
        if args.router {
            "through a router on"
        } else {
            "peer to peer from"
        },
        args.base_port,
        dir.display()
    );
    let options = LaunchOptions {
        base_port: args.base_port,
        duration_s: args.duration_s,
        router: args.router,
        tls: args.tls,
    };
    let report = troupe_sims::launch::launch(&args.scenario, &dir, &options, &troupe)?;
    let failed = report.exit_codes.iter().filter(|c| **c != Some(0)).count();
    println!(
        "{} robots finished ({} failed); closest approach {}",
        report.exit_codes.len(),
        failed,
        report
            .min_inter_robot_distance_m
            .map_or("n/a".into(), |d| format!("{d:.2} m"))
    );
    let cpu: Vec<f64> = report
        .robot_usage
        .iter()
        .flatten()
        .map(|u| u.cpu_percent)
        .collect();
    let rss = report
        .robot_usage
        .iter()
        .flatten()
        .map(|u| u.peak_rss_mib)
        .fold(0.0, f64::max);
    if let (Some(max_cpu), Some(launcher)) =
        (cpu.iter().copied().reduce(f64::max), report.launcher_usage)
    {
        println!(
            "robots: CPU {:.0} % of a core on average (at most {max_cpu:.0} %), peak memory at most {rss:.0} MiB; {}: CPU {:.0} %, peak memory {:.0} MiB (launch.json)",
            cpu.iter().sum::<f64>() / cpu.len() as f64,
            if args.router { "router" } else { "launcher" },
            launcher.cpu_percent,
            launcher.peak_rss_mib
        );
    }
    if failed > 0 {
        anyhow::bail!("{failed} robot processes failed");
    }
    Ok(())
}

fn robot(args: RobotArgs) -> anyhow::Result<()> {
    let mut process = RobotProcess::load(&args.config)?;
    if let Some(d) = args.duration_s {
        if !(d.is_finite() && d > 0.0) {
            anyhow::bail!("--duration-s must be a finite number > 0, got {d}");
        }
        process.config.duration_s = Some(d);
    }
    let summary = run_until_signal(&process)?;
    println!(
        "robot{}: {:.1} wall s, {} odometry samples; report: {}",
        summary.robot,
        summary.wall_s,
        summary.trajectory_samples,
        process.out.display()
    );
    Ok(())
}

fn base(args: BaseArgs) -> anyhow::Result<()> {
    let mut station = troupe_sims::base::BaseStation::load(&args.config)?;
    if let Some(d) = args.duration_s {
        if !(d.is_finite() && d > 0.0) {
            anyhow::bail!("--duration-s must be a finite number > 0, got {d}");
        }
        station.config.duration_s = Some(d);
    }
    println!(
        "base station (id {}) of {}: {} robots; maps in {}",
        station.base_id,
        station.scenario.name,
        station.scenario.robots,
        station.out.display()
    );
    let summary = troupe_sims::base::run_until_signal(&station)?;
    println!(
        "base: {:.1} wall s, {} keyframes from {} robots; maps: {}",
        summary.wall_s,
        summary.merged_keyframes,
        summary.robots.values().filter(|r| r.keyframes > 0).count(),
        station.out.display()
    );
    Ok(())
}

fn router(args: RouterArgs) -> anyhow::Result<()> {
    let mut zenoh = match &args.config {
        Some(path) => troupe_sims::router::read_settings(path)?,
        None if args.listen.is_empty() => settings(vec!["tcp/0.0.0.0:7447".into()], Vec::new()),
        None => settings(Vec::new(), Vec::new()),
    };
    zenoh.listen.extend(args.listen);
    zenoh.connect.extend(args.connect);
    zenoh.insecure |= args.insecure;
    let router = Router::open(&zenoh)?;
    println!(
        "zenoh router {} listening on {}",
        router.zid(),
        zenoh.listen.join(", ")
    );
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the runtime")?
        .block_on(shutdown_signal());
    router.close()?;
    Ok(())
}

fn keys(args: KeysArgs) -> anyhow::Result<()> {
    let robots = match (&args.scenario, args.team_size) {
        (Some(path), _) => Scenario::load(path)?.robots,
        (None, Some(n)) => n,
        (None, None) => anyhow::bail!("give a scenario or --team-size"),
    };
    let keys = troupe_sims::keys::write_team_keys(&args.out, robots)?;
    println!(
        "{} robots (ids 0..{}), base station id {}: {} files in {} (keep ca.key off the robots)",
        keys.robots,
        keys.robots,
        keys.robots,
        keys.files.len(),
        keys.dir.display()
    );
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
        Command::Robot(args) => robot(args),
        Command::Router(args) => router(args),
        Command::Keys(args) => keys(args),
        Command::Base(args) => base(args),
        Command::Replay(args) => replay(args),
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
    if args.no_record {
        scenario.metrics.record = false;
    }
    scenario.validate(&source)?;
    let mut team = Team::new(&scenario)
        .with_context(|| format!("assembling the robots of {}", source.display()))?;
    // Written beside the run directory while the run goes, moved into it at the end.
    let recording = if scenario.metrics.record {
        std::fs::create_dir_all(&args.out)
            .with_context(|| format!("creating {}", args.out.display()))?;
        let path = args.out.join(format!(
            ".{}.{RUN_RECORDING}.partial-{}",
            scenario.name,
            std::process::id()
        ));
        let mut recorder =
            Recorder::create_with(&path, Clock::Sim, record_options(&scenario.metrics))?;
        record_world(&mut recorder, team.world());
        let recorder = SharedRecorder::new(recorder);
        team.add_tap(recorder.clone());
        Some((recorder, path))
    } else {
        None
    };
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
    if let Some((recorder, path)) = recording {
        recorder.with(|r| record_outputs(r, &output, &scenario));
        let stats = recorder
            .finish()
            .context("the recording was finished twice")??;
        let to = dir.join(RUN_RECORDING);
        std::fs::rename(&path, &to).with_context(|| format!("moving {}", path.display()))?;
        let robot_minutes = f64::from(scenario.robots) * scenario.duration_s / 60.0;
        println!(
            "recording: {} ({:.1} MB, {:.2} MB per robot-minute)",
            to.display(),
            stats.bytes as f64 / 1e6,
            stats.bytes as f64 / 1e6 / robot_minutes.max(1e-9)
        );
    }
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

fn replay(args: ReplayArgs) -> anyhow::Result<()> {
    let file = RecordingFile::open(&args.recording)?;
    let summary = file.summary()?;
    // A closed pipe (`| head`) ends the listing with an error, not a panic.
    let mut out = std::io::stdout().lock();
    if args.json {
        writeln!(out, "{}", serde_json::to_string(&summary)?)?;
    } else {
        let [start, end] = summary.span_s.unwrap_or_default();
        writeln!(
            out,
            "{}: {} messages on {} channels, {:.3} s ({start:.3} to {end:.3} s){}",
            args.recording.display(),
            summary.messages,
            summary.channels.len(),
            summary.duration_s(),
            if summary.attachments.is_empty() {
                String::new()
            } else {
                format!("; attached: {}", summary.attachments.join(", "))
            }
        )?;
        let width = summary.channels.keys().map(String::len).max().unwrap_or(0);
        for (topic, channel) in &summary.channels {
            println!(
                "  {topic:<width$}  {:>8}  {}",
                channel.messages, channel.schema
            );
        }
    }
    if let Some(dir) = &args.plots {
        let stems = file.render_plots(dir)?;
        anyhow::ensure!(
            !stems.is_empty(),
            "{} has no samples to plot (only `troupe run` records them)",
            args.recording.display()
        );
        eprintln!("plots: {} in {}", stems.join(", "), dir.display());
    }
    Ok(())
}

fn sweep(args: SweepArgs) -> anyhow::Result<()> {
    let study = Study::load(&args.study)?;
    let all = study.variants()?;
    if !args.merge.is_empty() {
        return merge(&study, &all, &args.merge, &args.out);
    }
    let variants = match args.shard {
        Some(shard) => shard.select(&all),
        None => all,
    };
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
    let share = args.shard.map_or(String::new(), |s| format!(", shard {s}"));
    eprintln!(
        "{}{share}: {total} runs ({} seeds), {jobs} at a time",
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
                .and_then(|dir| save_finished_run(&dir, &study.name, variant, row));
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
    if let Some(e) = write_errors.first() {
        anyhow::bail!("writing a run report under {}: {e}", runs_dir.display());
    }
    if let Some(shard) = args.shard {
        // Other shards may be writing into the same directory: the study's tables
        // come from `--merge` once all of them are done.
        println!(
            "{} shard {shard}: {total} runs in {:.0} wall s under {}; when every shard is done: troupe sweep {} --merge DIR…",
            study.name,
            started.elapsed().as_secs_f64(),
            runs_dir.display(),
            args.study.display()
        );
        return Ok(());
    }
    let mut flown = flown.into_iter();
    for row in &mut rows {
        if row.is_none() {
            *row = flown.next();
        }
    }
    let rows: Vec<RunRow> = rows.into_iter().flatten().collect();
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

/// `troupe sweep STUDY --merge DIR…`: the study's tables from finished runs.
fn merge(
    study: &Study,
    variants: &[Variant],
    dirs: &[PathBuf],
    out: &std::path::Path,
) -> anyhow::Result<()> {
    let merged = merge_finished_runs(study, variants, dirs)?;
    let total = variants.len();
    let found = merged.rows.len();
    let places: Vec<String> = dirs.iter().map(|d| d.display().to_string()).collect();
    if found == 0 {
        anyhow::bail!(
            "no finished run of study `{}` under {}",
            study.name,
            places.join(", ")
        );
    }
    if merged.other_studies > 0 {
        eprintln!("passed over {} runs of other studies", merged.other_studies);
    }
    let root = out.join(&study.name);
    let written = write_study(&root, study, &merged.rows)
        .with_context(|| format!("writing the study outputs under {}", root.display()))?;
    println!(
        "{}: {found} of {total} runs merged from {}; outputs: {}",
        study.name,
        places.join(", "),
        written.join(", ")
    );
    if !merged.missing.is_empty() {
        for run in &merged.missing {
            eprintln!("missing: {run}");
        }
        anyhow::bail!(
            "{} of {total} runs missing (listed above): the outputs hold only the {found} found; fly the rest (e.g. their shards with --resume) and merge again",
            merged.missing.len()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory as _;

    fn parse(args: &[&str]) -> Result<Cli, clap::Error> {
        Cli::try_parse_from(std::iter::once("troupe").chain(args.iter().copied()))
    }

    fn sweep_args(args: &[&str]) -> SweepArgs {
        match parse(args).expect("parses").command {
            Command::Sweep(a) => a,
            other => panic!("not a sweep: {other:?}"),
        }
    }

    #[test]
    fn shard_and_merge_flags_parse() {
        let a = sweep_args(&["sweep", "s.toml", "--shard", "2/5", "--jobs", "3"]);
        assert_eq!(a.shard, Some(Shard::new(2, 5).expect("shard")));
        assert!(a.merge.is_empty());
        let a = sweep_args(&["sweep", "s.toml", "--merge", "a", "b/c", "--out", "o"]);
        assert_eq!(a.merge, [PathBuf::from("a"), PathBuf::from("b/c")]);
        assert_eq!(a.shard, None);
        assert_eq!(a.out, PathBuf::from("o"));
        for bad in [
            &["sweep", "s.toml", "--shard", "5/5"][..],
            &["sweep", "s.toml", "--shard", "1"],
            &["sweep", "s.toml", "--shard", "-1/3"],
            &["sweep", "s.toml", "--merge"],
            &["sweep", "s.toml", "--merge", "a", "--shard", "0/2"],
            &["sweep", "s.toml", "--merge", "a", "--resume"],
            &["sweep", "s.toml", "--merge", "a", "--jobs", "2"],
        ] {
            assert!(parse(bad).is_err(), "{bad:?} parsed");
        }
        let error = parse(&["sweep", "s.toml", "--shard", "3/2"])
            .expect_err("3/2")
            .to_string();
        assert!(error.contains("0 <= K < N"), "{error}");
    }

    #[test]
    fn robot_router_and_launch_flags_parse() {
        match parse(&["robot", "--config", "r.toml", "--duration-s", "4"])
            .expect("robot")
            .command
        {
            Command::Robot(a) => {
                assert_eq!(a.config, PathBuf::from("r.toml"));
                assert_eq!(a.duration_s, Some(4.0));
            }
            other => panic!("{other:?}"),
        }
        assert!(parse(&["robot"]).is_err(), "--config is required");
        match parse(&["router"]).expect("router").command {
            Command::Router(a) => {
                // tcp/0.0.0.0:7447 when there is no --config either.
                assert!(a.listen.is_empty() && a.connect.is_empty());
                assert!(a.config.is_none() && !a.insecure);
            }
            other => panic!("{other:?}"),
        }
        match parse(&["keys", "--team-size", "3", "--out", "k"])
            .expect("keys")
            .command
        {
            Command::Keys(a) => {
                assert_eq!((a.scenario, a.team_size), (None, Some(3)));
                assert_eq!(a.out, PathBuf::from("k"));
            }
            other => panic!("{other:?}"),
        }
        assert!(parse(&["keys"]).is_err(), "a scenario or --team-size");
        assert!(parse(&["keys", "t.toml", "--team-size", "3"]).is_err());
        match parse(&[
            "router",
            "--listen",
            "tcp/127.0.0.1:9000",
            "--connect",
            "tcp/h:7447",
        ])
        .expect("router")
        .command
        {
            Command::Router(a) => {
                assert_eq!(a.listen, ["tcp/127.0.0.1:9000"]);
                assert_eq!(a.connect, ["tcp/h:7447"]);
            }
            other => panic!("{other:?}"),
        }
        match parse(&["launch", "team.toml", "--router"])
            .expect("launch")
            .command
        {
            Command::Launch(a) => assert!(a.router && !a.tls),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn help_names_the_new_flags_and_commands() {
        Cli::command().debug_assert();
        let mut cli = Cli::command();
        let top = cli.render_long_help().to_string();
        for command in ["robot", "router", "sweep", "launch"] {
            assert!(top.contains(command), "{command} missing from: {top}");
        }
        let sweep = cli
            .find_subcommand_mut("sweep")
            .expect("sweep")
            .render_long_help()
            .to_string();
        for flag in ["--shard <K/N>", "--merge <DIR>", "modulo N"] {
            assert!(sweep.contains(flag), "{flag} missing from: {sweep}");
        }
    }
}
