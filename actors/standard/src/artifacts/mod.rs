//! Artifact reporting: the example of a custom actor that talks to other robots.
//!
//! Artifacts are small retroreflective bodies (the DARPA Subterranean Challenge's
//! survivors, backpacks, phones): in the depth + intensity frames they are pixels
//! whose intensity, corrected for the fall-off of the robot's own light with
//! distance, exceeds what any diffuse surface returns ([`detect`]). The
//! [`ArtifactActor`] localises them in the world frame, confirms each over a few
//! frames, and shares one [`ArtifactReport`] per artifact on the shared topic
//! [`ARTIFACT_REPORTS`] (store-and-forward, plan priority: ahead of keyframes,
//! never lost through a partition or a link restart). Every robot, and the base
//! station, keeps the team's deduplicated [`ArtifactList`] and publishes it on
//! [`ARTIFACT_LIST`].
//!
//! Wire it with `[robot.artifacts] enabled = true`; `[robot.link.shared."artifacts/report"]`
//! overrides how the reports travel.

mod actor;
mod detect;
mod list;

pub use actor::{ARTIFACT_LIST, ARTIFACT_REPORTS, ArtifactActor, ArtifactReport};
pub use detect::{ArtifactsConfig, Detection, detect};
pub use list::{Artifact, ArtifactList};
