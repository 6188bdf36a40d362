//! Frame conventions between troupe (ROS) and MAVLink autopilots, written once.
//!
//! troupe's world frame is **ENU** (x east, y north, z up) and its body frame is
//! **FLU** (x forward, y left, z up), as in ROS REP 103. PX4 and ArduPilot use
//! **NED** (x north, y east, z down) for the local world frame and **FRD** (x forward,
//! y right, z down) for the body. Both pairs share their origin; only the axes differ:
//!
//! - a world vector (position, velocity, acceleration) maps ENU → NED as
//!   `(x, y, z) ↦ (y, x, −z)`, and the same swap maps it back;
//! - a body vector maps FLU → FRD as `(x, y, z) ↦ (x, −y, −z)`, and back;
//! - an orientation (the rotation from body to world) maps as
//!   `R_ned_frd = R_ned_enu · R_enu_flu · R_flu_frd`;
//! - a heading (yaw) is measured from east counter-clockwise in ENU and from north
//!   clockwise in NED: `ψ_ned = π/2 − ψ_enu`, wrapped to (−π, π].
//!
//! Every conversion is its own inverse up to naming, and the tests check known poses
//! (facing north, facing east, pitched nose-up, rolled) and round trips.

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use troupe_algorithms::trajectory::wrap_angle;

/// The rotation taking ENU coordinates to NED coordinates (a half turn about the
/// axis (1, 1, 0)/√2; it is its own inverse).
fn ned_from_enu() -> UnitQuaternion<f64> {
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(Matrix3::new(
        0.0, 1.0, 0.0, //
        1.0, 0.0, 0.0, //
        0.0, 0.0, -1.0,
    )))
}

/// The rotation taking FRD coordinates to FLU coordinates (a half turn about x; it is
/// its own inverse).
fn flu_from_frd() -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
}

/// A world vector (position, velocity or acceleration) from ENU to NED.
#[must_use]
pub fn enu_to_ned(v: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(v.y, v.x, -v.z)
}

/// A world vector (position, velocity or acceleration) from NED to ENU.
#[must_use]
pub fn ned_to_enu(v: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(v.y, v.x, -v.z)
}

/// A body vector (e.g. a body rate or a body-frame velocity) from FLU to FRD.
#[must_use]
pub fn flu_to_frd(v: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(v.x, -v.y, -v.z)
}

/// A body vector from FRD to FLU.
#[must_use]
pub fn frd_to_flu(v: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(v.x, -v.y, -v.z)
}

/// An orientation (body FLU → world ENU) as the autopilot's (body FRD → world NED).
#[must_use]
pub fn enu_flu_to_ned_frd(q_enu_flu: &UnitQuaternion<f64>) -> UnitQuaternion<f64> {
    ned_from_enu() * q_enu_flu * flu_from_frd()
}

/// An autopilot orientation (body FRD → world NED) as troupe's (body FLU → world ENU).
#[must_use]
pub fn ned_frd_to_enu_flu(q_ned_frd: &UnitQuaternion<f64>) -> UnitQuaternion<f64> {
    // Both fixed rotations are half turns, hence their own inverses.
    ned_from_enu() * q_ned_frd * flu_from_frd()
}

/// The autopilot's orientation from `ATTITUDE` Euler angles (roll, pitch, yaw in
/// radians: the aerospace Z-Y-X sequence of the FRD body in NED).
#[must_use]
pub fn ned_frd_from_euler(roll_rad: f64, pitch_rad: f64, yaw_rad: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_euler_angles(roll_rad, pitch_rad, yaw_rad)
}

/// A heading from ENU (from east, counter-clockwise) to NED (from north, clockwise),
/// wrapped to (−π, π].
#[must_use]
pub fn yaw_enu_to_ned(yaw_enu_rad: f64) -> f64 {
    wrap_angle(std::f64::consts::FRAC_PI_2 - yaw_enu_rad)
}

