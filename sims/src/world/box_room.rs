//! A single box-shaped room with an exact distance field, for tests.

use nalgebra::Point3;

use super::gpu_scene::{GpuAlbedo, GpuGeometry, GpuScene};
use super::{Aabb, World};

/// Free space inside an axis-aligned box, rock everywhere outside it.
///
/// The field is the exact signed distance to the box boundary (Lipschitz 1). The texture
/// is a 0.5 m checkerboard so intensity images have edges.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxRoom {
    /// The free interior.
    pub interior: Aabb,
}

/// Checker square size of [`BoxRoom`]'s texture, in metres.
pub const BOX_ROOM_CHECKER_M: f64 = 0.5;

/// Reflectance of the checker squares whose index sum is even / odd.
const CHECKER_EVEN: f64 = 0.3;
const CHECKER_ODD: f64 = 0.8;

impl BoxRoom {
    /// A room with the given free interior.
    #[must_use]
    pub fn new(interior: Aabb) -> Self {
        Self { interior }
    }
}

impl World for BoxRoom {
    fn sdf_m(&self, p: &Point3<f64>) -> f64 {
        let b = &self.interior;
        if b.contains(p) {
            (0..3)
                .map(|i| (p[i] - b.min[i]).min(b.max[i] - p[i]))
                .fold(f64::INFINITY, f64::min)
        } else {
            -b.distance_m(p)
        }
    }

    fn albedo(&self, p: &Point3<f64>) -> f64 {
        let parity = (0..3)
            .map(|i| (p[i] / BOX_ROOM_CHECKER_M).floor() as i64)
            .sum::<i64>()
            .rem_euclid(2);
        if parity == 0 {
            CHECKER_EVEN
        } else {
            CHECKER_ODD
        }
    }

    fn bounds(&self) -> Aabb {
        self.interior
    }

    fn gpu_scene(&self) -> Option<GpuScene> {
        Some(GpuScene {
            geometry: GpuGeometry::Boxes {
                interior: self.interior,
                solids: Vec::new(),
            },
            albedo: GpuAlbedo::Checker {
                square_m: BOX_ROOM_CHECKER_M,
                even: CHECKER_EVEN,
                odd: CHECKER_ODD,
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn sdf_sign_and_normal() {
        let room = BoxRoom::new(Aabb::new(
            Point3::new(-3.0, -2.0, 0.0),
            Point3::new(3.0, 2.0, 3.0),
        ));
        assert_eq!(room.sdf_m(&Point3::new(0.0, 0.0, 1.0)), 1.0);
        assert_eq!(room.sdf_m(&Point3::new(4.0, 0.0, 1.0)), -1.0);
        let n = room.normal(&Point3::new(2.9, 0.0, 1.5));
        assert!((n - Vector3::new(-1.0, 0.0, 0.0)).norm() < 1e-9);
    }
}
