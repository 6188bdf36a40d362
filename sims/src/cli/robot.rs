//! `troupe robot --config ROBOT.toml`: one simulated robot of a team in this process
//! (`troupe_sims::process`, on the robot-process harness).

use std::path::PathBuf;

use crate::process::{RobotProcess, run_until_signal};
use troupe_robot::registry::Registry;

#[derive(Debug, clap::Args)]
pub(crate) struct RobotArgs {
    /// The robot file (TOML): `robot`, `scenario`, `duration_s`, `out`, `sequence`,
    /// `[zenoh]`.
    #[arg(long)]
    config: PathBuf,
    /// Override the file's `duration_s` (wall seconds).
    #[arg(long, value_name = "SECONDS")]
    duration_s: Option<f64>,
}

pub(crate) fn run(args: RobotArgs, registry: &Registry) -> anyhow::Result<()> {
    let mut process = RobotProcess::load(&args.config)?;
    process.parts = registry.clone();
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::{Command, parse};

    #[test]
    fn robot_flags_parse() {
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
    }
}
