//! The artifact actor (module docs of [`crate::artifacts`]).

use nalgebra::Point3;
use serde::{Deserialize, Serialize};
use troupe_runtime::{Actor, ActorResult, Context, Event, Message, QueuePolicy, Topic};

use super::detect::{ArtifactsConfig, detect};
use super::list::ArtifactList;
use crate::link::{Peer, SharePolicy, SharedTopic};
use crate::msgs::DEPTH_FRAME;

/// What a robot tells the team when it has found an artifact.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ArtifactReport {
    /// Where, in the reporter's world frame, metres.
    pub position_m: [f32; 3],
    /// When the reporter first saw it, seconds of run time.
    pub seen_s: f64,
}
impl Message for ArtifactReport {}

/// Reports travel store-and-forward at plan priority to every peer (a robot file
/// may change that under `[robot.link.shared."artifacts/report"]`).
pub const ARTIFACT_REPORTS: SharedTopic<ArtifactReport> = SharedTopic::new(
    "artifacts/report",
    1,
    SharePolicy::store_and_forward_in_plan_class(),
);

/// The team's artifact list as this robot knows it, published when it changes.
pub const ARTIFACT_LIST: Topic<ArtifactList> = Topic::new("artifacts/list");

/// A candidate seen by this robot, not yet confirmed.
struct Candidate {
    sum: nalgebra::Vector3<f64>,
    frames: u32,
    first_seen_s: f64,
}

/// Detects, confirms, reports and collects artifacts (see the [module
/// docs](crate::artifacts)). [`ArtifactActor::listening`] builds one that only
/// collects peers' reports (the base station).
pub struct ArtifactActor {
    config: ArtifactsConfig,
    detecting: bool,
    candidates: Vec<Candidate>,
    list: ArtifactList,
    /// [`ARTIFACT_REPORTS`]' peer topic (its name is built once).
    peer_reports: Topic<Peer<ArtifactReport>>,
}

impl ArtifactActor {
    /// An actor that detects in this robot's frames and collects the team's reports.
    #[must_use]
    pub fn new(config: ArtifactsConfig) -> Self {
        ArtifactActor {
            config,
            detecting: true,
            candidates: Vec::new(),
            list: ArtifactList::default(),
            peer_reports: ARTIFACT_REPORTS.peer_topic(),
        }
    }

    /// An actor that only collects the team's reports.
    #[must_use]
    pub fn listening(config: ArtifactsConfig) -> Self {
        ArtifactActor {
            detecting: false,
            ..ArtifactActor::new(config)
        }
    }

    fn publish_list(&self, ctx: &mut Context<'_>) {
        ctx.publish(&ARTIFACT_LIST, self.list.clone());
    }

    /// Confirms detections over frames; a confirmed artifact the team does not
    /// know yet goes into the list and out as a report.
    fn on_frame(&mut self, frame: &troupe_algorithms::frame::DepthFrame, ctx: &mut Context<'_>) {
        let now_s = frame.stamp.as_secs_f64();
        let radius = self.config.merge_radius_m;
        let mut changed = false;
        for d in detect(frame, &self.config) {
            if self.list.near(&d.position_m, radius).is_some() {
                continue; // the team knows it already
            }
            let candidate = match self
                .candidates
                .iter_mut()
                .find(|c| (c.sum / f64::from(c.frames) - d.position_m.coords).norm() <= radius)
            {
                Some(c) => {
                    c.sum += d.position_m.coords;
                    c.frames += 1;
                    c
                }
                None => {
                    self.candidates.push(Candidate {
                        sum: d.position_m.coords,
                        frames: 1,
                        first_seen_s: now_s,
                    });
                    self.candidates.last_mut().expect("just pushed")
                }
            };
            if candidate.frames >= self.config.confirm_frames {
                let position = Point3::from(candidate.sum / f64::from(candidate.frames));
                let seen_s = candidate.first_seen_s;
                self.list.add(position, ctx.robot().0, seen_s, radius);
                ctx.publish(
                    &ARTIFACT_REPORTS.topic(),
                    ArtifactReport {
                        position_m: position.coords.map(|v| v as f32).into(),
                        seen_s,
                    },
                );
                tracing::info!(robot = ctx.robot_name(), %position, "artifact found");
                changed = true;
            }
        }
        let list = &self.list;
        self.candidates.retain(|c| {
            list.near(&Point3::from(c.sum / f64::from(c.frames)), radius)
                .is_none()
        });
        if changed {
            self.publish_list(ctx);
        }
    }
}

impl Actor for ArtifactActor {
    fn start(&mut self, ctx: &mut Context<'_>) -> ActorResult {
        ARTIFACT_REPORTS.share(ctx);
        ctx.subscribe(&self.peer_reports, QueuePolicy::fifo(1024));
        if self.detecting {
            ctx.subscribe(&DEPTH_FRAME, QueuePolicy::LATEST);
        }
        Ok(())
    }

    fn handle(&mut self, event: &Event, ctx: &mut Context<'_>) -> ActorResult {
        let Event::Message(m) = event else {
            return Ok(());
        };
        if let Some(frame) = m.get(&DEPTH_FRAME) {
            self.on_frame(frame, ctx);
        } else if let Some(peer) = m.get(&self.peer_reports) {
            let position = Point3::from(peer.message.position_m.map(f64::from));
            self.list.add(
                position,
                peer.robot.0,
                peer.message.seen_s,
                self.config.merge_radius_m,
            );
            self.publish_list(ctx);
        }
        Ok(())
    }
}
