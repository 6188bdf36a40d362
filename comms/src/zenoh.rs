//! The zenoh transport (feature `zenoh`, on by default): frames between processes
//! and hosts (DESIGN §5, issue 3).
//!
//! - **Key expressions** `troupe/<team>/<robot>/<class>` with the *sending* robot's
//!   index and the frame's class (`odometry`, `plan`, `keyframe`, `bulk`; ack
//!   frames travel as `odometry`, like the shaper schedules them); under a
//!   subscription scope other than `all`, broadcast odometry, plans and keyframes
//!   of a robot that knows where it is add the cell of its position,
//!   `troupe/<team>/<robot>/<class>/c<x>_<y>` ([`crate::scope`]).
//! - **Subscriptions** ([`ZenohTransport::with_subscription`]): scope `all` (the
//!   default) subscribes to `troupe/<team>/**`; `neighbourhood` and `base`
//!   subscribe to the team-wide keys `troupe/<team>/*/*` and, for
//!   `neighbourhood`, one subscriber `troupe/<team>/*/*/<cell>` per cell near the
//!   robot, re-declared as [`ZenohTransport::set_position`] moves it into other
//!   cells. zenoh's routing (a router, or the publishing peer) then never sends
//!   a robot the cells it did not ask for.
//! - **Addressing**: a frame for one robot (acks, store-and-forward catch-up)
//!   carries the addressee as a 4-byte attachment; other robots drop it.
//! - **Signatures** ([`signing`]): with `[zenoh.signing]` every frame carries its
//!   sender's ECDSA P-256 signature in the attachment (after the addressee), and
//!   frames not signed by the robot their key expression names are refused, so a
//!   router, which may forward every id, cannot pose as one.
//! - **Checks on receipt** (each counted in [`ZenohStats`]): the key expression
//!   must parse, name our team and a known class, and agree with the frame's
//!   class; the frame must parse and be at most the largest MTU long. The link
//!   actor then checks that the envelope's sender is the robot of the key
//!   expression ([`ReceivedPacket::from`]) and rejects and counts a mismatch.
//! - **Sessions**: peer mode with explicit listen/connect endpoints, or client
//!   mode towards a router; multicast scouting off by default (a session with no
//!   endpoints and no scouting opens no socket); optional TLS (root CA,
//!   certificate, key files; client certificates required by default) and
//!   user/password authentication.
//! - **Security** ([`security`], issue 23, `docs/security.md`): with
//!   `[zenoh.access]`, zenoh's access control lets the session named `robot<id>`
//!   (certificate common name or user) publish only under its own id; a session
//!   listening off loopback without authentication refuses to open unless it says
//!   `insecure = true`; zenoh drops any message larger than `max_message_bytes`
//!   (twice the largest frame by default) while receiving it, before it is
//!   buffered whole.
//! - **Never blocking the robot**: [`PacketTransport::send`] puts the frame in a
//!   bounded queue drained by a sender thread (full queue: dropped and counted).
//!   Shaping happens above, in the link actor, so the same study runs over zenoh
//!   and the simulated network.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use ::zenoh::Wait;
use ::zenoh::pubsub::Subscriber;
use ::zenoh::sample::{Locality, Sample};
use serde::{Deserialize, Serialize};

use crate::scope::{Cell, Scope, SubscriptionConfig, cell_segment, parse_cell_segment};
use crate::shaping::MAX_MTU_BYTES;
use crate::shaping::frame;
use crate::transport::{
    PacketSink, PacketTransport, ReceivedPacket, TransportError, TransportStats,
};
use crate::wire::Class;
use signing::{FrameSigner, FrameVerifier};

pub mod refusals;
pub mod security;
pub mod signing;

pub use signing::{ZenohSigner, ZenohSigning};

/// Session mode.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ZenohMode {
    /// Peer-to-peer: listen and connect to explicit endpoints.
    #[default]
    Peer,
    /// Client of a zenoh router (`connect` names it).
    Client,
}

/// TLS files (PEM). Used by `tls/` endpoints.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ZenohTls {
    /// Certificate authority that signed the peers' certificates.
    pub root_ca_path: PathBuf,
    /// This process's certificate.
    pub cert_path: PathBuf,
    /// This process's private key.
    pub key_path: PathBuf,
    /// Require and check a client certificate on listening endpoints (mutual TLS;
    /// on by default: without it anyone can connect to a `tls/` endpoint).
    #[serde(default = "mutual_by_default")]
    pub mutual: bool,
}

fn mutual_by_default() -> bool {
    true
}

/// Who may publish under which id (a `[zenoh.access]` table, written by
/// `troupe keys`): zenoh's access control, enforced by zenoh on every message in
/// and out of the session ([`security`]).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ZenohAccess {
    /// The team's link ids, robots and base station: the session named
    /// `robot<id>` ([`security::identity_name`]; its certificate's common name under
    /// mutual TLS, its user under `auth`) may publish only under
    /// `troupe/<team>/<id>/`. Sessions with other names may publish nothing.
    pub ids: Vec<u32>,
    /// Names (certificate common names, users) of zenoh routers trusted to forward
    /// every id's frames (`troupe keys` names its router `router`).
    #[serde(default)]
    pub routers: Vec<String>,
}

