//! A warehouse with rows of shelves (thesis §4.2.2, Fig. 4.4: 60 m × 30 m × 11 m).

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};
use troupe_core::ConfigError;

use super::gpu_scene::{GpuAlbedo, GpuNoise, GpuScene};
use super::noise::{ValueNoise, mix64, unit_f64};
use super::solids::BoxSolids;
use super::{Aabb, Site, World};

/// Shape of a [`Warehouse`]; lengths in metres.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WarehouseParams {
    /// Interior size (x, y, z).
    pub size_m: [f64; 3],
    /// Rows of shelves (along x, side by side in y).
    pub shelf_rows: usize,
    /// Depth of a shelf row (y).
    pub shelf_depth_m: f64,
    /// Length of one shelf unit (x).
    pub shelf_unit_length_m: f64,
    /// Lowest and highest shelf unit.
    pub shelf_height_m: [f64; 2],
    /// Width of the aisles between rows.
    pub aisle_width_m: f64,
    /// Width of the cross aisles between units of a row.
    pub cross_aisle_m: f64,
    /// Free space kept between the outer walls and the first/last unit of a row (x).
    pub end_margin_m: f64,
    /// Chance that a shelf unit is missing (an open bay).
    pub missing_unit_prob: f64,
    /// Flight height of the waypoint routes.
    pub route_height_m: f64,
}

impl Default for WarehouseParams {
    fn default() -> Self {
        WarehouseParams {
            size_m: [60.0, 30.0, 11.0],
            shelf_rows: 6,
            shelf_depth_m: 1.2,
            shelf_unit_length_m: 8.0,
            shelf_height_m: [4.0, 8.0],
            aisle_width_m: 3.5,
            cross_aisle_m: 3.0,
            end_margin_m: 4.0,
            missing_unit_prob: 0.1,
            route_height_m: 1.5,
        }
    }
}

impl WarehouseParams {
    /// Checks that the shelves fit and every aisle is wide enough to fly.
    ///
    /// # Errors
    ///
    /// The offending key (relative to `[world.warehouse]`), its rule and its value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let [x, y, z] = self.size_m;
        if !(x.is_finite() && y.is_finite() && z.is_finite() && x >= 10.0 && y >= 6.0 && z >= 3.0) {
            return Err(ConfigError::new(
                "size_m",
                "must be at least [10, 6, 3] m",
                format!("{:?}", self.size_m),
            ));
        }
        for (key, v) in [
            ("shelf_depth_m", self.shelf_depth_m),
            ("shelf_unit_length_m", self.shelf_unit_length_m),
            ("cross_aisle_m", self.cross_aisle_m),
        ] {
            ConfigError::positive(key, v)?;
        }
        if !(self.aisle_width_m.is_finite() && self.aisle_width_m >= 2.0) {
            return Err(ConfigError::new(
                "aisle_width_m",
                "must be at least 2 m",
                self.aisle_width_m,
            ));
        }
        let [lo, hi] = self.shelf_height_m;
        if !(lo.is_finite() && hi.is_finite() && 0.5 <= lo && lo <= hi && hi <= z) {
            return Err(ConfigError::new(
                "shelf_height_m",
                "must be [low, high] with 0.5 ≤ low ≤ high ≤ size_m[2]",
                format!("{:?}", self.shelf_height_m),
            ));
        }
        if self.shelf_rows == 0 || self.y_margin_m() < 1.5 {
            return Err(ConfigError::new(
                "shelf_rows",
                format!(
                    "must be ≥ 1 with its rows ({} m deep, {} m aisles) fitting in \
                     size_m[1] = {y} m with 1.5 m to the walls",
                    self.shelf_depth_m, self.aisle_width_m
                ),
                self.shelf_rows,
            ));
        }
        if self.units_per_row() == 0 || self.end_margin_m.is_nan() || self.end_margin_m < 2.0 {
            return Err(ConfigError::new(
                "end_margin_m",
                "must be ≥ 2 m and leave room for one shelf unit",
                self.end_margin_m,
            ));
        }
        if !(0.0..1.0).contains(&self.missing_unit_prob) {
            return Err(ConfigError::new(
                "missing_unit_prob",
                "must be in [0, 1)",
                self.missing_unit_prob,
            ));
        }
        if !(self.route_height_m > 0.5 && self.route_height_m < z - 0.5) {
            return Err(ConfigError::new(
                "route_height_m",
                "must be at least 0.5 m from floor and ceiling",
                self.route_height_m,
            ));
        }
        Ok(())
    }

    fn y_margin_m(&self) -> f64 {
        let rows = self.shelf_rows as f64;
        (self.size_m[1] - rows * self.shelf_depth_m - (rows - 1.0) * self.aisle_width_m) / 2.0
    }

    fn units_per_row(&self) -> usize {
        let usable = self.size_m[0] - 2.0 * self.end_margin_m + self.cross_aisle_m;
        (usable / (self.shelf_unit_length_m + self.cross_aisle_m)).floor() as usize
    }
}

