//! A rectangular room with solid boxes in it (pillars): one room described once, flown
//! by `troupe run`, `troupe robot` and the hardware robot's closed loop
//! (`scripts/ros2/box_room_camera.py --scenario` renders the same `[world.room]` table,
//! `scripts/hardware_bench/` measures what each saw of its surfaces).
//!
//! The field is exact (walls, floor, ceiling and boxes through [`BoxSolids`]); the
//! texture is the 0.5 m checkerboard of [`super::BoxRoom`], so intensity images have
//! edges and the GPU camera renders it from tables.

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};
use troupe_core::ConfigError;

use super::gpu_scene::{GpuAlbedo, GpuScene};
use super::solids::BoxSolids;
use super::{Aabb, BoxRoom, Site, World};

/// Smallest free distance of a start position from every surface, metres.
pub const ROOM_START_CLEARANCE_M: f64 = 0.5;

/// One solid box of a room (a pillar, a cabinet), corners in metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RoomBox {
    /// Low corner `[x, y, z]`.
    pub min_m: [f64; 3],
    /// High corner `[x, y, z]`.
    pub max_m: [f64; 3],
}

/// Shape of a [`Room`] (`[world.room]`); world frame, z up, metres.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RoomParams {
    /// Low corner of the free interior (floor at `interior_min_m[2]`).
    pub interior_min_m: [f64; 3],
    /// High corner of the free interior (ceiling at `interior_max_m[2]`).
    pub interior_max_m: [f64; 3],
    /// Solid boxes inside the room.
    pub pillars: Vec<RoomBox>,
    /// Start positions: robot `i` starts at `starts_m[i % len]`, moved 1 m along +y per
    /// time round the list.
    pub starts_m: Vec<[f64; 3]>,
    /// Heading of each start, degrees from +x towards +y (empty: 0 for every start;
    /// otherwise one per start).
    pub start_yaw_deg: Vec<f64>,
}

/// The default pillars: 0.8 m × 0.8 m, floor to ceiling, one near each end of the
/// room's long walls but off-centre, so each corner is hidden from part of the room.
fn default_pillars() -> Vec<RoomBox> {
    [[3.5, 2.5], [8.0, 7.0], [12.5, 3.0], [16.5, 7.5]]
        .iter()
        .map(|&[x, y]| RoomBox {
            min_m: [x - 0.4, y - 0.4, 0.0],
            max_m: [x + 0.4, y + 0.4, 4.0],
        })
        .collect()
}

impl Default for RoomParams {
    fn default() -> Self {
        RoomParams {
            interior_min_m: [0.0, 0.0, 0.0],
            interior_max_m: [20.0, 10.0, 4.0],
            pillars: default_pillars(),
            starts_m: vec![[2.0, 5.0, 1.5]],
            start_yaw_deg: Vec::new(),
        }
    }
}

fn finite(p: &[f64; 3]) -> bool {
    p.iter().all(|v| v.is_finite())
}

impl RoomParams {
    /// The free interior.
    #[must_use]
    pub fn interior(&self) -> Aabb {
        Aabb::new(
            Point3::from(self.interior_min_m),
            Point3::from(self.interior_max_m),
        )
    }