/// User/password authentication of zenoh sessions.
#[derive(Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ZenohAuth {
    /// This session's user name.
    pub user: String,
    /// This session's password.
    pub password: String,
    /// File of `user:password` lines accepted from peers (needed to accept
    /// authenticated peers on a listening endpoint).
    #[serde(default)]
    pub dictionary_path: Option<PathBuf>,
}

impl std::fmt::Debug for ZenohAuth {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ZenohAuth")
            .field("user", &self.user)
            .field("password", &"<hidden>")
            .field("dictionary_path", &self.dictionary_path)
            .finish()
    }
}

/// zenoh settings (a robot's `[link.zenoh]` table).
///
/// ```
/// let config: troupe_comms::zenoh::ZenohConfig = toml::from_str(r#"
///     mode = "peer"
///     listen = ["tcp/127.0.0.1:7447"]
///     connect = ["tcp/127.0.0.1:7448"]
/// "#).unwrap();
/// config.validate().unwrap();
/// assert!(!config.multicast_scouting);
/// ```
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ZenohConfig {
    /// Peer or client.
    pub mode: ZenohMode,
    /// Endpoints to listen on, e.g. `tcp/0.0.0.0:7447`, `tls/0.0.0.0:7447`.
    pub listen: Vec<String>,
    /// Endpoints to connect to (peers, or the router in client mode).
    pub connect: Vec<String>,
    /// Discover peers by UDP multicast (and gossip). Off by default.
    pub multicast_scouting: bool,
    /// Peer mode: learn of the other peers from the sessions in `connect` (a
    /// router, or another peer) and connect to them directly — zenoh's gossip
    /// scouting, for networks without multicast (`docs/scale.md`). Off by
    /// default; on with `multicast_scouting` too.
    pub gossip_scouting: bool,
    /// TLS files; required when an endpoint uses `tls/`.
    pub tls: Option<ZenohTls>,
    /// User/password authentication.
    pub auth: Option<ZenohAuth>,
    /// Who may publish under which id (zenoh's access control).
    pub access: Option<ZenohAccess>,
    /// Sign every frame sent and accept only frames signed by their sender's key
    /// ([`signing`]: what keeps a router from posing as a robot).
    pub signing: Option<ZenohSigning>,
    /// Accept a listening endpoint off loopback without authentication or access
    /// control (anyone who reaches the port can pose as any robot).
    pub insecure: bool,
    /// Largest message zenoh receives, bytes; larger ones are dropped while they
    /// arrive, before they are buffered whole (zenoh's
    /// `transport/link/rx/max_message_size`). 0: [`DEFAULT_MAX_MESSAGE_BYTES`]
    /// (twice the largest frame a link sends: zenoh carries nothing else).
    pub max_message_bytes: usize,
    /// Frames waiting for the sender thread before new ones are dropped.
    pub send_queue_frames: usize,
    /// Seconds an accepted connection has to open its zenoh session before it is
    /// closed (zenoh's `transport/unicast/accept_timeout`). 0:
    /// [`DEFAULT_ACCEPT_TIMEOUT_S`].
    pub accept_timeout_s: f64,
    /// Connections that may be opening a session at once; more are closed as they
    /// arrive (zenoh's `transport/unicast/accept_pending`). 0:
    /// [`DEFAULT_ACCEPT_PENDING`].
    pub accept_pending: usize,
}

const DEFAULT_SEND_QUEUE_FRAMES: usize = 4096;

/// The smallest `max_message_bytes`: one frame of the largest MTU with headroom.
const MIN_MAX_MESSAGE_BYTES: usize = 64 * 1024;

/// The default `max_message_bytes`: twice the largest frame a link sends (zenoh
/// carries nothing larger for troupe). It bounds what zenoh buffers for one
/// incomplete message of one connection, so many hostile connections at once cost
/// little (each could hold 4 MiB with troupe's message limit as the bound).
pub const DEFAULT_MAX_MESSAGE_BYTES: usize = 128 * 1024;

/// The default `accept_timeout_s`: half zenoh's 10 s, still many round trips of a
/// slow radio link. With [`DEFAULT_ACCEPT_PENDING`], a stranger's idle or junk
/// connections keep a listener from taking new sessions only at 200 a second or
/// more (zenoh's 100 and 10 s: at 10 a second; `docs/security.md`).
pub const DEFAULT_ACCEPT_TIMEOUT_S: f64 = 5.0;

/// The default `accept_pending` (zenoh's: 100); [`DEFAULT_ACCEPT_TIMEOUT_S`].
pub const DEFAULT_ACCEPT_PENDING: usize = 1000;

/// zenoh's pause after each failed TLS handshake in this build, microseconds, as
/// the build environment set it (the workspace's `.cargo/config.toml`: 100); `None`:
/// zenoh's own 100 ms, under which a stranger's junk handshakes can keep the team's
/// sessions out (`docs/security.md`, "Connection floods"). zenoh reads the same
/// variable when it is compiled.
pub const TLS_ACCEPT_THROTTLE_US: Option<&str> = option_env!("TLS_ACCEPT_THROTTLE_TIME");

/// The shortest `accept_timeout_s` accepted but 0, seconds: a few round trips on
/// loopback.
const MIN_ACCEPT_TIMEOUT_S: f64 = 0.1;

