//! `troupe router`: a zenoh router (`troupe_robot::router`) until SIGINT or SIGTERM.

use std::path::PathBuf;

use troupe_robot::harness::wait_for_signal;
use troupe_robot::router::{Router, read_settings, settings};

#[derive(Debug, clap::Args)]
pub(crate) struct RouterArgs {
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

pub(crate) fn run(args: RouterArgs) -> anyhow::Result<()> {
    let mut zenoh = match &args.config {
        Some(path) => read_settings(path)?,
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
    wait_for_signal()?;
    router.close()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::{Command, parse};

    #[test]
    fn router_flags_parse() {
        match parse(&["router"]).expect("router").command {
            Command::Router(a) => {
                // tcp/0.0.0.0:7447 when there is no --config either.
                assert!(a.listen.is_empty() && a.connect.is_empty());
                assert!(a.config.is_none() && !a.insecure);
            }
            other => panic!("{other:?}"),
        }
        match parse(&[
            "router",
            "--listen",
            "tcp/127.0.0.1:9000",
            "--connect",
            "tcp/h:7447",
            "--config",
            "router.zenoh.toml",
            "--insecure",
        ])
        .expect("router")
        .command
        {
            Command::Router(a) => {
                assert_eq!(a.listen, ["tcp/127.0.0.1:9000"]);
                assert_eq!(a.connect, ["tcp/h:7447"]);
                assert_eq!(a.config, Some(PathBuf::from("router.zenoh.toml")));
                assert!(a.insecure);
            }
            other => panic!("{other:?}"),
        }
    }
}
