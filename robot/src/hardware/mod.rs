//! A hardware robot in one process (`troupe-robot --config robot.toml`): a depth
//! camera and odometry from ROS 2 ([`crate::ros2`]), a PX4 or ArduPilot flight
//! controller over MAVLink ([`crate::mavlink`]), the standard actors ([`crate::assemble`])
//! on the real-time executor, and the team link over zenoh exactly as a simulated
//! robot process has it, so hardware and simulated robots fly in one team.
//!
//! A robot file ([`HardwareFile`]) names this robot, its team and its drivers:
//!
//! ```toml
//! robot = 0                     # this robot's index in the team (its id on the link)
//! team_size = 3                 # robots in the team (ids 0..team_size)
//! out = "runs/hw0"              # relative to this file
//! [robot]                       # RobotConfig overrides (the standard robot)
//! [ros2]                        # Ros2Config: topics, format, its zenoh session
//! [mavlink]                     # MavlinkConfig: connection, timeouts, geofence
//! [zenoh]                       # the team link's zenoh session
//! ```
//!
//! `robot/examples/hardware_robot.toml` is a complete, commented file and
//! `docs/hardware.md` says how to fly one. [`HardwareRobot::load`] checks every table;
//! [`run`] then opens the ROS 2 session, waits for its topics, takes the camera's
//! calibration and opens the team link before the MAVLink vehicle starts, so a robot
//! that cannot start never sends a setpoint. Around the actors it is a process like
//! any other: [`crate::harness`] runs it (signals, duration, recording,
//! `summary.json`). Its sensor and vehicle drivers are the registry's `ros2` and
//! `mavlink` unless `[robot] sensor` / `vehicle` name others; [`run_with`] and
//! [`main_with`] take a registry with a user's parts ([`crate::registry`]).

mod command;
mod file;
mod run;

pub use command::main_with;
pub use file::{HardwareError, HardwareFile, HardwareRobot};
pub use run::{HardwareSummary, run, run_until_signal, run_with};
