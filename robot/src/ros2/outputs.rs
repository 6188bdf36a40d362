//! ROS 2 outputs: the committed plan as `nav_msgs/Path`, keyframe maps as
//! `sensor_msgs/PointCloud2`, a JSON status as `std_msgs/String` and the vehicle's
//! state as `diagnostic_msgs/DiagnosticArray`, on the key format of the inputs.
//!
//! [`Ros2Outputs`] (an actor) encodes in its handler and hands the bytes to the
//! publishing thread of a [`Ros2Publisher`] through a bounded channel: it never
//! waits for the network, and a full channel drops the message and counts it.
//! The thread puts each sample with an rmw_zenoh [`Attachment`] (sequence number
//! from 1 per topic, wall-clock source time, the publisher's GID) and, under
//! rmw_zenoh, holds a liveliness token per topic so the ROS graph lists them.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::time::Duration;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use troupe_actors::link::LINK_STATUS;
use troupe_actors::msgs::{KEYFRAME, PLAN};
use troupe_runtime::{Actor, ActorResult, Context, Event, QueuePolicy, TimerId};
use zenoh::Wait;

use super::Ros2Error;
use super::attachment::{Attachment, Gid};
use super::cdr::{RosMessage, encode};
use super::config::Ros2Config;
use super::convert::{StampMap, cloud_from_gmm, path_from_plan};
use super::inputs::{InputStats, Ros2Inputs, unix_now_ns};
use super::keyexpr::WireFormat;
use super::msgs::{
    DiagnosticArray, DiagnosticStatus, Header, KeyValue, Path, PointCloud2, RosString,
};
use crate::mavlink::{AUTOPILOT_STATUS, AutopilotStatus};

/// What goes out.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Output {
    Plan = 0,
    Map = 1,
    Status = 2,
    Diagnostics = 3,
}

/// Number of [`Output`]s.
const OUTPUTS: usize = 4;

/// Counters of the publishing side.
#[derive(Debug, Default)]
struct Counters {
    queued: AtomicU64,
    dropped_full: AtomicU64,
    sent: AtomicU64,
    send_errors: AtomicU64,
}

/// Counters of the publishing side, as numbers.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct OutputStats {
    /// Messages handed to the publishing thread.
    pub queued: u64,
    /// Messages dropped because its queue was full (or the thread had stopped).
    pub dropped_full: u64,
    /// Samples put on zenoh.
    pub sent: u64,
    /// Puts zenoh refused.
    pub send_errors: u64,
}

struct Lane {
    publisher: zenoh::pubsub::Publisher<'static>,
    _token: Option<zenoh::liveliness::LivelinessToken>,
    gid: Gid,
    sequence: i64,
}

/// The publishing side: one zenoh publisher per configured output topic and a thread
/// that puts what the [`Ros2Outputs`] actor queues. Cheap to clone; the thread ends
/// when the last clone is dropped.
#[derive(Clone)]
pub struct Ros2Publisher {
    queue: SyncSender<(Output, Vec<u8>)>,
    counters: Arc<Counters>,
    config: Arc<Ros2Config>,
    enabled: [bool; OUTPUTS],
}

