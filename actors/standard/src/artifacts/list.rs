//! The team's deduplicated artifact list.

use nalgebra::Point3;
use serde::Serialize;
use troupe_runtime::Message;

/// One artifact as the team knows it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Artifact {
    /// Where it is, world frame, metres (the first report's position).
    pub position_m: [f64; 3],
    /// The robot that reported it first (earliest sighting).
    pub first_reporter: u32,
    /// When it was first seen, seconds of run time.
    pub first_seen_s: f64,
    /// Reports merged into it (one per robot that found it).
    pub reports: u32,
}

/// A list of artifacts in which reports closer than a radius are one artifact.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ArtifactList {
    /// The artifacts, in the order they were first added.
    pub artifacts: Vec<Artifact>,
}
impl Message for ArtifactList {}

impl ArtifactList {
    /// The index of the artifact within `radius_m` of `position`, if any (the nearest).
    #[must_use]
    pub fn near(&self, position: &Point3<f64>, radius_m: f64) -> Option<usize> {
        self.artifacts
            .iter()
            .enumerate()
            .map(|(i, a)| (i, (Point3::from(a.position_m) - position).norm()))
            .filter(|(_, d)| *d <= radius_m)
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(i, _)| i)
    }

    /// Adds a report: a new artifact, or merged into the one within `radius_m`
    /// (which then keeps the earliest sighting's reporter and time; ties go to the
    /// lower robot index, so every robot's list agrees whatever the arrival order).
    /// Returns whether the artifact is new. Non-finite positions are ignored.
    pub fn add(
        &mut self,
        position: Point3<f64>,
        reporter: u32,
        seen_s: f64,
        radius_m: f64,
    ) -> bool {
        if !(position.coords.iter().all(|v| v.is_finite()) && seen_s.is_finite()) {
            return false;
        }
        match self.near(&position, radius_m) {
            Some(i) => {
                let a = &mut self.artifacts[i];
                a.reports += 1;
                if (seen_s, reporter) < (a.first_seen_s, a.first_reporter) {
                    a.first_seen_s = seen_s;
                    a.first_reporter = reporter;
                    a.position_m = position.into();
                }
                false
            }
            None => {
                self.artifacts.push(Artifact {
                    position_m: position.into(),
                    first_reporter: reporter,
                    first_seen_s: seen_s,
                    reports: 1,
                });
                true
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reports_within_the_radius_merge_and_keep_the_earliest() {
        let mut list = ArtifactList::default();
        assert!(list.add(Point3::new(1.0, 0.0, 0.0), 1, 20.0, 1.0));
        assert!(!list.add(Point3::new(1.5, 0.0, 0.0), 0, 12.0, 1.0));
        assert!(list.add(Point3::new(5.0, 0.0, 0.0), 1, 30.0, 1.0));
        assert!(!list.add(Point3::new(f64::NAN, 0.0, 0.0), 1, 30.0, 1.0));
        assert_eq!(list.artifacts.len(), 2);
        let a = list.artifacts[0];
        assert_eq!((a.first_reporter, a.first_seen_s, a.reports), (0, 12.0, 2));
        assert_eq!(a.position_m, [1.5, 0.0, 0.0]);
    }
}
