//! ROS 2 inputs: zenoh subscribers fill a bounded latest-value store; the
//! [`Ros2FrameSource`] and the [`OdometryInput`] actor read it without blocking.
//!
//! The store keeps the newest depth image (or point cloud), the newest calibration,
//! the last few intensity images and a bounded odometry history. `capture` returns
//! the newest depth frame not yet returned, paired with the odometry nearest its
//! stamp within `odometry_tolerance_s` (and, if configured, the intensity image
//! nearest it within `intensity_tolerance_s`): if newer odometry (intensity) exists
//! but none is close enough, the frame is skipped and counted; if it has not caught
//! up with the frame yet, the frame waits for the next capture (unless a newer frame
//! replaces it, which is counted too). Every message that cannot be decoded or
//! converted is counted by topic and reason ([`Ros2Inputs::stats`]).

use std::collections::{BTreeMap, VecDeque};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use nalgebra::Isometry3;
use serde::Serialize;
use troupe_actors::msgs::ODOMETRY;
use troupe_actors::sensor::FrameSource;
use troupe_algorithms::frame::{DepthFrame, Odometry};
use troupe_core::Time;
use troupe_runtime::{Actor, ActorError, ActorResult, Context, Event, TimerId};
use zenoh::Wait;
use zenoh::sample::Sample;

use super::Ros2Error;
use super::attachment::Attachment;
use super::cdr::decode;
use super::config::Ros2Config;
use super::convert::{
    DepthInputs, StampMap, camera_pose, depth_frame_from_image, depth_frame_from_points,
    isometry_from_pose, odometry_from_ros,
};
use super::keyexpr::WireFormat;
use super::msgs::{CameraInfo, Image, Odometry as RosOdometry, PointCloud2, RosTime};

/// Intensity images kept to pair with depth images.
const INTENSITY_HISTORY: usize = 8;

/// How often [`OdometryInput`] looks for new odometry.
const ODOMETRY_POLL: Duration = Duration::from_millis(10);

/// How often [`Ros2Inputs::wait_for_topics`] looks.
const STARTUP_POLL: Duration = Duration::from_millis(20);

/// Wall-clock time now, ns since the Unix epoch.
pub(crate) fn unix_now_ns() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_nanos()).unwrap_or(i64::MAX))
}

/// Counts by topic role and reason.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct InputStats {
    /// Samples received per input (`depth`, `camera_info`, `intensity`, `points`, `odometry`).
    pub received: BTreeMap<String, u64>,
    /// Messages rejected or frames skipped, per `<input>/<reason>`.
    pub rejected: BTreeMap<String, u64>,
    /// Frames returned by the frame source.
    pub frames: u64,
    /// Depth images or clouds replaced by a newer one before a capture took them (the
    /// camera runs faster than the sensor rate, or frames wait for odometry).
    pub superseded: u64,
    /// Odometry messages published by [`OdometryInput`].
    pub odometry: u64,
}

#[derive(Default)]
struct Store {
    next_seq: u64,
    depth: Option<Image>,
    points: Option<PointCloud2>,
    camera_info: Option<CameraInfo>,
    intensity: VecDeque<Image>,
    odometry: VecDeque<(u64, RosOdometry)>,
    stats: InputStats,
}

impl Store {
    fn reject(&mut self, key: String) {
        let count = self.stats.rejected.entry(key.clone()).or_default();
        if *count == 0 {
            tracing::warn!("ROS 2 input rejected: {key} (counted from now on)");
        }
        *count += 1;
    }

    /// The odometry nearest `stamp_ns`, if within `tolerance_ns`; `Err(true)` when
    /// newer odometry may still come (none is at or after the stamp).
    fn nearest_odometry(&self, stamp_ns: i64, tolerance_ns: i64) -> Result<&RosOdometry, bool> {
        let nearest = self
            .odometry
            .iter()
            .map(|(_, o)| o)
            .min_by_key(|o| (o.header.stamp.as_nanos() - stamp_ns).unsigned_abs());
        match nearest {
            Some(o) if (o.header.stamp.as_nanos() - stamp_ns).abs() <= tolerance_ns => Ok(o),
            _ => {
                let caught_up = self
                    .odometry
                    .back()
                    .is_some_and(|(_, o)| o.header.stamp.as_nanos() >= stamp_ns);
                Err(!caught_up)
            }
        }
    }
}

