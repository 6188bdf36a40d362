//! Keyframes (a mixture fitted to one observation with its sensor pose, §8.2.2) and
//! their selection by frustum overlap (thesis §8.2.2): the field of view of an
//! observation is approximated by a rectangular pyramid; an observation is a keyframe
//! when the fraction of its pyramid's volume that earlier keyframes' pyramids already
//! cover (together: a point inside any of them counts) is below the threshold λ.

use nalgebra::{Isometry3, Point3, Vector3};

use troupe_core::{Message, Time};

use crate::camera::PinholeIntrinsics;
use crate::sogmm::Gmm4;

/// A keyframe: a SOGMM fitted to one observation, with its sensor pose (§8.2.2).
#[derive(Clone, Debug, PartialEq)]
pub struct Keyframe {
    /// Per-robot keyframe counter.
    pub id: u32,
    /// Observation time.
    pub stamp: Time,
    /// Sensor (body) pose of the observation, in the owner's world frame.
    pub pose: nalgebra::Isometry3<f64>,
    /// Number of points the mixture was fitted to.
    pub support_size: u32,
    /// The mixture over (x, y, z, intensity) in the world frame.
    pub gmm: Gmm4,
}

impl Message for Keyframe {
    fn payload_bytes(&self) -> usize {
        // Mean 4 + covariance 16 + weight, f64.
        std::mem::size_of::<Self>() + self.gmm.len() * 21 * 8
    }
}

/// A camera's viewing pyramid: apex at the sensor, base at the range.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frustum {
    /// Camera body pose (looks along body +x).
    pub pose: Isometry3<f64>,
    /// Half-angle tangents: horizontal (body y) and vertical (body z).
    pub tan_half: [f64; 2],
    /// Depth of the base, metres.
    pub range_m: f64,
}

impl Frustum {
    /// The pyramid of a pinhole camera at `pose`.
    #[must_use]
    pub fn new(pose: Isometry3<f64>, k: &PinholeIntrinsics) -> Self {
        Frustum {
            pose,
            tan_half: [
                f64::from(k.width) / 2.0 / k.fx,
                f64::from(k.height) / 2.0 / k.fy,
            ],
            range_m: k.max_depth_m,
        }
    }

    /// Whether a world point lies inside.
    #[must_use]
    pub fn contains(&self, p: &Point3<f64>) -> bool {
        let b = self.pose.inverse_transform_point(p);
        b.x > 0.0
            && b.x <= self.range_m
            && b.y.abs() <= b.x * self.tan_half[0]
            && b.z.abs() <= b.x * self.tan_half[1]
    }

    /// Deterministic points spread uniformly through the volume (`n`³ of them): depth
    /// fractions by cube roots (a pyramid's volume grows with depth³), a regular grid
    /// across the image plane.
    #[must_use]
    pub fn samples(&self, n: usize) -> Vec<Point3<f64>> {
        let n = n.max(1);
        let mut out = Vec::with_capacity(n * n * n);
        for i in 0..n {
            let depth = self.range_m * ((i as f64 + 0.5) / n as f64).cbrt();
            for j in 0..n {
                let u = ((j as f64 + 0.5) / n as f64) * 2.0 - 1.0;
                for k in 0..n {
                    let v = ((k as f64 + 0.5) / n as f64) * 2.0 - 1.0;
                    let body = Vector3::new(
                        depth,
                        u * depth * self.tan_half[0],
                        v * depth * self.tan_half[1],
                    );
                    out.push(self.pose * Point3::from(body));
                }
            }
        }
        out
    }

    /// Fraction of this pyramid's volume inside `other`, estimated on `n`³ samples.
    #[must_use]
    pub fn overlap_with(&self, other: &Frustum, n: usize) -> f64 {
        let samples = self.samples(n);
        samples.iter().filter(|p| other.contains(p)).count() as f64 / samples.len() as f64
    }
}

/// Decides which observations are keyframes.
#[derive(Clone, Debug)]
pub struct KeyframeSelector {
    threshold: f64,
    keep: usize,
    samples_per_axis: usize,
    keyframes: Vec<Frustum>,
}

impl KeyframeSelector {
    /// A selector with overlap threshold λ ∈ [0, 1], remembering the last `keep`
    /// keyframes.
    #[must_use]
    pub fn new(threshold: f64, keep: usize) -> Self {
        KeyframeSelector {
            threshold: threshold.clamp(0.0, 1.0),
            keep: keep.max(1),
            samples_per_axis: 10,
            keyframes: Vec::new(),
        }
    }

