//! Between the robot's keyframes and plans and their wire forms
//! (`troupe_comms::wire::Keyframe`, 60 bytes per 4D component in f32, §8.2.2;
//! `troupe_comms::wire::Plan`, 20 bytes per knot plus the priority, §8.2.3).

use nalgebra::{
    Isometry3, Matrix4, Point3, Quaternion, Translation3, UnitQuaternion, Vector3, Vector4,
};
use troupe_comms::wire;

use troupe_algorithms::keyframe::Keyframe;
use troupe_algorithms::plan::Plan;
use troupe_algorithms::sogmm::Gmm4;
use troupe_algorithms::trajectory::{Knot, Trajectory};
use troupe_runtime::{ActorError, TeamClock, Time};

/// The wire form of a committed plan (thesis §8.2.3): knot times become `f32`
/// seconds after the first knot, whose time goes on the team clock (`clock`: this
/// run's), positions and yaw `f32`. `None` for an empty trajectory (nothing to share).
#[must_use]
pub fn plan_to_wire(
    plan: &Plan,
    plan_id: u32,
    priority: u16,
    clock: TeamClock,
) -> Option<wire::Plan> {
    let first = plan.trajectory.knots().first()?;
    let start = first.time;
    let knots = plan
        .trajectory
        .knots()
        .iter()
        .map(|k| wire::PlanKnot {
            t_s: k.time.saturating_since(start).as_secs_f64() as f32,
            position_m: [
                k.position_m.x as f32,
                k.position_m.y as f32,
                k.position_m.z as f32,
            ],
            yaw_rad: k.yaw_rad as f32,
        })
        .collect();
    Some(wire::Plan {
        plan_id,
        priority,
        start_ns: clock.to_team_ns(start),
        knots,
    })
}

/// A received plan as the robot's type (knot times `start_ns + t_s` from the team
/// clock into this run's time, `clock`); `stamp` is the envelope's stamp (when it was
/// committed) in this run's time.
pub fn plan_from_wire(
    plan: &wire::Plan,
    stamp: Time,
    clock: TeamClock,
) -> Result<Plan, ActorError> {
    let knots = plan
        .knots
        .iter()
        .map(|k| {
            // Validated on decode: finite and ≥ 0; the cast saturates.
            let offset_ns = (f64::from(k.t_s) * 1e9).round() as u64;
            Knot {
                time: clock.from_team_ns(plan.start_ns.saturating_add(offset_ns)),
                position_m: Point3::from(k.position_m.map(f64::from)),
                yaw_rad: f64::from(k.yaw_rad),
            }
        })
        .collect();
    let trajectory = Trajectory::new(knots)
        .map_err(|e| ActorError::with_source("plan trajectory is invalid", e))?;
    Ok(Plan::new(stamp, trajectory))
}

/// The wire form of a keyframe (f32; the receiver renormalises the weights).
#[must_use]
pub fn keyframe_to_wire(keyframe: &Keyframe) -> wire::Keyframe {
    let q = keyframe.pose.rotation.quaternion();
    let t = keyframe.pose.translation.vector;
    let components = (0..keyframe.gmm.len())
        .map(|i| {
            let m = keyframe.gmm.means()[i];
            let c = keyframe.gmm.covariances()[i];
            let mut covariance = [0f32; 10];
            let mut k = 0;
            for r in 0..4 {
                for col in r..4 {
                    covariance[k] = c[(r, col)] as f32;
                    k += 1;
                }
            }
            wire::Component4 {
                mean: [m.x as f32, m.y as f32, m.z as f32, m.w as f32],
                covariance,
                weight: keyframe.gmm.weights()[i] as f32,
            }
        })
        .collect();
    wire::Keyframe {
        keyframe_id: keyframe.id,
        sensor_pose: wire::SensorPose {
            position_m: [t.x as f32, t.y as f32, t.z as f32],
            orientation_xyzw: [q.i as f32, q.j as f32, q.k as f32, q.w as f32],
        },
        support_size: keyframe.support_size,
        mixture: wire::Mixture::SpatialIntensity(components),
    }
}