/// The longest `accept_timeout_s` accepted, seconds.
const MAX_ACCEPT_TIMEOUT_S: f64 = 60.0;

fn config_error(key: &str, reason: impl Into<String>) -> TransportError {
    TransportError::Config {
        key: key.to_owned(),
        reason: reason.into(),
    }
}

/// `value`, or `default` where a setting left at 0 means the default.
fn unless_zero<T: PartialEq + Default>(value: T, default: T) -> T {
    if value == T::default() {
        default
    } else {
        value
    }
}

impl ZenohConfig {
    /// Makes the relative TLS, dictionary and signing-key paths relative to `dir` (the
    /// directory of the file the settings were read from).
    pub fn resolve_paths(&mut self, dir: &Path) {
        if let Some(tls) = &mut self.tls {
            for p in [&mut tls.root_ca_path, &mut tls.cert_path, &mut tls.key_path] {
                *p = dir.join(&*p);
            }
        }
        if let Some(dictionary) = self.auth.as_mut().and_then(|a| a.dictionary_path.as_mut()) {
            *dictionary = dir.join(&*dictionary);
        }
        if let Some(signing) = &mut self.signing {
            signing.key_path = dir.join(&signing.key_path);
        }
    }

    /// `max_message_bytes`, with 0 meaning [`DEFAULT_MAX_MESSAGE_BYTES`].
    #[must_use]
    pub fn max_message_bytes(&self) -> usize {
        unless_zero(self.max_message_bytes, DEFAULT_MAX_MESSAGE_BYTES)
    }

    /// `accept_timeout_s`, with 0 meaning [`DEFAULT_ACCEPT_TIMEOUT_S`].
    #[must_use]
    pub fn accept_timeout_s(&self) -> f64 {
        unless_zero(self.accept_timeout_s, DEFAULT_ACCEPT_TIMEOUT_S)
    }

    /// `accept_pending`, with 0 meaning [`DEFAULT_ACCEPT_PENDING`].
    #[must_use]
    pub fn accept_pending(&self) -> usize {
        unless_zero(self.accept_pending, DEFAULT_ACCEPT_PENDING)
    }

    /// What `insecure = true` leaves open off this machine: each listening or
    /// connecting endpoint off loopback that authenticates no one, and multicast
    /// scouting without credentials. Empty when the settings are not insecure or
    /// nothing is open; a session that opens with something here logs it once.
    #[must_use]
    pub fn open_to_network(&self) -> Vec<String> {
        if !self.insecure {
            return Vec::new();
        }
        let credentials = self.tls.is_some() || self.auth.is_some();
        let mut open: Vec<String> = self
            .listen
            .iter()
            .chain(&self.connect)
            .filter(|e| {
                let address = e.split_once('/').map_or(e.as_str(), |(_, a)| a);
                !security::is_loopback(address) && !credentials
            })
            .cloned()
            .collect();
        if self.multicast_scouting && !credentials {
            open.push("multicast scouting".to_owned());
        }
        open
    }

    /// Checks the settings (endpoint syntax, TLS files present when needed,
    /// client mode has a router to connect to) and the secure defaults
    /// ([`security`]: authentication off loopback, a usable password dictionary,
    /// access control with names).
    pub fn validate(&self) -> Result<(), TransportError> {
        for (key, endpoints) in [("listen", &self.listen), ("connect", &self.connect)] {
            for e in endpoints {
                let Some((protocol, address)) = e.split_once('/') else {
                    return Err(config_error(
                        key,
                        format!("`{e}` is not `<protocol>/<address>`"),
                    ));
                };
                if !matches!(protocol, "tcp" | "udp" | "tls") {
                    return Err(config_error(
                        key,
                        format!("`{e}`: protocol must be tcp, udp or tls"),
                    ));
                }
                if address.is_empty() {
                    return Err(config_error(key, format!("`{e}` has no address")));
                }
                if protocol == "tls" && self.tls.is_none() {
                    return Err(config_error(
                        "tls",
                        format!("endpoint `{e}` needs the tls table"),
                    ));
                }
            }
        }
        if self.mode == ZenohMode::Client && self.connect.is_empty() {
            return Err(config_error(
                "connect",
                "client mode needs the router's endpoint",
            ));
        }
        if let Some(tls) = &self.tls {
            for (key, path) in [
                ("tls.root_ca_path", &tls.root_ca_path),
                ("tls.cert_path", &tls.cert_path),
                ("tls.key_path", &tls.key_path),
            ] {
                if !path.is_file() {
                    return Err(config_error(
                        key,
                        format!("{} is not a readable file", path.display()),
                    ));
                }
            }
        }
        if let Some(auth) = &self.auth {
            if auth.user.is_empty() {
                return Err(config_error("auth.user", "must not be empty"));
            }
            if let Some(path) = &auth.dictionary_path
                && !path.is_file()
            {
                return Err(config_error(
                    "auth.dictionary_path",
                    format!("{} is not a readable file", path.display()),
                ));
            }
        }
        if self.max_message_bytes != 0 && self.max_message_bytes < MIN_MAX_MESSAGE_BYTES {
            return Err(config_error(
                "max_message_bytes",
                format!("must be at least {MIN_MAX_MESSAGE_BYTES} (one frame), or 0"),
            ));
        }
        if !(self.accept_timeout_s == 0.0
            || (MIN_ACCEPT_TIMEOUT_S..=MAX_ACCEPT_TIMEOUT_S).contains(&self.accept_timeout_s))
        {
            return Err(config_error(
                "accept_timeout_s",
                format!(
                    "must be between {MIN_ACCEPT_TIMEOUT_S} and {MAX_ACCEPT_TIMEOUT_S} s, or 0 \
                     (the default)"
                ),
            ));
        }
        if let Some(signing) = &self.signing {
            signing.validate()?;
        }
        security::check(self)
    }

