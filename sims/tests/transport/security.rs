//! Issue 23, the transport side: identity bound by zenoh's access control with the
//! secure forms of `docs/security.md` as written, and secure defaults. The hostile
//! peer is a real zenoh client (`eclipse-zenoh` from PyPI, `.venv-ros2`,
//! `sims/tests/zenoh_hostile.py`); without it the tests that need it skip (saying
//! why). The same against `troupe robot` processes, memory under a flood and a
//! 200 MB message, and `kill -9`: `../security_processes.rs`.

use crate::{common, wait_for};

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use common::{root, zenoh_python as python};

use troupe_comms::shaping::{LinkShaper, ShaperConfig};
use troupe_comms::transport::{PacketSink, PacketTransport, ReceivedPacket};
use troupe_comms::wire::Class;
use troupe_comms::zenoh::{ZenohConfig, ZenohTransport};

const TEAM: u32 = 5;

/// `n` consecutive free loopback ports; the tests of this binary run in parallel
/// in one process, so each call starts its search elsewhere.
fn free_ports(n: usize) -> Vec<u16> {
    static NEXT: std::sync::atomic::AtomicU16 = std::sync::atomic::AtomicU16::new(0);
    let offset = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed) * 1_000;
    common::free_ports_from(1_100 + offset, n)
}

fn troupe(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_troupe"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run troupe")
}

/// One odometry frame from robot `from` whose body is `fill` bytes.
fn odometry_frame(fill: u8) -> Vec<u8> {
    let mut shaper = LinkShaper::new(ShaperConfig::default()).expect("shaper");
    shaper
        .offer(0, Class::Odometry, vec![fill; 40])
        .expect("offer");
    shaper.poll(0).expect("a frame").bytes
}

type Seen = Arc<Mutex<Vec<(u32, Vec<u8>)>>>;

fn recording_sink(seen: &Seen) -> PacketSink {
    let seen = seen.clone();
    Arc::new(move |p: ReceivedPacket<'_>| {
        seen.lock().expect("lock").push((p.from, p.bytes.to_vec()));
    })
}

/// A `[zenoh]` table (as a robot file writes it) read and resolved against `dir`.
fn zenoh_table(text: &str, dir: &Path) -> ZenohConfig {
    #[derive(serde::Deserialize)]
    struct File {
        zenoh: ZenohConfig,
    }
    let mut file: File = toml::from_str(text).expect("a [zenoh] table");
    file.zenoh.resolve_paths(dir);
    file.zenoh
}

/// A hostile client's credentials and the keys it puts on.
struct Hostile {
    name: &'static str,
    credentials: Vec<String>,
    keys: Vec<String>,
}

fn spawn_hostile(python: &Path, endpoint: &str, payload: &Path, h: &Hostile) -> Child {
    let mut c = Command::new(python);
    c.arg(root().join("sims/tests/zenoh_hostile.py"))
        .arg(endpoint)
        .args(&h.credentials)
        .arg("--payload-file")
        .arg(payload)
        .args(["--count", "40"]);
    for key in &h.keys {
        c.args(["--put", key]);
    }
    c.stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn python")
}

/// The ```` ```toml ```` block of `docs/security.md` (where the README sends its
/// readers for the secure forms) that contains `marker`.
fn documented_form(marker: &str) -> String {
    let doc = std::fs::read_to_string(root().join("docs/security.md")).expect("docs/security.md");
    doc.split("```toml\n")
        .skip(1)
        .filter_map(|block| block.split("```").next())
        .find(|block| block.contains(marker))
        .unwrap_or_else(|| panic!("no toml block with `{marker}` in docs/security.md"))
        .to_owned()
}

/// `text` with its line that starts with `prefix` replaced by `line`.
fn replace_line(text: &str, prefix: &str, line: &str) -> String {
    assert!(
        text.lines().any(|l| l.starts_with(prefix)),
        "no `{prefix}` in {text}"
    );
    text.lines()
        .map(|l| if l.starts_with(prefix) { line } else { l })
        .collect::<Vec<_>>()
        .join("\n")
}

/// The first `listen` endpoint of a `[zenoh]` table's text.
fn listen_endpoint(table: &str) -> String {
    table
        .lines()
        .find_map(|l| l.strip_prefix("listen = [\""))
        .and_then(|l| l.split('"').next())
        .expect("a listen endpoint")
        .to_owned()
}