impl Ros2Publisher {
    /// Validates `config`, declares the publishers (and rmw_zenoh liveliness tokens)
    /// of its output topics on `session`, and starts the publishing thread.
    pub fn open(session: &zenoh::Session, config: &Ros2Config) -> Result<Self, Ros2Error> {
        config.validate()?;
        let format = config.key_format()?;
        let zid = session.zid().to_string();
        let zid_bytes = session.zid().to_le_bytes();
        let t = &config.topics;
        let mut lanes: [Option<Lane>; OUTPUTS] = [None, None, None, None];
        let outputs = [
            (Output::Plan, t.plan.as_deref()),
            (Output::Map, t.map.as_deref()),
            (Output::Status, t.status.as_deref()),
            (Output::Diagnostics, t.diagnostics.as_deref()),
        ];
        for (output, topic) in outputs {
            let Some(topic) = topic else { continue };
            let entity = output as u32 + 1;
            let (key, token_key) = match output {
                Output::Plan => keys::<Path>(&format, &zid, entity, &config.node_name, topic)?,
                Output::Map => {
                    keys::<PointCloud2>(&format, &zid, entity, &config.node_name, topic)?
                }
                Output::Status => {
                    keys::<RosString>(&format, &zid, entity, &config.node_name, topic)?
                }
                Output::Diagnostics => {
                    keys::<DiagnosticArray>(&format, &zid, entity, &config.node_name, topic)?
                }
            };
            let zenoh_error = |context: String| move |source| Ros2Error::Zenoh { context, source };
            let publisher = session
                .declare_publisher(key.clone())
                .wait()
                .map_err(zenoh_error(format!("declaring a publisher on `{key}`")))?;
            let token = match token_key {
                Some(token_key) => Some(
                    session
                        .liveliness()
                        .declare_token(token_key.clone())
                        .wait()
                        .map_err(zenoh_error(format!("declaring the token `{token_key}`")))?,
                ),
                None => None,
            };
            let mut gid = [0u8; 16];
            gid.copy_from_slice(&zid_bytes[..16]);
            gid[15] ^= entity as u8;
            lanes[output as usize] = Some(Lane {
                publisher,
                _token: token,
                gid,
                sequence: 0,
            });
        }
        let enabled = lanes.each_ref().map(Option::is_some);
        let (queue, rx) = sync_channel(config.send_queue);
        let counters = Arc::new(Counters::default());
        let thread_counters = counters.clone();
        let attach = config.format == WireFormat::RmwZenoh;
        std::thread::Builder::new()
            .name("troupe-ros2-tx".into())
            .spawn(move || send_loop(&rx, lanes, attach, &thread_counters))
            .map_err(Ros2Error::Thread)?;
        Ok(Ros2Publisher {
            queue,
            counters,
            config: Arc::new(config.clone()),
            enabled,
        })
    }

    /// Counters so far.
    #[must_use]
    pub fn stats(&self) -> OutputStats {
        let c = &self.counters;
        OutputStats {
            queued: c.queued.load(Ordering::Relaxed),
            dropped_full: c.dropped_full.load(Ordering::Relaxed),
            sent: c.sent.load(Ordering::Relaxed),
            send_errors: c.send_errors.load(Ordering::Relaxed),
        }
    }

    /// Whether `output` has a topic.
    fn enabled(&self, output: Output) -> bool {
        self.enabled[output as usize]
    }

    /// Queues a message without waiting; counts it as dropped when the queue is full.
    fn offer<T: RosMessage>(&self, output: Output, message: &T) -> ActorResult {
        if !self.enabled(output) {
            return Ok(());
        }
        let bytes = encode(message)
            .map_err(|e| troupe_runtime::ActorError::with_source("ros2 output not encoded", e))?;
        match self.queue.try_send((output, bytes)) {
            Ok(()) => {
                self.counters.queued.fetch_add(1, Ordering::Relaxed);
            }
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
                self.counters.dropped_full.fetch_add(1, Ordering::Relaxed);
            }
        }
        Ok(())
    }
}

type Keys = (String, Option<String>);

fn keys<T: RosMessage>(
    format: &super::KeyFormat,
    zid: &str,
    entity: u32,
    node: &str,
    topic: &str,
) -> Result<Keys, Ros2Error> {
    Ok((
        format.topic_key::<T>(topic)?,
        format.publisher_liveliness_key::<T>(zid, entity, node, topic)?,
    ))
}

fn send_loop(
    rx: &Receiver<(Output, Vec<u8>)>,
    mut lanes: [Option<Lane>; OUTPUTS],
    attach: bool,
    counters: &Counters,
) {
    while let Ok((output, bytes)) = rx.recv() {
        let Some(lane) = lanes[output as usize].as_mut() else {
            continue;
        };
        lane.sequence += 1;
        let put = lane.publisher.put(bytes);
        let put = if attach {
            let attachment = Attachment {
                sequence_number: lane.sequence,
                source_timestamp_ns: unix_now_ns(),
                source_gid: lane.gid,
            };
            put.attachment(attachment.encode().to_vec())
        } else {
            put
        };
        match put.wait() {
            Ok(()) => counters.sent.fetch_add(1, Ordering::Relaxed),
            Err(e) => {
                tracing::warn!("ROS 2 output: put failed: {e}");
                counters.send_errors.fetch_add(1, Ordering::Relaxed)
            }
        };
    }
}