    /// Fraction of `frustum`'s volume inside the union of the remembered keyframes'
    /// pyramids, estimated on `samples_per_axis`³ points. Only keyframes whose apex
    /// is within reach (the sum of both ranges) can hold any of it.
    #[must_use]
    pub fn covered_fraction(&self, frustum: &Frustum) -> f64 {
        let apex = Point3::from(frustum.pose.translation.vector);
        let near: Vec<&Frustum> = self
            .keyframes
            .iter()
            .filter(|k| {
                let reach = k.range_m + frustum.range_m;
                (Point3::from(k.pose.translation.vector) - apex).norm_squared() <= reach * reach
            })
            .collect();
        if near.is_empty() {
            return 0.0;
        }
        let samples = frustum.samples(self.samples_per_axis);
        let inside = samples
            .iter()
            .filter(|p| near.iter().any(|k| k.contains(p)))
            .count();
        inside as f64 / samples.len() as f64
    }

    /// Whether `frustum` is a keyframe: less than λ of it is covered by earlier
    /// keyframes (the first view always is). A keyframe is remembered.
    pub fn offer(&mut self, frustum: Frustum) -> bool {
        if !self.keyframes.is_empty() && self.covered_fraction(&frustum) >= self.threshold {
            return false;
        }
        if self.keyframes.len() == self.keep {
            self.keyframes.remove(0);
        }
        self.keyframes.push(frustum);
        true
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::{Translation3, UnitQuaternion};

    use super::*;

    fn camera() -> PinholeIntrinsics {
        PinholeIntrinsics {
            width: 160,
            height: 120,
            fx: 80.0,
            fy: 104.0,
            cx: 80.0,
            cy: 60.0,
            max_depth_m: 5.0,
        }
    }

    fn at(x: f64, yaw: f64) -> Frustum {
        Frustum::new(
            Isometry3::from_parts(
                Translation3::new(x, 0.0, 0.0),
                UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
            ),
            &camera(),
        )
    }

    #[test]
    fn overlap_falls_as_the_camera_moves_or_turns() {
        let a = at(0.0, 0.0);
        assert!((a.overlap_with(&a, 10) - 1.0).abs() < 1e-12);
        let forward = a.overlap_with(&at(1.0, 0.0), 10);
        let further = a.overlap_with(&at(3.0, 0.0), 10);
        assert!(forward > further && further > 0.0, "{forward} {further}");
        assert_eq!(a.overlap_with(&at(0.0, std::f64::consts::PI), 10), 0.0);
    }

    #[test]
    fn selector_takes_the_first_and_novel_views_only() {
        let mut s = KeyframeSelector::new(0.5, 8);
        assert!(s.offer(at(0.0, 0.0)));
        assert!(!s.offer(at(0.2, 0.0)), "almost the same view");
        assert!(s.offer(at(0.0, std::f64::consts::PI)), "looking back");
        assert!(s.offer(at(6.0, 0.0)), "moved past the range");
    }

    /// Coverage counts the union of earlier views: a view that two keyframes cover
    /// together (each less than λ of it) is not a keyframe, and the fraction equals a
    /// direct count of samples inside either pyramid.
    #[test]
    fn coverage_is_of_the_union_of_earlier_keyframes() {
        let left = at(0.0, 0.6);
        let right = at(0.0, -0.6);
        let ahead = at(0.0, 0.0);
        let mut s = KeyframeSelector::new(0.6, 8);
        assert!(s.offer(left));
        assert!(s.offer(right), "looking the other way");
        let one = ahead
            .overlap_with(&left, 10)
            .max(ahead.overlap_with(&right, 10));
        let both = s.covered_fraction(&ahead);
        let samples = ahead.samples(10);
        let direct = samples
            .iter()
            .filter(|p| left.contains(p) || right.contains(p))
            .count() as f64
            / samples.len() as f64;
        assert!((both - direct).abs() < 1e-12);
        assert!(one < 0.6 && both >= 0.6, "one {one}, both {both}");
        assert!(!s.offer(ahead), "covered by the two together");
        // Far-away keyframes are not consulted (and cover nothing).
        assert_eq!(s.covered_fraction(&at(100.0, 0.0)), 0.0);
    }
}