/// Two robots with the `[zenoh]` tables `tables(i, ports)` (and, given one, a
/// router with the table `tables(2, ports)`) exchange frames; then hostile clients
/// connect to robot 0 (or the router) and put a marked frame under the keys they
/// name. Only the control (robot 2's credentials, its own key) may be delivered;
/// nothing else, under any id.
fn attack_two_robots(
    python: &Path,
    dir: &Path,
    tables: impl Fn(usize, &[u16]) -> String,
    hostiles: &[Hostile],
    router: bool,
) {
    let ports = free_ports(3);
    let router = router.then(|| {
        let table = tables(2, &ports);
        let router = troupe_robot::router::Router::open(&zenoh_table(&table, dir)).expect("router");
        (router, listen_endpoint(&table))
    });
    let robots: Vec<ZenohTransport> = (0..2)
        .map(|i| {
            let config = zenoh_table(&tables(i, &ports), dir);
            config.validate().expect("the form is valid");
            ZenohTransport::open(&config, TEAM, vec![i as u32]).expect("open")
        })
        .collect();
    let seen: Seen = Arc::default();
    robots[0].start(recording_sink(&seen)).expect("start");
    robots[1].start(Arc::new(|_| {})).expect("start");
    // The form works: robot 1's frames reach robot 0.
    let genuine = odometry_frame(0xAA);
    wait_for(
        "robot 1's frames at robot 0",
        Duration::from_secs(15),
        Duration::from_millis(20),
        || {
            robots[1].send(1, None, &genuine).expect("send");
            std::thread::sleep(Duration::from_millis(50));
            seen.lock()
                .expect("lock")
                .iter()
                .any(|(from, _)| *from == 1)
        },
    );
    let marked = odometry_frame(0xEE);
    let payload = dir.join("marked.frame");
    std::fs::write(&payload, &marked).expect("payload");
    let endpoint = match &router {
        Some((_, endpoint)) => endpoint.clone(),
        None => listen_endpoint(&tables(0, &ports)),
    };
    let children: Vec<Child> = hostiles
        .iter()
        .map(|h| spawn_hostile(python, &endpoint, &payload, h))
        .collect();
    let mut reports = Vec::new();
    for (h, child) in hostiles.iter().zip(children) {
        let out = common::finish(child, h.name);
        reports.push(format!(
            "{}: {}",
            h.name,
            String::from_utf8_lossy(&out.stdout).trim()
        ));
    }
    std::thread::sleep(Duration::from_millis(300));
    let seen = seen.lock().expect("lock");
    let marked_from: Vec<u32> = seen
        .iter()
        .filter(|(_, b)| *b == marked)
        .map(|(from, _)| *from)
        .collect();
    assert!(
        marked_from.contains(&2),
        "the control (robot 2 under its own id) must arrive, else the attack proves \
         nothing: {reports:?}"
    );
    assert!(
        marked_from.iter().all(|from| *from == 2),
        "a hostile frame arrived under another id ({marked_from:?}): {reports:?}"
    );
    // zenoh dropped them: troupe never saw a frame it had to reject.
    let stats = robots[0].stats();
    assert_eq!(
        (
            stats.rejected_sender,
            stats.rejected_key,
            stats.rejected_class
        ),
        (0, 0, 0),
        "{stats:?}"
    );
    for robot in &robots {
        robot.close().expect("close");
    }
    if let Some((router, _)) = router {
        router.close().expect("close the router");
    }
}

fn key(id: u32) -> String {
    format!("troupe/{TEAM}/{id}/odometry")
}

/// Robot 2's credentials claiming robots 1, 0 and a stranger 9, and under its own
/// id (the control).
fn impersonation(credentials: &[String]) -> [Hostile; 2] {
    [
        Hostile {
            name: "robot 2 claiming 1, 0 and 9",
            credentials: credentials.to_vec(),
            keys: vec![key(1), key(0), key(9)],
        },
        Hostile {
            name: "control: robot 2 as itself",
            credentials: credentials.to_vec(),
            keys: vec![key(2)],
        },
    ]
}

fn strings(s: &[&str]) -> Vec<String> {
    s.iter().map(|s| (*s).to_owned()).collect()
}

