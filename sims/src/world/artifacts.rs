//! Artifacts: a few small retroreflective spheres placed in a world by its seed, for
//! the artifact-reporting example (`troupe_actors::artifacts`) and its score.
//!
//! [`place`] picks positions uniformly in the world's bounds (a `ChaCha8` stream of
//! the world seed), keeps those with at least `clearance_m` of free space around
//! them, lets each fall to the floor, and keeps them `min_spacing_m` apart.
//! [`WithArtifacts`] adds them to a world: its field is the minimum of the world's
//! and the spheres' (exact) distances, and their reflectance is
//! [`ARTIFACT_REFLECTANCE`] — above the `[0, 1]` of diffuse surfaces, like a
//! retroreflector: the camera clamps the intensity it returns to 1, so an artifact
//! is the brightest thing in a frame at any distance a diffuse surface could match.
//! A world with artifacts has no GPU description: the GPU shader renders albedo in
//! `[0, 1]` and knows no spheres, so the camera renders such a world on the CPU
//! (`camera.backend = "auto"` chooses it, and a scenario that asks for `"gpu"` with
//! `[world.artifacts]` is refused with a message that says why).

use std::sync::Arc;

use nalgebra::{Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use troupe_core::ConfigError;

use super::{Aabb, Site, World, surface_distance_m};

/// Reflectance of an artifact's surface (see the module docs).
pub const ARTIFACT_REFLECTANCE: f64 = 4.0;

/// The `[world.artifacts]` table.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ArtifactParams {
    /// How many artifacts to place (0 = none; fewer when the world has too little
    /// room).
    pub count: usize,
    /// Radius of each sphere, metres.
    pub radius_m: f64,
    /// Free space required around a candidate position before it falls, metres.
    pub clearance_m: f64,
    /// Smallest distance between two artifacts, metres.
    pub min_spacing_m: f64,
}

impl Default for ArtifactParams {
    fn default() -> Self {
        ArtifactParams {
            count: 0,
            radius_m: 0.15,
            clearance_m: 0.8,
            min_spacing_m: 4.0,
        }
    }
}

impl ArtifactParams {
    /// Checks the ranges.
    ///
    /// # Errors
    ///
    /// The offending key (relative to `[world.artifacts]`), its rule and its value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.count > 1000 {
            return Err(ConfigError::new(
                "count",
                "must be at most 1000",
                self.count,
            ));
        }
        ConfigError::positive("radius_m", self.radius_m)?;
        ConfigError::positive("clearance_m", self.clearance_m)?;
        ConfigError::positive("min_spacing_m", self.min_spacing_m)?;
        if self.clearance_m <= self.radius_m {
            return Err(ConfigError::new(
                "clearance_m",
                "must exceed radius_m",
                self.clearance_m,
            ));
        }
        Ok(())
    }
}

/// Sphere centres for `params.count` artifacts in `world` (deterministic per `seed`).
#[must_use]
pub fn place(world: &dyn World, params: &ArtifactParams, seed: u64) -> Vec<Point3<f64>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x6172_7469_6661_6374);
    let b = world.bounds();
    let mut placed: Vec<Point3<f64>> = Vec::new();
    let attempts = 2000 * params.count.max(1);
    for _ in 0..attempts {
        if placed.len() >= params.count {
            break;
        }
        let mut p = Point3::new(
            rng.random_range(b.min.x..=b.max.x),
            rng.random_range(b.min.y..=b.max.y),
            rng.random_range(b.min.z..=b.max.z),
        );
        if surface_distance_m(world, &p, params.clearance_m) < params.clearance_m {
            continue;
        }
        // Fall until resting on the floor (certified steps never cross it).
        let rest = params.radius_m + 0.01;
        for _ in 0..200 {
            let step = world.safe_step_m(&p);
            if step <= rest {
                break;
            }
            p.z -= (step - rest).min(0.5);
        }
        let clear = surface_distance_m(world, &p, params.radius_m);
        if clear >= params.radius_m
            && placed
                .iter()
                .all(|q| (q - p).norm() >= params.min_spacing_m)
        {
            placed.push(p);
        }
    }
    placed
}

/// A site with artifacts added (see the module docs).
pub struct WithArtifacts {
    inner: Arc<dyn Site>,
    centres: Vec<Point3<f64>>,
    radius_m: f64,
}

