//! Analytic test scenes ray-cast into depth + intensity frames with the
//! `msgs::DepthFrame` camera convention (see [`super::points`]): support for tests and
//! benchmarks, with exact surface distances for the metrics of §6.2.4.

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use crate::camera::PinholeIntrinsics;

/// Intensity pattern of a rectangle, in its local coordinates (metres along its edges).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Texture {
    /// Constant intensity.
    Uniform(f64),
    /// Checkerboard of two intensities with square side `period_m`.
    Checker {
        /// Intensity of the even squares.
        low: f64,
        /// Intensity of the odd squares.
        high: f64,
        /// Square side, metres.
        period_m: f64,
    },
    /// Sinusoidal stripes along the first edge: `base + amplitude · sin(2π s / period)`.
    Stripes {
        /// Mean intensity.
        base: f64,
        /// Amplitude.
        amplitude: f64,
        /// Period, metres.
        period_m: f64,
    },
}

impl Texture {
    fn at(&self, s: f64, t: f64) -> f64 {
        match *self {
            Texture::Uniform(g) => g,
            Texture::Checker {
                low,
                high,
                period_m,
            } => {
                let k = (s / period_m).floor() as i64 + (t / period_m).floor() as i64;
                if k.rem_euclid(2) == 0 { low } else { high }
            }
            Texture::Stripes {
                base,
                amplitude,
                period_m,
            } => base + amplitude * (std::f64::consts::TAU * s / period_m).sin(),
        }
    }
}

/// A textured rectangle `origin + a·u + b·v`, `a, b ∈ [0, 1]`, `u ⟂ v`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rect {
    /// Corner.
    pub origin: Point3<f64>,
    /// First edge.
    pub u: Vector3<f64>,
    /// Second edge (orthogonal to `u`).
    pub v: Vector3<f64>,
    /// Intensity pattern.
    pub texture: Texture,
}

impl Rect {
    fn hit(&self, o: &Point3<f64>, d: &Vector3<f64>) -> Option<(f64, f64)> {
        let n = self.u.cross(&self.v);
        let denom = d.dot(&n);
        if denom.abs() < 1e-12 {
            return None;
        }
        let t = (self.origin - o).dot(&n) / denom;
        if t <= 1e-9 {
            return None;
        }
        let rel = o + d * t - self.origin;
        let a = rel.dot(&self.u) / self.u.norm_squared();
        let b = rel.dot(&self.v) / self.v.norm_squared();
        if !(0.0..=1.0).contains(&a) || !(0.0..=1.0).contains(&b) {
            return None;
        }
        Some((
            t,
            self.texture
                .at(a * self.u.norm(), b * self.v.norm())
                .clamp(0.0, 1.0),
        ))
    }

    fn distance(&self, p: &Point3<f64>) -> f64 {
        let rel = p - self.origin;
        let a = (rel.dot(&self.u) / self.u.norm_squared()).clamp(0.0, 1.0);
        let b = (rel.dot(&self.v) / self.v.norm_squared()).clamp(0.0, 1.0);
        (rel - self.u * a - self.v * b).norm()
    }
}

/// A set of rectangles.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scene {
    /// The surfaces.
    pub rects: Vec<Rect>,
}

fn rect(origin: [f64; 3], u: [f64; 3], v: [f64; 3], texture: Texture) -> Rect {
    Rect {
        origin: Point3::from(origin),
        u: Vector3::from(u),
        v: Vector3::from(v),
        texture,
    }
}

impl Scene {
    /// One wall at x = 3 m, 8 m × 6 m, uniform intensity 0.6: the "simple scene" of
    /// Fig. 6.2a (seen from the origin along +x it fills the view).
    #[must_use]
    pub fn single_plane() -> Self {
        Self {
            rects: vec![rect(
                [3.0, -4.0, -3.0],
                [0.0, 8.0, 0.0],
                [0.0, 0.0, 6.0],
                Texture::Uniform(0.6),
            )],
        }
    }

