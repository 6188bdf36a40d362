//! The MAVLink wire: the connection's threads and their bounded channels.

use std::io;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::{Arc, mpsc};
use std::thread::JoinHandle;
use std::time::Duration;

use mavlink::dialects::common::{
    HEARTBEAT_DATA, MavAutopilot, MavMessage, MavModeFlag, MavState, MavType,
    SET_POSITION_TARGET_LOCAL_NED_DATA,
};
use mavlink::error::MessageReadError;
use mavlink::{Connectable, ConnectionAddress, MavConnection, MavHeader};

/// Messages waiting to be written, at most.
pub const OUTBOUND_CAPACITY: usize = 16;
/// Decoded messages waiting for the actor, at most.
pub const INBOUND_CAPACITY: usize = 256;
/// Pause between attempts to open the connection.
pub const RECONNECT_PERIOD: Duration = Duration::from_secs(1);
/// How long a blocking read waits before the reader checks whether to stop.
const READ_TIMEOUT: Duration = Duration::from_millis(100);

/// What this program may send.
#[derive(Clone, Debug, PartialEq)]
pub enum Outbound {
    /// Its own heartbeat (an onboard controller, no autopilot), once a second.
    Heartbeat,
    /// A position target.
    Setpoint(SET_POSITION_TARGET_LOCAL_NED_DATA),
}

/// A message received from the vehicle's network, with its sender.
#[derive(Clone, Debug, PartialEq)]
pub struct Inbound {
    /// Sender's system id.
    pub system_id: u32,
    /// Sender's component id.
    pub component_id: u8,
    /// The message (one of the kinds the vehicle reads).
    pub message: MavMessage,
}

/// Counters of the wire (shared with the I/O threads).
#[derive(Debug, Default)]
struct Counters {
    sent: AtomicU64,
    send_errors: AtomicU64,
    outbound_dropped: AtomicU64,
    received: AtomicU64,
    ignored: AtomicU64,
    decode_errors: AtomicU64,
    inbound_dropped: AtomicU64,
    open_failures: AtomicU64,
    connected: AtomicBool,
}

/// A snapshot of the wire's counters.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LinkStats {
    /// Messages written.
    pub sent: u64,
    /// Writes that failed.
    pub send_errors: u64,
    /// Messages dropped because the outbound queue was full.
    pub outbound_dropped: u64,
    /// Messages decoded and queued for the actor.
    pub received: u64,
    /// Messages decoded but of kinds the vehicle does not read.
    pub ignored: u64,
    /// Frames that did not decode (bad CRC, unknown id, bad payload) and read errors.
    pub decode_errors: u64,
    /// Messages dropped because the inbound queue was full.
    pub inbound_dropped: u64,
    /// Failed attempts to open the connection.
    pub open_failures: u64,
    /// Whether the connection is open now.
    pub connected: bool,
}

/// The MAVLink wire: a thread that owns the connection, joined to the actor by two
/// bounded channels, so that no actor handler ever waits on a socket or serial port.
///
/// - Outbound ([`MavlinkLink::try_send`]): at most [`OUTBOUND_CAPACITY`] messages wait;
///   a full queue drops the new message and counts it (a stale setpoint is worth
///   nothing; the next tick sends a fresh one).
/// - Inbound ([`MavlinkLink::try_recv`]): the reader thread decodes frames, keeps the
///   ones the vehicle reads (`HEARTBEAT`, `LOCAL_POSITION_NED`, `ATTITUDE`) and queues
///   at most [`INBOUND_CAPACITY`]; a full queue drops the new message and counts it.
///   Bytes that do not decode are counted and skipped (never a panic).
///
/// Only the two message kinds of [`Outbound`] can be sent: this program cannot arm
/// the vehicle or change its mode, by construction.
///
/// The connection is opened on the I/O thread and reopened after a transport error
/// (TCP closed, serial port unplugged), once per [`RECONNECT_PERIOD`].
///
/// Dropping it stops the I/O threads (within 100 ms for UDP, outbound TCP and
/// serial links; an inbound TCP link waits for its peer first).
pub struct MavlinkLink {
    outbound: SyncSender<Outbound>,
    inbound: Receiver<Inbound>,
    stop: Arc<AtomicBool>,
    counters: Arc<Counters>,
}