impl WithArtifacts {
    /// `inner` with spheres of `radius_m` at `centres`.
    #[must_use]
    pub fn new(inner: Arc<dyn Site>, centres: Vec<Point3<f64>>, radius_m: f64) -> Self {
        WithArtifacts {
            inner,
            centres,
            radius_m,
        }
    }

    /// Signed distance to the nearest artifact and its centre.
    fn nearest(&self, p: &Point3<f64>) -> Option<(f64, &Point3<f64>)> {
        self.centres
            .iter()
            .map(|c| ((p - c).norm() - self.radius_m, c))
            .min_by(|a, b| a.0.total_cmp(&b.0))
    }
}

/// Within this of a sphere's surface a point is on the artifact, metres.
const ON_ARTIFACT_M: f64 = 0.01;

impl World for WithArtifacts {
    fn sdf_m(&self, p: &Point3<f64>) -> f64 {
        let world = self.inner.sdf_m(p);
        self.nearest(p).map_or(world, |(d, _)| world.min(d))
    }

    fn lipschitz(&self) -> f64 {
        self.inner.lipschitz().max(1.0)
    }

    fn safe_step_m(&self, p: &Point3<f64>) -> f64 {
        let world = self.inner.safe_step_m(p);
        self.nearest(p).map_or(world, |(d, _)| world.min(d))
    }

    fn albedo(&self, p: &Point3<f64>) -> f64 {
        match self.nearest(p) {
            Some((d, _)) if d < ON_ARTIFACT_M => ARTIFACT_REFLECTANCE,
            _ => self.inner.albedo(p),
        }
    }

    fn bounds(&self) -> Aabb {
        self.inner.bounds()
    }

    fn normal(&self, p: &Point3<f64>) -> Vector3<f64> {
        match self.nearest(p) {
            Some((d, c)) if d < ON_ARTIFACT_M && d < self.inner.sdf_m(p) => {
                (p - c).try_normalize(1e-12).unwrap_or_else(Vector3::z)
            }
            _ => self.inner.normal(p),
        }
    }
}

impl Site for WithArtifacts {
    fn start_position(&self, robot_index: usize, robot_count: usize) -> Point3<f64> {
        self.inner.start_position(robot_index, robot_count)
    }

    fn route(&self, robot_index: usize, robot_count: usize) -> Vec<Point3<f64>> {
        self.inner.route(robot_index, robot_count)
    }

    fn route_length_m(&self) -> f64 {
        self.inner.route_length_m()
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use crate::world::{CaveParams, CaveWorld};

    #[test]
    fn artifacts_rest_in_free_space_apart_and_deterministically() {
        let cave: Arc<dyn Site> = Arc::new(CaveWorld::generate(&CaveParams::default(), 7));
        let params = ArtifactParams {
            count: 6,
            ..ArtifactParams::default()
        };
        let a = place(cave.as_ref(), &params, 7);
        assert_eq!(a, place(cave.as_ref(), &params, 7));
        assert_ne!(a, place(cave.as_ref(), &params, 8));
        assert_eq!(a.len(), 6);
        for (i, p) in a.iter().enumerate() {
            let clear = surface_distance_m(cave.as_ref(), p, 1.0);
            assert!(
                clear >= params.radius_m && clear < params.radius_m + 0.2,
                "{p}: {clear}"
            );
            for q in &a[..i] {
                assert!((p - q).norm() >= params.min_spacing_m);
            }
        }
        let world = WithArtifacts::new(cave.clone(), a.clone(), params.radius_m);
        let on = a[0] + Vector3::new(0.0, 0.0, params.radius_m);
        assert!(world.sdf_m(&on).abs() < 1e-9);
        assert_eq!(world.albedo(&on), ARTIFACT_REFLECTANCE);
        assert!((world.normal(&on) - Vector3::z()).norm() < 1e-9);
        assert!(world.sdf_m(&a[0]) < 0.0);
        let far = cave.start_position(0, 1);
        assert_eq!(world.albedo(&far), cave.albedo(&far));
    }

    #[test]
    fn bad_params_are_named() {
        let bad = ArtifactParams {
            radius_m: f64::NAN,
            ..ArtifactParams::default()
        };
        assert_eq!(bad.validate().unwrap_err().key, "radius_m");
        let bad = ArtifactParams {
            clearance_m: 0.1,
            ..ArtifactParams::default()
        };
        assert_eq!(bad.validate().unwrap_err().key, "clearance_m");
    }
}