    /// Checks the room, its boxes and its starts.
    ///
    /// # Errors
    ///
    /// The offending key (relative to `[world.room]`, e.g. `pillars[2].max_m`), its
    /// rule and its value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let (lo, hi) = (self.interior_min_m, self.interior_max_m);
        if !finite(&lo) {
            return Err(ConfigError::new(
                "interior_min_m",
                "must be three finite numbers",
                format!("{lo:?}"),
            ));
        }
        if !(finite(&hi) && (0..3).all(|i| hi[i] - lo[i] >= 1.0)) {
            return Err(ConfigError::new(
                "interior_max_m",
                "must be at least 1 m above interior_min_m on every axis",
                format!("{hi:?}"),
            ));
        }
        for (i, b) in self.pillars.iter().enumerate() {
            if !finite(&b.min_m) {
                return Err(ConfigError::new(
                    format!("pillars[{i}].min_m"),
                    "must be three finite numbers",
                    format!("{:?}", b.min_m),
                ));
            }
            if !(finite(&b.max_m) && (0..3).all(|k| b.max_m[k] > b.min_m[k])) {
                return Err(ConfigError::new(
                    format!("pillars[{i}].max_m"),
                    "must be above min_m on every axis",
                    format!("{:?}", b.max_m),
                ));
            }
            let overlaps = (0..3).all(|k| b.min_m[k] < hi[k] && b.max_m[k] > lo[k]);
            if !overlaps {
                return Err(ConfigError::new(
                    format!("pillars[{i}]"),
                    "must overlap the interior (interior_min_m..interior_max_m)",
                    format!("{:?}..{:?}", b.min_m, b.max_m),
                ));
            }
        }
        if self.starts_m.is_empty() {
            return Err(ConfigError::new(
                "starts_m",
                "must give at least one start position",
                "[]",
            ));
        }
        let room = Room::generate(self);
        for (i, p) in self.starts_m.iter().enumerate() {
            let clearance = if finite(p) {
                room.sdf_m(&Point3::from(*p))
            } else {
                f64::NAN
            };
            if clearance.is_nan() || clearance < ROOM_START_CLEARANCE_M {
                return Err(ConfigError::new(
                    format!("starts_m[{i}]"),
                    format!(
                        "must be in free space, at least {ROOM_START_CLEARANCE_M} m from every \
                         wall and pillar"
                    ),
                    format!("{p:?}"),
                ));
            }
        }
        if !self.start_yaw_deg.is_empty() && self.start_yaw_deg.len() != self.starts_m.len() {
            return Err(ConfigError::new(
                "start_yaw_deg",
                format!(
                    "must be empty or give one heading per start ({})",
                    self.starts_m.len()
                ),
                format!("{:?}", self.start_yaw_deg),
            ));
        }
        if let Some((i, y)) = self
            .start_yaw_deg
            .iter()
            .enumerate()
            .find(|(_, y)| !y.is_finite())
        {
            return Err(ConfigError::new(
                format!("start_yaw_deg[{i}]"),
                "must be a finite number of degrees",
                y,
            ));
        }
        Ok(())
    }
}

/// See the [module docs](self).
#[derive(Debug, Clone)]
pub struct Room {
    params: RoomParams,
    solids: BoxSolids,
    texture: BoxRoom,
}

impl Room {
    /// Builds the room (validate the parameters first).
    #[must_use]
    pub fn generate(params: &RoomParams) -> Self {
        let interior = params.interior();
        let solids = params
            .pillars
            .iter()
            .map(|b| Aabb::new(Point3::from(b.min_m), Point3::from(b.max_m)))
            .collect();
        Room {
            params: params.clone(),
            solids: BoxSolids::new(interior, solids, 2.0),
            texture: BoxRoom::new(interior),
        }
    }

    /// The solid boxes.
    #[must_use]
    pub fn pillars(&self) -> &[Aabb] {
        self.solids.solids()
    }

    /// Heading of robot `robot_index`'s start, radians from +x towards +y.
    #[must_use]
    pub fn start_yaw_rad(&self, robot_index: usize) -> f64 {
        let yaws = &self.params.start_yaw_deg;
        if yaws.is_empty() {
            0.0
        } else {
            yaws[robot_index % yaws.len()].to_radians()
        }
    }
}

impl World for Room {
    fn sdf_m(&self, p: &Point3<f64>) -> f64 {
        self.solids.sdf_m(p)
    }

    fn albedo(&self, p: &Point3<f64>) -> f64 {
        self.texture.albedo(p)
    }

    fn bounds(&self) -> Aabb {
        self.solids.interior()
    }

    fn gpu_scene(&self) -> Option<GpuScene> {
        let albedo: GpuAlbedo = self.texture.gpu_scene()?.albedo;
        Some(GpuScene {
            geometry: self.solids.gpu_geometry(),
            albedo,
        })
    }
}

impl Site for Room {
    fn start_position(&self, robot_index: usize, _robot_count: usize) -> Point3<f64> {
        let starts = &self.params.starts_m;
        let base = Point3::from(starts[robot_index % starts.len()]);
        base + Vector3::y() * (robot_index / starts.len()) as f64
    }

    /// The start and a point 1 m ahead along the start's heading (which is how a
    /// simulated robot takes its initial heading from a site).
    fn route(&self, robot_index: usize, robot_count: usize) -> Vec<Point3<f64>> {
        let start = self.start_position(robot_index, robot_count);
        let yaw = self.start_yaw_rad(robot_index);
        vec![start, start + Vector3::new(yaw.cos(), yaw.sin(), 0.0)]
    }

