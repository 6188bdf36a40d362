//! The autopilot status topic and flight-mode names.

use mavlink::dialects::common::{HEARTBEAT_DATA, MavAutopilot, MavModeFlag, MavType};
use serde::Serialize;
use troupe_core::{Message, Time};
use troupe_runtime::Topic;

use super::link::LinkStats;
use crate::safety::{GuardCounters, HoldReason};

/// What the MAVLink vehicle knows about its autopilot and what its guard does.
#[derive(Clone, Debug, PartialEq)]
pub struct AutopilotStatus {
    /// When it was published.
    pub stamp: Time,
    /// The autopilot's (system id, component id), once known.
    pub autopilot: Option<(u8, u8)>,
    /// Whether the autopilot reports itself armed.
    pub armed: bool,
    /// Its flight mode (e.g. `"OFFBOARD"`, `"GUIDED"`), empty before a heartbeat.
    pub mode: String,
    /// Seconds since its last heartbeat, if one ever arrived.
    pub heartbeat_age_s: Option<f64>,
    /// Whether setpoints are withheld because the heartbeat is missing.
    pub heartbeat_lost: bool,
    /// Whether the pilot has handed control over: armed and in OFFBOARD (PX4) or GUIDED
    /// (ArduPilot) ([`in_control`]).
    pub in_control: bool,
    /// Why the vehicle holds instead of following the plan, if it does.
    pub hold: Option<HoldReason>,
    /// Setpoints sent in the last second, Hz.
    pub setpoint_rate_hz: f64,
    /// The vehicle gave up waiting for the autopilot ([`GaveUp`]): it sends nothing
    /// more and the robot process stops with this error.
    pub gave_up: Option<GaveUp>,
    /// What the guard did so far.
    pub guard: GuardCounters,
    /// The wire's counters.
    pub link: LinkStats,
}
impl Message for AutopilotStatus {}

/// The vehicle's state in a few fields: what `/diagnostics` (ROS 2) and the
/// recording's `/robot<i>/vehicle` channel (`troupe.VehicleStatus`) carry.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct VehicleState {
    /// Whether the autopilot reports itself armed.
    pub armed: bool,
    /// Its flight mode, empty before a heartbeat.
    pub mode: String,
    /// Whether the pilot has handed control over.
    pub in_control: bool,
    /// Why the vehicle holds instead of following the plan (`""`: it follows it).
    pub hold: String,
    /// Setpoints sent in the last second, Hz.
    pub setpoint_rate_hz: f64,
    /// Seconds since the last heartbeat (`None`: none ever).
    pub heartbeat_age_s: Option<f64>,
    /// Whether setpoints are withheld because the heartbeat is missing.
    pub heartbeat_lost: bool,
    /// Setpoints sent so far.
    pub setpoints: u64,
    /// Of those, holds.
    pub holds: u64,
}

impl AutopilotStatus {
    /// The state in a few fields.
    #[must_use]
    pub fn state(&self) -> VehicleState {
        VehicleState {
            armed: self.armed,
            mode: self.mode.clone(),
            in_control: self.in_control,
            hold: self.hold.map_or("", HoldReason::as_str).to_owned(),
            setpoint_rate_hz: self.setpoint_rate_hz,
            heartbeat_age_s: self.heartbeat_age_s,
            heartbeat_lost: self.heartbeat_lost,
            setpoints: self.guard.tracked + self.guard.held,
            holds: self.guard.held,
        }
    }

    /// How a monitor should take it (diagnostic level): `OK` (0) while it follows plans,
    /// `WARN` (1) while it holds, `ERROR` (2) without a heartbeat or after giving up;
    /// and the reason in words.
    #[must_use]
    pub fn level(&self) -> (u8, String) {
        if let Some(why) = &self.gave_up {
            (2, why.to_string())
        } else if self.heartbeat_lost || self.heartbeat_age_s.is_none() {
            (2, "no autopilot heartbeat: sending nothing".to_owned())
        } else if let Some(hold) = self.hold {
            (1, format!("holding: {}", hold.as_str()))
        } else {
            (0, "following plans".to_owned())
        }
    }
}

/// Why the MAVLink vehicle gave up waiting (`[mavlink] autopilot_wait_s`,
/// `control_wait_s`).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum GaveUp {
    /// No autopilot heartbeat on the connection.
    #[error(
        "no autopilot heartbeat on `{connection}` within {wait_s} s of the start \
         ([mavlink] autopilot_wait_s): is the flight controller on this connection, with \
         MAVLink 2 on that port? No setpoint was sent"
    )]
    NoAutopilot {
        /// The connection string.
        connection: String,
        /// The wait, seconds.
        wait_s: f64,
    },
    /// The autopilot was heard but never armed and in offboard.
    #[error(
        "the autopilot was not armed and in OFFBOARD or GUIDED within {wait_s} s of the \
         start ([mavlink] control_wait_s; last seen {}, mode {mode}): the robot held and \
         planned nothing",
        if *armed { "armed" } else { "disarmed" }
    )]
    NoControl {
        /// The wait, seconds.
        wait_s: f64,
        /// Whether it was armed.
        armed: bool,
        /// Its last mode.
        mode: String,
    },
}

/// The MAVLink vehicle's status (published at 2 Hz and on every change).
pub const AUTOPILOT_STATUS: Topic<AutopilotStatus> = Topic::new("vehicle/autopilot");

