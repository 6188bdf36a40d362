//! The base station (issue 17): two `troupe robot` processes and a `troupe base`
//! process on loopback over zenoh; the base collects both robots' keyframes, prints
//! its status lines every second and, stopped by SIGTERM, writes the merged map and
//! the per-robot maps.

use crate::common;

use std::io::{BufRead, BufReader, Read};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use common::wait_exit;
use troupe_algorithms::mapfile::GmmMap;
use troupe_robot::launch::loopback_endpoints;
use troupe_sims::process::write_team;

fn troupe() -> Command {
    Command::new(env!("CARGO_BIN_EXE_troupe"))
}

/// `n` consecutive free TCP ports on loopback, in this binary's range.
fn free_ports(n: usize) -> Vec<u16> {
    common::free_ports_from(20_000, n)
}

/// The vertex count of a binary PLY file, after checking its header and that the
/// body holds exactly that many vertices of the declared properties.
fn ply_vertices(path: &Path) -> usize {
    let bytes = std::fs::read(path).expect("ply");
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .expect("end_header")
        + 11;
    let header = std::str::from_utf8(&bytes[..end]).expect("ascii header");
    let mut lines = header.lines();
    assert_eq!(lines.next(), Some("ply"));
    assert_eq!(lines.next(), Some("format binary_little_endian 1.0"));
    let mut vertices = None;
    let mut stride = 0;
    for line in lines {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["element", "vertex", n] => vertices = Some(n.parse::<usize>().expect("count")),
            ["property", "float", _] => stride += 4,
            ["property", "uchar", _] => stride += 1,
            ["property", ..] => panic!("unexpected property `{line}`"),
            _ => {}
        }
    }
    let vertices = vertices.expect("element vertex");
    assert_eq!(bytes.len() - end, vertices * stride, "{}", path.display());
    vertices
}

/// Sends `messages` frames of garbage (each a whole message that does not decode) as
/// robot 5 of team 0 to `endpoint` through the real zenoh transport; returns how
/// many messages went out.
fn send_garbage(endpoint: &str, messages: u64) -> u64 {
    use troupe_comms::shaping::{LinkShaper, ShaperConfig};
    use troupe_comms::transport::PacketTransport as _;
    use troupe_comms::wire::Class;
    use troupe_comms::zenoh::{ZenohConfig, ZenohTransport};

    let config = ZenohConfig {
        connect: vec![endpoint.to_owned()],
        ..ZenohConfig::default()
    };
    let transport = ZenohTransport::open(&config, 0, vec![5]).expect("zenoh");
    std::thread::sleep(Duration::from_millis(500));
    let mut shaper = LinkShaper::new(ShaperConfig::default()).expect("shaper");
    let mut now_ns = 0;
    let mut sent = 0;
    for i in 0..messages {
        let garbage: Vec<u8> = (0..200u64).map(|b| (b * 31 + i * 7) as u8).collect();
        if shaper.offer(now_ns, Class::Odometry, garbage).is_ok() {
            sent += 1;
        }
        now_ns += 50_000_000;
        while let Some(frame) = shaper.poll(now_ns) {
            transport.send(5, frame.to, &frame.bytes).expect("send");
        }
    }
    std::thread::sleep(Duration::from_millis(500));
    transport.close().expect("close");
    sent
}

#[test]
fn base_help_names_its_flags() {
    let out = troupe().args(["base", "--help"]).output().expect("run");
    assert!(out.status.success());
    let help = String::from_utf8(out.stdout).expect("utf8");
    assert!(help.contains("--config"), "{help}");
    assert!(help.contains("--duration-s"), "{help}");
    let out = troupe().arg("base").output().expect("run");
    assert!(!out.status.success(), "--config is required");
}

#[test]
fn a_bad_base_file_is_refused_with_the_key() {
    let dir = tempfile::tempdir().expect("tempdir");
    std::fs::write(dir.path().join("team.toml"), "name = \"t\"\nrobots = 2\n").expect("scenario");
    for (text, key) in [
        ("scenario = \"team.toml\"\nbase_id = 1\n", "base_id"),
        (
            "scenario = \"team.toml\"\nduration_s = -1.0\n",
            "duration_s",
        ),
        (
            "scenario = \"team.toml\"\nply_points = \"many\"\n",
            "ply_points",
        ),
        ("scenario = \"team.toml\"\nbogus = 1\n", "bogus"),
    ] {
        let file = dir.path().join("base.toml");
        std::fs::write(&file, text).expect("base file");
        let out = troupe()
            .args(["base", "--config"])
            .arg(&file)
            .output()
            .expect("run");
        assert!(!out.status.success(), "{text}");
        let error = String::from_utf8_lossy(&out.stderr);
        assert!(error.contains(key), "{text}: {error}");
        assert!(!error.contains("panicked"), "{error}");
    }
}