    /// The zenoh configuration these settings stand for. Warns once per process if
    /// it listens on TLS in a build that kept zenoh's 100 ms pause after a failed
    /// handshake ([`TLS_ACCEPT_THROTTLE_US`]).
    pub fn to_zenoh(&self) -> Result<::zenoh::Config, TransportError> {
        self.validate()?;
        if TLS_ACCEPT_THROTTLE_US.is_none() && self.listen.iter().any(|e| e.starts_with("tls/")) {
            static WARNED: std::sync::Once = std::sync::Once::new();
            WARNED.call_once(|| {
                tracing::warn!(
                    "this build keeps zenoh's 100 ms pause after each failed TLS handshake: \
                     a stranger's junk handshakes can keep peers out; build troupe with \
                     TLS_ACCEPT_THROTTLE_TIME=100 (docs/security.md, \"Connection floods\")"
                );
            });
        }
        let mut c = ::zenoh::Config::default();
        let json = |v: &dyn erased::Json| v.json();
        let mode = match self.mode {
            ZenohMode::Peer => "peer",
            ZenohMode::Client => "client",
        };
        let mut set = |key: &str, value: String| {
            c.insert_json5(key, &value)
                .map_err(|e| TransportError::Network {
                    context: format!("setting zenoh `{key}`"),
                    source: e,
                })
        };
        set("mode", json(&mode))?;
        set("listen/endpoints", json(&self.listen))?;
        set("connect/endpoints", json(&self.connect))?;
        set("scouting/multicast/enabled", json(&self.multicast_scouting))?;
        set(
            "scouting/gossip/enabled",
            json(&(self.multicast_scouting || self.gossip_scouting)),
        )?;
        set(
            "transport/link/rx/max_message_size",
            self.max_message_bytes().to_string(),
        )?;
        set(
            "transport/unicast/accept_timeout",
            format!("{:.0}", self.accept_timeout_s() * 1000.0),
        )?;
        set(
            "transport/unicast/accept_pending",
            self.accept_pending().to_string(),
        )?;
        if let Some(tls) = &self.tls {
            let path = |p: &PathBuf| json(&p.display().to_string());
            set(
                "transport/link/tls/root_ca_certificate",
                path(&tls.root_ca_path),
            )?;
            set(
                "transport/link/tls/listen_certificate",
                path(&tls.cert_path),
            )?;
            set("transport/link/tls/listen_private_key", path(&tls.key_path))?;
            set(
                "transport/link/tls/connect_certificate",
                path(&tls.cert_path),
            )?;
            set(
                "transport/link/tls/connect_private_key",
                path(&tls.key_path),
            )?;
            set("transport/link/tls/enable_mtls", json(&tls.mutual))?;
            // Certificates name robots, not hosts: the team's CA vouches for the
            // name, and the access control binds the name to an id.
            set("transport/link/tls/verify_name_on_connect", json(&false))?;
        }
        if let Some(auth) = &self.auth {
            set("transport/auth/usrpwd/user", json(&auth.user))?;
            set("transport/auth/usrpwd/password", json(&auth.password))?;
            if let Some(path) = &auth.dictionary_path {
                set(
                    "transport/auth/usrpwd/dictionary_file",
                    json(&path.display().to_string()),
                )?;
            }
        }
        if let Some(acl) = security::access_control_json5(self) {
            set("access_control", acl)?;
        }
        Ok(c)
    }
}

/// JSON text of config values without pulling serde_json in.
mod erased {
    pub trait Json {
        fn json(&self) -> String;
    }
    impl Json for bool {
        fn json(&self) -> String {
            self.to_string()
        }
    }
    impl Json for str {
        fn json(&self) -> String {
            quote(self)
        }
    }
    impl Json for &str {
        fn json(&self) -> String {
            quote(self)
        }
    }
    impl Json for String {
        fn json(&self) -> String {
            quote(self)
        }
    }
    impl Json for Vec<String> {
        fn json(&self) -> String {
            let items: Vec<String> = self.iter().map(|s| quote(s)).collect();
            format!("[{}]", items.join(","))
        }
    }
    fn quote(s: &str) -> String {
        let mut out = String::with_capacity(s.len() + 2);
        out.push('"');
        for ch in s.chars() {
            match ch {
                '"' => out.push_str("\\\""),
                '\\' => out.push_str("\\\\"),
                c if (c as u32) < 0x20 => out.push_str(&format!("\\u{:04x}", c as u32)),
                c => out.push(c),
            }
        }
        out.push('"');
        out
    }
}