struct Shared {
    config: Ros2Config,
    optical_in_body: Isometry3<f64>,
    store: Mutex<Store>,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Store> {
        // A panic while holding the lock leaves plain data behind; keep using it.
        self.store
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Decodes one sample's payload (and attachment) and stores it.
    fn ingest(&self, input: Input, payload: &[u8], attachment: Option<&[u8]>) {
        let attachment_problem = match (self.config.format, attachment.map(Attachment::decode)) {
            (WireFormat::RmwZenoh, None) => Some("no_attachment"),
            (WireFormat::RmwZenoh, Some(Err(_))) => Some("attachment"),
            _ => None,
        };
        // Decode before taking the lock: a depth image is large.
        let decoded = match input {
            Input::Depth | Input::Intensity => decode::<Image>(payload).map(Decoded::Image),
            Input::Points => decode::<PointCloud2>(payload).map(Decoded::Points),
            Input::CameraInfo => {
                decode::<CameraInfo>(payload).map(|m| Decoded::CameraInfo(Box::new(m)))
            }
            Input::Odometry => {
                decode::<RosOdometry>(payload).map(|m| Decoded::Odometry(Box::new(m)))
            }
        };
        let mut store = self.lock();
        *store
            .stats
            .received
            .entry(input.name().to_owned())
            .or_default() += 1;
        if let Some(problem) = attachment_problem {
            store.reject(format!("{}/{problem}", input.name()));
        }
        let decoded = match decoded {
            Ok(decoded) => decoded,
            Err(e) => {
                tracing::debug!("{}: {e}", input.name());
                store.reject(format!("{}/malformed", input.name()));
                return;
            }
        };
        let superseded = match decoded {
            Decoded::Image(m) if input == Input::Intensity => {
                if store.intensity.len() == INTENSITY_HISTORY {
                    store.intensity.pop_front();
                }
                store.intensity.push_back(m);
                false
            }
            Decoded::Image(m) => store.depth.replace(m).is_some(),
            Decoded::Points(m) => store.points.replace(m).is_some(),
            Decoded::CameraInfo(m) => {
                store.camera_info = Some(*m);
                false
            }
            Decoded::Odometry(m) => {
                store.next_seq += 1;
                let seq = store.next_seq;
                if store.odometry.len() >= self.config.odometry_history {
                    store.odometry.pop_front();
                }
                store.odometry.push_back((seq, *m));
                false
            }
        };
        if superseded {
            store.stats.superseded += 1;
        }
    }

    /// Whether the stored frame stamped `stamp` can be converted now: the body pose
    /// and intensity image to use, or why it must wait or be skipped.
    fn readiness(&self, store: &Store, stamp: RosTime) -> Readiness {
        let config = &self.config;
        let tolerance_ns = (config.odometry_tolerance_s * 1e9) as i64;
        let body = match store.nearest_odometry(stamp.as_nanos(), tolerance_ns) {
            Ok(o) => o.pose.pose,
            Err(true) => return Readiness::Wait,
            Err(false) => return Readiness::Skip("no_odometry"),
        };
        let Some(body) = isometry_from_pose(&body) else {
            return Readiness::Skip("odometry_pose");
        };
        if store.depth.is_none() {
            return Readiness::Ready(body, None);
        }
        if store.camera_info.is_none() {
            return Readiness::Wait;
        }
        if config.topics.intensity.is_none() {
            return Readiness::Ready(body, None);
        }
        let window_ns = (config.intensity_tolerance_s * 1e9) as i64;
        let offset = |i: &Image| (i.header.stamp.as_nanos() - stamp.as_nanos()).abs();
        let found = store
            .intensity
            .iter()
            .filter(|i| offset(i) <= window_ns)
            .min_by_key(|i| offset(i));
        match found {
            Some(image) => Readiness::Ready(body, Some(image.clone())),
            None if store
                .intensity
                .back()
                .is_none_or(|i| i.header.stamp.as_nanos() < stamp.as_nanos()) =>
            {
                Readiness::Wait
            }
            None => Readiness::Skip("no_intensity"),
        }
    }

    /// The newest depth frame not yet returned, paired with odometry (see the module doc).
    fn capture(&self, now: Time) -> Option<DepthFrame> {
        let config = &self.config;
        let mut store = self.lock();
        let stamp = match (&store.depth, &store.points) {
            (Some(d), _) => d.header.stamp,
            (None, Some(p)) => p.header.stamp,
            (None, None) => return None,
        };
        let (body, intensity) = match self.readiness(&store, stamp) {
            Readiness::Ready(body, intensity) => (body, intensity),
            Readiness::Wait => return None,
            Readiness::Skip(reason) => {
                store.depth = None;
                store.points = None;
                store.reject(format!("frame/{reason}"));
                return None;
            }
        };
        let pose = camera_pose(&body, &self.optical_in_body);
        let stamps = StampMap {
            troupe_now: now,
            unix_now_ns: unix_now_ns(),
        };
        let troupe_stamp = stamps.to_troupe(stamp);
        let info = store.camera_info.clone();
        let (depth, cloud) = (store.depth.take(), store.points.take());
        drop(store);
        let converted = match (depth, info, cloud) {
            (Some(depth), Some(info), _) => depth_frame_from_image(
                &DepthInputs {
                    depth: &depth,
                    info: &info,
                    intensity: intensity.as_ref(),
                    depth_encodings: &config.depth_encodings,
                    intensity_encodings: &config.intensity_encodings,
                    max_depth_m: config.max_depth_m,
                },
                pose,
                troupe_stamp,
            ),
            // Validated: `points_intrinsics` is set whenever `topics.points` is.
            (None, _, Some(cloud)) => {
                depth_frame_from_points(&cloud, config.points_intrinsics?, pose, troupe_stamp)
            }
            _ => return None,
        };
        let mut store = self.lock();
        match converted {
            Ok(frame) => {
                store.stats.frames += 1;
                Some(frame)
            }
            Err(e) => {
                tracing::debug!("depth frame: {e}");
                store.reject(format!("frame/{}", e.reason()));
                None
            }
        }
    }
}

/// A decoded input message.
enum Decoded {
    Image(Image),
    Points(PointCloud2),
    CameraInfo(Box<CameraInfo>),
    Odometry(Box<RosOdometry>),
}

/// Whether a stored frame can be converted.
enum Readiness {
    /// Yes: with this body pose and intensity image.
    Ready(Isometry3<f64>, Option<Image>),
    /// Not yet: what it needs may still come.
    Wait,
    /// Never: skip it, for this reason.
    Skip(&'static str),
}

/// An input topic's role.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Input {
    Depth,
    CameraInfo,
    Intensity,
    Points,
    Odometry,
}

impl Input {
    fn name(self) -> &'static str {
        match self {
            Input::Depth => "depth",
            Input::CameraInfo => "camera_info",
            Input::Intensity => "intensity",
            Input::Points => "points",
            Input::Odometry => "odometry",
        }
    }
}