/// A warehouse: free interior with rows of shelf units of random heights; robots start
/// at the x = 0 end and follow the aisles.
#[derive(Debug, Clone)]
pub struct Warehouse {
    params: WarehouseParams,
    solids: BoxSolids,
    texture: ValueNoise,
    /// y of the centre of each aisle (between rows, plus the two wall-side strips).
    aisle_y_m: Vec<f64>,
}

impl Warehouse {
    /// Builds the warehouse for `seed` (validate the parameters first).
    #[must_use]
    pub fn generate(params: &WarehouseParams, seed: u64) -> Self {
        let [sx, sy, sz] = params.size_m;
        let interior = Aabb::new(Point3::origin(), Point3::new(sx, sy, sz));
        let units = params.units_per_row();
        let used_x = units as f64 * (params.shelf_unit_length_m + params.cross_aisle_m)
            - params.cross_aisle_m;
        let x0 = (sx - used_x) / 2.0;
        let y0 = params.y_margin_m();
        let mut solids = Vec::new();
        let mut aisle_y_m = vec![y0 / 2.0];
        for row in 0..params.shelf_rows {
            let y_min = y0 + row as f64 * (params.shelf_depth_m + params.aisle_width_m);
            if row > 0 {
                aisle_y_m.push(y_min - params.aisle_width_m / 2.0);
            }
            for unit in 0..units {
                let h = mix64(seed ^ mix64((row * 1000 + unit) as u64 + 1));
                if unit_f64(h) < params.missing_unit_prob {
                    continue;
                }
                let [lo, hi] = params.shelf_height_m;
                let height = lo + (hi - lo) * unit_f64(mix64(h));
                let x_min = x0 + unit as f64 * (params.shelf_unit_length_m + params.cross_aisle_m);
                solids.push(Aabb::new(
                    Point3::new(x_min, y_min, 0.0),
                    Point3::new(
                        x_min + params.shelf_unit_length_m,
                        y_min + params.shelf_depth_m,
                        height,
                    ),
                ));
            }
        }
        aisle_y_m.push(sy - y0 / 2.0);
        let bucket_m = params.aisle_width_m.max(params.cross_aisle_m).max(2.0);
        Warehouse {
            params: params.clone(),
            solids: BoxSolids::new(interior, solids, bucket_m),
            texture: ValueNoise::new(seed ^ 0x7761_7265),
            aisle_y_m,
        }
    }

    /// The shelf units.
    #[must_use]
    pub fn shelves(&self) -> &[Aabb] {
        self.solids.solids()
    }
}

impl World for Warehouse {
    fn sdf_m(&self, p: &Point3<f64>) -> f64 {
        self.solids.sdf_m(p)
    }

    fn albedo(&self, p: &Point3<f64>) -> f64 {
        // Concrete floor and walls with grain; shelves get horizontal beams every 1.5 m.
        let grain = self.texture.fbm(&Point3::from(p.coords / 0.3), 3);
        let beams = if (p.z / 1.5).fract() < 0.08 {
            0.25
        } else {
            0.0
        };
        (0.45 + 0.25 * grain + beams).clamp(0.05, 1.0)
    }