/// The key-expression segment of a class.
#[must_use]
pub fn class_segment(class: Class) -> &'static str {
    match class {
        Class::Odometry => "odometry",
        Class::Plan => "plan",
        Class::Keyframe => "keyframe",
        Class::Bulk => "bulk",
    }
}

/// `troupe/<team>/<robot>/<class>`.
#[must_use]
pub fn key_expr(team: u32, robot: u32, class: Class) -> String {
    format!("troupe/{team}/{robot}/{}", class_segment(class))
}

/// Why a received sample was dropped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KeyError {
    /// Not `troupe/<team>/<robot>/<class>` with numbers and a known class.
    Malformed,
    /// Another team's key.
    OtherTeam,
}

/// Parses `troupe/<team>/<robot>/<class>` (or, but for bulk, with a cell segment
/// `/c<x>_<y>` after the class) for `team`: the sender and the class.
pub fn parse_key_expr(key: &str, team: u32) -> Result<(u32, Class), KeyError> {
    let mut parts = key.split('/');
    let (Some("troupe"), Some(t), Some(r), Some(c), cell, None) = (
        parts.next(),
        parts.next(),
        parts.next(),
        parts.next(),
        parts.next(),
        parts.next(),
    ) else {
        return Err(KeyError::Malformed);
    };
    let t: u32 = t.parse().map_err(|_| KeyError::Malformed)?;
    let robot: u32 = r.parse().map_err(|_| KeyError::Malformed)?;
    let class = Class::ALL
        .into_iter()
        .find(|k| class_segment(*k) == c)
        .ok_or(KeyError::Malformed)?;
    if let Some(cell) = cell
        && (class == Class::Bulk || parse_cell_segment(cell).is_none())
    {
        return Err(KeyError::Malformed);
    }
    if t != team {
        return Err(KeyError::OtherTeam);
    }
    Ok((robot, class))
}

/// The class a frame travels in (acks: odometry, the shaper's first class).
pub fn frame_class(bytes: &[u8]) -> Result<Class, TransportError> {
    Ok(frame::class_of(bytes)?)
}

/// Counters of a [`ZenohTransport`].
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct ZenohStats {
    /// Frames handed to zenoh.
    pub sent_frames: u64,
    /// Bytes handed to zenoh.
    pub sent_bytes: u64,
    /// Frames dropped because the send queue was full.
    pub send_queue_drops: u64,
    /// Frames zenoh refused to publish.
    pub send_errors: u64,
    /// Frames delivered to the sink.
    pub received_frames: u64,
    /// Frames addressed to another robot (ignored, not an error).
    pub not_for_us: u64,
    /// Rejected: key expression not `troupe/<team>/<robot>/<class>`.
    pub rejected_key: u64,
    /// Rejected: another team's key expression.
    pub rejected_team: u64,
    /// Rejected: bytes that are not a frame (or longer than the largest MTU, a
    /// frame no link sends), or a bad addressee attachment.
    pub rejected_frame: u64,
    /// Rejected: the frame's class differs from the key expression's.
    pub rejected_class: u64,
    /// Rejected: a key expression naming one of this process's own robots as
    /// the sender (someone else is using its key).
    pub rejected_sender: u64,
    /// Rejected under `[zenoh.signing]`: no signature, or not the named sender's
    /// ([`signing`]).
    pub rejected_signature: u64,
    /// Cells subscribed to now (scope `neighbourhood`; [`crate::scope`]).
    pub subscribed_cells: u64,
    /// Times the cell subscriptions changed because a local robot moved.
    pub resubscriptions: u64,
    /// Connections zenoh refused before they became sessions, by kind
    /// ([`refusals::Refusal::name`]; every session of this process, since it
    /// started).
    pub refused_connections: std::collections::BTreeMap<String, u64>,
}

#[derive(Default)]
struct Counters {
    sent_frames: AtomicU64,
    sent_bytes: AtomicU64,
    send_queue_drops: AtomicU64,
    send_errors: AtomicU64,
    received_frames: AtomicU64,
    not_for_us: AtomicU64,
    rejected_key: AtomicU64,
    rejected_team: AtomicU64,
    rejected_frame: AtomicU64,
    rejected_class: AtomicU64,
    rejected_sender: AtomicU64,
    rejected_signature: AtomicU64,
    /// Unix second of the last warning about unsigned frames (one per 10 s).
    signature_warned_s: AtomicU64,
    subscribed_cells: AtomicU64,
    resubscriptions: AtomicU64,
}

fn bump(c: &AtomicU64) {
    c.fetch_add(1, Ordering::Relaxed);
}

impl Counters {
    fn snapshot(&self) -> ZenohStats {
        let l = |c: &AtomicU64| c.load(Ordering::Relaxed);
        ZenohStats {
            sent_frames: l(&self.sent_frames),
            sent_bytes: l(&self.sent_bytes),
            send_queue_drops: l(&self.send_queue_drops),
            send_errors: l(&self.send_errors),
            received_frames: l(&self.received_frames),
            not_for_us: l(&self.not_for_us),
            rejected_key: l(&self.rejected_key),
            rejected_team: l(&self.rejected_team),
            rejected_frame: l(&self.rejected_frame),
            rejected_class: l(&self.rejected_class),
            rejected_sender: l(&self.rejected_sender),
            rejected_signature: l(&self.rejected_signature),
            subscribed_cells: l(&self.subscribed_cells),
            resubscriptions: l(&self.resubscriptions),
            refused_connections: refusals::refused_connections(),
        }
    }
}