/// A heading from NED to ENU, wrapped to (−π, π].
#[must_use]
pub fn yaw_ned_to_enu(yaw_ned_rad: f64) -> f64 {
    wrap_angle(std::f64::consts::FRAC_PI_2 - yaw_ned_rad)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};

    fn close(a: &Vector3<f64>, b: &Vector3<f64>) -> bool {
        (a - b).norm() < 1e-12
    }

    fn same_angle(a: f64, b: f64) -> bool {
        wrap_angle(a - b).abs() < 1e-12
    }

    #[test]
    fn world_vectors_swap_axes() {
        // 3 m east, 2 m north, 1 m up = 2 m north, 3 m east, 1 m "down" negative.
        let enu = Vector3::new(3.0, 2.0, 1.0);
        assert_eq!(enu_to_ned(&enu), Vector3::new(2.0, 3.0, -1.0));
        assert_eq!(ned_to_enu(&enu_to_ned(&enu)), enu);
        assert_eq!(enu_to_ned(&ned_to_enu(&enu)), enu);
    }

    #[test]
    fn body_vectors_flip_y_and_z() {
        let flu = Vector3::new(1.0, 2.0, 3.0);
        assert_eq!(flu_to_frd(&flu), Vector3::new(1.0, -2.0, -3.0));
        assert_eq!(frd_to_flu(&flu_to_frd(&flu)), flu);
    }

    #[test]
    fn known_headings() {
        // Facing north: ENU yaw π/2, NED yaw 0.
        assert!(same_angle(yaw_enu_to_ned(FRAC_PI_2), 0.0));
        // Facing east: ENU yaw 0, NED yaw π/2.
        assert!(same_angle(yaw_enu_to_ned(0.0), FRAC_PI_2));
        // Facing west: ENU π, NED −π/2. Facing south: ENU −π/2, NED π.
        assert!(same_angle(yaw_enu_to_ned(PI), -FRAC_PI_2));
        assert!(same_angle(yaw_enu_to_ned(-FRAC_PI_2), PI));
        // North-east: ENU π/4, NED π/4.
        assert!(same_angle(yaw_enu_to_ned(FRAC_PI_4), FRAC_PI_4));
    }

    #[test]
    fn yaw_wraps_and_round_trips() {
        for k in -20..=20 {
            let yaw = f64::from(k) * 0.37;
            let ned = yaw_enu_to_ned(yaw);
            assert!(ned > -PI && ned <= PI, "{yaw} → {ned}");
            assert!(same_angle(yaw_ned_to_enu(ned), yaw));
        }
        // Across the ±π seam: ENU −3 rad (west-ish, south of west) stays in range.
        let w = yaw_enu_to_ned(-3.0);
        assert!(w > -PI && w <= PI);
        assert!(same_angle(w, FRAC_PI_2 + 3.0));
    }

    #[test]
    fn level_orientations_match_their_headings() {
        for yaw_enu in [0.0, FRAC_PI_2, PI, -FRAC_PI_2, 0.3, -2.9] {
            let q_enu = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw_enu);
            let q_ned = enu_flu_to_ned_frd(&q_enu);
            let (roll, pitch, yaw) = q_ned.euler_angles();
            assert!(roll.abs() < 1e-12 && pitch.abs() < 1e-12, "{roll} {pitch}");
            assert!(
                same_angle(yaw, yaw_enu_to_ned(yaw_enu)),
                "{yaw_enu} → {yaw}"
            );
            // The body's forward axis points the same way in both worlds.
            let forward_enu = q_enu * Vector3::x();
            let forward_ned = q_ned * Vector3::x();
            assert!(close(&enu_to_ned(&forward_enu), &forward_ned));
        }
    }

    #[test]
    fn facing_north_and_east() {
        // NED yaw 0 = facing north: body forward is world +y in ENU, left is −x (west).
        let q = ned_frd_to_enu_flu(&ned_frd_from_euler(0.0, 0.0, 0.0));
        assert!(close(&(q * Vector3::x()), &Vector3::new(0.0, 1.0, 0.0)));
        assert!(close(&(q * Vector3::y()), &Vector3::new(-1.0, 0.0, 0.0)));
        assert!(close(&(q * Vector3::z()), &Vector3::new(0.0, 0.0, 1.0)));
        // NED yaw π/2 = facing east: ENU identity.
        let q = ned_frd_to_enu_flu(&ned_frd_from_euler(0.0, 0.0, FRAC_PI_2));
        assert!(q.angle_to(&UnitQuaternion::identity()) < 1e-12);
    }

    #[test]
    fn pitched_nose_up_and_rolled_right() {
        // NED pitch +0.3 rad is nose up: the forward axis climbs in ENU.
        let q = ned_frd_to_enu_flu(&ned_frd_from_euler(0.0, 0.3, 0.0));
        let forward = q * Vector3::x();
        assert!((forward.z - 0.3f64.sin()).abs() < 1e-12, "{forward}");
        assert!((forward.y - 0.3f64.cos()).abs() < 1e-12, "{forward}");
        // NED roll +0.2 rad is right wing down: the body's left axis rises.
        let q = ned_frd_to_enu_flu(&ned_frd_from_euler(0.2, 0.0, 0.0));
        let left = q * Vector3::y();
        assert!((left.z - 0.2f64.sin()).abs() < 1e-12, "{left}");
    }

    #[test]
    fn orientations_round_trip() {
        for (r, p, y) in [(0.1, -0.2, 2.5), (-0.4, 0.3, -3.0), (0.0, 1.2, 0.7)] {
            let q_ned = ned_frd_from_euler(r, p, y);
            let back = enu_flu_to_ned_frd(&ned_frd_to_enu_flu(&q_ned));
            assert!(back.angle_to(&q_ned) < 1e-12);
            // A body vector expressed in either convention lands on the same world direction.
            let v_flu = Vector3::new(0.3, -1.0, 2.0);
            let world_enu = ned_frd_to_enu_flu(&q_ned) * v_flu;
            let world_ned = q_ned * flu_to_frd(&v_flu);
            assert!(close(&enu_to_ned(&world_enu), &world_ned));
        }
    }
}
