//! Security checks and zenoh access control for a [`ZenohConfig`] (issue 23).
//!
//! - **Secure defaults** (checked by [`ZenohConfig::validate`]): a listening endpoint off loopback must
//!   authenticate its peers (mutual TLS on a `tls/` endpoint, or a user/password
//!   dictionary) and bind identities to ids (`[zenoh.access]`), a `connect` endpoint
//!   off loopback must be `tls/` with `[zenoh.tls]` or carry `[zenoh.auth]`, and
//!   multicast scouting needs TLS or users, unless the settings say
//!   `insecure = true` (a session that says so logs one warning naming what is
//!   open, [`ZenohConfig::open_to_network`]); `auth` on a listening session needs a usable dictionary;
//!   `access` needs a name for every session (mutual TLS; or users on a session
//!   that only listens, such as a router: zenoh's user/password check names only
//!   the side that connects).
//! - **Identity bound by zenoh** (with `[zenoh.access]`, in [`ZenohConfig::to_zenoh`]): zenoh's access control
//!   with `default_permission = "deny"`. The session named `robot<id>`
//!   ([`identity_name`]: its certificate's common name under mutual TLS, its user
//!   under `auth`) may put only under `troupe/*/<id>/*` (and `troupe/*/<id>/*/*`,
//!   the cells of [`crate::scope`]); the routers named in
//!   `access.routers` may put any team key (they forward); every named session may
//!   declare subscribers on `troupe/**`. Everything else (an unnamed session, another
//!   id's key, queries, deletes, liveliness) is dropped by zenoh before it reaches
//!   troupe.

use std::collections::BTreeSet;
use std::path::Path;

use super::{ZenohAccess, ZenohConfig, config_error, erased::Json as _};
use crate::transport::TransportError;

/// The name (certificate common name, user name) of the session of link id `id`:
/// `robot<id>`, the base station included (it is one more id of the team).
#[must_use]
pub fn identity_name(id: u32) -> String {
    format!("robot{id}")
}

/// Whether an endpoint's address (`host:port`, `[v6]:port`, with optional `#...`
/// or `?...` metadata) is on this machine's loopback only.
#[must_use]
pub fn is_loopback(address: &str) -> bool {
    let address = address.split(['#', '?']).next().unwrap_or(address);
    let host = match address.rsplit_once(':') {
        Some((host, _port)) => host,
        None => address,
    };
    let host = host.trim_start_matches('[').trim_end_matches(']');
    if host.eq_ignore_ascii_case("localhost") {
        return true;
    }
    host.parse::<std::net::IpAddr>()
        .is_ok_and(|ip| ip.is_loopback())
}

/// Reads a `user:password` dictionary as zenoh does; returns its user names.
pub fn read_dictionary(path: &Path) -> Result<BTreeSet<String>, TransportError> {
    let key = "auth.dictionary_path";
    let text = std::fs::read_to_string(path)
        .map_err(|e| config_error(key, format!("{}: {e}", path.display())))?;
    let mut users = BTreeSet::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let ok = line
            .split_once(':')
            .filter(|(u, p)| !u.trim().is_empty() && !p.trim().is_empty());
        let Some((user, _)) = ok else {
            return Err(config_error(
                key,
                format!("{} line {}: not `user:password`", path.display(), n + 1),
            ));
        };
        users.insert(user.trim().to_owned());
    }
    if users.is_empty() {
        return Err(config_error(
            key,
            format!("{} has no `user:password` line", path.display()),
        ));
    }
    Ok(users)
}

/// Whether peers connecting to `protocol` endpoints must prove who they are.
fn authenticates(config: &ZenohConfig, protocol: &str) -> bool {
    let mutual_tls = protocol == "tls" && config.tls.as_ref().is_some_and(|t| t.mutual);
    let users = config
        .auth
        .as_ref()
        .is_some_and(|a| a.dictionary_path.is_some());
    mutual_tls || users
}

/// The secure-default checks (see the module docs). Endpoint syntax and files are
/// checked before, by [`ZenohConfig::validate`].
pub(super) fn check(config: &ZenohConfig) -> Result<(), TransportError> {
    if let Some(auth) = &config.auth {
        match &auth.dictionary_path {
            Some(path) => {
                read_dictionary(path)?;
            }
            None if !config.listen.is_empty() => {
                return Err(config_error(
                    "auth.dictionary_path",
                    "a listening session with `auth` needs `dictionary_path` (a file of \
                     the peers' `user:password` lines); without it every peer is refused",
                ));
            }
            None => {}
        }
    }
    if let Some(access) = &config.access {
        check_access(config, access)?;
    }
    if config.insecure {
        return Ok(());
    }
    if config.multicast_scouting && !(config.tls.is_some() || config.auth.is_some()) {
        return Err(config_error(
            "multicast_scouting",
            "multicast scouting lets any host on the LAN find the team and join it: \
             add `[zenoh.tls]` or `[zenoh.auth]` and `[zenoh.access]` (`troupe keys` \
             writes them), or `insecure = true`",
        ));
    }
    for endpoint in &config.connect {
        let (protocol, address) = endpoint.split_once('/').unwrap_or(("", endpoint));
        let proven = (protocol == "tls" && config.tls.is_some()) || config.auth.is_some();
        if !is_loopback(address) && !proven {
            return Err(config_error(
                "connect",
                format!(
                    "`{endpoint}` is a link off this machine that proves nothing: whoever \
                     answers there can pose as the team and read what it says: use tls/ \
                     endpoints with `[zenoh.tls]`, or `[zenoh.auth]` (`troupe keys`, \
                     docs/security.md), or `insecure = true` on a closed network"
                ),
            ));
        }
    }
    for endpoint in &config.listen {
        let (protocol, address) = endpoint.split_once('/').unwrap_or(("", endpoint));
        if is_loopback(address) {
            continue;
        }
        if !authenticates(config, protocol) {
            return Err(config_error(
                "listen",
                format!(
                    "`{endpoint}` lets anyone on the network join the team: add `[zenoh.tls]` \
                     (tls/ endpoints) or `[zenoh.auth]`, and `[zenoh.access]` (`troupe keys` \
                     writes them), or `insecure = true` (`troupe router --insecure`)"
                ),
            ));
        }
        if config.access.is_none() {
            return Err(config_error(
                "access",
                format!(
                    "`{endpoint}`: any holder of a team credential could speak for any \
                     robot: add `[zenoh.access]` (`troupe keys` writes it), or `insecure = true` \
                     (`troupe router --insecure`)"
                ),
            ));
        }
    }
    Ok(())
}