/// A frame waiting for the sender thread.
struct Outgoing {
    key: String,
    from: u32,
    class: Class,
    to: Option<u32>,
    bytes: Vec<u8>,
}

/// What received samples go to.
type SampleHandler = Arc<dyn Fn(&Sample) + Send + Sync>;

/// The session's subscribers: the team-wide one and one per subscribed cell.
#[derive(Default)]
struct Subscriptions {
    /// Set by [`PacketTransport::start`].
    handler: Option<SampleHandler>,
    team_wide: Option<Subscriber<()>>,
    cells: std::collections::BTreeMap<Cell, Subscriber<()>>,
    /// The last known position of each local robot.
    positions: std::collections::BTreeMap<u32, [f64; 3]>,
}

/// One zenoh session carrying the frames of the robots `local` of team `team`.
/// See the [module docs](self).
pub struct ZenohTransport {
    team: u32,
    local: Vec<u32>,
    session: ::zenoh::Session,
    queue: Mutex<Option<SyncSender<Outgoing>>>,
    sender: Mutex<Option<JoinHandle<()>>>,
    subscription: SubscriptionConfig,
    subscriptions: Mutex<Subscriptions>,
    counters: Arc<Counters>,
    /// The signers' keys, with `[zenoh.signing]`.
    verifier: Option<Arc<FrameVerifier>>,
}

impl ZenohTransport {
    /// Opens a session for the robots `local` (indices in team `team`).
    pub fn open(config: &ZenohConfig, team: u32, local: Vec<u32>) -> Result<Self, TransportError> {
        let zc = config.to_zenoh()?;
        let open = config.open_to_network();
        if !open.is_empty() {
            tracing::warn!(
                "insecure = true: {} accept(s) anyone on the network, who can pose as any \
                 robot of team {team} (docs/security.md)",
                open.join(", ")
            );
        }
        let (signer, verifier) = match &config.signing {
            Some(signing) => {
                let (signer, verifier) = signing.open(&local)?;
                (Some(signer), Some(Arc::new(verifier)))
            }
            None => (None, None),
        };
        let session = ::zenoh::open(zc)
            .wait()
            .map_err(|e| TransportError::Network {
                context: "opening the zenoh session".into(),
                source: e,
            })?;
        let capacity = if config.send_queue_frames == 0 {
            DEFAULT_SEND_QUEUE_FRAMES
        } else {
            config.send_queue_frames
        };
        let (tx, rx) = sync_channel::<Outgoing>(capacity);
        let counters = Arc::new(Counters::default());
        let thread_session = session.clone();
        let thread_counters = counters.clone();
        let sender = std::thread::Builder::new()
            .name(format!("troupe-zenoh-tx-{team}"))
            .spawn(move || {
                send_loop(
                    &thread_session,
                    &rx,
                    &thread_counters,
                    team,
                    signer.as_ref(),
                );
            })
            .map_err(|e| TransportError::Network {
                context: "starting the zenoh sender thread".into(),
                source: Box::new(e),
            })?;
        Ok(ZenohTransport {
            team,
            local,
            session,
            queue: Mutex::new(Some(tx)),
            sender: Mutex::new(Some(sender)),
            subscription: SubscriptionConfig::default(),
            subscriptions: Mutex::new(Subscriptions::default()),
            counters,
            verifier,
        })
    }

    /// Receives what `subscription` selects instead of every peer's frames (call
    /// before [`PacketTransport::start`]; [`crate::scope`]). Frames are then
    /// published under the cell of the sender's position too, so every robot of a
    /// team must use the same `cell_m`.
    #[must_use]
    pub fn with_subscription(mut self, subscription: SubscriptionConfig) -> Self {
        self.subscription = subscription;
        self
    }

    /// Tells the transport where local robot `robot` is (its own odometry, metres):
    /// its broadcast odometry, plans and keyframes go out under that cell, and under scope
    /// `neighbourhood` the cell subscriptions follow it. Cheap when the cell has
    /// not changed; other robots' ids are ignored.
    pub fn set_position(&self, robot: u32, position_m: [f64; 3]) {
        if !self.local.contains(&robot) {
            return;
        }
        let Ok(mut subs) = self.subscriptions.lock() else {
            return;
        };
        let before = subs.positions.insert(robot, position_m);
        let cell = |p: Option<[f64; 3]>| p.and_then(|p| self.subscription.cell_of(p));
        if before.is_none() || cell(before) != cell(Some(position_m)) {
            self.resubscribe(&mut subs);
        }
    }

    /// The cells the local robots' positions call for.
    fn wanted_cells(&self, subs: &Subscriptions) -> std::collections::BTreeSet<Cell> {
        subs.positions
            .values()
            .flat_map(|p| self.subscription.subscribed_cells(Some(*p)))
            .collect()
    }

