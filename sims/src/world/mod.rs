//! Ground-truth worlds: signed distance fields with a surface texture.
//!
//! A [`World`] answers three questions about a point in the world frame (z up, metres):
//! how far the nearest surface is ([`World::sdf_m`], positive in free space, negative in
//! rock), what the surface looks like there ([`World::albedo`]), and which box holds all of
//! its free space ([`World::bounds`]). The camera sphere-traces it and the coverage metric
//! samples it; robots never see it directly.
//!
//! A [`Site`] is a world robots are put into: it also says where they start and which
//! waypoint route each follows.
//!
//! Implementations: [`CaveWorld`] (procedural tunnel network from a seed), [`Warehouse`]
//! (rows of shelves, thesis §4.2.2), [`OpeningScene`] (the window and door scenes of
//! §5.2), [`OpenField`] (flat ground and a few boxes, for crossing missions), the scripted
//! [`tunnels`] (a T-junction and a dead end, for exploration tests), [`Room`] (a room
//! with pillars, shared with the hardware robot's closed loop) and [`BoxRoom`] (one
//! analytic box, for tests). [`WorldConfig`] picks one.

pub mod artifacts;
mod box_room;
pub mod cave;
mod config;
pub mod gpu_scene;
pub mod mesh;
mod mesh_io;
pub mod noise;
pub mod open_field;
pub mod room;
pub mod scenes;
pub mod solids;
mod triangle_mesh;
pub mod tunnels;
pub mod warehouse;

pub use box_room::BoxRoom;
pub use cave::{CaveParams, CaveWorld};
pub use config::{WorldConfig, WorldKind};
pub use gpu_scene::{GpuAlbedo, GpuCaveField, GpuGeometry, GpuNoise, GpuPrimitive, GpuScene};
pub use mesh::{FreeSpace, MeshParams, MeshWorld, TriangleMesh};
pub use open_field::{OpenField, OpenFieldParams};
pub use room::{Room, RoomBox, RoomParams};
pub use scenes::{DoorParams, OpeningScene, WindowParams};
pub use troupe_algorithms::geometry::Aabb;
pub use tunnels::TunnelParams;
pub use warehouse::{Warehouse, WarehouseParams};

use nalgebra::{Point3, Vector3};

/// Step used by the default [`World::normal`] for its central differences, in metres.
pub const NORMAL_STEP_M: f64 = 1e-3;

/// Directions searched by [`surface_distance_m`] (a Fibonacci sphere: neighbours are
/// about 0.22 rad apart, 6.6 cm at 0.3 m).
pub const SURFACE_SEARCH_DIRECTIONS: usize = 256;

/// A march step below this counts as reaching the surface, metres.
const SURFACE_HIT_EPS_M: f64 = 1e-3;

/// The distance from `p` to the nearest surface, if it is below `limit_m`; `limit_m`
/// otherwise; `sdf_m(p) / lipschitz()` (≤ 0) when `p` is in rock.
///
/// [`World::sdf_m`] is only a bound on the distance (a cave's rough walls make it up to
/// `lipschitz()` times too large or several times too small), so ground-truth checks must
/// not compare it with a radius. Where the certified step [`World::safe_step_m`] already
/// reaches `limit_m` this costs one evaluation; otherwise it sphere-traces
/// [`SURFACE_SEARCH_DIRECTIONS`] rays out to `limit_m` with safe steps (never stepping
/// through a surface) and returns the nearest hit: exact along those rays, and within
/// a few centimetres of the true distance for surfaces no sharper than the rays'
/// spacing.
#[must_use]
pub fn surface_distance_m(world: &dyn World, p: &Point3<f64>, limit_m: f64) -> f64 {
    let sdf = world.sdf_m(p);
    if sdf <= 0.0 {
        return sdf / world.lipschitz();
    }
    if world.safe_step_m(p) >= limit_m {
        return limit_m;
    }
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let n = SURFACE_SEARCH_DIRECTIONS;
    let mut nearest = limit_m;
    for i in 0..n {
        let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
        let r = (1.0 - z * z).sqrt();
        let phi = golden * i as f64;
        let dir = Vector3::new(r * phi.cos(), r * phi.sin(), z);
        let mut t = 0.0;
        while t < nearest {
            let step = world.safe_step_m(&(p + dir * t));
            if step < SURFACE_HIT_EPS_M {
                nearest = t;
                break;
            }
            t += step;
        }
    }
    nearest
}

/// A static world given as a signed distance field.
///
/// The field must satisfy `|sdf(p) - sdf(q)| <= lipschitz() * |p - q|`; the camera's
/// sphere tracer relies on it to never step through a surface.
pub trait World: Send + Sync {
    /// Signed distance from `p` to the nearest surface in metres: positive in free space,
    /// negative inside rock, zero on the surface.
    ///
    /// It need not be an exact distance, but `|sdf_m(p)| / lipschitz()` must never exceed
    /// the true distance to the surface.
    fn sdf_m(&self, p: &Point3<f64>) -> f64;

    /// Lipschitz bound of [`World::sdf_m`] (1 for an exact distance field).
    fn lipschitz(&self) -> f64 {
        1.0
    }

    /// A distance from `p` within which there is certainly no surface, for `p` in free
    /// space (the sphere tracer's step). The default is `sdf_m(p) / lipschitz()`; worlds may
    /// return something larger (but still safe) or cheaper.
    fn safe_step_m(&self, p: &Point3<f64>) -> f64 {
        self.sdf_m(p) / self.lipschitz()
    }

    /// Surface texture (reflectance) at `p`, in `[0, 1]`; meaningful on the surface.
    fn albedo(&self, p: &Point3<f64>) -> f64;