/// The vehicle's state as one `diagnostic_msgs/DiagnosticStatus` named
/// `troupe/<robot>/vehicle` ([`AutopilotStatus::level`], [`AutopilotStatus::state`]).
#[must_use]
pub fn vehicle_diagnostics(
    status: &AutopilotStatus,
    robot: &str,
    header: Header,
) -> DiagnosticArray {
    let (level, message) = status.level();
    let state = status.state();
    let value = |key: &str, value: String| KeyValue {
        key: key.to_owned(),
        value,
    };
    DiagnosticArray {
        header,
        status: vec![DiagnosticStatus {
            level,
            name: format!("troupe/{robot}/vehicle"),
            message,
            hardware_id: status.autopilot.map_or_else(
                || "no autopilot heard".to_owned(),
                |(system, component)| format!("MAVLink system {system} component {component}"),
            ),
            values: vec![
                value("armed", state.armed.to_string()),
                value("mode", state.mode),
                value("in_control", state.in_control.to_string()),
                value("hold", state.hold),
                value("setpoint_rate_hz", format!("{:.1}", state.setpoint_rate_hz)),
                value(
                    "heartbeat_age_s",
                    state
                        .heartbeat_age_s
                        .map_or_else(|| "never".to_owned(), |a| format!("{a:.2}")),
                ),
                value("setpoints", state.setpoints.to_string()),
                value("holds", state.holds.to_string()),
            ],
        }],
    }
}

/// The status message (JSON in a `std_msgs/String`).
#[derive(Debug, Serialize)]
struct Status<'a> {
    robot: &'a str,
    time_s: f64,
    plans: u64,
    keyframes: u64,
    outputs: OutputStats,
    inputs: Option<InputStats>,
    /// Team members the link has not heard for `peer_timeout_s` (the base station
    /// among them when it is absent); `None` before the link's first status.
    silent_peers: Option<&'a [u32]>,
}

const STATUS: TimerId = TimerId(0);

/// Publishes the committed plan, keyframe maps and a status (every `status_period_s`)
/// to ROS 2 through a [`Ros2Publisher`].
pub struct Ros2Outputs {
    publisher: Ros2Publisher,
    inputs: Option<Ros2Inputs>,
    status_period: Duration,
    rng: ChaCha8Rng,
    plans: u64,
    keyframes: u64,
    silent_peers: Option<Vec<u32>>,
}

impl Ros2Outputs {
    /// Outputs through `publisher`; the status includes `inputs`' counters if given.
    #[must_use]
    pub fn new(publisher: Ros2Publisher, inputs: Option<Ros2Inputs>) -> Self {
        let status_period = Duration::from_secs_f64(publisher.config.status_period_s);
        Ros2Outputs {
            publisher,
            inputs,
            status_period,
            rng: ChaCha8Rng::seed_from_u64(0),
            plans: 0,
            keyframes: 0,
            silent_peers: None,
        }
    }

    fn stamps(ctx: &Context<'_>) -> StampMap {
        StampMap {
            troupe_now: ctx.now(),
            unix_now_ns: unix_now_ns(),
        }
    }
}

