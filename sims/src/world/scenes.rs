//! The teleoperation scenes of thesis §5.2: a window in a wall (§5.2.1, Fig. 5.4) and a
//! door into a building (Fig. 5.6). The robot starts in front of the opening, facing it
//! along +x; its route goes straight through.

use nalgebra::Point3;
use serde::{Deserialize, Serialize};
use troupe_core::ConfigError;

use super::gpu_scene::{GpuAlbedo, GpuNoise, GpuScene};
use super::noise::ValueNoise;
use super::solids::BoxSolids;
use super::{Aabb, Site, World};

/// The window scene: a 0.9 m × 0.9 m window in a wall 10 m ahead (thesis §5.2.1).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WindowParams {
    /// Distance from the start to the wall's front face, metres.
    pub distance_m: f64,
    /// Window width and height, metres.
    pub window_m: [f64; 2],
    /// Height of the window's centre (and of the flight), metres.
    pub height_m: f64,
    /// Wall thickness, metres.
    pub wall_thickness_m: f64,
}

impl Default for WindowParams {
    fn default() -> Self {
        WindowParams {
            distance_m: 10.0,
            window_m: [0.9, 0.9],
            height_m: 2.0,
            wall_thickness_m: 0.2,
        }
    }
}

/// The door scene: a building whose front wall, 12 m ahead, has a 0.9 m wide door
/// (thesis §5.2, Fig. 5.6).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DoorParams {
    /// Distance from the start to the building's front face, metres.
    pub distance_m: f64,
    /// Door width and height, metres.
    pub door_m: [f64; 2],
    /// Building footprint (depth along x, width along y) and wall height, metres.
    pub building_m: [f64; 3],
    /// Wall thickness, metres.
    pub wall_thickness_m: f64,
    /// Flight height, metres.
    pub height_m: f64,
}

impl Default for DoorParams {
    fn default() -> Self {
        DoorParams {
            distance_m: 12.0,
            door_m: [0.9, 2.1],
            building_m: [10.0, 10.0, 3.5],
            wall_thickness_m: 0.2,
            height_m: 1.2,
        }
    }
}

impl WindowParams {
    /// Checks the scene can be built and flown.
    ///
    /// # Errors
    ///
    /// The offending key (relative to `[world.window]`), its rule and its value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        ConfigError::positive("wall_thickness_m", self.wall_thickness_m)?;
        ConfigError::positive("window_m[0]", self.window_m[0])?;
        ConfigError::positive("window_m[1]", self.window_m[1])?;
        check_distance_m(self.distance_m)?;
        if !(self.height_m - self.window_m[1] / 2.0 > 0.2 && self.height_m <= 4.0) {
            return Err(ConfigError::new(
                "height_m",
                "must put the window above the floor and be ≤ 4 m",
                self.height_m,
            ));
        }
        Ok(())
    }
}

impl DoorParams {
    /// Checks the scene can be built and flown.
    ///
    /// # Errors
    ///
    /// The offending key (relative to `[world.door]`), its rule and its value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        ConfigError::positive("wall_thickness_m", self.wall_thickness_m)?;
        ConfigError::positive("door_m[0]", self.door_m[0])?;
        ConfigError::positive("door_m[1]", self.door_m[1])?;
        let [depth, width, height] = self.building_m;
        if !(depth >= 3.0 && width >= self.door_m[0] + 1.0 && height > self.door_m[1]) {
            return Err(ConfigError::new(
                "building_m",
                "must be at least 3 m deep, wider than the door and taller than it",
                format!("{:?}", self.building_m),
            ));
        }
        check_distance_m(self.distance_m)?;
        if !(self.height_m > 0.3 && self.height_m < self.door_m[1] - 0.3) {
            return Err(ConfigError::new(
                "height_m",
                "must be inside the door's height with 0.3 m to spare",
                self.height_m,
            ));
        }
        Ok(())
    }
}

