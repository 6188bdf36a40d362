//! Connections zenoh refuses before they become sessions, counted per kind and
//! logged as one line per kind at most every [`REFUSAL_LOG_PERIOD_S`] (issue 45,
//! item 3; `docs/security.md`, "Connection floods").
//!
//! zenoh logs one line per refused connection (a stranger's junk or
//! certificate-less TLS handshake, an idle socket that timed out, a session over
//! the pending limit), some only at debug or trace level: a flood of 30 junk
//! handshakes a second wrote 775 warnings in 30 s, and a plain-TCP listener full of
//! pending connections refused new ones without a word. [`refusal_layer`] (a
//! `tracing` layer installed by the binaries' logging) counts those events by
//! [`Refusal`] kind instead; [`hide_refusals`] keeps them out of the log, and a
//! reporter thread, started by the first refusal, writes one line per kind per
//! period with the count and the latest detail: a warning, or an info line for a
//! few of the kinds a team's own sessions cause now and then. [`refused_connections`] gives the
//! process's totals (a robot's `summary.json`, `zenoh.refused_connections`).

use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use tracing::field::{Field, Visit};
use tracing::{Event, Level, Metadata, Subscriber};
use tracing_subscriber::layer::{Context, Filter, Layer};

/// Shortest time between two log lines of one kind of refusal, seconds.
pub const REFUSAL_LOG_PERIOD_S: f64 = 10.0;

/// Routine refusals in one line's period below which the line is at info level
/// ([`Refusal`]'s `is_routine`).
const ROUTINE_REFUSALS: u64 = 10;

/// A kind of connection zenoh refused before it became a session.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Refusal {
    /// A TLS client without a certificate at a mutual-TLS listener.
    NoCertificate,
    /// A TLS client whose certificate the team's CA did not sign (or expired).
    BadCertificate,
    /// A TLS handshake not finished within zenoh's handshake timeout (an idle
    /// socket).
    HandshakeTimeout,
    /// A TLS handshake that failed otherwise: not TLS at all, or a client that went
    /// away mid-handshake.
    MalformedHandshake,
    /// A connection over zenoh's limit of sessions being opened
    /// (`transport/unicast/accept_pending`), closed at once.
    PendingLimit,
    /// A connection that did not open a zenoh session within
    /// `transport/unicast/accept_timeout` (e.g. an idle plain-TCP socket).
    SessionTimeout,
    /// A connection that sent something other than zenoh's session handshake.
    SessionRefused,
    /// The listener could not accept (e.g. out of file descriptors).
    AcceptFailed,
    /// Any other per-connection warning of zenoh's TCP and TLS listeners.
    Other,
}

const KINDS: usize = 9;

impl Refusal {
    /// Every kind, in declaration order.
    pub const ALL: [Refusal; KINDS] = [
        Refusal::NoCertificate,
        Refusal::BadCertificate,
        Refusal::HandshakeTimeout,
        Refusal::MalformedHandshake,
        Refusal::PendingLimit,
        Refusal::SessionTimeout,
        Refusal::SessionRefused,
        Refusal::AcceptFailed,
        Refusal::Other,
    ];

    fn index(self) -> usize {
        self as usize
    }

    /// Its name in `summary.json` and log lines.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Refusal::NoCertificate => "no_certificate",
            Refusal::BadCertificate => "bad_certificate",
            Refusal::HandshakeTimeout => "handshake_timeout",
            Refusal::MalformedHandshake => "malformed_handshake",
            Refusal::PendingLimit => "pending_limit",
            Refusal::SessionTimeout => "session_timeout",
            Refusal::SessionRefused => "session_refused",
            Refusal::AcceptFailed => "accept_failed",
            Refusal::Other => "other",
        }
    }

    /// Whether a team's own sessions cause a few of these: two peers that connect to
    /// each other at once close the spare connection mid-handshake, and a peer
    /// back from a dropout finds the connections its peers opened meanwhile gone
    /// stale. Fewer than [`ROUTINE_REFUSALS`] in a line's period are logged at info
    /// level, more as a warning.
    fn is_routine(self) -> bool {
        matches!(
            self,
            Refusal::MalformedHandshake | Refusal::HandshakeTimeout | Refusal::SessionTimeout
        )
    }

    /// What the refused connections were, for a log line.
    fn what(self) -> &'static str {
        match self {
            Refusal::NoCertificate => "TLS clients without a certificate",
            Refusal::BadCertificate => "TLS clients with a certificate the team's CA did not sign",
            Refusal::HandshakeTimeout => "connections idle through the TLS handshake timeout",
            Refusal::MalformedHandshake => {
                "TLS handshakes that failed (not TLS, or the client went away)"
            }
            Refusal::PendingLimit => "connections over the limit of sessions being opened",
            Refusal::SessionTimeout => "connections that opened no session in time",
            Refusal::SessionRefused => "connections that did not speak zenoh",
            Refusal::AcceptFailed => "connections the listener could not accept",
            Refusal::Other => "connections zenoh warned about",
        }
    }

    /// The kind of refusal a zenoh log event stands for, from its target, level
    /// and message; `None` for every other event.
    #[must_use]
    pub fn of_event(target: &str, level: Level, message: &str) -> Option<Refusal> {
        let link = target.starts_with("zenoh_link_tls::unicast")
            || target.starts_with("zenoh_link_tcp::unicast");
        if link && level == Level::WARN {
            return Some(if message.contains("Too many open files") {
                Refusal::AcceptFailed
            } else if message.contains("peer sent no certificates") {
                Refusal::NoCertificate
            } else if message.contains("certificate") {
                Refusal::BadCertificate
            } else if message.contains("Timeout during TLS handshake") {
                Refusal::HandshakeTimeout
            } else if target.starts_with("zenoh_link_tls") && message.contains("Hint:") {
                Refusal::MalformedHandshake
            } else if message.contains("Hint:") {
                Refusal::AcceptFailed
            } else {
                Refusal::Other
            });
        }
        if target == "zenoh_transport::unicast::manager" {
            if message.contains("preventing potential DoS") {
                return Some(Refusal::PendingLimit);
            }
            if message.contains("Failed to accept link before deadline") {
                return Some(Refusal::SessionTimeout);
            }
        }
        if target == "zenoh_transport::unicast::establishment::accept" && level == Level::ERROR {
            return Some(Refusal::SessionRefused);
        }
        None
    }
}