/// A received keyframe as the robot's type; 3D mixtures are refused (the mapper
/// shares 4D ones), and the model is validated again in f64.
pub fn keyframe_from_wire(keyframe: &wire::Keyframe, stamp: Time) -> Result<Keyframe, ActorError> {
    let mixture = keyframe.mixture.expand();
    let wire::Mixture::SpatialIntensity(components) = mixture else {
        return Err(ActorError::msg("keyframe mixture is not 4D"));
    };
    let total: f64 = components.iter().map(|c| f64::from(c.weight)).sum();
    if total.is_nan() || total <= 0.0 {
        return Err(ActorError::msg("keyframe weights sum to zero"));
    }
    let weights = components
        .iter()
        .map(|c| f64::from(c.weight) / total)
        .collect();
    let means = components
        .iter()
        .map(|c| Vector4::from(c.mean.map(f64::from)))
        .collect();
    let covariances = components
        .iter()
        .map(|c| {
            let m = c.covariance_matrix();
            Matrix4::from_fn(|r, col| m[r][col])
        })
        .collect();
    let gmm = Gmm4::new(weights, means, covariances)
        .map_err(|e| ActorError::with_source("keyframe mixture is invalid", e))?;
    let p = keyframe.sensor_pose.position_m.map(f64::from);
    let [x, y, z, w] = keyframe.sensor_pose.orientation_xyzw.map(f64::from);
    Ok(Keyframe {
        id: keyframe.keyframe_id,
        stamp,
        pose: Isometry3::from_parts(
            Translation3::from(Vector3::from(p)),
            UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z)),
        ),
        support_size: keyframe.support_size,
        gmm,
    })
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;
    use troupe_comms::wire::{Envelope, Payload, decode, encode};

    use super::*;
    use troupe_algorithms::sogmm::Gmm4;

    #[test]
    fn keyframes_survive_the_wire() {
        let gmm = Gmm4::new(
            vec![0.25, 0.75],
            vec![
                Vector4::new(1.0, 2.0, 0.5, 0.3),
                Vector4::new(-1.0, 0.0, 1.0, 0.8),
            ],
            vec![
                Matrix4::from_diagonal(&Vector4::new(0.01, 0.02, 0.005, 0.001)),
                Matrix4::new(
                    0.04, 0.01, 0.0, 0.0, 0.01, 0.03, 0.0, 0.001, 0.0, 0.0, 0.02, 0.0, 0.0, 0.001,
                    0.0, 0.002,
                ),
            ],
        )
        .unwrap();
        let keyframe = Keyframe {
            id: 7,
            stamp: Time::from_secs_f64(3.0),
            pose: Isometry3::new(Vector3::new(1.0, 2.0, 3.0), Vector3::new(0.1, -0.2, 0.7)),
            support_size: 4800,
            gmm,
        };
        let bytes = encode(&Envelope::new(
            0,
            1,
            0,
            3_000_000_000,
            Payload::Keyframe(keyframe_to_wire(&keyframe)),
        ))
        .unwrap();
        // 60 bytes per 4D component (§8.2.2) plus fixed overhead.
        assert!(bytes.len() < 2 * 60 + 60, "{}", bytes.len());
        let Payload::Keyframe(wire) = decode(&bytes).unwrap().payload else {
            panic!("not a keyframe")
        };
        let back = keyframe_from_wire(&wire, keyframe.stamp).unwrap();
        assert_eq!(back.id, 7);
        assert_eq!(back.support_size, 4800);
        assert!((back.pose.translation.vector - keyframe.pose.translation.vector).norm() < 1e-6);
        assert!(back.pose.rotation.angle_to(&keyframe.pose.rotation) < 1e-6);
        // The densities agree to f32 precision.
        for p in [
            Vector4::new(1.0, 2.0, 0.5, 0.3),
            Vector4::new(-0.9, 0.1, 1.0, 0.7),
        ] {
            let a = keyframe.gmm.log_likelihood(&p);
            let b = back.gmm.log_likelihood(&p);
            assert!((a - b).abs() < 1e-4, "{a} vs {b}");
        }
    }
}
