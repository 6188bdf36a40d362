//! Helpers shared by troupe's integration tests (`robot/tests`, `sims/tests`,
//! `tests/tests`): the workspace's Python venvs and the stand-ins they run for real
//! hardware (a ROS 2 depth camera, a PX4-like autopilot), loopback ports, child
//! processes and JSON reports. A dev-dependency only; troupe's crates never use it.

use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Output, Stdio};
use std::sync::atomic::{AtomicU16, Ordering};
use std::time::{Duration, Instant};

/// The modules the ROS 2 stand-ins import from `.venv-ros2`.
const ROS2_MODULES: &str = "rclpy.serialization, nav_msgs.msg, zenoh, numpy";

/// The workspace root.
#[must_use]
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .nth(2)
        .expect("tests/kit lies two folders below the workspace root")
        .to_path_buf()
}

/// The Python of the workspace's venv `venv` (e.g. `.venv-ros2`) if it imports
/// `modules` (e.g. `"rclpy.serialization, zenoh"`), or why not: `.ci/run` installs
/// them.
///
/// # Errors
///
/// Why the venv's Python cannot be used.
pub fn venv_python(venv: &str, modules: &str) -> Result<PathBuf, String> {
    python_importing(&root().join(venv).join("bin/python"), modules)
}

/// `python` if it imports `modules`, or why not.
fn python_importing(python: &Path, modules: &str) -> Result<PathBuf, String> {
    let ok = Command::new(python)
        .args(["-c", &format!("import {modules}")])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if ok {
        Ok(python.to_path_buf())
    } else {
        Err(format!(
            "{} cannot import {modules} (.ci/run installs it)",
            python.display()
        ))
    }
}

/// The venv's Python that imports `zenoh` (the hostile peer of the security tests,
/// `sims/tests/zenoh_hostile.py`), or why there is none.
///
/// # Errors
///
/// Why the venv's Python cannot be used.
pub fn zenoh_python() -> Result<PathBuf, String> {
    venv_python(".venv-ros2", "zenoh")
}

/// `.venv-ros2`'s Python if it imports what [`spawn_box_room_camera`] needs (rclpy's
/// serialisation, the message packages, zenoh, numpy), or why not.
///
/// # Errors
///
/// Why the venv's Python cannot be used.
pub fn ros2_python() -> Result<PathBuf, String> {
    venv_python(".venv-ros2", ROS2_MODULES)
}

/// The Python with pymavlink: `TROUPE_PYMAVLINK_PYTHON` if set, else
/// `.venv-pymavlink`'s; or why there is none.
///
/// # Errors
///
/// Why that Python cannot be used.
pub fn pymavlink_python() -> Result<PathBuf, String> {
    let python = std::env::var_os("TROUPE_PYMAVLINK_PYTHON")
        .map_or_else(|| root().join(".venv-pymavlink/bin/python"), PathBuf::from);
    python_importing(&python, "pymavlink")
}

/// The Pythons of the hardware stand-ins: `.venv-ros2`'s for
/// [`spawn_box_room_camera`] and the pymavlink one for [`spawn_autopilot`].
///
/// # Errors
///
/// Why either cannot be used, both reasons joined.
pub fn hardware_pythons() -> Result<(PathBuf, PathBuf), String> {
    match (ros2_python(), pymavlink_python()) {
        (Ok(ros), Ok(mavlink)) => Ok((ros, mavlink)),
        (ros, mavlink) => Err([ros.err(), mavlink.err()]
            .into_iter()
            .flatten()
            .collect::<Vec<_>>()
            .join("; ")),
    }
}

/// What a lookup such as [`hardware_pythons`] found, or `None` after saying on
/// stderr that `test` is skipped and why (`SKIPPED <test>: <why>`).
pub fn or_skip<T>(found: Result<T, String>, test: &str) -> Option<T> {
    match found {
        Ok(value) => Some(value),
        Err(why) => {
            eprintln!("SKIPPED {test}: {why}");
            None
        }
    }
}

/// `scripts/mavlink/px4_like_autopilot.py` on `python`: a point mass starting 1.2 m up
/// that flies the setpoints it gets on UDP `mavlink_port`, sends its state to UDP
/// `state_port` (the camera's pose), writes its report to `report` and stops after
/// `duration_s`. Its stderr is piped.
#[must_use]
pub fn spawn_autopilot(
    python: &Path,
    mavlink_port: u16,
    state_port: u16,
    report: &Path,
    duration_s: f64,
) -> Child {
    Command::new(python)
        .arg(root().join("scripts/mavlink/px4_like_autopilot.py"))
        .args(["--connection", &format!("udpout:127.0.0.1:{mavlink_port}")])
        .arg("--report")
        .arg(report)
        .args(["--duration-s", &duration_s.to_string()])
        .args(["--start-ned", "0,0,-1.2"])
        .args(["--state-to", &format!("127.0.0.1:{state_port}")])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start the autopilot")
}

