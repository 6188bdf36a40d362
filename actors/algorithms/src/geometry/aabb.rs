//! Axis-aligned boxes.

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

/// An axis-aligned box in the world frame, in metres; `min <= max` on every axis.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Aabb {
    /// Lowest corner.
    pub min: Point3<f64>,
    /// Highest corner.
    pub max: Point3<f64>,
}

impl Aabb {
    /// The box spanned by two corners given in any order.
    #[must_use]
    pub fn new(a: Point3<f64>, b: Point3<f64>) -> Self {
        Self {
            min: a.inf(&b),
            max: a.sup(&b),
        }
    }

    /// The box of a single point.
    #[must_use]
    pub fn from_point(p: Point3<f64>) -> Self {
        Self { min: p, max: p }
    }

    /// Edge lengths along x, y, z.
    #[must_use]
    pub fn size(&self) -> Vector3<f64> {
        self.max - self.min
    }

    /// The centre point.
    #[must_use]
    pub fn centre(&self) -> Point3<f64> {
        nalgebra::center(&self.min, &self.max)
    }

    /// Volume in cubic metres.
    #[must_use]
    pub fn volume_m3(&self) -> f64 {
        let s = self.size();
        s.x * s.y * s.z
    }

    /// Whether `p` lies inside or on the boundary.
    #[must_use]
    pub fn contains(&self, p: &Point3<f64>) -> bool {
        (0..3).all(|i| p[i] >= self.min[i] && p[i] <= self.max[i])
    }

    /// The smallest box holding both `self` and `other`.
    #[must_use]
    pub fn union(&self, other: &Aabb) -> Aabb {
        Aabb {
            min: self.min.inf(&other.min),
            max: self.max.sup(&other.max),
        }
    }

    /// The box grown by `margin_m` on every side.
    #[must_use]
    pub fn expanded(&self, margin_m: f64) -> Aabb {
        let m = Vector3::repeat(margin_m);
        Aabb {
            min: self.min - m,
            max: self.max + m,
        }
    }

    /// Euclidean distance from `p` to the box (0 inside).
    #[must_use]
    pub fn distance_m(&self, p: &Point3<f64>) -> f64 {
        let below = self.min - p;
        let above = p - self.max;
        below.sup(&above).sup(&Vector3::zeros()).norm()
    }

    /// The ray parameters `(t_enter, t_exit)` where `origin + t * dir` is inside the box,
    /// clipped to `[t_min, t_max]`; `None` when the ray misses that interval.
    #[must_use]
    pub fn clip_ray(
        &self,
        origin: &Point3<f64>,
        dir: &Vector3<f64>,
        t_min: f64,
        t_max: f64,
    ) -> Option<(f64, f64)> {
        let (mut t0, mut t1) = (t_min, t_max);
        for i in 0..3 {
            if dir[i] == 0.0 {
                if origin[i] < self.min[i] || origin[i] > self.max[i] {
                    return None;
                }
                continue;
            }
            let inv = 1.0 / dir[i];
            let (a, b) = (
                (self.min[i] - origin[i]) * inv,
                (self.max[i] - origin[i]) * inv,
            );
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
        }
        (t0 <= t1).then_some((t0, t1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clip_ray_enters_and_leaves_box() {
        let b = Aabb::new(Point3::new(0.0, 0.0, 0.0), Point3::new(2.0, 1.0, 1.0));
        let o = Point3::new(-1.0, 0.5, 0.5);
        let (t0, t1) = b.clip_ray(&o, &Vector3::x(), 0.0, 10.0).expect("hits");
        assert!((t0 - 1.0).abs() < 1e-12 && (t1 - 3.0).abs() < 1e-12);
        assert!(b.clip_ray(&o, &Vector3::y(), 0.0, 10.0).is_none());
        assert_eq!(b.distance_m(&o), 1.0);
        assert_eq!(b.volume_m3(), 2.0);
    }
}
