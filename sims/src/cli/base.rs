//! `troupe base --config BASE.toml`: the base station (`troupe_robot::base`) of a
//! team whose scenario file the base file names.

use std::path::PathBuf;

use crate::scenario::load_team;
use troupe_robot::base::{BaseStation, run_until_signal};

#[derive(Debug, clap::Args)]
pub(crate) struct BaseArgs {
    /// The base file (TOML): `scenario`, `base_id`, `duration_s`, `out`,
    /// `ply_points`, `[zenoh]`.
    #[arg(long)]
    config: PathBuf,
    /// Override the file's `duration_s` (wall seconds).
    #[arg(long, value_name = "SECONDS")]
    duration_s: Option<f64>,
}

pub(crate) fn run(args: BaseArgs) -> anyhow::Result<()> {
    let mut station = BaseStation::load(&args.config, load_team)?;
    if let Some(d) = args.duration_s {
        if !(d.is_finite() && d > 0.0) {
            anyhow::bail!("--duration-s must be a finite number > 0, got {d}");
        }
        station.config.duration_s = Some(d);
    }
    println!(
        "base station (id {}) of {}: {} robots; maps in {}",
        station.base_id,
        station.team.name,
        station.team.robots,
        station.out.display()
    );
    let summary = run_until_signal(&station)?;
    println!(
        "base: {:.1} wall s, {} keyframes from {} robots; maps: {}",
        summary.wall_s,
        summary.merged_keyframes,
        summary.robots.values().filter(|r| r.keyframes > 0).count(),
        station.out.display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::{Command, parse};

    #[test]
    fn base_flags_parse() {
        match parse(&["base", "--config", "b.toml"])
            .expect("base")
            .command
        {
            Command::Base(a) => {
                assert_eq!(a.config, PathBuf::from("b.toml"));
                assert_eq!(a.duration_s, None);
            }
            other => panic!("{other:?}"),
        }
        match parse(&["base", "--config", "b.toml", "--duration-s", "2.5"])
            .expect("base")
            .command
        {
            Command::Base(a) => assert_eq!(a.duration_s, Some(2.5)),
            other => panic!("{other:?}"),
        }
        assert!(parse(&["base"]).is_err(), "--config is required");
    }
}