/// `scripts/ros2/box_room_camera.py` on `python`: 640×480 depth of a box room at
/// 15 Hz, published over zenoh to the robot listening on TCP `ros_port`, from the
/// poses the autopilot sends to UDP `state_port`; with `team_port`, it also watches
/// the robot's team session there. Stops after `duration_s`; stdout (its report, the
/// last line) and stderr are piped.
#[must_use]
pub fn spawn_box_room_camera(
    python: &Path,
    ros_port: u16,
    state_port: u16,
    team_port: Option<u16>,
    duration_s: f64,
) -> Child {
    let mut camera = Command::new(python);
    camera
        .arg(root().join("scripts/ros2/box_room_camera.py"))
        .args(["--connect", &format!("tcp/127.0.0.1:{ros_port}")]);
    if let Some(team_port) = team_port {
        camera.args(["--team-connect", &format!("tcp/127.0.0.1:{team_port}")]);
    }
    camera
        .args(["--state-port", &state_port.to_string()])
        .args(["--duration-s", &duration_s.to_string()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start the camera")
}

/// Panics unless every setpoint in the report of [`spawn_autopilot`] lies inside the
/// geofence from `fence_min_m` to `fence_max_m` (ENU metres, 1 mm of slack); the
/// report's setpoints are NED (`x` north, `y` east, `z` down).
pub fn assert_setpoints_inside_fence(
    report: &serde_json::Value,
    fence_min_m: [f64; 3],
    fence_max_m: [f64; 3],
) {
    let setpoints = report["setpoints"].as_array().expect("setpoints");
    for s in setpoints {
        let f = |k: &str| s[k].as_f64().expect("a number");
        let enu = [f("y"), f("x"), -f("z")];
        for k in 0..3 {
            assert!(
                (fence_min_m[k] - 1e-3..=fence_max_m[k] + 1e-3).contains(&enu[k]),
                "setpoint {enu:?} outside the geofence"
            );
        }
    }
}

/// The `[ros2]` table of a robot file that takes its depth, camera info and odometry
/// from [`spawn_box_room_camera`]: rmw_zenoh keys on a zenoh session listening on TCP
/// `ros_port`, `startup_timeout_s` to wait for the topics, and `[ros2.topics]` naming
/// the camera's three topics. The text ends inside `[ros2.topics]`, so that a robot
/// that publishes (`plan = "/troupe/plan"`, …) appends its output topics.
#[must_use]
pub fn box_room_camera_ros2_table(ros_port: u16, startup_timeout_s: f64) -> String {
    format!(
        r#"[ros2]
format = "rmw_zenoh"
startup_timeout_s = {startup_timeout_s:?}
zenoh = {{ listen = ["tcp/127.0.0.1:{ros_port}"] }}
[ros2.topics]
depth = "/camera/depth/image_rect_raw"
camera_info = "/camera/depth/camera_info"
odometry = "/odom"
"#
    )
}

/// The `[mavlink]` tables of a robot file that flies [`spawn_autopilot`]: it listens
/// on UDP `mavlink_port` (where the autopilot sends), takes its odometry from ROS 2
/// (`external`) and keeps its setpoints inside the geofence from `fence_min_m` to
/// `fence_max_m`.
#[must_use]
pub fn autopilot_mavlink_tables(
    mavlink_port: u16,
    fence_min_m: [f64; 3],
    fence_max_m: [f64; 3],
) -> String {
    format!(
        r#"[mavlink]
connection = "udpin:127.0.0.1:{mavlink_port}"
odometry_source = "external"
[mavlink.geofence]
min_m = {fence_min_m:?}
max_m = {fence_max_m:?}
"#
    )
}

/// `n` consecutive free TCP ports on loopback in `[first, first + 9000)`, below the
/// kernel's ephemeral range (32768 and up by default): a port picked from that range
/// could be handed to one robot's outgoing connection before the robot meant to
/// listen on it has bound it. Test binaries that run at the same time use disjoint
/// ranges; within a binary each call starts 30 ports after the previous one, so that
/// tests running side by side do not pick the same ports before their robots bind
/// them.
///
/// # Panics
///
/// When no `n` consecutive ports in the range are free.
#[must_use]
pub fn free_ports_from(first: u16, n: usize) -> Vec<u16> {
    static CALLS: AtomicU16 = AtomicU16::new(0);
    let call = CALLS.fetch_add(1, Ordering::Relaxed) % 300;
    let start = first + ((std::process::id() % 3_000) as u16 * 3 + call * 30) % 9_000;
    (0..3_000u16)
        .map(|k| first + (start - first + k * 3) % 9_000)
        .find_map(|base| {
            let ports: Vec<u16> = (0..n as u16).map(|i| base + i).collect();
            let bound: Result<Vec<TcpListener>, _> = ports
                .iter()
                .map(|p| TcpListener::bind(("127.0.0.1", *p)))
                .collect();
            bound.ok().map(|_| ports)
        })
        .unwrap_or_else(|| {
            panic!(
                "no {n} free ports in [{first}, {})",
                u32::from(first) + 9_000
            )
        })
}

/// A loopback TCP port nobody listens on right now (from the kernel's ephemeral
/// range: for a process that binds it at once).
#[must_use]
pub fn free_tcp_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free loopback port")
        .port()
}

/// A loopback UDP port nobody uses right now.
#[must_use]
pub fn free_udp_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .expect("a free loopback port")
        .port()
}