/// The subscribed ROS 2 inputs of one robot. Cheap to clone; the subscribers live
/// as long as any clone (or a frame source or odometry actor made from one).
#[derive(Clone)]
pub struct Ros2Inputs {
    shared: Arc<Shared>,
    subscribed: Arc<Vec<Subscribed>>,
}

struct Subscribed {
    input: Input,
    topic: String,
    key: String,
    _subscriber: zenoh::pubsub::Subscriber<()>,
}

impl Ros2Inputs {
    /// Validates `config` and subscribes to its input topics on `session`.
    pub fn subscribe(session: &zenoh::Session, config: &Ros2Config) -> Result<Self, Ros2Error> {
        let shared = Arc::new(Shared::new(config)?);
        let format = config.key_format()?;
        let t = &config.topics;
        let entries = [
            (Input::Depth, t.depth.as_ref()),
            (Input::CameraInfo, t.camera_info.as_ref()),
            (Input::Intensity, t.intensity.as_ref()),
            (Input::Points, t.points.as_ref()),
            (Input::Odometry, Some(&t.odometry)),
        ];
        let mut subscribed = Vec::new();
        for (input, topic) in entries {
            let Some(topic) = topic else { continue };
            let key = match input {
                Input::Depth | Input::Intensity => format.subscribe_key::<Image>(topic),
                Input::CameraInfo => format.subscribe_key::<CameraInfo>(topic),
                Input::Points => format.subscribe_key::<PointCloud2>(topic),
                Input::Odometry => format.subscribe_key::<RosOdometry>(topic),
            }?;
            let sink = shared.clone();
            let subscriber = session
                .declare_subscriber(key.clone())
                .callback(move |sample: Sample| {
                    let payload = sample.payload().to_bytes();
                    let attachment = sample.attachment().map(|a| a.to_bytes());
                    sink.ingest(input, &payload, attachment.as_deref());
                })
                .wait()
                .map_err(|source| Ros2Error::Zenoh {
                    context: format!("subscribing to `{key}`"),
                    source,
                })?;
            subscribed.push(Subscribed {
                input,
                topic: topic.clone(),
                key,
                _subscriber: subscriber,
            });
        }
        Ok(Ros2Inputs {
            shared,
            subscribed: Arc::new(subscribed),
        })
    }

