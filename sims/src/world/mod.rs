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
//! §5.2), [`OpenField`] (flat ground and a few boxes, for crossing missions) and [`BoxRoom`] (one analytic box, for tests). [`WorldConfig`] picks one.

mod box_room;
pub mod cave;
mod config;
pub mod mesh;
mod mesh_io;
pub mod noise;
pub mod open_field;
pub mod scenes;
pub mod solids;
pub mod warehouse;

pub use box_room::BoxRoom;
pub use cave::{CaveParams, CaveWorld};
pub use config::{WorldConfig, WorldKind};
pub use mesh::{FreeSpace, MeshParams, MeshWorld, TriangleMesh};
pub use open_field::{OpenField, OpenFieldParams};
pub use scenes::{DoorParams, OpeningScene, WindowParams};
pub use troupe_actors::geometry::Aabb;
pub use warehouse::{Warehouse, WarehouseParams};

use nalgebra::{Point3, Vector3};

/// Step used by the default [`World::normal`] for its central differences, in metres.
pub const NORMAL_STEP_M: f64 = 1e-3;

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
}

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
