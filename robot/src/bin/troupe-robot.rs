//! `troupe-robot`: one hardware robot — ROS 2 camera and odometry, a MAVLink flight
//! controller, the standard actors and the team link over zenoh (see
//! `docs/hardware.md` and [`troupe_robot::hardware`]).

fn main() -> std::process::ExitCode {
    troupe_robot::hardware::main_with(troupe_robot::registry::Registry::hardware())
}