/// zenoh's callsites that may log a refused connection, each with the least severe
/// level that may: the counting layer's static filter, and [`may_be_refusal`].
const REFUSAL_CALLSITES: [(&str, Level); 4] = [
    ("zenoh_link_tls::unicast", Level::WARN),
    ("zenoh_link_tcp::unicast", Level::WARN),
    ("zenoh_transport::unicast::manager", Level::TRACE),
    (
        "zenoh_transport::unicast::establishment::accept",
        Level::ERROR,
    ),
];

/// Whether events at this callsite may stand for a refusal (the message decides).
fn may_be_refusal(meta: &Metadata<'_>) -> bool {
    REFUSAL_CALLSITES
        .iter()
        .any(|(target, level)| meta.target().starts_with(target) && meta.level() <= level)
}

/// Counts since the process started, and since each kind's last log line.
struct Tally {
    total: [AtomicU64; KINDS],
    unlogged: [AtomicU64; KINDS],
    latest: Mutex<[Option<String>; KINDS]>,
}

static TALLY: Tally = Tally {
    total: [const { AtomicU64::new(0) }; KINDS],
    unlogged: [const { AtomicU64::new(0) }; KINDS],
    latest: Mutex::new([const { None }; KINDS]),
};

static REPORTER: std::sync::Once = std::sync::Once::new();

fn record(kind: Refusal, detail: String) {
    TALLY.total[kind.index()].fetch_add(1, Ordering::Relaxed);
    TALLY.unlogged[kind.index()].fetch_add(1, Ordering::Relaxed);
    if let Ok(mut latest) = TALLY.latest.lock() {
        latest[kind.index()] = Some(detail);
    }
    REPORTER.call_once(|| {
        // Without the thread the counts still reach `refused_connections`.
        let _ = std::thread::Builder::new()
            .name("troupe-refusals".into())
            .spawn(report_forever);
    });
}

/// Writes, once a second, one line per kind refused since its last line, if that
/// line is at least [`REFUSAL_LOG_PERIOD_S`] old.
fn report_forever() {
    let mut last_line: [Option<Instant>; KINDS] = [None; KINDS];
    loop {
        std::thread::sleep(Duration::from_secs(1));
        for kind in Refusal::ALL {
            let i = kind.index();
            if last_line[i].is_some_and(|t| t.elapsed().as_secs_f64() < REFUSAL_LOG_PERIOD_S) {
                continue;
            }
            let count = TALLY.unlogged[i].swap(0, Ordering::Relaxed);
            if count == 0 {
                continue;
            }
            let latest = TALLY
                .latest
                .lock()
                .ok()
                .and_then(|l| l[i].clone())
                .unwrap_or_default();
            let since = last_line[i].map_or(String::new(), |t| {
                format!(" in the last {:.0} s", t.elapsed().as_secs_f64())
            });
            if kind.is_routine() && count < ROUTINE_REFUSALS {
                tracing::info!(
                    kind = kind.name(),
                    count,
                    "zenoh refused {count} connection(s){since}: {}; latest: {latest}",
                    kind.what()
                );
            } else {
                tracing::warn!(
                    kind = kind.name(),
                    count,
                    "zenoh refused {count} connection(s){since}: {}; latest: {latest}",
                    kind.what()
                );
            }
            last_line[i] = Some(Instant::now());
        }
    }
}

/// Connections refused since the process started, by [`Refusal::name`] (kinds
/// never seen are absent).
#[must_use]
pub fn refused_connections() -> std::collections::BTreeMap<String, u64> {
    Refusal::ALL
        .iter()
        .filter_map(|k| {
            let n = TALLY.total[k.index()].load(Ordering::Relaxed);
            (n > 0).then(|| (k.name().to_owned(), n))
        })
        .collect()
}

/// The text of an event's `message` field.
#[derive(Default)]
struct MessageText(String);