    fn bounds(&self) -> Aabb {
        self.solids.interior()
    }

    fn gpu_scene(&self) -> Option<GpuScene> {
        Some(GpuScene {
            geometry: self.solids.gpu_geometry(),
            albedo: GpuAlbedo::Warehouse {
                texture: GpuNoise::from(&self.texture),
            },
        })
    }
}

impl Site for Warehouse {
    fn start_position(&self, robot_index: usize, robot_count: usize) -> Point3<f64> {
        // Side by side across the x = 0 end, 2 m from the wall.
        let sy = self.params.size_m[1];
        let spacing = sy / (robot_count as f64 + 1.0);
        Point3::new(
            2.0,
            spacing * (robot_index as f64 + 1.0),
            self.params.route_height_m,
        )
    }

    fn route(&self, robot_index: usize, robot_count: usize) -> Vec<Point3<f64>> {
        // Aisles dealt round-robin; each robot sweeps its aisles in a serpentine,
        // moving between aisles along the free strips at the two ends.
        let z = self.params.route_height_m;
        let near_x = 2.0;
        let far_x = self.params.size_m[0] - 2.0;
        let mut route = vec![self.start_position(robot_index, robot_count)];
        let mut at_near_end = true;
        for &y in self
            .aisle_y_m
            .iter()
            .skip(robot_index)
            .step_by(robot_count.max(1))
        {
            let (from, to) = if at_near_end {
                (near_x, far_x)
            } else {
                (far_x, near_x)
            };
            route.push(Point3::new(from, y, z));
            route.push(Point3::new(to, y, z));
            at_near_end = !at_near_end;
        }
        route
    }

    fn route_length_m(&self) -> f64 {
        polyline_length_m(&self.route(0, 1))
    }
}

/// Length of a polyline, metres.
#[must_use]
pub fn polyline_length_m(points: &[Point3<f64>]) -> f64 {
    points.windows(2).map(|w| (w[1] - w[0]).norm()).sum()
}

/// Smallest clearance (world distance) along a polyline, sampled every `step_m`.
#[must_use]
pub fn route_clearance_m(world: &dyn World, points: &[Point3<f64>], step_m: f64) -> f64 {
    let mut clearance = f64::INFINITY;
    for w in points.windows(2) {
        let d: Vector3<f64> = w[1] - w[0];
        let n = (d.norm() / step_m).ceil().max(1.0) as usize;
        for k in 0..=n {
            let p = w[0] + d * (k as f64 / n as f64);
            clearance = clearance.min(world.sdf_m(&p));
        }
    }
    clearance
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_warehouse_has_shelves_and_clear_routes() {
        let params = WarehouseParams::default();
        assert_eq!(params.validate(), Ok(()));
        let w = Warehouse::generate(&params, 5);
        assert!(w.shelves().len() > 20, "{} shelves", w.shelves().len());
        assert_eq!(w.bounds().size(), Vector3::new(60.0, 30.0, 11.0));
        for n in [1, 2, 4] {
            for i in 0..n {
                let route = w.route(i, n);
                assert!(route.len() >= 3);
                let clearance = route_clearance_m(&w, &route, 0.1);
                assert!(clearance >= 1.0, "robot {i}/{n}: clearance {clearance}");
            }
        }
        // Inside a shelf is rock; the same seed gives the same warehouse.
        let shelf = w.shelves()[0];
        assert!(w.sdf_m(&shelf.centre()) < 0.0);
        let again = Warehouse::generate(&params, 5);
        assert_eq!(again.shelves(), w.shelves());
    }

    #[test]
    fn invalid_parameters_are_named() {
        let params = WarehouseParams {
            shelf_rows: 20,
            ..WarehouseParams::default()
        };
        assert_eq!(params.validate().unwrap_err().key, "shelf_rows");
    }
}
