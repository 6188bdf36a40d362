//! The artifact study's score: the team's artifact lists (as each robot published
//! them on `artifacts/list`) against the world's ground truth, as in the DARPA
//! Subterranean Challenge: a reported artifact is correct within
//! [`CORRECT_WITHIN_M`] of a placed one it is the nearest report to; every other
//! report is false.

use std::sync::{Arc, Mutex, PoisonError};

use nalgebra::Point3;
use serde::Serialize;
use troupe_actors::artifacts::{ARTIFACT_LIST, Artifact, ArtifactList};
use troupe_runtime::{Publication, Tap};

/// A report this close to a placed artifact scores, metres.
pub const CORRECT_WITHIN_M: f64 = 1.0;

/// One artifact of the team's merged list, scored (`summary.json` `artifacts[]`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ScoredArtifact {
    /// Reported position, world frame, metres.
    pub position_m: [f64; 3],
    /// The robot that reported it first.
    pub first_reporter: u32,
    /// When it was first seen, seconds of run time.
    pub first_seen_s: f64,
    /// Distance to the nearest placed artifact, metres.
    pub error_m: f64,
    /// Within [`CORRECT_WITHIN_M`] of a placed artifact no other report claimed first.
    pub correct: bool,
}

/// Found / placed / false for a list (`summary.json` `artifact_score`).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ArtifactScore {
    /// Artifacts placed in the world.
    pub placed: usize,
    /// Placed artifacts with a correct report.
    pub found: usize,
    /// Reports that are not correct.
    pub false_reports: usize,
    /// Per robot: (found, false reports) of its own list.
    pub per_robot: Vec<[usize; 2]>,
}

/// Scores `list` against `truth`: each placed artifact is claimed by the nearest
/// unclaimed report within [`CORRECT_WITHIN_M`], in list order.
#[must_use]
pub fn score(list: &[Artifact], truth: &[Point3<f64>]) -> Vec<ScoredArtifact> {
    let mut claimed = vec![false; truth.len()];
    list.iter()
        .map(|a| {
            let p = Point3::from(a.position_m);
            let nearest = truth
                .iter()
                .enumerate()
                .map(|(i, t)| (i, (t - p).norm()))
                .min_by(|x, y| x.1.total_cmp(&y.1));
            let error_m = nearest.map_or(f64::INFINITY, |(_, d)| d);
            let correct = match nearest {
                Some((i, d)) if d <= CORRECT_WITHIN_M && !claimed[i] => {
                    claimed[i] = true;
                    true
                }
                _ => false,
            };
            ScoredArtifact {
                position_m: a.position_m,
                first_reporter: a.first_reporter,
                first_seen_s: a.first_seen_s,
                error_m,
                correct,
            }
        })
        .collect()
}

/// Found and false reports of a scored list.
#[must_use]
pub fn tally(scored: &[ScoredArtifact]) -> [usize; 2] {
    let found = scored.iter().filter(|a| a.correct).count();
    [found, scored.len() - found]
}

/// The union of several lists, merged as a robot merges reports (so it equals the
/// list of a robot or base station that heard every report).
#[must_use]
pub fn union(lists: &[ArtifactList], merge_radius_m: f64) -> ArtifactList {
    let mut all: Vec<&Artifact> = lists.iter().flat_map(|l| &l.artifacts).collect();
    all.sort_by(|a, b| {
        (a.first_seen_s, a.first_reporter)
            .partial_cmp(&(b.first_seen_s, b.first_reporter))
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    let mut merged = ArtifactList::default();
    for a in all {
        merged.add(
            Point3::from(a.position_m),
            a.first_reporter,
            a.first_seen_s,
            merge_radius_m,
        );
    }
    merged
}

/// The summary's `artifacts` (the union of `lists`, scored) and `artifact_score`
/// (absent when no artifact was placed).
#[must_use]
pub fn summarise(
    lists: &[ArtifactList],
    truth: &[Point3<f64>],
    merge_radius_m: f64,
) -> (Vec<ScoredArtifact>, Option<ArtifactScore>) {
    let team = score(&union(lists, merge_radius_m).artifacts, truth);
    let result = (!truth.is_empty()).then(|| {
        let [found, false_reports] = tally(&team);
        ArtifactScore {
            placed: truth.len(),
            found,
            false_reports,
            per_robot: lists
                .iter()
                .map(|l| tally(&score(&l.artifacts, truth)))
                .collect(),
        }
    });
    (team, result)
}

/// A tap that keeps each robot's latest artifact list.
pub struct ArtifactCollector {
    lists: Arc<Mutex<Vec<ArtifactList>>>,
}

impl ArtifactCollector {
    /// A collector for `robots` robots.
    #[must_use]
    pub fn new(robots: usize) -> Self {
        ArtifactCollector {
            lists: Arc::new(Mutex::new(vec![ArtifactList::default(); robots])),
        }
    }

    /// The lists, shared with the tap.
    #[must_use]
    pub fn lists(&self) -> Arc<Mutex<Vec<ArtifactList>>> {
        self.lists.clone()
    }
}

impl Tap for ArtifactCollector {
    fn on_publish(&mut self, p: &Publication<'_>) {
        if let Some(list) = p.get(&ARTIFACT_LIST) {
            let mut lists = self.lists.lock().unwrap_or_else(PoisonError::into_inner);
            if let Some(slot) = lists.get_mut(p.robot.0 as usize) {
                *slot = list.clone();
            }
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    fn artifact(x: f64, reporter: u32, t: f64) -> Artifact {
        Artifact {
            position_m: [x, 0.0, 0.0],
            first_reporter: reporter,
            first_seen_s: t,
            reports: 1,
        }
    }

    #[test]
    fn reports_score_once_within_a_metre() {
        let truth = [Point3::new(0.0, 0.0, 0.0), Point3::new(10.0, 0.0, 0.0)];
        let list = [
            artifact(0.5, 0, 1.0),
            artifact(-0.6, 1, 2.0),
            artifact(20.0, 1, 3.0),
        ];
        let scored = score(&list, &truth);
        assert_eq!(
            scored.iter().map(|a| a.correct).collect::<Vec<_>>(),
            [true, false, false]
        );
        assert_eq!(tally(&scored), [1, 2]);
    }

    #[test]
    fn the_union_keeps_the_earliest_report() {
        let a = ArtifactList {
            artifacts: vec![artifact(0.0, 0, 5.0), artifact(8.0, 0, 9.0)],
        };
        let b = ArtifactList {
            artifacts: vec![artifact(0.3, 1, 3.0)],
        };
        let u = union(&[a, b], 1.0);
        assert_eq!(u.artifacts.len(), 2);
        assert_eq!(u.artifacts[0].first_reporter, 1);
        assert_eq!(u.artifacts[0].first_seen_s, 3.0);
    }
}
