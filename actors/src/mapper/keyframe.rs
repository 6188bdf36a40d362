//! Keyframe selection by frustum overlap (thesis §8.2.2): the field of view of an
//! observation is approximated by a rectangular pyramid; an observation is a keyframe
//! when the fraction of its pyramid's volume that earlier keyframes already cover is
//! below the threshold λ.

use nalgebra::{Isometry3, Point3, Vector3};

use crate::msgs::PinholeIntrinsics;

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

    /// Whether `frustum` is a keyframe: the largest fraction of it covered by one
    /// earlier keyframe is below λ. A keyframe is remembered.
    pub fn offer(&mut self, frustum: Frustum) -> bool {
        let covered = self
            .keyframes
            .iter()
            .map(|k| frustum.overlap_with(k, self.samples_per_axis))
            .fold(0.0, f64::max);
        if covered >= self.threshold && !self.keyframes.is_empty() {
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
}
