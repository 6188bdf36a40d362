//! The window scenario of thesis §5.2.1 as a synthetic scene, for tests and benches:
//! a wall with a 0.9 m × 0.9 m window 10 m ahead and a back wall behind it.

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Matrix4, Point3, Vector3, Vector4};
use troupe_core::Time;

use crate::camera::PinholeIntrinsics;
use crate::keyframe::Keyframe;
use crate::sogmm::Gmm4;
use crate::sogmm::synthetic::{Rect, Scene, Texture};

/// Where the wall stands, metres along x.
pub const WALL_X_M: f64 = 10.0;
/// Half the window's edge, metres.
pub const HALF_WINDOW_M: f64 = 0.45;

fn plane_x(x: f64, y: [f64; 2], z: [f64; 2]) -> Rect {
    Rect {
        origin: Point3::new(x, y[0], z[0]),
        u: Vector3::new(0.0, y[1] - y[0], 0.0),
        v: Vector3::new(0.0, 0.0, z[1] - z[0]),
        texture: Texture::Uniform(0.5),
    }
}

/// The wall at x = 10 m (10 m × 6 m) around a 0.9 m × 0.9 m window centred on the
/// flight line, and a back wall at x = 20 m that the robot sees through the window.
pub fn window_scene() -> Scene {
    let (w, h, a) = (5.0, 3.0, HALF_WINDOW_M);
    Scene {
        rects: vec![
            plane_x(WALL_X_M, [-w, -a], [-h, h]),
            plane_x(WALL_X_M, [a, w], [-h, h]),
            plane_x(WALL_X_M, [-a, a], [-h, -a]),
            plane_x(WALL_X_M, [-a, a], [a, h]),
            plane_x(20.0, [-8.0, 8.0], [-5.0, 5.0]),
        ],
    }
}

/// A wide camera (about 103° horizontal), 12 m range.
pub fn camera() -> PinholeIntrinsics {
    PinholeIntrinsics {
        width: 160,
        height: 120,
        fx: 64.0,
        fy: 64.0,
        cx: 80.0,
        cy: 60.0,
        max_depth_m: 12.0,
    }
}

/// A keyframe GMM built from the surface points the camera sees at `pose`: one
/// component per 0.225 m bin (the window edges fall on bin edges) of points (its sample mean and covariance).
pub fn keyframe_at(scene: &Scene, id: u32, pose: Isometry3<f64>) -> Keyframe {
    let k = camera();
    let (depth, _) = scene.render(&k, &pose);
    let mut bins: BTreeMap<[i64; 3], Vec<Vector3<f64>>> = BTreeMap::new();
    for row in 0..k.height {
        for col in 0..k.width {
            let d = f64::from(depth[(row * k.width + col) as usize]);
            if d > 0.0 {
                let p = pose * k.back_project(col, row, d);
                let key = [0, 1, 2].map(|i| (p[i] / 0.225).floor() as i64);
                bins.entry(key).or_default().push(p.coords);
            }
        }
    }
    let (mut weights, mut means, mut covariances) = (Vec::new(), Vec::new(), Vec::new());
    let mut support = 0;
    for points in bins.values().filter(|p| p.len() >= 3) {
        let n = points.len() as f64;
        let mean = points.iter().sum::<Vector3<f64>>() / n;
        let mut cov = Matrix4::identity() * 0.01;
        let spatial = points
            .iter()
            .map(|p| (p - mean) * (p - mean).transpose())
            .sum::<nalgebra::Matrix3<f64>>()
            / n
            + nalgebra::Matrix3::identity() * 1e-5;
        cov.fixed_view_mut::<3, 3>(0, 0).copy_from(&spatial);
        weights.push(n);
        means.push(Vector4::new(mean.x, mean.y, mean.z, 0.5));
        covariances.push(cov);
        support += points.len();
    }
    let total: f64 = weights.iter().sum();
    weights.iter_mut().for_each(|w| *w /= total);
    Keyframe {
        id,
        stamp: Time::ZERO,
        pose,
        support_size: support as u32,
        gmm: Gmm4::new(weights, means, covariances).expect("binned components are valid"),
    }
}