    fn route_length_m(&self) -> f64 {
        let size = self.bounds().size();
        size.x.max(size.y)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    /// First hit of a ray from `o` along unit `d` by sphere tracing the field.
    fn trace(room: &Room, o: Point3<f64>, d: Vector3<f64>) -> f64 {
        let mut t = 0.0;
        for _ in 0..1000 {
            let s = room.sdf_m(&(o + d * t));
            if s < 1e-6 {
                return t;
            }
            t += s;
        }
        f64::INFINITY
    }

    #[test]
    fn default_room_is_valid_and_its_field_is_signed() {
        let params = RoomParams::default();
        assert_eq!(params.validate(), Ok(()));
        let room = Room::generate(&params);
        assert_eq!(room.pillars().len(), 4);
        assert_eq!(room.bounds().size(), Vector3::new(20.0, 10.0, 4.0));
        // Free space: the distance to the nearest wall, floor, ceiling or pillar.
        assert!((room.sdf_m(&Point3::new(2.0, 5.0, 1.5)) - 1.5).abs() < 1e-12);
        assert!((room.sdf_m(&Point3::new(3.5, 1.6, 2.0)) - 0.5).abs() < 1e-12);
        // Inside a pillar and outside the room: negative.
        assert!((room.sdf_m(&Point3::new(3.5, 2.5, 2.0)) + 0.4).abs() < 1e-12);
        assert!((room.sdf_m(&Point3::new(-1.0, 5.0, 2.0)) + 1.0).abs() < 1e-12);
        assert!(room.sdf_m(&Point3::new(10.0, 5.0, 4.5)) < 0.0);
        assert!(room.gpu_scene().is_some());
        let again = Room::generate(&params);
        assert_eq!(again.pillars(), room.pillars());
    }

    #[test]
    fn a_pillar_hides_the_wall_behind_it() {
        let room = Room::generate(&RoomParams::default());
        // From (3.5, 5.5) looking at -y: the pillar at (3.5, 2.5) is hit at y = 2.9,
        // not the wall at y = 0.
        let from = Point3::new(3.5, 5.5, 2.0);
        let t = trace(&room, from, -Vector3::y());
        assert!((t - 2.6).abs() < 1e-5, "{t}");
        // Beside the pillar the wall is visible.
        let t = trace(&room, Point3::new(5.0, 5.5, 2.0), -Vector3::y());
        assert!((t - 5.5).abs() < 1e-5, "{t}");
    }

    #[test]
    fn the_start_heading_comes_from_the_route() {
        let params = RoomParams {
            starts_m: vec![[2.0, 5.0, 1.5], [18.0, 5.0, 1.5]],
            start_yaw_deg: vec![0.0, 180.0],
            ..RoomParams::default()
        };
        assert_eq!(params.validate(), Ok(()));
        let room = Room::generate(&params);
        let route = room.route(1, 2);
        assert_eq!(route[0], Point3::new(18.0, 5.0, 1.5));
        assert!((route[1] - Point3::new(17.0, 5.0, 1.5)).norm() < 1e-12);
        // A third robot starts 1 m along +y from the first start.
        assert_eq!(room.start_position(2, 3), Point3::new(2.0, 6.0, 1.5));
    }

    #[test]
    fn invalid_rooms_are_named_by_key() {
        let key = |p: RoomParams| p.validate().unwrap_err().key;
        let d = RoomParams::default;
        assert_eq!(
            key(RoomParams {
                interior_max_m: [20.0, 10.0, 0.5],
                ..d()
            }),
            "interior_max_m"
        );
        assert_eq!(
            key(RoomParams {
                interior_min_m: [f64::NAN, 0.0, 0.0],
                ..d()
            }),
            "interior_min_m"
        );
        let mut pillars = default_pillars();
        pillars[2].max_m[0] = pillars[2].min_m[0];
        assert_eq!(key(RoomParams { pillars, ..d() }), "pillars[2].max_m");
        let mut pillars = default_pillars();
        pillars[1] = RoomBox {
            min_m: [30.0, 1.0, 0.0],
            max_m: [31.0, 2.0, 4.0],
        };
        assert_eq!(key(RoomParams { pillars, ..d() }), "pillars[1]");
        // In a pillar, too near a wall, missing.
        for start in [[3.5, 2.5, 1.5], [0.2, 5.0, 1.5]] {
            assert_eq!(
                key(RoomParams {
                    starts_m: vec![[2.0, 5.0, 1.5], start],
                    ..d()
                }),
                "starts_m[1]"
            );
        }
        assert_eq!(
            key(RoomParams {
                starts_m: Vec::new(),
                ..d()
            }),
            "starts_m"
        );
        assert_eq!(
            key(RoomParams {
                start_yaw_deg: vec![0.0, 90.0],
                ..d()
            }),
            "start_yaw_deg"
        );
        assert_eq!(
            key(RoomParams {
                start_yaw_deg: vec![f64::INFINITY],
                ..d()
            }),
            "start_yaw_deg[0]"
        );
    }
}