    /// A room corner (floor z = 0 with a checkerboard, back wall x = 5 m with stripes,
    /// side walls y = ±3 m) and a box on the floor with a different intensity per face:
    /// the "cluttered scene" of Fig. 6.2b. View it from [`room_pose`].
    #[must_use]
    pub fn room_corner() -> Self {
        let h = 2.7;
        let mut rects = vec![
            rect(
                [-1.0, -3.0, 0.0],
                [6.0, 0.0, 0.0],
                [0.0, 6.0, 0.0],
                Texture::Checker {
                    low: 0.25,
                    high: 0.7,
                    period_m: 0.5,
                },
            ),
            rect(
                [5.0, -3.0, 0.0],
                [0.0, 6.0, 0.0],
                [0.0, 0.0, h],
                Texture::Stripes {
                    base: 0.55,
                    amplitude: 0.2,
                    period_m: 0.8,
                },
            ),
            rect(
                [-1.0, 3.0, 0.0],
                [6.0, 0.0, 0.0],
                [0.0, 0.0, h],
                Texture::Uniform(0.85),
            ),
            rect(
                [-1.0, -3.0, 0.0],
                [6.0, 0.0, 0.0],
                [0.0, 0.0, h],
                Texture::Uniform(0.75),
            ),
        ];
        // Box [2.2, 3.0] × [0.2, 1.0] × [0, 0.7].
        let (x0, x1, y0, y1, z1) = (2.2, 3.0, 0.2, 1.0, 0.7);
        let (dx, dy) = (x1 - x0, y1 - y0);
        rects.push(rect(
            [x0, y0, 0.0],
            [0.0, dy, 0.0],
            [0.0, 0.0, z1],
            Texture::Uniform(0.35),
        ));
        rects.push(rect(
            [x1, y0, 0.0],
            [0.0, dy, 0.0],
            [0.0, 0.0, z1],
            Texture::Uniform(0.4),
        ));
        rects.push(rect(
            [x0, y0, 0.0],
            [dx, 0.0, 0.0],
            [0.0, 0.0, z1],
            Texture::Uniform(0.45),
        ));
        rects.push(rect(
            [x0, y1, 0.0],
            [dx, 0.0, 0.0],
            [0.0, 0.0, z1],
            Texture::Uniform(0.3),
        ));
        rects.push(rect(
            [x0, y0, z1],
            [dx, 0.0, 0.0],
            [0.0, dy, 0.0],
            Texture::Uniform(0.5),
        ));
        Self { rects }
    }

    /// A corridor `length_m` long along +x (from x = 0), 4 m wide (y ∈ [−2, 2]) and
    /// 3 m high, closed at both ends: checkerboard floor, striped left wall, chequered
    /// right wall, uniform ceiling, and a box every 3 m alternating between the sides,
    /// each face with its own intensity. The scene of the simulated flights
    /// ([`flight_pose`]).
    #[must_use]
    pub fn corridor(length_m: f64) -> Self {
        let (w, h) = (2.0, 3.0);
        let l = length_m.max(1.0);
        let mut rects = vec![
            rect(
                [0.0, -w, 0.0],
                [l, 0.0, 0.0],
                [0.0, 2.0 * w, 0.0],
                Texture::Checker {
                    low: 0.2,
                    high: 0.6,
                    period_m: 0.5,
                },
            ),
            rect(
                [0.0, -w, h],
                [l, 0.0, 0.0],
                [0.0, 2.0 * w, 0.0],
                Texture::Uniform(0.8),
            ),
            rect(
                [0.0, w, 0.0],
                [l, 0.0, 0.0],
                [0.0, 0.0, h],
                Texture::Stripes {
                    base: 0.5,
                    amplitude: 0.25,
                    period_m: 1.0,
                },
            ),
            rect(
                [0.0, -w, 0.0],
                [l, 0.0, 0.0],
                [0.0, 0.0, h],
                Texture::Checker {
                    low: 0.35,
                    high: 0.75,
                    period_m: 0.6,
                },
            ),
            rect(
                [0.0, -w, 0.0],
                [0.0, 2.0 * w, 0.0],
                [0.0, 0.0, h],
                Texture::Uniform(0.45),
            ),
            rect(
                [l, -w, 0.0],
                [0.0, 2.0 * w, 0.0],
                [0.0, 0.0, h],
                Texture::Uniform(0.55),
            ),
        ];
        let mut x0 = 2.0;
        let mut side = 1.0;
        let mut k = 0u32;
        while x0 + 0.6 < l {
            let (y0, y1) = if side > 0.0 { (1.0, 1.6) } else { (-1.6, -1.0) };
            let z1 = 0.5 + 0.25 * f64::from(k % 4);
            let (x1, dx, dy) = (x0 + 0.6, 0.6, y1 - y0);
            let g = 0.15 + 0.1 * f64::from(k % 5);
            rects.push(rect(
                [x0, y0, 0.0],
                [0.0, dy, 0.0],
                [0.0, 0.0, z1],
                Texture::Uniform(g),
            ));
            rects.push(rect(
                [x1, y0, 0.0],
                [0.0, dy, 0.0],
                [0.0, 0.0, z1],
                Texture::Uniform(g + 0.2),
            ));
            rects.push(rect(
                [x0, y0, 0.0],
                [dx, 0.0, 0.0],
                [0.0, 0.0, z1],
                Texture::Uniform(g + 0.1),
            ));
            rects.push(rect(
                [x0, y1, 0.0],
                [dx, 0.0, 0.0],
                [0.0, 0.0, z1],
                Texture::Uniform(g + 0.3),
            ));
            rects.push(rect(
                [x0, y0, z1],
                [dx, 0.0, 0.0],
                [0.0, dy, 0.0],
                Texture::Uniform(g + 0.4),
            ));
            x0 += 3.0;
            side = -side;
            k += 1;
        }
        Self { rects }
    }

    /// Nearest hit along a ray: `(t, intensity)` with the point at `o + t·d`.
    #[must_use]
    pub fn cast(&self, o: &Point3<f64>, d: &Vector3<f64>) -> Option<(f64, f64)> {
        self.rects
            .iter()
            .filter_map(|r| r.hit(o, d))
            .min_by(|a, b| a.0.total_cmp(&b.0))
    }