/// The opening stands at least 2 m ahead of the start.
fn check_distance_m(distance_m: f64) -> Result<(), ConfigError> {
    if distance_m.is_finite() && distance_m >= 2.0 {
        Ok(())
    } else {
        Err(ConfigError::new("distance_m", "must be ≥ 2 m", distance_m))
    }
}

/// A scene made of solid boxes with a straight route through an opening.
#[derive(Debug, Clone)]
pub struct OpeningScene {
    solids: BoxSolids,
    texture: ValueNoise,
    start: Point3<f64>,
    goal: Point3<f64>,
    opening_centre: Point3<f64>,
}

/// Boxes of a wall at `x0..x0+thickness` across `y_range × z_range`, with a rectangular
/// opening centred at (`y`, `z`) of size `w × h`.
fn wall_with_opening(
    x0: f64,
    thickness: f64,
    y_range: [f64; 2],
    z_range: [f64; 2],
    centre: [f64; 2],
    size: [f64; 2],
) -> Vec<Aabb> {
    let x1 = x0 + thickness;
    let [yc, zc] = centre;
    let (y_lo, y_hi) = (yc - size[0] / 2.0, yc + size[0] / 2.0);
    let (z_lo, z_hi) = (zc - size[1] / 2.0, zc + size[1] / 2.0);
    let boxes = [
        // Left and right of the opening, full height.
        ([y_range[0], z_range[0]], [y_lo, z_range[1]]),
        ([y_hi, z_range[0]], [y_range[1], z_range[1]]),
        // Below and above it.
        ([y_lo, z_range[0]], [y_hi, z_lo]),
        ([y_lo, z_hi], [y_hi, z_range[1]]),
    ];
    boxes
        .into_iter()
        .filter(|(a, b)| b[0] > a[0] && b[1] > a[1])
        .map(|(a, b)| Aabb::new(Point3::new(x0, a[0], a[1]), Point3::new(x1, b[0], b[1])))
        .collect()
}

impl OpeningScene {
    /// The window scene of §5.2.1.
    #[must_use]
    pub fn window(params: &WindowParams, seed: u64) -> Self {
        let d = params.distance_m;
        let interior = Aabb::new(
            Point3::new(-3.0, -8.0, 0.0),
            Point3::new(d + params.wall_thickness_m + 10.0, 8.0, 6.0),
        );
        let solids = wall_with_opening(
            d,
            params.wall_thickness_m,
            [interior.min.y, interior.max.y],
            [interior.min.z, interior.max.z],
            [0.0, params.height_m],
            params.window_m,
        );
        OpeningScene {
            solids: BoxSolids::new(interior, solids, 4.0),
            texture: ValueNoise::new(seed ^ 0x77_696e),
            start: Point3::new(0.0, 0.0, params.height_m),
            goal: Point3::new(d + params.wall_thickness_m + 8.0, 0.0, params.height_m),
            opening_centre: Point3::new(d + params.wall_thickness_m / 2.0, 0.0, params.height_m),
        }
    }

    /// The door scene of Fig. 5.6: a closed building (walls and roof) with one door.
    #[must_use]
    pub fn door(params: &DoorParams, seed: u64) -> Self {
        let d = params.distance_m;
        let t = params.wall_thickness_m;
        let [depth, width, height] = params.building_m;
        let interior = Aabb::new(
            Point3::new(-3.0, -width / 2.0 - 6.0, 0.0),
            Point3::new(d + depth + 6.0, width / 2.0 + 6.0, height + 3.0),
        );
        let (y0, y1) = (-width / 2.0, width / 2.0);
        let mut solids = wall_with_opening(
            d,
            t,
            [y0, y1],
            [0.0, height],
            [0.0, params.door_m[1] / 2.0],
            params.door_m,
        );
        solids.extend([
            // Back wall, side walls, roof.
            Aabb::new(
                Point3::new(d + depth - t, y0, 0.0),
                Point3::new(d + depth, y1, height),
            ),
            Aabb::new(
                Point3::new(d, y0, 0.0),
                Point3::new(d + depth, y0 + t, height),
            ),
            Aabb::new(
                Point3::new(d, y1 - t, 0.0),
                Point3::new(d + depth, y1, height),
            ),
            Aabb::new(
                Point3::new(d, y0, height),
                Point3::new(d + depth, y1, height + t),
            ),
        ]);
        OpeningScene {
            solids: BoxSolids::new(interior, solids, 4.0),
            texture: ValueNoise::new(seed ^ 0x646f_6f72),
            start: Point3::new(0.0, 0.0, params.height_m),
            goal: Point3::new(d + depth / 2.0, 0.0, params.height_m),
            opening_centre: Point3::new(d + t / 2.0, 0.0, params.door_m[1] / 2.0),
        }
    }