impl Visit for MessageText {
    fn record_str(&mut self, field: &Field, value: &str) {
        if field.name() == "message" {
            value.clone_into(&mut self.0);
        }
    }

    fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            self.0 = format!("{value:?}");
        }
    }
}

fn refusal_of(event: &Event<'_>) -> Option<(Refusal, String)> {
    let meta = event.metadata();
    if !may_be_refusal(meta) {
        return None;
    }
    let mut text = MessageText::default();
    event.record(&mut text);
    let kind = Refusal::of_event(meta.target(), *meta.level(), &text.0)?;
    // zenoh's listeners add this hint to every failed handshake; it fits only an
    // accept that failed for want of file descriptors.
    let detail = match text
        .0
        .split_once(". Hint: increase the system open file limit")
    {
        Some((detail, _)) if kind != Refusal::AcceptFailed => detail.to_owned(),
        _ => text.0,
    };
    Some((kind, detail))
}

/// The `tracing` layer that counts zenoh's refused connections (module docs),
/// filtered to the callsites that may carry them. Install it beside the log's
/// layer, and [`hide_refusals`] on that layer.
#[must_use]
pub fn refusal_layer<S>() -> impl Layer<S>
where
    S: Subscriber + for<'a> tracing_subscriber::registry::LookupSpan<'a>,
{
    // A static filter: every other callsite's interest is decided once, so the
    // layer costs nothing where zenoh and troupe log at trace level.
    RefusalLayer.with_filter(
        REFUSAL_CALLSITES
            .iter()
            .copied()
            .collect::<tracing_subscriber::filter::Targets>(),
    )
}

struct RefusalLayer;

impl<S: Subscriber> Layer<S> for RefusalLayer {
    fn on_event(&self, event: &Event<'_>, _: Context<'_, S>) {
        if let Some((kind, detail)) = refusal_of(event) {
            record(kind, detail);
        }
    }
}

/// A per-layer filter for the log's layer that drops the events [`refusal_layer`]
/// counts (their summary lines take their place).
#[must_use]
pub fn hide_refusals<S: Subscriber>() -> impl Filter<S> {
    HideRefusals
}

struct HideRefusals;

impl<S: Subscriber> Filter<S> for HideRefusals {
    fn enabled(&self, _: &Metadata<'_>, _: &Context<'_, S>) -> bool {
        true
    }

    fn callsite_enabled(&self, meta: &'static Metadata<'static>) -> tracing::subscriber::Interest {
        if may_be_refusal(meta) {
            tracing::subscriber::Interest::sometimes()
        } else {
            tracing::subscriber::Interest::always()
        }
    }

    fn event_enabled(&self, event: &Event<'_>, _: &Context<'_, S>) -> bool {
        refusal_of(event).is_none()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zenoh_lines_are_sorted_into_kinds() {
        let tls = "zenoh_link_tls::unicast";
        let hint = ". Hint: increase the system open file limit.";
        for (message, kind) in [
            ("peer sent no certificates", Refusal::NoCertificate),
            (
                "invalid peer certificate: UnknownIssuer",
                Refusal::BadCertificate,
            ),
            ("Timeout during TLS handshake", Refusal::HandshakeTimeout),
            ("tls handshake eof", Refusal::MalformedHandshake),
            (
                "received corrupt message of type InvalidContentType",
                Refusal::MalformedHandshake,
            ),
            ("Too many open files (os error 24)", Refusal::AcceptFailed),
        ] {
            let line = format!("{message}{hint}");
            assert_eq!(
                Refusal::of_event(tls, Level::WARN, &line),
                Some(kind),
                "{line}"
            );
        }
        assert_eq!(
            Refusal::of_event(
                "zenoh_link_tcp::unicast",
                Level::WARN,
                &format!("Too many open files (os error 24){hint}")
            ),
            Some(Refusal::AcceptFailed)
        );
        let manager = "zenoh_transport::unicast::manager";
        assert_eq!(
            Refusal::of_event(
                manager,
                Level::TRACE,
                "Closing link for preventing potential DoS: tcp/..."
            ),
            Some(Refusal::PendingLimit)
        );
        assert_eq!(
            Refusal::of_event(
                manager,
                Level::DEBUG,
                "Failed to accept link before deadline (10000ms)"
            ),
            Some(Refusal::SessionTimeout)
        );
        // The same module's other lines, and other crates' warnings, are not refusals.
        assert_eq!(
            Refusal::of_event(manager, Level::TRACE, "Accepting link... tcp/..."),
            None
        );
        assert_eq!(
            Refusal::of_event(
                "zenoh_link_tls::utils",
                Level::WARN,
                "Skipping name verification of TLS server"
            ),
            None
        );
        assert_eq!(
            Refusal::of_event(tls, Level::DEBUG, "Accepted TLS connection"),
            None
        );
    }

    #[test]
    fn every_kind_has_its_own_name() {
        let names: std::collections::BTreeSet<_> = Refusal::ALL.iter().map(|k| k.name()).collect();
        assert_eq!(names.len(), KINDS);
        for (i, k) in Refusal::ALL.iter().enumerate() {
            assert_eq!(k.index(), i);
        }
    }
}
