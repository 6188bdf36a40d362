//! An open field: flat ground, a bounded square extent, and a few box obstacles placed
//! from a seed outside the crossing area. Robots start on a circle around the centre and
//! fly straight to the opposite point, so every route crosses the centre: the scene of
//! the inter-robot avoidance tests (thesis §8.2.3).

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};
use troupe_core::ConfigError;

use super::gpu_scene::{GpuAlbedo, GpuNoise, GpuScene};
use super::noise::{ValueNoise, mix64, unit_f64};
use super::solids::BoxSolids;
use super::warehouse::polyline_length_m;
use super::{Aabb, Site, World};

/// Shape of an [`OpenField`]; lengths in metres.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OpenFieldParams {
    /// Half the side of the square field (x and y from −half to +half).
    pub half_extent_m: f64,
    /// Height of the free space above the ground.
    pub height_m: f64,
    /// Radius of the circle the robots start on (and cross to the opposite side of).
    pub route_radius_m: f64,
    /// Flight height of the routes.
    pub route_height_m: f64,
    /// Number of box obstacles.
    pub obstacles: usize,
    /// Smallest and largest edge of an obstacle (x, y); heights span the field.
    pub obstacle_size_m: [f64; 2],
    /// Free margin kept between the route circle and any obstacle.
    pub keep_clear_m: f64,
    /// When > 0: robots that leave at the team's staggered departures
    /// ([`super::DEPARTURE_INTERVAL_S`]) and fly at this speed reach the centre
    /// together: later robots start closer to it (never closer than 2 m). 0: every
    /// robot starts on the route circle.
    pub arrival_speed_mps: f64,
}

impl Default for OpenFieldParams {
    fn default() -> Self {
        OpenFieldParams {
            half_extent_m: 20.0,
            height_m: 6.0,
            route_radius_m: 8.0,
            route_height_m: 1.5,
            obstacles: 6,
            obstacle_size_m: [1.0, 3.0],
            keep_clear_m: 2.0,
            arrival_speed_mps: 0.0,
        }
    }
}

impl OpenFieldParams {
    /// Checks that the routes fit in the field with room for the obstacles.
    ///
    /// # Errors
    ///
    /// The offending key (relative to `[world.open_field]`), its rule and its value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        for (key, v) in [
            ("half_extent_m", self.half_extent_m),
            ("height_m", self.height_m),
            ("route_radius_m", self.route_radius_m),
            ("route_height_m", self.route_height_m),
            ("keep_clear_m", self.keep_clear_m),
        ] {
            ConfigError::positive(key, v)?;
        }
        ConfigError::non_negative("arrival_speed_mps", self.arrival_speed_mps)?;
        let [lo, hi] = self.obstacle_size_m;
        if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && hi >= lo) {
            return Err(ConfigError::new(
                "obstacle_size_m",
                "must be [min, max] with 0 < min ≤ max",
                format!("{:?}", self.obstacle_size_m),
            ));
        }
        if self.route_height_m + 1.0 > self.height_m {
            return Err(ConfigError::new(
                "route_height_m",
                format!("must leave 1 m below the top (height_m {})", self.height_m),
                self.route_height_m,
            ));
        }
        if self.route_radius_m + 1.0 > self.half_extent_m {
            return Err(ConfigError::new(
                "route_radius_m",
                format!(
                    "must leave 1 m to the edge (half_extent_m {})",
                    self.half_extent_m
                ),
                self.route_radius_m,
            ));
        }
        if self.obstacles > 0
            && self.route_radius_m + self.keep_clear_m + hi * std::f64::consts::SQRT_2
                > self.half_extent_m
        {
            return Err(ConfigError::new(
                "half_extent_m",
                "must leave room for obstacles outside the routes",
                self.half_extent_m,
            ));
        }
        Ok(())
    }
}

/// See the [module docs](self).
#[derive(Debug, Clone)]
pub struct OpenField {
    params: OpenFieldParams,
    solids: BoxSolids,
    texture: ValueNoise,
}

impl OpenField {
    /// Places the obstacles from `seed` (validate `params` first): uniformly in the
    /// ring between the route circle plus `keep_clear_m` and the field's edge.
    #[must_use]
    pub fn generate(params: &OpenFieldParams, seed: u64) -> Self {
        let h = params.half_extent_m;
        let interior = Aabb::new(Point3::new(-h, -h, 0.0), Point3::new(h, h, params.height_m));
        let [lo, hi] = params.obstacle_size_m;
        let clear = params.route_radius_m + params.keep_clear_m;
        let mut solids = Vec::new();
        let mut draw = 0u64;
        let mut next = || {
            draw += 1;
            unit_f64(mix64(seed ^ mix64(draw)))
        };
        // Rejection sampling with a cap: a crowded field gets fewer boxes.
        for _ in 0..params.obstacles * 100 {
            if solids.len() == params.obstacles {
                break;
            }
            let size = Vector3::new(lo + (hi - lo) * next(), lo + (hi - lo) * next(), 0.0);
            let half = size.xy().norm() / 2.0;
            let centre = Point3::new(
                (2.0 * next() - 1.0) * (h - half),
                (2.0 * next() - 1.0) * (h - half),
                0.0,
            );
            if centre.coords.xy().norm() - half < clear {
                continue;
            }
            solids.push(Aabb::new(
                Point3::new(centre.x - size.x / 2.0, centre.y - size.y / 2.0, 0.0),
                Point3::new(
                    centre.x + size.x / 2.0,
                    centre.y + size.y / 2.0,
                    params.height_m,
                ),
            ));
        }
        OpenField {
            params: params.clone(),
            solids: BoxSolids::new(interior, solids, 4.0),
            texture: ValueNoise::new(seed ^ 0x6f70_656e),
        }
    }

