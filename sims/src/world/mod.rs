//! Ground-truth worlds: signed distance fields with a surface texture.
//!
//! A [`World`] answers three questions about a point in the world frame (z up, metres):
//! how far the nearest surface is ([`World::sdf_m`], positive in free space, negative in
//! rock), what the surface looks like there ([`World::albedo`]), and which box holds all of
//! its free space ([`World::bounds`]). The camera sphere-traces it and the coverage metric
//! samples it; robots never see it directly.
//!
//! Implementations: [`CaveWorld`] (procedural tunnel network from a seed) and [`BoxRoom`]
//! (one analytic box, for tests).

mod box_room;
pub mod cave;
pub mod noise;

pub use box_room::BoxRoom;
pub use cave::{CaveParams, CaveWorld};
pub use troupe_actors::geometry::Aabb;

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