    /// An axis-aligned box that contains all free space.
    fn bounds(&self) -> Aabb;

    /// Unit outward normal of the free space (pointing from rock into free space) at `p`,
    /// by central differences of [`World::sdf_m`]; `+z` where the gradient vanishes.
    fn normal(&self, p: &Point3<f64>) -> Vector3<f64> {
        let h = NORMAL_STEP_M;
        let d = |axis: Vector3<f64>| self.sdf_m(&(p + axis * h)) - self.sdf_m(&(p - axis * h));
        let g = Vector3::new(d(Vector3::x()), d(Vector3::y()), d(Vector3::z()));
        g.try_normalize(1e-12).unwrap_or_else(Vector3::z)
    }

    /// The world's field and texture as tables for the GPU camera, or `None` when the
    /// world has no GPU description (the camera then renders on the CPU). Worlds that
    /// return one must keep it in step with [`World::sdf_m`] and [`World::albedo`].
    fn gpu_scene(&self) -> Option<GpuScene> {
        None
    }
}

/// Seconds between the departures of consecutive robots (a team leaves one robot
/// after another; a [`Site`] may place later robots by it).
pub const DEPARTURE_INTERVAL_S: f64 = 4.0;

/// A world with places for robots: start positions and waypoint routes.
pub trait Site: World {
    /// Start position of robot `robot_index` of `robot_count`, in free space.
    fn start_position(&self, robot_index: usize, robot_count: usize) -> Point3<f64>;

    /// Waypoint route of robot `robot_index` of `robot_count` (for route-following
    /// behaviours); it starts at [`Site::start_position`] and keeps clear of surfaces.
    fn route(&self, robot_index: usize, robot_count: usize) -> Vec<Point3<f64>>;

    /// A length scale for reports: the tunnel centre lines of a cave, the route of a
    /// single robot elsewhere, metres.
    fn route_length_m(&self) -> f64;
}

impl Site for CaveWorld {
    fn start_position(&self, robot_index: usize, robot_count: usize) -> Point3<f64> {
        CaveWorld::start_position(self, robot_index, robot_count)
    }

    fn route(&self, robot_index: usize, robot_count: usize) -> Vec<Point3<f64>> {
        self.centreline_route(robot_index, robot_count)
    }

    fn route_length_m(&self) -> f64 {
        self.graph().total_length_m()
    }
}

#[cfg(test)]
mod surface_distance_tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    /// The distance to the nearest point with `sdf < 0` on a 1 cm lattice (slow
    /// reference), capped at `limit_m`.
    fn brute_force(world: &dyn World, p: &Point3<f64>, limit_m: f64) -> f64 {
        let n = (limit_m / 0.01).ceil() as i64;
        let mut best = limit_m;
        for i in -n..=n {
            for j in -n..=n {
                for k in -n..=n {
                    let d = Vector3::new(i as f64, j as f64, k as f64) * 0.01;
                    if d.norm() < best && world.sdf_m(&(p + d)) < 0.0 {
                        best = d.norm();
                    }
                }
            }
        }
        best
    }

    #[test]
    fn matches_a_brute_force_search_near_rough_cave_walls() {
        let cave = CaveWorld::generate(&CaveParams::default(), 7);
        let start = cave.start_position(0, 1);
        let limit = 0.4;
        let mut near_wall = 0;
        // Points on a line from the start towards a wall, until inside the rock.
        for dir in [Vector3::x(), Vector3::y(), -Vector3::y(), -Vector3::z()] {
            for s in 0..400 {
                let p = start + dir * (0.01 * f64::from(s));
                if cave.sdf_m(&p) <= 0.0 {
                    break;
                }
                let fast = surface_distance_m(&cave, &p, limit);
                if fast >= limit || s % 3 != 0 {
                    continue;
                }
                near_wall += 1;
                let slow = brute_force(&cave, &p, limit);
                // Rays are exact; the lattice is 1 cm, the ray spacing a few cm.
                assert!(
                    (fast - slow).abs() < 0.03,
                    "{p}: rays {fast}, lattice {slow}"
                );
            }
        }
        assert!(near_wall >= 10, "{near_wall} points near a wall");
    }

    #[test]
    fn the_cave_sdf_is_not_the_distance() {
        // A knot of a committed plan that `sdf < radius` called unsafe (default cave,
        // seed 5, robot 1 at 36.2 s): the SDF says 0.29 m, the rock is 0.72 m away.
        let cave = CaveWorld::generate(&CaveParams::default(), 7);
        let p = Point3::new(22.2136, 4.6684, -1.0589);
        assert!(cave.sdf_m(&p) < 0.3);
        let fast = surface_distance_m(&cave, &p, 1.0);
        assert!((fast - 0.72).abs() < 0.03, "{fast}");
    }

    #[test]
    fn equals_the_sdf_of_an_exact_field_and_is_negative_inside() {
        let room = BoxRoom::new(Aabb::new(
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(4.0, 4.0, 3.0),
        ));
        for p in [
            Point3::new(0.2, 2.0, 1.5),
            Point3::new(1.0, 0.35, 0.3),
            Point3::new(2.0, 2.0, 2.9),
        ] {
            let d = surface_distance_m(&room, &p, 0.5);
            assert!((d - room.sdf_m(&p)).abs() < 2e-3, "{p}: {d}");
        }
        assert_eq!(
            surface_distance_m(&room, &Point3::new(2.0, 2.0, 1.5), 0.5),
            0.5
        );
        assert!(surface_distance_m(&room, &Point3::new(-0.1, 2.0, 1.5), 0.5) < 0.0);
    }
}