/// Whether a heartbeat says the vehicle is armed.
#[must_use]
pub fn is_armed(heartbeat: &HEARTBEAT_DATA) -> bool {
    heartbeat
        .base_mode
        .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED)
}

/// Whether the pilot has handed the vehicle to the companion computer: armed, and in
/// PX4's OFFBOARD or ArduPilot's GUIDED (or, for an autopilot whose modes troupe does
/// not name, with the heartbeat's guided flag set).
#[must_use]
pub fn in_control(heartbeat: &HEARTBEAT_DATA) -> bool {
    let guided = match flight_mode(heartbeat).as_str() {
        "OFFBOARD" | "GUIDED" | "GUIDED_NOGPS" => true,
        mode if mode.starts_with("custom mode") => heartbeat
            .base_mode
            .contains(MavModeFlag::MAV_MODE_FLAG_GUIDED_ENABLED),
        _ => false,
    };
    is_armed(heartbeat) && guided
}

/// The flight mode a heartbeat reports, by name for PX4 and ArduPilot multicopters,
/// else as the raw custom mode.
#[must_use]
pub fn flight_mode(heartbeat: &HEARTBEAT_DATA) -> String {
    let custom = heartbeat.custom_mode;
    let name = match heartbeat.autopilot {
        MavAutopilot::MAV_AUTOPILOT_PX4 => px4_mode(custom),
        MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA if is_copter(heartbeat.mavtype) => {
            arducopter_mode(custom)
        }
        _ => None,
    };
    name.map_or_else(|| format!("custom mode {custom}"), str::to_owned)
}

/// PX4 packs its main mode in bits 16–23 and its sub-mode in bits 24–31.
fn px4_mode(custom: u32) -> Option<&'static str> {
    let main = (custom >> 16) & 0xff;
    let sub = (custom >> 24) & 0xff;
    Some(match (main, sub) {
        (1, _) => "MANUAL",
        (2, _) => "ALTCTL",
        (3, _) => "POSCTL",
        (4, 2) => "AUTO.TAKEOFF",
        (4, 3) => "AUTO.LOITER",
        (4, 4) => "AUTO.MISSION",
        (4, 5) => "AUTO.RTL",
        (4, 6) => "AUTO.LAND",
        (4, _) => "AUTO",
        (5, _) => "ACRO",
        (6, _) => "OFFBOARD",
        (7, _) => "STABILIZED",
        _ => return None,
    })
}

fn is_copter(t: MavType) -> bool {
    matches!(
        t,
        MavType::MAV_TYPE_QUADROTOR
            | MavType::MAV_TYPE_HEXAROTOR
            | MavType::MAV_TYPE_OCTOROTOR
            | MavType::MAV_TYPE_TRICOPTER
            | MavType::MAV_TYPE_COAXIAL
            | MavType::MAV_TYPE_HELICOPTER
    )
}

fn arducopter_mode(custom: u32) -> Option<&'static str> {
    Some(match custom {
        0 => "STABILIZE",
        1 => "ACRO",
        2 => "ALT_HOLD",
        3 => "AUTO",
        4 => "GUIDED",
        5 => "LOITER",
        6 => "RTL",
        9 => "LAND",
        16 => "POSHOLD",
        17 => "BRAKE",
        20 => "GUIDED_NOGPS",
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::dialects::common::MavState;

    fn heartbeat(autopilot: MavAutopilot, custom_mode: u32, armed: bool) -> HEARTBEAT_DATA {
        HEARTBEAT_DATA {
            custom_mode,
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot,
            base_mode: if armed {
                MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED
                    | MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            } else {
                MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            },
            system_status: MavState::MAV_STATE_ACTIVE,
            mavlink_version: 3,
        }
    }

    #[test]
    fn names_modes_and_armed_state() {
        let px4 = heartbeat(MavAutopilot::MAV_AUTOPILOT_PX4, 6 << 16, true);
        assert_eq!(flight_mode(&px4), "OFFBOARD");
        assert!(is_armed(&px4));
        let px4 = heartbeat(
            MavAutopilot::MAV_AUTOPILOT_PX4,
            (4 << 16) | (3 << 24),
            false,
        );
        assert_eq!(flight_mode(&px4), "AUTO.LOITER");
        assert!(!is_armed(&px4));
        let ardu = heartbeat(MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA, 4, true);
        assert_eq!(flight_mode(&ardu), "GUIDED");
        let other = heartbeat(MavAutopilot::MAV_AUTOPILOT_GENERIC, 77, false);
        assert_eq!(flight_mode(&other), "custom mode 77");
    }

    #[test]
    fn control_is_armed_and_offboard_or_guided() {
        let px4 = |mode: u32, armed| heartbeat(MavAutopilot::MAV_AUTOPILOT_PX4, mode << 16, armed);
        assert!(in_control(&px4(6, true)));
        assert!(!in_control(&px4(6, false)), "disarmed");
        assert!(!in_control(&px4(3, true)), "POSCTL: the pilot flies");
        let ardu = |mode, armed| heartbeat(MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA, mode, armed);
        assert!(in_control(&ardu(4, true)));
        assert!(!in_control(&ardu(5, true)), "LOITER");
        let mut other = heartbeat(MavAutopilot::MAV_AUTOPILOT_GENERIC, 77, true);
        assert!(!in_control(&other));
        other.base_mode |= MavModeFlag::MAV_MODE_FLAG_GUIDED_ENABLED;
        assert!(in_control(&other));
    }
}
