//! `troupe launch SCENARIO.toml`: a scenario's team as separate `troupe robot`
//! processes on this machine (`troupe_robot::launch` with the simulator's robot
//! files, `troupe_sims::process::SimulatedTeam`).

use std::path::PathBuf;

use crate::process::SimulatedTeam;
use crate::scenario::Scenario;
use anyhow::Context as _;
use troupe_robot::launch::{LaunchOptions, launch};
use troupe_robot::registry::Registry;

#[derive(Debug, clap::Args)]
pub(crate) struct LaunchArgs {
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

pub(crate) fn run(args: LaunchArgs, registry: &Registry) -> anyhow::Result<()> {
    if args.duration_s.is_some_and(|d| !(d.is_finite() && d > 0.0)) {
        anyhow::bail!("--duration-s must be a finite number > 0");
    }
    let scenario = Scenario::load(&args.scenario)?;
    // The robots are this binary's `robot` subcommand, with the same parts.
    registry
        .check(&scenario.robot)
        .map_err(|e| e.within("robot"))
        .with_context(|| format!("{}: the robots' parts", args.scenario.display()))?;
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
    if !args.tls {
        println!(
            "the team is open: any process on this machine can talk to it as any robot \
             (--tls gives each robot its own certificate, docs/security.md)"
        );
    }
    let options = LaunchOptions {
        base_port: args.base_port,
        duration_s: args.duration_s,
        router: args.router,
        tls: args.tls,
    };
    let team = SimulatedTeam {
        scenario: std::fs::canonicalize(&args.scenario)
            .with_context(|| args.scenario.display().to_string())?,
        robots: scenario.robots,
        duration_s: args.duration_s,
        troupe,
    };
    let report = launch(&team, &dir, &options)?;
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::{Command, parse};

    #[test]
    fn launch_flags_parse() {
        match parse(&["launch", "team.toml", "--router"])
            .expect("launch")
            .command
        {
            Command::Launch(a) => {
                assert!(a.router && !a.tls);
                assert_eq!(a.scenario, PathBuf::from("team.toml"));
                assert_eq!((a.base_port, a.duration_s), (7447, None));
                assert_eq!(a.out, PathBuf::from("runs/launch"));
            }
            other => panic!("{other:?}"),
        }
        match parse(&[
            "launch",
            "team.toml",
            "--tls",
            "--base-port",
            "9000",
            "--duration-s",
            "30",
            "--out",
            "o",
        ])
        .expect("launch")
        .command
        {
            Command::Launch(a) => {
                assert!(a.tls && !a.router);
                assert_eq!((a.base_port, a.duration_s), (9000, Some(30.0)));
            }
            other => panic!("{other:?}"),
        }
        assert!(parse(&["launch"]).is_err(), "the scenario is required");
        assert!(parse(&["launch", "t.toml", "--base-port", "70000"]).is_err());
    }
}
