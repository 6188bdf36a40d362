//! `troupe router`: a zenoh router for teams beyond a handful of robots.
//!
//! Robots in peer mode connect to every other robot (zenoh peers do not forward),
//! which grows as the square of the team. zenoh's own answer is a router: a zenoh
//! session in router mode that forwards between the sessions connected to it. Robots
//! then run in client mode and name only the router (`mode = "client"`,
//! `connect = ["tcp/<router host>:7447"]` in the robot file's `[zenoh]` table,
//! [`troupe_comms::zenoh::ZenohConfig`]). Routers may connect to other routers
//! (`connect`), e.g. one per site.
//!
//! This module only opens the session: routing is zenoh's. The settings are the same
//! [`ZenohConfig`] a robot uses (endpoints, scouting, TLS, authentication, access
//! control), with the mode set to router; `troupe router --config FILE` reads them
//! from a file's `[zenoh]` table ([`read_settings`], e.g. `router.zenoh.toml` of
//! `troupe keys`, whose `[zenoh.access]` makes the router accept from `robot<id>`
//! only frames under its own id, `docs/security.md`).

use std::path::Path;

use troupe_comms::transport::TransportError;
use troupe_comms::zenoh::ZenohConfig;
use zenoh::Wait as _;

/// Why a router could not start.
#[derive(Debug, thiserror::Error)]
pub enum RouterError {
    /// The settings file cannot be read or does not have the expected shape.
    #[error(transparent)]
    File(#[from] crate::toml_file::TomlFileError),
    /// The settings are invalid (an endpoint's syntax, a missing TLS file).
    #[error("router settings")]
    Config(#[source] TransportError),
    /// zenoh refused the configuration or could not open the session (e.g. the
    /// listening port is taken).
    #[error("{context}")]
    Open {
        /// What was being done.
        context: String,
        /// zenoh's error.
        #[source]
        source: zenoh::Error,
    },
}

/// A running zenoh router; it routes until dropped or [`Router::close`]d.
pub struct Router {
    session: zenoh::Session,
}

impl std::fmt::Debug for Router {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Router").field("zid", &self.zid()).finish()
    }
}

impl Router {
    /// Opens a zenoh session in router mode with `settings`' endpoints, scouting, TLS
    /// and authentication (their `mode` is ignored). Returns once it listens.
    pub fn open(settings: &ZenohConfig) -> Result<Router, RouterError> {
        if settings.listen.is_empty() {
            return Err(RouterError::Config(TransportError::Config {
                key: "listen".into(),
                reason: "a router needs an endpoint to listen on".into(),
            }));
        }
        let mut config = settings.to_zenoh().map_err(RouterError::Config)?;
        let open = settings.open_to_network();
        if !open.is_empty() {
            tracing::warn!(
                "insecure = true: {} accept(s) anyone on the network, who can pose as any \
                 robot (docs/security.md)",
                open.join(", ")
            );
        }
        config
            .insert_json5("mode", "\"router\"")
            .map_err(|source| RouterError::Open {
                context: "setting zenoh `mode` to router".into(),
                source,
            })?;
        let session = zenoh::open(config)
            .wait()
            .map_err(|source| RouterError::Open {
                context: format!("opening the zenoh router on {}", settings.listen.join(", ")),
                source,
            })?;
        Ok(Router { session })
    }

    /// The router's zenoh id.
    #[must_use]
    pub fn zid(&self) -> String {
        self.session.zid().to_string()
    }

    /// Closes the session: connected robots lose the router.
    pub fn close(self) -> Result<(), RouterError> {
        self.session
            .close()
            .wait()
            .map_err(|source| RouterError::Open {
                context: "closing the zenoh router".into(),
                source,
            })
    }
}

/// A router file: one `[zenoh]` table.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RouterFile {
    zenoh: ZenohConfig,
}

/// Reads the `[zenoh]` table of the router file `path`, its TLS and dictionary
/// paths made relative to the file.
pub fn read_settings(path: &Path) -> Result<ZenohConfig, RouterError> {
    let file: RouterFile = crate::toml_file::read_toml(path)?;
    let mut zenoh = file.zenoh;
    zenoh.resolve_paths(path.parent().unwrap_or(Path::new(".")));
    Ok(zenoh)
}

/// Router settings listening on `listen` and connecting to the routers `connect`,
/// without multicast scouting (troupe's default: no socket nobody asked for).
#[must_use]
pub fn settings(listen: Vec<String>, connect: Vec<String>) -> ZenohConfig {
    ZenohConfig {
        listen,
        connect,
        ..ZenohConfig::default()
    }
}
