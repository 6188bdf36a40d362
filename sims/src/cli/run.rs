//! `troupe run [SCENARIO]`: a team of simulated robots in one process, in sim time,
//! and its report (and `run.mcap`).

use std::path::PathBuf;

use crate::recording::{record_options, record_outputs, record_world};
use crate::report::write_run;
use crate::scenario::Scenario;
use crate::team::Team;
use anyhow::Context as _;
use troupe_record::{Clock, RUN_RECORDING, Recorder, SharedRecorder};
use troupe_robot::registry::Registry;

use super::progress_bar;

#[derive(Debug, clap::Args)]
pub(crate) struct RunArgs {
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

pub(crate) fn run(args: RunArgs, registry: &Registry) -> anyhow::Result<()> {
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
    let mut team = Team::with_parts(&scenario, registry, |_, _| {})
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::{Command, parse};

    #[test]
    fn run_flags_parse() {
        match parse(&["run"]).expect("run").command {
            Command::Run(a) => {
                assert_eq!(a.scenario, None);
                assert_eq!(a.out, PathBuf::from("runs"));
                assert!(!a.no_record && !a.no_progress);
            }
            other => panic!("{other:?}"),
        }
        match parse(&[
            "run",
            "s.toml",
            "--seed",
            "3",
            "--duration-s",
            "5",
            "--robots",
            "4",
            "--name",
            "n",
            "--out",
            "o",
            "--no-progress",
            "--no-record",
        ])
        .expect("run")
        .command
        {
            Command::Run(a) => {
                assert_eq!(a.scenario, Some(PathBuf::from("s.toml")));
                assert_eq!(
                    (a.seed, a.duration_s, a.robots),
                    (Some(3), Some(5.0), Some(4))
                );
                assert_eq!(a.name.as_deref(), Some("n"));
                assert!(a.no_record && a.no_progress);
            }
            other => panic!("{other:?}"),
        }
        assert!(parse(&["run", "--seed", "x"]).is_err());
    }
}
