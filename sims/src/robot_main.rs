//! `troupe-robot`: one robot of a team in its own process, talking to the others over
//! zenoh (see `troupe_sims::process`).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use troupe_sims::process::{RobotProcess, run};

/// Run one robot: its simulated vehicle and camera in the scenario's world (or, with
/// `sequence` in the robot file, a recorded sequence replayed as its sensor), the
/// standard actors on the wall clock, the link over zenoh. Writes `summary.json` and
/// `trajectory.csv` on exit (end of `duration_s`, Ctrl-C or SIGTERM).
#[derive(Debug, Parser)]
#[command(name = "troupe-robot", version, about, long_about = None)]
struct Args {
    /// The robot file (TOML): `robot`, `scenario`, `duration_s`, `out`, `sequence`,
    /// `[zenoh]`.
    #[arg(long)]
    config: PathBuf,
    /// Override the file's `duration_s` (wall seconds).
    #[arg(long)]
    duration_s: Option<f64>,
}

fn main() -> ExitCode {
    troupe_sims::init_logging();
    let args = Args::parse();
    let mut process = match RobotProcess::load(&args.config) {
        Ok(p) => p,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    if let Some(d) = args.duration_s {
        if !(d.is_finite() && d > 0.0) {
            eprintln!("error: --duration-s must be a finite number > 0, got {d}");
            return ExitCode::from(2);
        }
        process.config.duration_s = Some(d);
    }
    let runtime = match tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
    {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: starting the runtime: {e}");
            return ExitCode::FAILURE;
        }
    };
    let outcome = runtime.block_on(run(&process, shutdown_signal()));
    match outcome {
        Ok(summary) => {
            println!(
                "robot{}: {:.1} wall s, {} odometry samples; report: {}",
                summary.robot,
                summary.wall_s,
                summary.trajectory_samples,
                process.out.display()
            );
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Resolves on Ctrl-C or SIGTERM.
async fn shutdown_signal() {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{SignalKind, signal};
        match signal(SignalKind::terminate()) {
            Ok(mut term) => {
                tokio::select! {
                    _ = tokio::signal::ctrl_c() => {}
                    _ = term.recv() => {}
                }
            }
            Err(_) => {
                let _ = tokio::signal::ctrl_c().await;
            }
        }
    }
    #[cfg(not(unix))]
    {
        let _ = tokio::signal::ctrl_c().await;
    }
}