    /// Render row-major z-depth (0 = no return or beyond `max_depth_m`) and intensity.
    #[must_use]
    pub fn render(
        &self,
        intrinsics: &PinholeIntrinsics,
        pose: &Isometry3<f64>,
    ) -> (Vec<f32>, Vec<f32>) {
        let n = (intrinsics.width * intrinsics.height) as usize;
        let mut depth = vec![0.0f32; n];
        let mut intensity = vec![0.0f32; n];
        let o = Point3::from(pose.translation.vector);
        for row in 0..intrinsics.height {
            for col in 0..intrinsics.width {
                // Body ray with unit x component: t is the z-depth.
                let dir = pose.rotation * intrinsics.pixel_ray(col, row);
                if let Some((t, g)) = self.cast(&o, &dir)
                    && t <= intrinsics.max_depth_m
                {
                    let i = (row * intrinsics.width + col) as usize;
                    depth[i] = t as f32;
                    intensity[i] = g as f32;
                }
            }
        }
        (depth, intensity)
    }

    /// Exact distance from a point to the nearest surface of the scene.
    #[must_use]
    pub fn distance(&self, p: &Point3<f64>) -> f64 {
        self.rects
            .iter()
            .map(|r| r.distance(p))
            .fold(f64::INFINITY, f64::min)
    }
}

/// Intrinsics with `fx = fy = 0.75 · width` (about 67° horizontal field of view),
/// centred principal point, 8 m range.
#[must_use]
pub fn intrinsics(width: u32, height: u32) -> PinholeIntrinsics {
    let f = 0.75 * f64::from(width);
    PinholeIntrinsics {
        width,
        height,
        fx: f,
        fy: f,
        cx: f64::from(width) / 2.0,
        cy: f64::from(height) / 2.0,
        max_depth_m: 8.0,
    }
}

/// The same camera at `factor` times the resolution (for dense ground truth).
#[must_use]
pub fn scaled(intrinsics: &PinholeIntrinsics, factor: u32) -> PinholeIntrinsics {
    let f = f64::from(factor);
    PinholeIntrinsics {
        width: intrinsics.width * factor,
        height: intrinsics.height * factor,
        fx: intrinsics.fx * f,
        fy: intrinsics.fy * f,
        cx: intrinsics.cx * f,
        cy: intrinsics.cy * f,
        max_depth_m: intrinsics.max_depth_m,
    }
}

/// Camera 1.3 m above the floor, yawed 25° left and pitched 15° down: sees the floor,
/// the box, the back wall and the left wall of [`Scene::room_corner`].
#[must_use]
pub fn room_pose() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(0.0, 0.0, 1.3),
        UnitQuaternion::from_euler_angles(0.0, 15f64.to_radians(), 25f64.to_radians()),
    )
}

/// Three views of [`Scene::room_corner`]: [`room_pose`], then the camera moved to
/// (0.5, 0.5, 1.1) m, pitched 20° and yawed 40°, then moved to (1, −1, 1.5) m,
/// pitched 25° and yawed 10°.
#[must_use]
pub fn room_views() -> [Isometry3<f64>; 3] {
    [
        room_pose(),
        Isometry3::from_parts(
            Translation3::new(0.5, 0.5, 1.1),
            UnitQuaternion::from_euler_angles(0.0, 20f64.to_radians(), 40f64.to_radians()),
        ),
        Isometry3::from_parts(
            Translation3::new(1.0, -1.0, 1.5),
            UnitQuaternion::from_euler_angles(0.0, 25f64.to_radians(), 10f64.to_radians()),
        ),
    ]
}

/// Pose `i` of `n` of a flight through [`Scene::corridor`]`(length_m)`: the camera
/// moves along the centre line from x = 0.5 m to `length_m − 4` m at 1.2–1.6 m height,
/// looking ahead with a yaw sweeping ±35° (period 40 frames) and a slight downward
/// pitch, so consecutive frames overlap strongly and every part of the corridor is seen.
#[must_use]
pub fn flight_pose(i: usize, n: usize, length_m: f64) -> Isometry3<f64> {
    let s = if n > 1 {
        i as f64 / (n - 1) as f64
    } else {
        0.0
    };
    let x = 0.5 + s * (length_m - 4.5).max(0.0);
    let phase = std::f64::consts::TAU * i as f64 / 40.0;
    let y = 0.4 * (0.5 * phase).sin();
    let z = 1.4 + 0.2 * (0.7 * phase).sin();
    let yaw = 35f64.to_radians() * phase.sin();
    let pitch = 10f64.to_radians() + 5f64.to_radians() * (0.5 * phase).cos();
    Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_euler_angles(0.0, pitch, yaw),
    )
}

/// The synthetic room-corner depth frame (80 × 60) the occupancy-agreement tests use.
pub fn room_corner_frame() -> crate::frame::DepthFrame {
    let k = intrinsics(80, 60);
    let pose = room_pose();
    let (depth_m, intensity) = Scene::room_corner().render(&k, &pose);
    crate::frame::DepthFrame {
        stamp: troupe_core::Time::ZERO,
        pose,
        intrinsics: k,
        depth_m,
        intensity,
    }
}