impl MavlinkLink {
    /// Starts the I/O thread for a connection string (checked by
    /// [`MavlinkConfig::validate`](super::MavlinkConfig::validate)); our messages carry
    /// `source_system_id` / `source_component_id`.
    pub fn open(
        connection: &str,
        source_system_id: u8,
        source_component_id: u8,
    ) -> io::Result<Self> {
        let address = with_read_timeout(ConnectionAddress::parse_address(connection)?);
        let (outbound, outbound_rx) = mpsc::sync_channel(OUTBOUND_CAPACITY);
        let (inbound_tx, inbound) = mpsc::sync_channel(INBOUND_CAPACITY);
        let stop = Arc::new(AtomicBool::new(false));
        let counters = Arc::new(Counters::default());
        let io = IoThread {
            address,
            header: MavHeader {
                system_id: u32::from(source_system_id),
                component_id: source_component_id,
                sequence: 0,
            },
            outbound: outbound_rx,
            inbound: inbound_tx,
            stop: stop.clone(),
            counters: counters.clone(),
        };
        std::thread::Builder::new()
            .name("mavlink-io".into())
            .spawn(move || io.run())?;
        Ok(MavlinkLink {
            outbound,
            inbound,
            stop,
            counters,
        })
    }

    /// Queues a message for the wire without waiting. `false`: dropped (queue full, or
    /// the I/O thread is gone), and counted.
    pub fn try_send(&self, message: Outbound) -> bool {
        match self.outbound.try_send(message) {
            Ok(()) => true,
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
                self.counters
                    .outbound_dropped
                    .fetch_add(1, Ordering::Relaxed);
                false
            }
        }
    }

    /// The next received message, if one is waiting.
    #[must_use]
    pub fn try_recv(&self) -> Option<Inbound> {
        self.inbound.try_recv().ok()
    }

    /// The wire's counters now.
    #[must_use]
    pub fn stats(&self) -> LinkStats {
        let c = &self.counters;
        let get = |a: &AtomicU64| a.load(Ordering::Relaxed);
        LinkStats {
            sent: get(&c.sent),
            send_errors: get(&c.send_errors),
            outbound_dropped: get(&c.outbound_dropped),
            received: get(&c.received),
            ignored: get(&c.ignored),
            decode_errors: get(&c.decode_errors),
            inbound_dropped: get(&c.inbound_dropped),
            open_failures: get(&c.open_failures),
            connected: c.connected.load(Ordering::Relaxed),
        }
    }
}

impl Drop for MavlinkLink {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// Blocking reads must return now and then so the reader can notice a stop.
fn with_read_timeout(address: ConnectionAddress) -> ConnectionAddress {
    match address {
        ConnectionAddress::Udp(c) => ConnectionAddress::Udp(c.read_timeout(READ_TIMEOUT)),
        ConnectionAddress::Serial(c) => ConnectionAddress::Serial(c.timeout(READ_TIMEOUT)),
        // `tcpout` sets its own 100 ms timeout; `tcpin` waits for its peer.
        other => other,
    }
}

type Connection = mavlink::Connection<MavMessage>;

struct IoThread {
    address: ConnectionAddress,
    header: MavHeader,
    outbound: Receiver<Outbound>,
    inbound: SyncSender<Inbound>,
    stop: Arc<AtomicBool>,
    counters: Arc<Counters>,
}

impl IoThread {
    fn stopped(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }

    fn run(self) {
        let mut failures_logged = false;
        while !self.stopped() {
            match self.address.connect::<MavMessage>() {
                Ok(mut connection) => {
                    connection.set_allow_recv_any_version(true);
                    failures_logged = false;
                    tracing::info!(link = %self.address, "MAVLink connection open");
                    self.counters.connected.store(true, Ordering::Relaxed);
                    self.session(Arc::new(connection));
                    self.counters.connected.store(false, Ordering::Relaxed);
                }
                Err(e) => {
                    self.counters.open_failures.fetch_add(1, Ordering::Relaxed);
                    if !failures_logged {
                        tracing::warn!(link = %self.address, "cannot open the MAVLink connection (retrying every {RECONNECT_PERIOD:?}): {e}");
                        failures_logged = true;
                    }
                }
            }
            if !self.stopped() {
                std::thread::sleep(RECONNECT_PERIOD);
            }
        }
    }

