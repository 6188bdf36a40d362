//! The `troupe-robot` command as a library ([`main_with`]): a user's binary runs a
//! hardware robot with its own parts.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;

use super::{HardwareRobot, run_with};
use crate::harness::shutdown_signal;
use crate::registry::Registry;

/// Fly one hardware robot of a troupe team until SIGINT/SIGTERM (or the duration).
#[derive(Parser)]
#[command(version)]
struct Args {
    /// The robot file (TOML): `id`, `team_size`, `[robot]`, `[camera]`, `[ros2]`,
    /// `[mavlink]`, `[zenoh]`, `out` (see robot/examples/hardware_robot.toml).
    #[arg(long)]
    config: PathBuf,
    /// Wall seconds to run (overrides the file's `duration_s`).
    #[arg(long)]
    duration_s: Option<f64>,
}

/// The `troupe-robot` command (logging, the command line of this process, the run, the
/// exit code) with the robot's parts from `registry` ([`Registry::hardware`] extended
/// with a user's drivers and actors, named in the robot file's `[robot]`).
#[must_use]
pub fn main_with(registry: Registry) -> ExitCode {
    crate::harness::init_logging_with(crate::harness::HARDWARE_LOG_FILTER);
    let args = Args::parse();
    let result = HardwareRobot::load(&args.config).and_then(|mut robot| {
        if args.duration_s.is_some() {
            robot.file.duration_s = args.duration_s;
            robot.file.validate(&robot.path)?;
        }
        run_with(&robot, &registry, shutdown_signal()).map(|summary| (robot, summary))
    });
    match result {
        Ok((robot, s)) => {
            let (setpoints, holds) = s
                .vehicle
                .as_ref()
                .map_or((0, 0), |v| (v.setpoints, v.holds));
            println!(
                "robot{}: {:.1} wall s, {} frames, {} keyframes, {} plans, {setpoints} setpoints \
                 sent ({holds} holds); report: {}",
                s.robot,
                s.wall_s,
                s.frames,
                s.keyframes,
                s.plans,
                robot.out.join("summary.json").display()
            );
            ExitCode::SUCCESS
        }
        Err(e) => {
            let mut line = format!("troupe-robot: {e}");
            let mut cause = std::error::Error::source(&e);
            while let Some(c) = cause {
                line.push_str(&format!(": {c}"));
                cause = c.source();
            }
            eprintln!("{line}");
            ExitCode::FAILURE
        }
    }
}
