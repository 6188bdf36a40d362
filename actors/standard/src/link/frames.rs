//! Changing a peer's data into this robot's world frame (thesis Eq. 8.1):
//! μʲ = R₀ʲⁱ μⁱ + T₀ʲⁱ, Σʲ = R₀ʲⁱ Σⁱ (R₀ʲⁱ)ᵀ, applied to the spatial block of each
//! 4D component (intensity is frame-free), to the sensor pose, and to the knots of
//! peers' plans (§8.2.3).

use nalgebra::{Isometry3, Matrix4, UnitQuaternion, Vector3, Vector4};
use serde::{Deserialize, Serialize};

use troupe_algorithms::keyframe::Keyframe;
use troupe_algorithms::mixture::{Gmm4, MixtureError};
use troupe_algorithms::plan::Plan;
use troupe_algorithms::trajectory::{Knot, Trajectory, TrajectoryError};

/// Where a peer's world frame sits in ours (T₀ʲⁱ of Eq. 8.1).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PeerFrame {
    /// The peer's robot index.
    pub robot: u32,
    /// Translation of the peer's origin in our frame, metres.
    pub translation_m: [f64; 3],
    /// Rotation of the peer's frame in ours: roll, pitch, yaw, degrees.
    pub rotation_rpy_deg: [f64; 3],
}

impl PeerFrame {
    /// The rigid transform from the peer's world frame to ours.
    #[must_use]
    pub fn transform(&self) -> Isometry3<f64> {
        let [r, p, y] = self.rotation_rpy_deg.map(f64::to_radians);
        Isometry3::from_parts(
            Vector3::from(self.translation_m).into(),
            UnitQuaternion::from_euler_angles(r, p, y),
        )
    }
}

/// A mixture moved by a rigid transform (Eq. 8.1 on the spatial block).
pub fn transform_gmm(gmm: &Gmm4, transform: &Isometry3<f64>) -> Result<Gmm4, MixtureError> {
    let mut b = Matrix4::identity();
    b.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(transform.rotation.to_rotation_matrix().matrix());
    let t = transform.translation.vector;
    let offset = Vector4::new(t.x, t.y, t.z, 0.0);
    let means = gmm.means().iter().map(|m| b * m + offset).collect();
    let covariances = gmm
        .covariances()
        .iter()
        .map(|c| {
            let rotated = b * c * b.transpose();
            // Keep exact symmetry against rounding.
            (rotated + rotated.transpose()) * 0.5
        })
        .collect();
    Gmm4::new(gmm.weights().to_vec(), means, covariances)
}

/// A keyframe moved into another frame: mixture and sensor pose.
pub fn transform_keyframe(
    keyframe: &Keyframe,
    transform: &Isometry3<f64>,
) -> Result<Keyframe, MixtureError> {
    Ok(Keyframe {
        gmm: transform_gmm(&keyframe.gmm, transform)?,
        pose: transform * keyframe.pose,
        ..keyframe.clone()
    })
}

/// A plan moved into another frame (Eq. 8.1 on each knot's position; the heading
/// is the rotated forward direction's angle about z, exact for yaw-only rotations
/// and the heading of the horizontal projection otherwise). Fails only if a moved
/// knot is no longer finite.
pub fn transform_plan(plan: &Plan, transform: &Isometry3<f64>) -> Result<Plan, TrajectoryError> {
    let knots = plan
        .trajectory
        .knots()
        .iter()
        .map(|k| {
            let forward = transform.rotation * Vector3::new(k.yaw_rad.cos(), k.yaw_rad.sin(), 0.0);
            Knot {
                time: k.time,
                position_m: transform * k.position_m,
                yaw_rad: forward.y.atan2(forward.x),
            }
        })
        .collect();
    Ok(Plan::new(plan.stamp, Trajectory::new(knots)?))
}

#[cfg(test)]
mod tests {
    use nalgebra::Point3;

    use super::*;
    use troupe_runtime::Time;

    #[test]
    fn transformed_keyframes_give_the_same_world_densities() {
        let gmm = Gmm4::new(
            vec![0.4, 0.6],
            vec![
                Vector4::new(1.0, 2.0, 0.5, 0.3),
                Vector4::new(-1.0, 0.5, 1.5, 0.7),
            ],
            vec![
                Matrix4::new(
                    0.05, 0.01, 0.0, 0.002, 0.01, 0.02, 0.003, 0.0, 0.0, 0.003, 0.01, 0.0, 0.002,
                    0.0, 0.0, 0.004,
                ),
                Matrix4::from_diagonal(&Vector4::new(0.02, 0.08, 0.01, 0.003)),
            ],
        )
        .unwrap();
        let keyframe = Keyframe {
            id: 1,
            stamp: Time::ZERO,
            pose: Isometry3::translation(0.5, 0.0, 1.0),
            support_size: 1000,
            gmm,
        };
        let frame = PeerFrame {
            robot: 1,
            translation_m: [3.0, -2.0, 0.5],
            rotation_rpy_deg: [10.0, -20.0, 135.0],
        };
        let t = frame.transform();
        let moved = transform_keyframe(&keyframe, &t).unwrap();
        // The same physical point, described in each frame, has the same density.
        for p in [
            Point3::new(1.0, 2.0, 0.5),
            Point3::new(-0.8, 0.7, 1.4),
            Point3::new(0.0, 0.0, 0.0),
        ] {
            for intensity in [0.3, 0.6] {
                let here = Vector4::new(p.x, p.y, p.z, intensity);
                let q = t * p;
                let there = Vector4::new(q.x, q.y, q.z, intensity);
                let a = keyframe.gmm.log_likelihood(&here);
                let b = moved.gmm.log_likelihood(&there);
                assert!((a - b).abs() < 1e-9, "{a} vs {b}");
            }
        }
        let sensor = moved.pose.translation.vector - (t * Point3::new(0.5, 0.0, 1.0)).coords;
        assert!(sensor.norm() < 1e-12);
    }
}