fn check_access(config: &ZenohConfig, access: &ZenohAccess) -> Result<(), TransportError> {
    if access.ids.is_empty() {
        return Err(config_error("access.ids", "must name the team's ids"));
    }
    let unique: BTreeSet<u32> = access.ids.iter().copied().collect();
    if unique.len() != access.ids.len() {
        return Err(config_error("access.ids", "lists an id twice"));
    }
    if access.routers.iter().any(String::is_empty) {
        return Err(config_error("access.routers", "a name must not be empty"));
    }
    let users = config.auth.is_some();
    let certificates = config.tls.as_ref().is_some_and(|t| t.mutual);
    if !users && !certificates {
        return Err(config_error(
            "access",
            "needs mutual TLS (`[zenoh.tls]`, `mutual = true`) or `[zenoh.auth]`: \
             without them no session has a name",
        ));
    }
    if !certificates && !config.connect.is_empty() {
        return Err(config_error(
            "access",
            "with users and no mutual TLS, zenoh names only the sessions that connect to \
             this one, so a session this one connects to could publish under any id: use \
             mutual TLS, or let a router enforce it (robots as its clients, without \
             `[zenoh.access]`)",
        ));
    }
    if !users {
        for (key, endpoints) in [("listen", &config.listen), ("connect", &config.connect)] {
            if let Some(e) = endpoints.iter().find(|e| !e.starts_with("tls/")) {
                return Err(config_error(
                    key,
                    format!(
                        "`{e}`: with `[zenoh.access]` and no `[zenoh.auth]`, sessions are \
                         named by certificates, so every endpoint must be tls/"
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// zenoh's `access_control` section for `config` (see the module docs), as JSON5.
/// `None` when the settings have no `[zenoh.access]` table.
pub(super) fn access_control_json5(config: &ZenohConfig) -> Option<String> {
    let access = config.access.as_ref()?;
    let certificates = config.tls.as_ref().is_some_and(|t| t.mutual);
    let users = config.auth.is_some();
    // A subject's attributes must all match: under both TLS and users, a session
    // needs both the certificate and the user of its name.
    let subject = |id: &str, name: &str| {
        let mut s = format!("{{\"id\":{}", id.json());
        if certificates {
            s.push_str(&format!(",\"cert_common_names\":[{}]", name.json()));
        }
        if users {
            s.push_str(&format!(",\"usernames\":[{}]", name.json()));
        }
        s.push('}');
        s
    };
    let mut subjects = Vec::new();
    let mut rules = Vec::new();
    let mut policies = Vec::new();
    let mut everyone = Vec::new();
    for id in &access.ids {
        let sid = format!("id{id}");
        subjects.push(subject(&sid, &identity_name(*id)));
        rules.push(format!(
            "{{\"id\":\"put{id}\",\"messages\":[\"put\"],\"flows\":[\"ingress\"],\
             \"permission\":\"allow\",\"key_exprs\":[\"troupe/*/{id}/*\",\"troupe/*/{id}/*/*\"]}}"
        ));
        policies.push(format!(
            "{{\"rules\":[\"put{id}\"],\"subjects\":[{}]}}",
            sid.json()
        ));
        everyone.push(sid);
    }
    let mut routers = Vec::new();
    for (n, name) in access.routers.iter().enumerate() {
        let sid = format!("router{n}");
        subjects.push(subject(&sid, name));
        routers.push(sid.clone());
        everyone.push(sid);
    }
    rules.push(
        "{\"id\":\"forward\",\"messages\":[\"put\"],\"flows\":[\"ingress\"],\
         \"permission\":\"allow\",\"key_exprs\":[\"troupe/**\"]}"
            .to_owned(),
    );
    rules.push(
        "{\"id\":\"send\",\"messages\":[\"put\"],\"flows\":[\"egress\"],\
         \"permission\":\"allow\",\"key_exprs\":[\"troupe/**\"]}"
            .to_owned(),
    );
    rules.push(
        "{\"id\":\"subscribe\",\"messages\":[\"declare_subscriber\"],\
         \"flows\":[\"ingress\",\"egress\"],\"permission\":\"allow\",\
         \"key_exprs\":[\"troupe/**\"]}"
            .to_owned(),
    );
    let list = |ids: &[String]| {
        ids.iter()
            .map(|s| s.as_str().json())
            .collect::<Vec<_>>()
            .join(",")
    };
    if !routers.is_empty() {
        policies.push(format!(
            "{{\"rules\":[\"forward\"],\"subjects\":[{}]}}",
            list(&routers)
        ));
    }
    policies.push(format!(
        "{{\"rules\":[\"send\",\"subscribe\"],\"subjects\":[{}]}}",
        list(&everyone)
    ));
    Some(format!(
        "{{\"enabled\":true,\"default_permission\":\"deny\",\"rules\":[{}],\
         \"subjects\":[{}],\"policies\":[{}]}}",
        rules.join(","),
        subjects.join(","),
        policies.join(",")
    ))
}
