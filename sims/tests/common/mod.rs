//! Helpers shared by the integration tests that start robot processes.

use std::net::TcpListener;

/// `n` consecutive free TCP ports on loopback in `[first, first + 9000)`, below the
/// kernel's ephemeral range (32768 and up by default): a port picked from that range
/// could be handed to one robot's outgoing connection before the robot meant to
/// listen on it has bound it. Test binaries that run at the same time use disjoint
/// ranges; within a binary each call starts 30 ports after the previous one, so that
/// tests running side by side do not pick the same ports before their robots bind
/// them.
pub fn free_ports_from(first: u16, n: usize) -> Vec<u16> {
    static CALLS: std::sync::atomic::AtomicU16 = std::sync::atomic::AtomicU16::new(0);
    let call = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed) % 300;
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

/// The workspace root.
#[allow(dead_code)] // not every test binary that shares this module uses it
pub fn root() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("workspace")
        .to_path_buf()
}

/// The venv's Python that imports `zenoh` (the hostile peer of the security tests,
/// `sims/tests/zenoh_hostile.py`), or why there is none.
#[allow(dead_code)] // not every test binary that shares this module uses it
pub fn zenoh_python() -> Result<std::path::PathBuf, String> {
    venv_python(".venv-ros2", "zenoh")
}

/// The Python of the workspace's venv `venv` (e.g. `.venv-ros2`) if it imports
/// `modules` (e.g. `"rclpy.serialization, zenoh"`), or why not: `.ci/run` installs
/// them.
#[allow(dead_code)] // not every test binary that shares this module uses it
pub fn venv_python(venv: &str, modules: &str) -> Result<std::path::PathBuf, String> {
    let python = root().join(venv).join("bin/python");
    let ok = std::process::Command::new(&python)
        .args(["-c", &format!("import {modules}")])
        .output()
        .is_ok_and(|o| o.status.success());
    if ok {
        Ok(python)
    } else {
        Err(format!(
            "{} cannot import {modules} (.ci/run installs it)",
            python.display()
        ))
    }
}

/// The JSON file at `path` (a summary, a report); panics naming the file.
#[allow(dead_code)] // not every test binary that shares this module uses it
pub fn read_json(path: &std::path::Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// `text` without its terminal colour sequences (`ESC [ … m`).
#[allow(dead_code)] // not every test binary that shares this module uses it
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
#[allow(dead_code)] // not every test binary that shares this module uses it
pub fn seconds_of_day(stamp: &str) -> Option<f64> {
    let time = stamp.split('T').nth(1)?.trim_end_matches('Z');
    let mut parts = time.split(':');
    let h: f64 = parts.next()?.parse().ok()?;
    let m: f64 = parts.next()?.parse().ok()?;
    let s: f64 = parts.next()?.parse().ok()?;
    Some(3600.0 * h + 60.0 * m + s)
}

/// Waits until something listens on each loopback port; panics after `within`.
#[allow(dead_code)] // not every test binary that shares this module uses it
pub fn wait_listening(ports: &[u16], within: std::time::Duration) {
    let start = std::time::Instant::now();
    while !ports
        .iter()
        .all(|p| std::net::TcpStream::connect(("127.0.0.1", *p)).is_ok())
    {
        assert!(start.elapsed() < within, "nothing listens on {ports:?}");
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
}

/// Waits for a process at most `within`; kills it and fails after that.
#[allow(dead_code)] // not every test binary that shares this module uses it
pub fn wait_exit(
    child: &mut std::process::Child,
    what: &str,
    within: std::time::Duration,
) -> std::process::ExitStatus {
    let start = std::time::Instant::now();
    loop {
        if let Some(status) = child.try_wait().expect("wait") {
            return status;
        }
        if start.elapsed() > within {
            let _ = child.kill();
            panic!("{what} did not stop within {within:?}");
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
}