/// An empty folder `name` under `parent` (a test's `CARGO_TARGET_TMPDIR`; a previous
/// run's files removed), kept after the test to look at.
#[must_use]
pub fn fresh_dir(parent: &str, name: &str) -> PathBuf {
    let dir = Path::new(parent).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("the test directory");
    dir
}

/// Runs `binary` (a test's `env!("CARGO_BIN_EXE_…")`) with `args` in `dir`, its
/// tracing off (`RUST_LOG=off`), and returns what it wrote.
///
/// # Panics
///
/// When the binary cannot be started.
#[must_use]
pub fn run_quiet(binary: &str, args: &[&str], dir: &Path) -> Output {
    Command::new(binary)
        .args(args)
        .current_dir(dir)
        .env("RUST_LOG", "off")
        .output()
        .unwrap_or_else(|e| panic!("run {binary}: {e}"))
}

/// Waits for `child` (stdout and stderr piped) and returns what it wrote; fails the
/// test with its stderr unless it exited with success.
///
/// # Panics
///
/// When `child` fails.
pub fn finish(child: Child, name: &str) -> Output {
    let output = child.wait_with_output().expect("wait");
    assert!(
        output.status.success(),
        "{name} failed: {}\n{}",
        output.status,
        String::from_utf8_lossy(&output.stderr)
    );
    output
}

/// The JSON file at `path` (a summary, a report); panics naming the file.
#[must_use]
pub fn read_json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// `text` without its terminal colour sequences (`ESC [ … m`).
#[must_use]
pub fn strip_ansi(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut chars = text.chars();
    while let Some(c) = chars.next() {
        if c == '\u{1b}' {
            for c in chars.by_ref() {
                if c == 'm' {
                    break;
                }
            }
        } else {
            out.push(c);
        }
    }
    out
}

/// Seconds since midnight of a tracing timestamp (`2026-11-26T07:50:01.123456Z`).
#[must_use]
pub fn seconds_of_day(stamp: &str) -> Option<f64> {
    let time = stamp.split('T').nth(1)?.trim_end_matches('Z');
    let mut parts = time.split(':');
    let h: f64 = parts.next()?.parse().ok()?;
    let m: f64 = parts.next()?.parse().ok()?;
    let s: f64 = parts.next()?.parse().ok()?;
    Some(3600.0 * h + 60.0 * m + s)
}

/// Waits until something listens on each loopback port; panics after `within`.
pub fn wait_listening(ports: &[u16], within: Duration) {
    let start = Instant::now();
    while !ports
        .iter()
        .all(|p| std::net::TcpStream::connect(("127.0.0.1", *p)).is_ok())
    {
        assert!(start.elapsed() < within, "nothing listens on {ports:?}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Waits for a process at most `within`; kills it and fails after that.
pub fn wait_exit(child: &mut Child, what: &str, within: Duration) -> ExitStatus {
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().expect("wait") {
            return status;
        }
        if start.elapsed() > within {
            let _ = child.kill();
            panic!("{what} did not stop within {within:?}");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}