#[test]
fn the_base_collects_both_robots_maps_and_writes_them_on_sigterm() {
    let dir = tempfile::tempdir().expect("tempdir");
    let duration_s = 16.0;
    std::fs::write(
        dir.path().join("team.toml"),
        "name = \"base\"\nrobots = 2\n",
    )
    .expect("scenario");
    let endpoints = loopback_endpoints(&free_ports(3));
    let files = write_team(
        dir.path(),
        Path::new("team.toml"),
        &endpoints[..2],
        Some(duration_s),
    )
    .expect("robot files");
    std::fs::write(
        dir.path().join("base.toml"),
        format!(
            "scenario = \"team.toml\"\nout = \"station\"\nply_points = 20000\n\n[zenoh]\nlisten = [\"{}\"]\nconnect = [\"{}\", \"{}\"]\n",
            endpoints[2], endpoints[0], endpoints[1]
        ),
    )
    .expect("base file");
    let mut base = troupe()
        .args(["base", "--config"])
        .arg(dir.path().join("base.toml"))
        .stdout(Stdio::piped())
        .spawn()
        .expect("spawn troupe base");
    let mut robots: Vec<Child> = files
        .iter()
        .map(|f| {
            troupe()
                .args(["robot", "--config"])
                .arg(f)
                .stdout(Stdio::null())
                .spawn()
                .expect("spawn troupe robot")
        })
        .collect();
    // Read the base's status lines as they come.
    let stdout = base.stdout.take().expect("stdout");
    let reader = std::thread::spawn(move || {
        let mut lines = Vec::new();
        let mut stdout = BufReader::new(stdout);
        let mut line = String::new();
        while stdout.read_line(&mut line).unwrap_or(0) > 0 {
            lines.push(std::mem::take(&mut line));
        }
        let mut rest = String::new();
        let _ = stdout.read_to_string(&mut rest);
        lines
    });
    for robot in &mut robots {
        let status = wait_exit(robot, "robot", Duration::from_secs_f64(duration_s + 60.0));
        assert!(status.success(), "troupe robot exited with {status}");
    }
    // A hostile participant of the session (robot 5, which does not exist) sends
    // well-framed messages of garbage: the base's link rejects and counts them.
    let hostile = send_garbage(&endpoints[2], 40);
    std::thread::sleep(Duration::from_secs(2));
    // The base runs until told to stop.
    let pid = base.id().to_string();
    assert!(
        Command::new("kill")
            .args(["-TERM", &pid])
            .status()
            .expect("kill")
            .success()
    );
    let status = wait_exit(&mut base, "base", Duration::from_secs(60));
    assert!(status.success(), "troupe base exited with {status}");
    let lines = reader.join().expect("reader");
    let status_lines = |robot: u32| {
        lines
            .iter()
            .filter(|l| l.starts_with(&format!("robot{robot} keyframes=")))
            .count()
    };
    for robot in 0..2 {
        // One line a second for ~16 s; allow for a slow start.
        assert!(status_lines(robot) >= 8, "robot{robot}: {lines:?}");
    }
    assert!(
        lines.iter().any(|l| l.starts_with("robot0 ")
            && !l.contains("keyframes=0 ")
            && l.contains("odometry_age_s=0.")),
        "{lines:?}"
    );

    let out = dir.path().join("station");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).expect("summary"))
            .expect("json");
    assert_eq!(summary["base_id"].as_u64(), Some(2), "{summary}");
    let rejected = summary["rejected"].as_u64().expect("rejected");
    assert!(
        (1..=hostile).contains(&rejected),
        "{rejected} of {hostile}: {summary}"
    );
    assert_eq!(summary["robots"]["5"]["keyframes"].as_u64(), Some(0));
    let mut total = 0;
    for robot in 0..2 {
        let map = GmmMap::load(&out.join(format!("maps/robot{robot}.troupe"))).expect("map");
        assert!(map.keyframes.len() >= 2, "robot{robot}: {summary}");
        let r = &summary["robots"][robot.to_string()];
        assert_eq!(r["keyframes"].as_u64(), Some(map.keyframes.len() as u64));
        assert!(r["odometry"].as_u64() > Some(50), "robot{robot}: {summary}");
        assert!(r["plans"].as_u64() >= Some(2), "robot{robot}: {summary}");
        let points = ply_vertices(&out.join(format!("maps/robot{robot}.ply")));
        assert!(points > 0);
        assert_eq!(r["ply_points"].as_u64(), Some(points as u64));
        total += map.keyframes.len();
    }
    let merged = GmmMap::load(&out.join("merged_map.troupe")).expect("merged map");
    assert_eq!(merged.keyframes.len(), total);
    merged.merged_occupied().expect("Eq. 3.5 merge");
    let points = ply_vertices(&out.join("merged_map.ply"));
    assert!((19_990..=20_010).contains(&points), "{points}");
}

#[test]
fn the_example_base_file_loads() {
    let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("robots/base.toml");
    let station = troupe_robot::base::BaseStation::load(&file, troupe_sims::scenario::load_team)
        .expect("sims/robots/base.toml");
    assert_eq!(station.base_id, station.team.robots);
    assert_eq!(
        station.config.zenoh.connect.len(),
        station.team.robots as usize
    );
}
