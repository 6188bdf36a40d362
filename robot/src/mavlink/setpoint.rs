//! A guarded [`Setpoint`] (ENU) as a MAVLink `SET_POSITION_TARGET_LOCAL_NED`.

use mavlink::dialects::common::{
    MavFrame, PositionTargetTypemask, SET_POSITION_TARGET_LOCAL_NED_DATA,
};
use nalgebra::Vector3;

use crate::frames::{enu_to_ned, yaw_enu_to_ned};
use crate::safety::Setpoint;

/// Where to send a setpoint.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Target {
    /// The autopilot's system id.
    pub system_id: u8,
    /// The autopilot's component id.
    pub component_id: u8,
}

/// The type mask for position + velocity + acceleration + yaw (yaw rate ignored).
#[must_use]
pub fn full_state_mask() -> PositionTargetTypemask {
    PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
}

/// The message for a setpoint, in `MAV_FRAME_LOCAL_NED`. A track or a hold at a known
/// position sets position, velocity, acceleration and yaw (a hold with zero velocity
/// and acceleration; a track without an acceleration, from a route's knots, marks it
/// ignored); a hold with no known position sets zero velocity and zero yaw rate only.
/// An unknown hold heading ignores yaw and sets zero yaw rate.
#[must_use]
pub fn position_target(
    setpoint: &Setpoint,
    target: Target,
    time_boot_ms: u32,
) -> SET_POSITION_TARGET_LOCAL_NED_DATA {
    let zero = Vector3::zeros();
    let (position, velocity, acceleration, yaw) = match *setpoint {
        Setpoint::Track(r) => (
            Some(r.position_m.coords),
            r.velocity_mps,
            r.acceleration_mps2,
            Some(r.yaw_rad),
        ),
        Setpoint::Hold {
            position_m,
            yaw_rad,
            ..
        } => (position_m.map(|p| p.coords), zero, Some(zero), yaw_rad),
    };
    let mut mask = PositionTargetTypemask::empty();
    if acceleration.is_none() {
        mask |= PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AX_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AY_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AZ_IGNORE;
    }
    if position.is_none() {
        mask |= PositionTargetTypemask::POSITION_TARGET_TYPEMASK_X_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_Y_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_Z_IGNORE;
    }
    if yaw.is_some() {
        mask |= PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE;
    } else {
        mask |= PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_IGNORE;
    }
    let p = enu_to_ned(&position.unwrap_or(zero));
    let v = enu_to_ned(&velocity);
    let a = enu_to_ned(&acceleration.unwrap_or(zero));
    SET_POSITION_TARGET_LOCAL_NED_DATA {
        time_boot_ms,
        x: p.x as f32,
        y: p.y as f32,
        z: p.z as f32,
        vx: v.x as f32,
        vy: v.y as f32,
        vz: v.z as f32,
        afx: a.x as f32,
        afy: a.y as f32,
        afz: a.z as f32,
        yaw: yaw.map_or(0.0, yaw_enu_to_ned) as f32,
        yaw_rate: 0.0,
        type_mask: mask,
        target_system: target.system_id,
        target_component: target.component_id,
        coordinate_frame: MavFrame::MAV_FRAME_LOCAL_NED,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::safety::{HoldReason, Reference};
    use nalgebra::Point3;
    use std::f64::consts::FRAC_PI_2;

    const TARGET: Target = Target {
        system_id: 1,
        component_id: 1,
    };

    #[test]
    fn track_converts_every_field_to_ned() {
        let sp = Setpoint::Track(Reference {
            position_m: Point3::new(3.0, 2.0, 1.5),
            velocity_mps: Vector3::new(1.0, -0.5, 0.2),
            acceleration_mps2: Some(Vector3::new(0.1, 0.2, -0.3)),
            yaw_rad: 0.0,
        });
        let m = position_target(&sp, TARGET, 1234);
        assert_eq!((m.x, m.y, m.z), (2.0, 3.0, -1.5));
        assert_eq!((m.vx, m.vy, m.vz), (-0.5, 1.0, -0.2));
        assert!(
            (m.afx - 0.2).abs() < 1e-6 && (m.afy - 0.1).abs() < 1e-6 && (m.afz - 0.3).abs() < 1e-6
        );
        // Facing east in ENU is yaw π/2 in NED.
        assert!((f64::from(m.yaw) - FRAC_PI_2).abs() < 1e-6);
        assert_eq!(m.type_mask.bits(), 0x800);
        assert_eq!(m.coordinate_frame, MavFrame::MAV_FRAME_LOCAL_NED);
        let knots = Setpoint::Track(Reference {
            acceleration_mps2: None,
            ..match sp {
                Setpoint::Track(r) => r,
                Setpoint::Hold { .. } => unreachable!("a track"),
            }
        });
        let without = position_target(&knots, TARGET, 0);
        // No acceleration to give: marked ignored (bits 6–8), not sent as zero.
        assert_eq!(without.type_mask.bits(), 0x800 | 0x40 | 0x80 | 0x100);
        assert_eq!(
            (m.target_system, m.target_component, m.time_boot_ms),
            (1, 1, 1234)
        );
    }

    #[test]
    fn holds_stop_the_vehicle() {
        let hold = Setpoint::Hold {
            position_m: Some(Point3::new(1.0, 2.0, 3.0)),
            yaw_rad: Some(FRAC_PI_2),
            reason: HoldReason::SensorTimeout,
        };
        let m = position_target(&hold, TARGET, 0);
        assert_eq!((m.x, m.y, m.z), (2.0, 1.0, -3.0));
        assert_eq!(
            (m.vx, m.vy, m.vz, m.afx, m.afy, m.afz),
            (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        );
        assert!(m.yaw.abs() < 1e-6, "facing north");
        assert_eq!(m.type_mask, full_state_mask());
        let blind = Setpoint::Hold {
            position_m: None,
            yaw_rad: None,
            reason: HoldReason::OdometryTimeout,
        };
        let m = position_target(&blind, TARGET, 0);
        // Position and yaw ignored; zero velocity, acceleration and yaw rate.
        assert_eq!(m.type_mask.bits(), 0x1 | 0x2 | 0x4 | 0x400);
        assert_eq!((m.vx, m.vy, m.vz, m.yaw_rate), (0.0, 0.0, 0.0, 0.0));
    }
}
