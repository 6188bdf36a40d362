//! The autopilot status topic and flight-mode names.

use mavlink::dialects::common::{HEARTBEAT_DATA, MavAutopilot, MavModeFlag, MavType};
use troupe_actors::runtime::{Message, Time, Topic};

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
    /// Why the vehicle holds instead of following the plan, if it does.
    pub hold: Option<HoldReason>,
    /// What the guard did so far.
    pub guard: GuardCounters,
    /// The wire's counters.
    pub link: LinkStats,
}
impl Message for AutopilotStatus {}

/// The MAVLink vehicle's status (published at 2 Hz and on every change).
pub const AUTOPILOT_STATUS: Topic<AutopilotStatus> = Topic::new("vehicle/autopilot");

/// Whether a heartbeat says the vehicle is armed.
#[must_use]
pub fn is_armed(heartbeat: &HEARTBEAT_DATA) -> bool {
    heartbeat
        .base_mode
        .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED)
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
}
