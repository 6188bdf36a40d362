//! The `troupe` command line.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context as _;
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use troupe_sims::report::write_run;
use troupe_sims::scenario::Scenario;
use troupe_sims::study::{Study, run_variants, write_study};
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

fn main() -> ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .init();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Run(args) => run(args),
        Command::Sweep(args) => sweep(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::FAILURE
        }
    }
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
    let bar = if !args.no_progress && std::io::stderr().is_terminal() {
        let bar = ProgressBar::new((scenario.duration_s * 10.0).round() as u64);
        bar.set_style(
            ProgressStyle::with_template("{spinner} [{elapsed_precise}] {wide_bar} {msg}")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        bar
    } else {
        ProgressBar::hidden()
    };
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
    let started = std::time::Instant::now();
    let mut finished = 0usize;
    let mut write_errors = Vec::new();
    let rows = run_variants(
        &variants,
        &study.coverage_levels,
        jobs,
        |variant, output, row| {
            finished += 1;
            if let Err(e) = write_run(&runs_dir, &variant.name, output) {
                write_errors.push(format!("{}: {e}", variant.name));
            }
            eprintln!(
                "[{finished}/{total}] {}: coverage {:.1}%, collisions {}, map bytes {}, {:.0} wall s",
                variant.name,
                100.0 * row.final_coverage,
                row.collisions,
                row.map_bytes_sent,
                row.wall_s
            );
        },
    )?;
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
