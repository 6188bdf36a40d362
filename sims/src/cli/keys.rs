//! `troupe keys`: a team's credentials for mutual TLS (`troupe_robot::keys`).

use std::path::PathBuf;

use crate::scenario::Scenario;
use troupe_robot::keys::write_team_keys;

#[derive(Debug, clap::Args)]
pub(crate) struct KeysArgs {
    /// The team's scenario (its number of robots); or give `--team-size`.
    #[arg(required_unless_present = "team_size", conflicts_with = "team_size")]
    scenario: Option<PathBuf>,
    /// Robots in the team (ids 0..N; the base station is id N).
    #[arg(long, value_name = "N")]
    team_size: Option<u32>,
    /// The team runs through a `troupe router`: also write the router's certificate
    /// and let every member accept it forwarding the others' keys.
    #[arg(long)]
    router: bool,
    /// Directory that receives the files.
    #[arg(long, default_value = "keys")]
    out: PathBuf,
}

pub(crate) fn run(args: KeysArgs) -> anyhow::Result<()> {
    let robots = match (&args.scenario, args.team_size) {
        (Some(path), _) => Scenario::load(path)?.robots,
        (None, Some(n)) => n,
        (None, None) => anyhow::bail!("give a scenario or --team-size"),
    };
    let keys = write_team_keys(&args.out, robots, args.router)?;
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::{Command, parse};

    #[test]
    fn keys_flags_parse() {
        match parse(&["keys", "--team-size", "3", "--out", "k"])
            .expect("keys")
            .command
        {
            Command::Keys(a) => {
                assert_eq!((a.scenario, a.team_size), (None, Some(3)));
                assert_eq!(a.out, PathBuf::from("k"));
                assert!(!a.router);
            }
            other => panic!("{other:?}"),
        }
        match parse(&["keys", "t.toml"]).expect("keys").command {
            Command::Keys(a) => {
                assert_eq!(a.scenario, Some(PathBuf::from("t.toml")));
                assert_eq!(a.out, PathBuf::from("keys"));
            }
            other => panic!("{other:?}"),
        }
        assert!(parse(&["keys"]).is_err(), "a scenario or --team-size");
        assert!(parse(&["keys", "t.toml", "--team-size", "3"]).is_err());
    }
}