    /// Writes until stopped or the transport fails; a reader thread runs alongside.
    fn session(&self, connection: Arc<Connection>) {
        let alive = Arc::new(AtomicBool::new(true));
        let reader = self.spawn_reader(connection.clone(), alive.clone());
        while !self.stopped() && alive.load(Ordering::Relaxed) {
            match self.outbound.recv_timeout(READ_TIMEOUT) {
                Ok(message) => {
                    let message = match message {
                        Outbound::Heartbeat => own_heartbeat(),
                        Outbound::Setpoint(data) => MavMessage::SET_POSITION_TARGET_LOCAL_NED(data),
                    };
                    match connection.send(&self.header, &message) {
                        Ok(_) => {
                            self.counters.sent.fetch_add(1, Ordering::Relaxed);
                        }
                        Err(e) => {
                            self.counters.send_errors.fetch_add(1, Ordering::Relaxed);
                            if let mavlink::error::MessageWriteError::Io(io) = &e
                                && is_closed(io.kind())
                            {
                                tracing::warn!(link = %self.address, "MAVLink connection closed while writing: {e}");
                                alive.store(false, Ordering::Relaxed);
                            }
                        }
                    }
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => break,
            }
        }
        alive.store(false, Ordering::Relaxed);
        if let Some(reader) = reader {
            let _ = reader.join();
        }
    }

    fn spawn_reader(
        &self,
        connection: Arc<Connection>,
        alive: Arc<AtomicBool>,
    ) -> Option<JoinHandle<()>> {
        let reader = Reader {
            serial: matches!(self.address, ConnectionAddress::Serial(_)),
            datagrams: matches!(self.address, ConnectionAddress::Udp(_)),
            inbound: self.inbound.clone(),
            stop: self.stop.clone(),
            counters: self.counters.clone(),
            link: self.address.to_string(),
        };
        match std::thread::Builder::new()
            .name("mavlink-rx".into())
            .spawn(move || reader.run(&connection, &alive))
        {
            Ok(handle) => Some(handle),
            Err(e) => {
                tracing::error!("cannot start the MAVLink reader thread: {e}");
                None
            }
        }
    }
}

fn is_closed(kind: io::ErrorKind) -> bool {
    matches!(
        kind,
        io::ErrorKind::UnexpectedEof
            | io::ErrorKind::ConnectionReset
            | io::ErrorKind::ConnectionAborted
            | io::ErrorKind::BrokenPipe
            | io::ErrorKind::NotConnected
    )
}

fn own_heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_ONBOARD_CONTROLLER,
        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
        base_mode: MavModeFlag::empty(),
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

struct Reader {
    serial: bool,
    /// UDP: an empty datagram reads as end-of-file but closes nothing.
    datagrams: bool,
    inbound: SyncSender<Inbound>,
    stop: Arc<AtomicBool>,
    counters: Arc<Counters>,
    link: String,
}

impl Reader {
    fn run(&self, connection: &Connection, alive: &AtomicBool) {
        while alive.load(Ordering::Relaxed) && !self.stop.load(Ordering::Relaxed) {
            // A serial link retries timeouts inside `recv`, so it is polled instead
            // (its reads still wait up to the port timeout).
            let result = if self.serial {
                connection.try_recv()
            } else {
                connection.recv()
            };
            match result {
                Ok((header, message)) => self.deliver(header, message),
                Err(MessageReadError::Io(e))
                    if matches!(
                        e.kind(),
                        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                    ) => {}
                Err(MessageReadError::Io(e)) if !self.datagrams && is_closed(e.kind()) => {
                    tracing::warn!(link = %self.link, "MAVLink connection closed: {e}");
                    alive.store(false, Ordering::Relaxed);
                }
                Err(MessageReadError::Io(_)) => {
                    // E.g. an ICMP "port unreachable" on UDP: count it, and do not spin.
                    self.counters.decode_errors.fetch_add(1, Ordering::Relaxed);
                    std::thread::sleep(Duration::from_millis(10));
                }
                Err(MessageReadError::Parse(_)) => {
                    self.counters.decode_errors.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
    }

    fn deliver(&self, header: MavHeader, message: MavMessage) {
        let wanted = matches!(
            message,
            MavMessage::HEARTBEAT(_) | MavMessage::LOCAL_POSITION_NED(_) | MavMessage::ATTITUDE(_)
        );
        if !wanted {
            self.counters.ignored.fetch_add(1, Ordering::Relaxed);
            return;
        }
        let inbound = Inbound {
            system_id: header.system_id,
            component_id: header.component_id,
            message,
        };
        match self.inbound.try_send(inbound) {
            Ok(()) => {
                self.counters.received.fetch_add(1, Ordering::Relaxed);
            }
            Err(TrySendError::Full(_)) => {
                self.counters
                    .inbound_dropped
                    .fetch_add(1, Ordering::Relaxed);
            }
            Err(TrySendError::Disconnected(_)) => self.stop.store(true, Ordering::Relaxed),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::MavlinkVersion;
    use mavlink::dialects::common::ATTITUDE_DATA;
    use std::net::UdpSocket;
    use std::time::Instant;

    fn frame(sequence: u8, message: &MavMessage) -> Vec<u8> {
        let mut bytes = Vec::new();
        let header = MavHeader {
            system_id: 1,
            component_id: 1,
            sequence,
        };
        mavlink::write_versioned_msg(&mut bytes, MavlinkVersion::V2, header, message).unwrap();
        bytes
    }

    fn attitude() -> MavMessage {
        MavMessage::ATTITUDE(ATTITUDE_DATA {
            yaw: 0.5,
            ..ATTITUDE_DATA::default()
        })
    }

    /// Waits up to 3 s for the link to deliver something.
    fn next(link: &MavlinkLink) -> Option<Inbound> {
        let deadline = Instant::now() + Duration::from_secs(3);
        while Instant::now() < deadline {
            if let Some(m) = link.try_recv() {
                return Some(m);
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        None
    }

    #[test]
    fn hostile_bytes_are_counted_and_skipped_then_replies_flow() {
        let port = UdpSocket::bind("127.0.0.1:0")
            .and_then(|s| s.local_addr())
            .unwrap()
            .port();
        let link = MavlinkLink::open(&format!("udpin:127.0.0.1:{port}"), 1, 191).unwrap();
        let peer = UdpSocket::bind("127.0.0.1:0").unwrap();
        peer.set_read_timeout(Some(Duration::from_secs(3))).unwrap();
        let to = ("127.0.0.1", port);
        // Wait for the link to be open (a datagram before the bind would be lost).
        let deadline = Instant::now() + Duration::from_secs(3);
        while !link.stats().connected && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(5));
        }
        let good = frame(0, &attitude());
        let mut bad_crc = good.clone();
        let last = bad_crc.len() - 1;
        bad_crc[last] ^= 0xff;
        let mut wrong_length = good.clone();
        wrong_length[1] = 250;
        let hostile = [
            vec![0xfd; 3],
            (0..=255u8).collect::<Vec<_>>(),
            bad_crc,
            wrong_length,
            vec![],
        ];
        let system_time =
            MavMessage::SYSTEM_TIME(mavlink::dialects::common::SYSTEM_TIME_DATA::default());
        for (i, bytes) in hostile.iter().enumerate() {
            peer.send_to(bytes, to).unwrap();
            // A frame cut short or claiming a wrong length swallows what follows until
            // its length is reached and its checksum fails; then the decoder rescans.
            // A live autopilot streams on, so it resynchronises within a few frames.
            peer.send_to(&frame(0, &system_time), to).unwrap();
            for sequence in 1..=12 {
                peer.send_to(&frame(sequence, &attitude()), to).unwrap();
            }
            let inbound = next(&link).unwrap_or_else(|| panic!("stuck after hostile input {i}"));
            assert_eq!((inbound.system_id, inbound.component_id), (1, 1));
            assert_eq!(inbound.message, attitude());
            while link.try_recv().is_some() {}
        }
        let stats = link.stats();
        assert!(stats.connected && stats.ignored >= 1, "{stats:?}");
        // The link now knows where to answer: our heartbeat reaches the peer and decodes.
        assert!(link.try_send(Outbound::Heartbeat));
        let mut buf = [0u8; 300];
        let n = peer.recv(&mut buf).expect("our heartbeat");
        let mut reader = mavlink::MavlinkReader::new(&buf[..n]);
        let (header, message) = reader
            .read_any_message::<MavMessage>()
            .expect("a MAVLink frame");
        assert_eq!((header.system_id, header.component_id), (1, 191));
        let MavMessage::HEARTBEAT(hb) = message else {
            panic!("expected a heartbeat, got {message:?}");
        };
        assert_eq!(hb.autopilot, MavAutopilot::MAV_AUTOPILOT_INVALID);
        assert_eq!(hb.mavtype, MavType::MAV_TYPE_ONBOARD_CONTROLLER);
        assert!(hb.base_mode.is_empty(), "never claims a mode");
    }
}