    /// Declares the cell subscribers now wanted and undeclares the others (once
    /// started).
    fn resubscribe(&self, subs: &mut Subscriptions) {
        let Some(handler) = subs.handler.clone() else {
            return;
        };
        let wanted = self.wanted_cells(subs);
        let before = subs.cells.len();
        subs.cells.retain(|cell, _| wanted.contains(cell));
        let mut changed = before != subs.cells.len();
        for cell in wanted {
            if subs.cells.contains_key(&cell) {
                continue;
            }
            let handler = handler.clone();
            let declared = self
                .session
                .declare_subscriber(format!("troupe/{}/*/*/{}", self.team, cell_segment(cell)))
                .callback(move |sample| handler(&sample))
                .wait();
            match declared {
                Ok(subscriber) => {
                    subs.cells.insert(cell, subscriber);
                    changed = true;
                }
                Err(e) => tracing::warn!(?cell, "zenoh: cannot subscribe to a cell: {e}"),
            }
        }
        if changed {
            bump(&self.counters.resubscriptions);
        }
        self.counters
            .subscribed_cells
            .store(subs.cells.len() as u64, Ordering::Relaxed);
    }

    /// Counters so far.
    #[must_use]
    pub fn stats(&self) -> ZenohStats {
        self.counters.snapshot()
    }

    /// Stops the sender thread (after it sent what was queued) and closes the
    /// session.
    pub fn close(&self) -> Result<(), TransportError> {
        let queue = self.queue.lock().map(|mut q| q.take());
        drop(queue);
        if let Ok(mut sender) = self.sender.lock()
            && let Some(handle) = sender.take()
        {
            let _ = handle.join();
        }
        if let Ok(mut s) = self.subscriptions.lock() {
            s.team_wide.take();
            s.cells.clear();
            s.handler.take();
        }
        self.session
            .close()
            .wait()
            .map_err(|e| TransportError::Network {
                context: "closing the zenoh session".into(),
                source: e,
            })
    }
}

impl Drop for ZenohTransport {
    fn drop(&mut self) {
        if let Err(e) = self.close() {
            tracing::debug!("zenoh transport: {e}");
        }
    }
}

fn send_loop(
    session: &::zenoh::Session,
    rx: &Receiver<Outgoing>,
    counters: &Counters,
    team: u32,
    signer: Option<&FrameSigner>,
) {
    let mut publishers: std::collections::HashMap<String, ::zenoh::pubsub::Publisher<'static>> =
        std::collections::HashMap::new();
    while let Ok(out) = rx.recv() {
        if !publishers.contains_key(&out.key) {
            let declared = session
                .declare_publisher(out.key.clone())
                .allowed_destination(Locality::Remote)
                .wait();
            match declared {
                Ok(p) => {
                    publishers.insert(out.key.clone(), p);
                }
                Err(e) => {
                    bump(&counters.send_errors);
                    tracing::warn!(key = %out.key, "zenoh: cannot declare a publisher: {e}");
                    continue;
                }
            }
        }
        let Some(publisher) = publishers.get(&out.key) else {
            continue;
        };
        // The addressee (4 bytes) if any, then the signature if signing.
        let mut attachment = out
            .to
            .map(|to| to.to_le_bytes().to_vec())
            .unwrap_or_default();
        if let Some(signer) = signer {
            let message = signing::signed_bytes(team, out.from, out.class, out.to, &out.bytes);
            let Some(signature) = signer.sign(&message) else {
                bump(&counters.send_errors);
                tracing::warn!(key = %out.key, "zenoh: cannot sign a frame (no randomness)");
                continue;
            };
            attachment.extend_from_slice(&signature);
        }
        let len = out.bytes.len() as u64;
        let put = publisher.put(out.bytes);
        let put = if attachment.is_empty() {
            put
        } else {
            put.attachment(attachment)
        };
        match put.wait() {
            Ok(()) => {
                bump(&counters.sent_frames);
                counters.sent_bytes.fetch_add(len, Ordering::Relaxed);
            }
            Err(e) => {
                bump(&counters.send_errors);
                tracing::warn!(key = %out.key, "zenoh: put failed: {e}");
            }
        }
    }
}

/// Bytes of the addressee in an attachment (a robot id, little-endian).
const ADDRESSEE_BYTES: usize = 4;

/// The addressee and the signature of a sample's attachment: none, the addressee
/// (4 bytes), a signature, or both in that order; `Err` for anything else.
fn read_attachment(attachment: &[u8]) -> Result<(Option<u32>, Option<&[u8]>), ()> {
    let signed = ADDRESSEE_BYTES + signing::SIGNATURE_BYTES;
    let (to, signature) = match attachment.len() {
        0 | signing::SIGNATURE_BYTES => attachment.split_at(0),
        n if n == ADDRESSEE_BYTES || n == signed => attachment.split_at(ADDRESSEE_BYTES),
        _ => return Err(()),
    };
    let to = <[u8; 4]>::try_from(to).ok().map(u32::from_le_bytes);
    Ok((to, (!signature.is_empty()).then_some(signature)))
}

/// What a session receives with: its team and robots, its counters, and the
/// signers' keys with `[zenoh.signing]`.
struct Receiving {
    team: u32,
    local: Vec<u32>,
    counters: Arc<Counters>,
    verifier: Option<Arc<FrameVerifier>>,
}