    /// Centre of the window or door.
    #[must_use]
    pub fn opening_centre(&self) -> Point3<f64> {
        self.opening_centre
    }
}

impl World for OpeningScene {
    fn sdf_m(&self, p: &Point3<f64>) -> f64 {
        self.solids.sdf_m(p)
    }

    fn albedo(&self, p: &Point3<f64>) -> f64 {
        let grain = self.texture.fbm(&Point3::from(p.coords / 0.25), 3);
        let bricks = if ((p.z / 0.3).floor() as i64 + (p.y / 0.6).floor() as i64) % 2 == 0 {
            0.1
        } else {
            -0.1
        };
        (0.5 + 0.25 * grain + bricks).clamp(0.05, 1.0)
    }

    fn bounds(&self) -> Aabb {
        self.solids.interior()
    }

    fn gpu_scene(&self) -> Option<GpuScene> {
        Some(GpuScene {
            geometry: self.solids.gpu_geometry(),
            albedo: GpuAlbedo::Bricks {
                texture: GpuNoise::from(&self.texture),
            },
        })
    }
}

impl Site for OpeningScene {
    fn start_position(&self, robot_index: usize, _robot_count: usize) -> Point3<f64> {
        // One behind the other along −x, 2 m apart.
        self.start - nalgebra::Vector3::x() * (2.0 * robot_index as f64)
    }

    fn route(&self, robot_index: usize, robot_count: usize) -> Vec<Point3<f64>> {
        let start = self.start_position(robot_index, robot_count);
        let approach = Point3::new(self.opening_centre.x - 2.0, 0.0, self.start.z);
        vec![start, approach, self.goal]
    }

    fn route_length_m(&self) -> f64 {
        (self.goal - self.start).norm()
    }
}

#[cfg(test)]
mod tests {
    use super::super::warehouse::route_clearance_m;
    use super::*;

    #[test]
    fn window_is_open_and_the_wall_is_solid() {
        let params = WindowParams::default();
        assert_eq!(params.validate(), Ok(()));
        let scene = OpeningScene::window(&params, 1);
        let c = scene.opening_centre();
        // Half the window's width to the frame.
        assert!((scene.sdf_m(&c) - 0.45).abs() < 1e-12);
        assert!(scene.sdf_m(&Point3::new(c.x, 1.0, c.z)) < 0.0);
        assert!(scene.sdf_m(&Point3::new(c.x, 0.0, c.z + 0.6)) < 0.0);
        let route = scene.route(0, 1);
        assert!(route_clearance_m(&scene, &route, 0.05) > 0.4);
    }

    #[test]
    fn door_leads_inside_a_closed_building() {
        let params = DoorParams::default();
        assert_eq!(params.validate(), Ok(()));
        let scene = OpeningScene::door(&params, 1);
        let route = scene.route(0, 1);
        assert!(route_clearance_m(&scene, &route, 0.05) > 0.4);
        // The roof and the side walls are solid.
        let inside = route[route.len() - 1];
        assert!(scene.sdf_m(&Point3::new(inside.x, inside.y, 3.6)) < 0.0);
        assert!(scene.sdf_m(&Point3::new(inside.x, 4.9, 1.0)) < 0.0);
        assert!(params.validate().is_ok());
        let narrow = DoorParams {
            height_m: 2.0,
            ..params
        };
        assert_eq!(narrow.validate().unwrap_err().key, "height_m");
    }
}