    /// Waits (blocking, polling) until every input topic has delivered a sample, or
    /// fails after `startup_timeout_s` naming the first silent topic and its key.
    pub fn wait_for_topics(&self) -> Result<(), Ros2Error> {
        let timeout = Duration::from_secs_f64(self.shared.config.startup_timeout_s);
        let start = Instant::now();
        loop {
            let silent = {
                let store = self.shared.lock();
                self.subscribed
                    .iter()
                    .find(|s| !store.stats.received.contains_key(s.input.name()))
                    .map(|s| (s.topic.clone(), s.key.clone()))
            };
            let Some((topic, key)) = silent else {
                return Ok(());
            };
            if start.elapsed() >= timeout {
                return Err(Ros2Error::TopicSilent {
                    topic,
                    key,
                    timeout_s: self.shared.config.startup_timeout_s,
                });
            }
            std::thread::sleep(STARTUP_POLL);
        }
    }

    /// Counters so far.
    #[must_use]
    pub fn stats(&self) -> InputStats {
        self.shared.lock().stats.clone()
    }

    /// A frame source reading these inputs.
    #[must_use]
    pub fn frame_source(&self) -> Ros2FrameSource {
        Ros2FrameSource {
            inputs: self.clone(),
        }
    }

    /// An actor publishing [`ODOMETRY`] from these inputs.
    #[must_use]
    pub fn odometry_actor(&self) -> OdometryInput {
        OdometryInput {
            inputs: self.clone(),
            published_seq: 0,
        }
    }
}

impl Shared {
    fn new(config: &Ros2Config) -> Result<Self, Ros2Error> {
        config.validate()?;
        let optical_in_body = config.extrinsics.isometry().ok_or_else(|| {
            crate::ConfigError::new(
                "extrinsics",
                "needs a finite translation and a non-zero quaternion",
                format!("{:?}", config.extrinsics),
            )
        })?;
        Ok(Shared {
            config: config.clone(),
            optical_in_body,
            store: Mutex::new(Store::default()),
        })
    }
}

/// A [`FrameSource`] fed by ROS 2 topics; `capture` never blocks on the network.
pub struct Ros2FrameSource {
    inputs: Ros2Inputs,
}

impl FrameSource for Ros2FrameSource {
    fn capture(
        &mut self,
        now: Time,
        _odometry: Option<&Odometry>,
    ) -> Result<Option<DepthFrame>, ActorError> {
        Ok(self.inputs.shared.capture(now))
    }
}

const POLL: TimerId = TimerId(0);

/// Publishes [`ODOMETRY`] from `nav_msgs/Odometry`: every 10 ms, the newest message not
/// yet published (stamped by its age, see [`StampMap`]).
pub struct OdometryInput {
    inputs: Ros2Inputs,
    published_seq: u64,
}

impl Actor for OdometryInput {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ctx.set_timer(POLL, ODOMETRY_POLL);
        Ok(())
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        if !matches!(event, Event::Timer(POLL)) {
            return Ok(());
        }
        let mut store = self.inputs.shared.lock();
        let Some((seq, newest)) = store.odometry.back() else {
            return Ok(());
        };
        if *seq <= self.published_seq {
            return Ok(());
        }
        self.published_seq = *seq;
        let stamps = StampMap {
            troupe_now: ctx.now(),
            unix_now_ns: unix_now_ns(),
        };
        match odometry_from_ros(newest, stamps.to_troupe(newest.header.stamp)) {
            Ok(odometry) => {
                store.stats.odometry += 1;
                drop(store);
                ctx.publish(&ODOMETRY, odometry);
            }
            Err(e) => store.reject(format!("odometry/{}", e.reason())),
        }
        Ok(())
    }
}

#[cfg(test)]
#[path = "inputs_tests.rs"]
mod tests;