/// Counts a frame refused for its signature and warns at most once per 10 s.
fn refuse_signature(counters: &Counters, from: u32, key: &str) {
    bump(&counters.rejected_signature);
    let now_s = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let last = counters.signature_warned_s.load(Ordering::Relaxed);
    if now_s >= last + 10
        && counters
            .signature_warned_s
            .compare_exchange(last, now_s, Ordering::Relaxed, Ordering::Relaxed)
            .is_ok()
    {
        tracing::warn!(
            claimed = from,
            key,
            refused = counters.rejected_signature.load(Ordering::Relaxed),
            "zenoh: refused frames not signed by the robot they name (one line per 10 s)"
        );
    }
}

/// Checks one received sample and hands it to the sink.
fn receive(sample: &Sample, r: &Receiving, sink: &PacketSink) {
    let (team, local, counters) = (r.team, r.local.as_slice(), &*r.counters);
    let (from, class) = match parse_key_expr(sample.key_expr().as_str(), team) {
        Ok(parsed) => parsed,
        Err(KeyError::Malformed) => return bump(&counters.rejected_key),
        Err(KeyError::OtherTeam) => return bump(&counters.rejected_team),
    };
    if local.contains(&from) {
        // Our publications never come back (they are published for remote
        // subscribers only): someone else is using a local robot's key.
        return bump(&counters.rejected_sender);
    }
    let attachment = sample
        .attachment()
        .map(|a| a.to_bytes())
        .unwrap_or_default();
    let Ok((to, signature)) = read_attachment(&attachment) else {
        return bump(&counters.rejected_frame);
    };
    if to.is_some_and(|to| !local.contains(&to)) {
        return bump(&counters.not_for_us);
    }
    if sample.payload().len() > MAX_MTU_BYTES {
        // No link sends a frame this long: junk, refused before it is copied.
        return bump(&counters.rejected_frame);
    }
    let bytes = sample.payload().to_bytes();
    match frame_class(&bytes) {
        Ok(c) if c == class => {}
        Ok(_) => return bump(&counters.rejected_class),
        Err(_) => return bump(&counters.rejected_frame),
    }
    if let Some(verifier) = &r.verifier {
        let message = signing::signed_bytes(team, from, class, to, &bytes);
        if !signature.is_some_and(|s| verifier.verify(from, &message, s)) {
            return refuse_signature(counters, from, sample.key_expr().as_str());
        }
    }
    bump(&counters.received_frames);
    sink(ReceivedPacket {
        from,
        to,
        bytes: &bytes,
    });
}

impl PacketTransport for ZenohTransport {
    fn start(&self, sink: PacketSink) -> Result<(), TransportError> {
        let team = self.team;
        let receiving = Receiving {
            team,
            local: self.local.clone(),
            counters: self.counters.clone(),
            verifier: self.verifier.clone(),
        };
        let handler: SampleHandler =
            Arc::new(move |sample: &Sample| receive(sample, &receiving, &sink));
        let key = match self.subscription.scope {
            Scope::All => format!("troupe/{team}/**"),
            Scope::Neighbourhood | Scope::Base => format!("troupe/{team}/*/*"),
        };
        let team_handler = handler.clone();
        let subscriber = self
            .session
            .declare_subscriber(key)
            .callback(move |sample| team_handler(&sample))
            .wait()
            .map_err(|e| TransportError::Network {
                context: "declaring the zenoh subscriber".into(),
                source: e,
            })?;
        let mut subs = self
            .subscriptions
            .lock()
            .map_err(|_| TransportError::Closed)?;
        subs.team_wide = Some(subscriber);
        subs.handler = Some(handler);
        self.resubscribe(&mut subs);
        Ok(())
    }

    fn stats(&self) -> TransportStats {
        let z = self.counters.snapshot();
        TransportStats {
            sent_frames: z.sent_frames,
            sent_bytes: z.sent_bytes,
            send_failures: z.send_queue_drops + z.send_errors,
            received_frames: z.received_frames,
            rejected_frames: z.rejected_key
                + z.rejected_team
                + z.rejected_frame
                + z.rejected_class
                + z.rejected_sender
                + z.rejected_signature,
        }
    }

    fn send(&self, from: u32, to: Option<u32>, frame: &[u8]) -> Result<(), TransportError> {
        let class = frame_class(frame)?;
        let position = self
            .subscriptions
            .lock()
            .ok()
            .and_then(|s| s.positions.get(&from).copied());
        let mut key = key_expr(self.team, from, class);
        if let Some(cell) = self
            .subscription
            .publish_cell(class, to.is_some(), position)
        {
            key = format!("{key}/{}", cell_segment(cell));
        }
        let out = Outgoing {
            key,
            from,
            class,
            to,
            bytes: frame.to_vec(),
        };
        let queue = self.queue.lock().map_err(|_| TransportError::Closed)?;
        let Some(tx) = queue.as_ref() else {
            return Err(TransportError::Closed);
        };
        match tx.try_send(out) {
            Ok(()) => Ok(()),
            Err(TrySendError::Full(_)) => {
                bump(&self.counters.send_queue_drops);
                Err(TransportError::QueueFull)
            }
            Err(TrySendError::Disconnected(_)) => Err(TransportError::Closed),
        }
    }
}

#[cfg(test)]
mod tests;