    /// The obstacles.
    #[must_use]
    pub fn obstacles(&self) -> &[Aabb] {
        self.solids.solids()
    }
}

impl World for OpenField {
    fn sdf_m(&self, p: &Point3<f64>) -> f64 {
        self.solids.sdf_m(p)
    }

    fn albedo(&self, p: &Point3<f64>) -> f64 {
        // Grass-like grain on the ground, plainer boxes and walls.
        let grain = self.texture.fbm(&Point3::from(p.coords / 0.5), 3);
        let base = if p.z < 0.05 { 0.35 } else { 0.55 };
        (base + 0.3 * grain).clamp(0.05, 1.0)
    }

    fn bounds(&self) -> Aabb {
        self.solids.interior()
    }

    fn gpu_scene(&self) -> Option<GpuScene> {
        Some(GpuScene {
            geometry: self.solids.gpu_geometry(),
            albedo: GpuAlbedo::OpenField {
                texture: GpuNoise::from(&self.texture),
            },
        })
    }
}

impl Site for OpenField {
    /// Robot `i` of `n` starts at angle `π i / n` on the route circle (closer in with
    /// [`OpenFieldParams::arrival_speed_mps`]): the lines to the opposite points are
    /// `π / n` apart and all cross at the centre.
    fn start_position(&self, robot_index: usize, robot_count: usize) -> Point3<f64> {
        let n = robot_count.max(1);
        let a = std::f64::consts::PI * robot_index as f64 / n as f64;
        let lead_s = n.saturating_sub(1 + robot_index) as f64 * super::DEPARTURE_INTERVAL_S;
        let r = (self.params.route_radius_m - lead_s * self.params.arrival_speed_mps)
            .max(2.0_f64.min(self.params.route_radius_m));
        Point3::new(r * a.cos(), r * a.sin(), self.params.route_height_m)
    }

    /// From the start through the centre to the opposite point of the route circle.
    fn route(&self, robot_index: usize, robot_count: usize) -> Vec<Point3<f64>> {
        let start = self.start_position(robot_index, robot_count);
        let r = self.params.route_radius_m;
        let dir = start.coords.xy().normalize();
        let goal = Point3::new(-r * dir.x, -r * dir.y, start.z);
        vec![start, goal]
    }

    fn route_length_m(&self) -> f64 {
        polyline_length_m(&self.route(0, 1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::warehouse::route_clearance_m;

    #[test]
    fn routes_cross_at_the_centre_clear_of_obstacles() {
        let params = OpenFieldParams::default();
        assert_eq!(params.validate(), Ok(()));
        let field = OpenField::generate(&params, 4);
        assert_eq!(field.obstacles().len(), params.obstacles);
        for n in [1, 2, 4] {
            for i in 0..n {
                let route = field.route(i, n);
                // Through the centre.
                let mid = Point3::from((route[0].coords + route[1].coords) / 2.0);
                assert!((mid - Point3::new(0.0, 0.0, params.route_height_m)).norm() < 1e-9);
                let clearance = route_clearance_m(&field, &route, 0.1);
                assert!(clearance >= 1.0, "robot {i}/{n}: clearance {clearance}");
            }
        }
        // Obstacles are rock; the same seed gives the same field, another seed another.
        assert!(field.sdf_m(&field.obstacles()[0].centre()) < 0.0);
        assert_eq!(
            OpenField::generate(&params, 4).obstacles(),
            field.obstacles()
        );
        assert_ne!(
            OpenField::generate(&params, 5).obstacles(),
            field.obstacles()
        );
        // Flat ground: 1.5 m above it near the centre.
        assert!((field.sdf_m(&Point3::new(0.0, 0.0, 1.5)) - 1.5).abs() < 1e-9);
    }

    #[test]
    fn invalid_parameters_are_named() {
        let p = OpenFieldParams {
            route_radius_m: 30.0,
            ..OpenFieldParams::default()
        };
        assert_eq!(p.validate().unwrap_err().key, "route_radius_m");
        let p = OpenFieldParams {
            obstacle_size_m: [2.0, 1.0],
            ..OpenFieldParams::default()
        };
        assert_eq!(p.validate().unwrap_err().key, "obstacle_size_m");
    }
}