#[test]
fn under_mutual_tls_a_robot_publishes_only_as_itself() {
    let python = match python() {
        Ok(p) => p,
        Err(why) => return eprintln!("skipped: {why}"),
    };
    let dir = tempfile::tempdir().expect("tempdir");
    for out in ["keys", "rogue"] {
        let o = troupe(&["keys", "--team-size", "3", "--out", out], dir.path());
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let k = |d: &str, f: &str| dir.path().join(d).join(f).display().to_string();
    // The TLS robot file of docs/security.md as written, but for its addresses
    // (robot 1 connects to robot 0) and the robot's own files; paths relative to the
    // robot file (here `dir`).
    let form = documented_form("cert_path");
    let tables = |i: usize, ports: &[u16]| {
        let connect = if i == 1 {
            format!("connect = [\"tls/127.0.0.1:{}\"]", ports[0])
        } else {
            "connect = []".to_owned()
        };
        let table = replace_line(&form, "connect = ", &connect)
            .replace("tls/0.0.0.0:7447", &format!("tls/127.0.0.1:{}", ports[i]))
            .replace("keys/robot0.", &format!("keys/robot{i}."));
        assert!(table.contains(&format!("keys/robot{i}.key")), "{table}");
        table
    };
    let robot2 = vec![
        "--ca".into(),
        k("keys", "ca.pem"),
        "--cert".into(),
        k("keys", "robot2.pem"),
        "--key".into(),
        k("keys", "robot2.key"),
    ];
    let [claims, control] = impersonation(&robot2);
    let hostiles = [
        Hostile {
            name: "no certificate",
            credentials: vec!["--ca".into(), k("keys", "ca.pem")],
            keys: vec![key(1), key(2)],
        },
        Hostile {
            name: "another CA's robot 2",
            credentials: vec![
                "--ca".into(),
                k("rogue", "ca.pem"),
                "--cert".into(),
                k("rogue", "robot2.pem"),
                "--key".into(),
                k("rogue", "robot2.key"),
            ],
            keys: vec![key(1), key(2)],
        },
        Hostile {
            name: "another CA's robot 2 trusting ours",
            credentials: vec![
                "--ca".into(),
                k("keys", "ca.pem"),
                "--cert".into(),
                k("rogue", "robot2.pem"),
                "--key".into(),
                k("rogue", "robot2.key"),
            ],
            keys: vec![key(1), key(2)],
        },
        claims,
        control,
    ];
    attack_two_robots(&python, dir.path(), tables, &hostiles, false);
}

#[test]
fn with_users_a_router_lets_a_robot_publish_only_as_itself() {
    let python = match python() {
        Ok(p) => p,
        Err(why) => return eprintln!("skipped: {why}"),
    };
    let dir = tempfile::tempdir().expect("tempdir");
    std::fs::write(
        dir.path().join("users.txt"),
        "robot0:pw-zero\nrobot1:pw-one\nrobot2:pw-two\n",
    )
    .expect("dictionary");
    // The user/password forms of docs/security.md as written, but for their
    // addresses (loopback) and each robot's own user and password: zenoh names only
    // the side that connects, so the router (which every robot connects to) holds
    // the users and the access control, and the robots are its clients.
    let (router_form, robot_form) = (
        documented_form("# router file"),
        documented_form("# robot file"),
    );
    let tables = |i: usize, ports: &[u16]| {
        let router = format!("tcp/127.0.0.1:{}", ports[2]);
        if i == 2 {
            return router_form.replace("tcp/0.0.0.0:7447", &router);
        }
        let password = ["pw-zero", "pw-one"][i];
        replace_line(
            &robot_form,
            "password = ",
            &format!("password = \"{password}\""),
        )
        .replace("tcp/10.0.0.1:7447", &router)
        .replace("\"robot0\"", &format!("\"robot{i}\""))
    };
    let [claims, control] = impersonation(&strings(&["--user", "robot2", "--password", "pw-two"]));
    let hostiles = [
        Hostile {
            name: "no user",
            credentials: Vec::new(),
            keys: vec![key(1), key(2)],
        },
        Hostile {
            name: "robot 2 with a wrong password",
            credentials: strings(&["--user", "robot2", "--password", "guess"]),
            keys: vec![key(1), key(2)],
        },
        claims,
        control,
    ];
    attack_two_robots(&python, dir.path(), tables, &hostiles, true);
}

/// The robot file of robot 0 of `team.toml` with `zenoh` as its `[zenoh]` table.
fn robot_file(dir: &Path, zenoh: &str) -> PathBuf {
    std::fs::write(dir.join("team.toml"), "name = \"security\"\nrobots = 2\n").expect("scenario");
    let file = dir.join("robot0.toml");
    std::fs::write(
        &file,
        format!("robot = 0\nscenario = \"team.toml\"\nduration_s = 1.0\n\n{zenoh}"),
    )
    .expect("robot file");
    file
}

#[test]
fn insecure_forms_refuse_to_start_with_one_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    std::fs::write(dir.path().join("users.txt"), "robot0:pw\n").expect("dictionary");
    let cases = [
        (
            "[zenoh]\nlisten = [\"tcp/0.0.0.0:7447\"]\n",
            "insecure = true",
        ),
        (
            "[zenoh]\nlisten = [\"tcp/127.0.0.1:7447\"]\n[zenoh.auth]\nuser = \"robot0\"\npassword = \"pw\"\n",
            "dictionary_path",
        ),
        (
            "[zenoh]\nlisten = [\"tcp/0.0.0.0:7447\"]\n[zenoh.auth]\nuser = \"robot0\"\npassword = \"pw\"\ndictionary_path = \"users.txt\"\n",
            "[zenoh.access]",
        ),
    ];
    for (zenoh, hint) in cases {
        let file = robot_file(dir.path(), zenoh);
        let out = troupe(
            &["robot", "--config", &file.display().to_string()],
            dir.path(),
        );
        let stderr = String::from_utf8_lossy(&out.stderr);
        let lines: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
        assert!(!out.status.success(), "{zenoh} started");
        assert_eq!(lines.len(), 1, "{stderr}");
        assert!(lines[0].contains(hint), "{zenoh}: {stderr}");
    }
    let out = troupe(&["router"], dir.path());
    assert!(!out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("--insecure"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}