impl Actor for Ros2Outputs {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.subscribe(&PLAN, QueuePolicy::LATEST);
        ctx.subscribe(&KEYFRAME, QueuePolicy::Fifo { capacity: 8 });
        if self.publisher.enabled(Output::Diagnostics) {
            ctx.subscribe(&AUTOPILOT_STATUS, QueuePolicy::LATEST);
        }
        if !self.status_period.is_zero() {
            ctx.subscribe(&LINK_STATUS, QueuePolicy::LATEST);
            ctx.set_timer(STATUS, self.status_period);
        }
        Ok(())
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        let config = self.publisher.config.clone();
        match event {
            Event::Message(m) => {
                if let Some(plan) = m.get(&PLAN)
                    && self.publisher.enabled(Output::Plan)
                {
                    self.plans += 1;
                    let path = path_from_plan(plan, &config.world_frame_id, &Self::stamps(ctx));
                    self.publisher.offer(Output::Plan, &path)?;
                }
                if let Some(keyframe) = m.get(&KEYFRAME)
                    && self.publisher.enabled(Output::Map)
                {
                    self.keyframes += 1;
                    let header = Header {
                        stamp: Self::stamps(ctx).to_ros(keyframe.stamp),
                        frame_id: config.world_frame_id.clone(),
                    };
                    let cloud =
                        cloud_from_gmm(&keyframe.gmm, config.map_points, header, &mut self.rng);
                    self.publisher.offer(Output::Map, &cloud)?;
                }
                if let Some(link) = m.get(&LINK_STATUS) {
                    self.silent_peers = Some(link.silent_peers.clone());
                }
                if let Some(status) = m.get(&AUTOPILOT_STATUS) {
                    let header = Header {
                        stamp: Self::stamps(ctx).to_ros(status.stamp),
                        frame_id: String::new(),
                    };
                    let diagnostics = vehicle_diagnostics(status, ctx.robot_name(), header);
                    self.publisher.offer(Output::Diagnostics, &diagnostics)?;
                }
            }
            Event::Timer(_) => {
                let status = Status {
                    robot: ctx.robot_name(),
                    time_s: ctx.now().as_secs_f64(),
                    plans: self.plans,
                    keyframes: self.keyframes,
                    outputs: self.publisher.stats(),
                    inputs: self.inputs.as_ref().map(Ros2Inputs::stats),
                    silent_peers: self.silent_peers.as_deref(),
                };
                let data = serde_json::to_string(&status).unwrap_or_default();
                self.publisher.offer(Output::Status, &RosString { data })?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Mutex;

    use super::*;
    use crate::ros2::cdr::decode;
    use crate::ros2::msgs::PoseStamped;

    fn config(send_queue: usize) -> Ros2Config {
        toml::from_str(&format!(
            r#"
            format = "rmw_zenoh"
            send_queue = {send_queue}
            [topics]
            depth = "/d"
            camera_info = "/i"
            odometry = "/o"
            plan = "/troupe/plan"
            "#
        ))
        .unwrap()
    }

    /// A session with no endpoints delivers inside the process.
    fn session(config: &Ros2Config) -> zenoh::Session {
        crate::ros2::open_session(config).unwrap()
    }

    #[test]
    fn every_offer_is_sent_or_counted_as_dropped_with_sequenced_attachments() {
        let config = config(1);
        let session = session(&config);
        let received: Arc<Mutex<Vec<(Path, Attachment)>>> = Arc::default();
        let sink = received.clone();
        let key = config
            .key_format()
            .unwrap()
            .topic_key::<Path>("/troupe/plan")
            .unwrap();
        let _subscriber = session
            .declare_subscriber(key)
            .callback(move |sample| {
                let path = decode::<Path>(&sample.payload().to_bytes()).unwrap();
                let attachment = Attachment::decode(&sample.attachment().unwrap().to_bytes());
                sink.lock().unwrap().push((path, attachment.unwrap()));
            })
            .wait()
            .unwrap();
        let publisher = Ros2Publisher::open(&session, &config).unwrap();
        let offers = 2000;
        for i in 0..offers {
            let path = Path {
                poses: vec![PoseStamped::default(); i % 7],
                ..Path::default()
            };
            publisher.offer(Output::Plan, &path).unwrap();
            // Outputs that are not configured are ignored, not counted.
            publisher
                .offer(Output::Status, &RosString::default())
                .unwrap();
        }
        let stats = publisher.stats();
        assert_eq!(stats.queued + stats.dropped_full, offers as u64);
        drop(publisher);
        let deadline = std::time::Instant::now() + Duration::from_secs(10);
        while (received.lock().unwrap().len() as u64) < stats.queued
            && std::time::Instant::now() < deadline
        {
            std::thread::sleep(Duration::from_millis(5));
        }
        let received = received.lock().unwrap();
        assert_eq!(received.len() as u64, stats.queued);
        for (i, (_, attachment)) in received.iter().enumerate() {
            assert_eq!(attachment.sequence_number, i as i64 + 1);
            assert_eq!(attachment.source_gid, received[0].1.source_gid);
            assert!(attachment.source_timestamp_ns > 1_600_000_000_000_000_000);
        }
    }
}
