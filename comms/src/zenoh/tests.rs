//! zenoh transport: settings, key expressions, and two sessions on loopback.

use std::sync::Mutex;
use std::time::{Duration, Instant};

use super::*;
use crate::shaping::{LinkShaper, ShaperConfig};
use signing::tests::{member_key, signing};
use signing::{SIGNATURE_BYTES, signed_bytes};

#[test]
fn settings_read_from_toml_and_bad_ones_name_the_key() {
    let c: ZenohConfig = toml::from_str(
        r#"
        mode = "client"
        connect = ["tcp/10.0.0.1:7447"]
        multicast_scouting = true
        [auth]
        user = "robot"
        password = "secret"
        "#,
    )
    .unwrap();
    c.validate().unwrap();
    assert_eq!(c.mode, ZenohMode::Client);
    assert!(
        !format!("{c:?}").contains("secret"),
        "passwords stay out of logs"
    );
    let z = c.to_zenoh().unwrap();
    assert!(format!("{z}").contains("10.0.0.1:7447"));
    let gossip = |on: bool| {
        let c = ZenohConfig {
            connect: vec!["tcp/127.0.0.1:7447".into()],
            gossip_scouting: on,
            ..ZenohConfig::default()
        };
        c.to_zenoh()
            .unwrap()
            .get_json("scouting/gossip/enabled")
            .unwrap()
    };
    assert_eq!(
        (gossip(false), gossip(true)),
        ("false".into(), "true".into())
    );
    assert!(toml::from_str::<ZenohConfig>("listn = []").is_err());
    let bad = |text: &str| match toml::from_str::<ZenohConfig>(text).unwrap().validate() {
        Err(TransportError::Config { key, .. }) => key,
        other => panic!("{other:?}"),
    };
    assert_eq!(bad(r#"listen = ["127.0.0.1:7447"]"#), "listen");
    assert_eq!(bad(r#"connect = ["quic/1.2.3.4:5"]"#), "connect");
    assert_eq!(bad(r#"listen = ["tls/0.0.0.0:7447"]"#), "tls");
    assert_eq!(bad(r#"mode = "client""#), "connect");
    assert_eq!(
        bad(
            r#"tls = { root_ca_path = "/nonexistent/ca.pem", cert_path = "/nonexistent/c.pem", key_path = "/nonexistent/k.pem" }"#
        ),
        "tls.root_ca_path"
    );
    assert_eq!(bad(r#"auth = { user = "", password = "x" }"#), "auth.user");
}

#[test]
fn key_expressions_name_team_sender_and_class() {
    for class in Class::ALL {
        let key = key_expr(3, 17, class);
        assert_eq!(parse_key_expr(&key, 3), Ok((17, class)));
        assert_eq!(parse_key_expr(&key, 4), Err(KeyError::OtherTeam));
    }
    assert_eq!(key_expr(1, 2, Class::Plan), "troupe/1/2/plan");
    for bad in [
        "troupe/1/2",
        "troupe/1/2/plan/x",
        "troupe/1/two/plan",
        "troupe/1/2/plans",
        "other/1/2/plan",
        "troupe/-1/2/plan",
        "troupe/1/2/bulk/c1_2",
        "troupe/1/2/keyframe/c1",
        "troupe/1/2/keyframe/c1_2/x",
    ] {
        assert_eq!(parse_key_expr(bad, 1), Err(KeyError::Malformed), "{bad}");
    }
    assert_eq!(
        parse_key_expr("troupe/1/2/keyframe/c-1_20", 1),
        Ok((2, Class::Keyframe))
    );
    assert_eq!(
        parse_key_expr("troupe/1/2/plan/c0_0", 1),
        Ok((2, Class::Plan))
    );
}

/// A port for this test run (distinct per test and per process).
fn port(offset: u16) -> u16 {
    20_000 + (std::process::id() % 20_000) as u16 + offset
}

type Seen = Arc<Mutex<Vec<(u32, Option<u32>, Vec<u8>)>>>;

fn sink(seen: &Seen) -> PacketSink {
    let seen = seen.clone();
    Arc::new(move |p: ReceivedPacket<'_>| {
        seen.lock().unwrap().push((p.from, p.to, p.bytes.to_vec()));
    })
}

fn wait_for(what: &str, mut done: impl FnMut() -> bool) {
    let start = Instant::now();
    while !done() {
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "timed out waiting for {what}"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// `count` distinct encoded frames (one plan each: plans are keep-latest, so each
/// comes from its own shaper).
fn frames(count: usize) -> Vec<Vec<u8>> {
    (0..count)
        .map(|i| {
            let mut shaper = LinkShaper::new(ShaperConfig::default()).unwrap();
            shaper.offer(0, Class::Plan, vec![i as u8; 300]).unwrap();
            shaper.poll(0).unwrap().bytes
        })
        .collect()
}

#[test]
fn two_sessions_on_loopback_exchange_frames_and_reject_bad_ones() {
    let p = port(0);
    let listen = ZenohConfig {
        listen: vec![format!("tcp/127.0.0.1:{p}")],
        ..ZenohConfig::default()
    };
    let connect = ZenohConfig {
        connect: vec![format!("tcp/127.0.0.1:{p}")],
        ..ZenohConfig::default()
    };
    let a = ZenohTransport::open(&listen, 1, vec![0]).unwrap();
    let b = ZenohTransport::open(&connect, 1, vec![1]).unwrap();
    let seen_a: Seen = Arc::default();
    let seen_b: Seen = Arc::default();
    a.start(sink(&seen_a)).unwrap();
    b.start(sink(&seen_b)).unwrap();
    let sent = frames(3);
    // Subscriptions propagate asynchronously: resend the first frame until it lands.
    wait_for("the first frame", || {
        a.send(0, None, &sent[0]).unwrap();
        std::thread::sleep(Duration::from_millis(50));
        !seen_b.lock().unwrap().is_empty()
    });
    seen_b.lock().unwrap().clear();
    a.send(0, None, &sent[1]).unwrap();
    a.send(0, Some(1), &sent[2]).unwrap();
    a.send(0, Some(7), &sent[2]).unwrap(); // for a robot that is not B
    b.send(1, Some(0), &sent[0]).unwrap();
    wait_for("three frames", || {
        seen_b.lock().unwrap().len() >= 2 && !seen_a.lock().unwrap().is_empty()
    });
    {
        let got = seen_b.lock().unwrap();
        assert_eq!(got[0], (0, None, sent[1].clone()));
        assert_eq!(got[1], (0, Some(1), sent[2].clone()));
    }
    assert_eq!(seen_a.lock().unwrap()[0], (1, Some(0), sent[0].clone()));
    wait_for("the foreign frame to be counted", || {
        b.stats().not_for_us == 1
    });
    // Not frames: a raw session publishes bad samples on our team's keys. It connects
    // to A, which listens (peers do not forward between other peers by default).
    let raw = ::zenoh::open(connect.to_zenoh().unwrap()).wait().unwrap();
    let keyframe_frame = {
        let mut shaper = LinkShaper::new(ShaperConfig::default()).unwrap();
        shaper.offer(0, Class::Keyframe, vec![1; 10]).unwrap();
        shaper.poll(0).unwrap().bytes
    };
    let before = a.stats();
    wait_for("bad samples to be counted", || {
        raw.put("troupe/1/5/plan", keyframe_frame.clone())
            .wait()
            .unwrap();
        raw.put("troupe/1/5/plan", vec![9u8, 9, 9]).wait().unwrap();
        raw.put("troupe/1/x/plan", sent[0].clone()).wait().unwrap();
        raw.put("troupe/1/0/plan", sent[0].clone()).wait().unwrap();
        std::thread::sleep(Duration::from_millis(20));
        let s = a.stats();
        s.rejected_class > 0 && s.rejected_frame > 0 && s.rejected_key > 0 && s.rejected_sender > 0
    });
    assert_eq!(
        a.stats().received_frames,
        before.received_frames,
        "none delivered"
    );
    raw.close().wait().unwrap();
    a.close().unwrap();
    b.close().unwrap();
    assert!(matches!(
        a.send(0, None, &sent[0]),
        Err(TransportError::Closed)
    ));
}

#[test]
fn loopback_endpoints_are_told_apart_from_the_network() {
    for a in [
        "127.0.0.1:7447",
        "127.3.2.1:1",
        "[::1]:7447",
        "localhost:7447",
    ] {
        assert!(security::is_loopback(a), "{a}");
    }
    for a in [
        "0.0.0.0:7447",
        "[::]:7447",
        "10.0.0.2:7447",
        "robot1.local:7447",
        "127.0.0.1.example:7447",
    ] {
        assert!(!security::is_loopback(a), "{a}");
    }
    assert!(security::is_loopback("127.0.0.1:7447#iface=lo"));
}

/// A file in the temp directory, unique to this process and `name`.
fn temp_file(name: &str, text: &str) -> PathBuf {
    let path = std::env::temp_dir().join(format!("troupe-zenoh-{}-{name}", std::process::id()));
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn secure_defaults_refuse_open_doors_and_unusable_credentials() {
    let users = temp_file("users.txt", "robot0:a\n\nrobot1 : b\n");
    let bad_users = temp_file("bad-users.txt", "robot0\n");
    let empty_users = temp_file("empty-users.txt", "\n");
    let with = |text: &str| {
        let text = text
            .replace("USERS", &users.display().to_string())
            .replace("BAD", &bad_users.display().to_string())
            .replace("EMPTY", &empty_users.display().to_string());
        toml::from_str::<ZenohConfig>(&text).unwrap().validate()
    };
    let key = |r: Result<(), TransportError>| match r {
        Err(TransportError::Config { key, reason }) => {
            assert!(!reason.contains('\n'), "one line: {reason}");
            key
        }
        other => panic!("{other:?}"),
    };
    // Loopback needs nothing; a plain link off this machine, connecting or
    // listening, and multicast scouting without credentials are refused unless
    // insecure (which then names what is open).
    with(r#"listen = ["tcp/127.0.0.1:7447"]"#).unwrap();
    with(r#"connect = ["tcp/127.0.0.1:7447"]"#).unwrap();
    assert_eq!(key(with(r#"connect = ["tcp/10.0.0.1:7447"]"#)), "connect");
    assert_eq!(key(with("multicast_scouting = true")), "multicast_scouting");
    let open: ZenohConfig = toml::from_str(
        "listen = [\"tcp/127.0.0.1:1\"]\nconnect = [\"tcp/10.0.0.1:7447\"]\n\
         multicast_scouting = true\ninsecure = true",
    )
    .unwrap();
    open.validate().unwrap();
    assert_eq!(
        open.open_to_network(),
        ["tcp/10.0.0.1:7447", "multicast scouting"]
    );
    // Off loopback without authentication: refused unless insecure.
    assert_eq!(key(with(r#"listen = ["tcp/0.0.0.0:7447"]"#)), "listen");
    with("listen = [\"tcp/0.0.0.0:7447\"]\ninsecure = true").unwrap();
    // auth on a listening session needs a usable dictionary.
    let auth = "[auth]\nuser = \"robot0\"\npassword = \"a\"\n";
    assert_eq!(
        key(with(&format!("listen = [\"tcp/127.0.0.1:1\"]\n{auth}"))),
        "auth.dictionary_path"
    );
    with(&format!("connect = [\"tcp/10.0.0.1:1\"]\n{auth}")).unwrap();
    for bad in ["BAD", "EMPTY"] {
        assert_eq!(
            key(with(&format!(
                "listen = [\"tcp/127.0.0.1:1\"]\n{auth}dictionary_path = \"{bad}\""
            ))),
            "auth.dictionary_path"
        );
    }
    let users_auth = format!("{auth}dictionary_path = \"USERS\"\n");
    // Off loopback with users but no access control: anyone of the team could
    // speak for anyone.
    assert_eq!(
        key(with(&format!("listen = [\"tcp/0.0.0.0:1\"]\n{users_auth}"))),
        "access"
    );
    with(&format!(
        "listen = [\"tcp/0.0.0.0:1\"]\n{users_auth}[access]\nids = [0, 1]"
    ))
    .unwrap();
    // Access control needs names, and each id once.
    assert_eq!(
        key(with(
            "listen = [\"tcp/127.0.0.1:1\"]\n[access]\nids = [0, 1]"
        )),
        "access"
    );
    assert_eq!(
        key(with(&format!(
            "listen = [\"tcp/127.0.0.1:1\"]\n{users_auth}[access]\nids = [0, 0]"
        ))),
        "access.ids"
    );
    assert_eq!(key(with("max_message_bytes = 100")), "max_message_bytes");
    // TLS requires client certificates unless told otherwise.
    let tls: ZenohTls =
        toml::from_str("root_ca_path = \"a\"\ncert_path = \"b\"\nkey_path = \"c\"").unwrap();
    assert!(tls.mutual);
    for p in [users, bad_users, empty_users] {
        let _ = std::fs::remove_file(p);
    }
}

#[test]
fn relative_paths_resolve_against_the_file() {
    let mut c: ZenohConfig = toml::from_str(
        "[tls]\nroot_ca_path = \"keys/ca.pem\"\ncert_path = \"/abs/c.pem\"\nkey_path = \"k.pem\"\n\
         [auth]\nuser = \"u\"\npassword = \"p\"\ndictionary_path = \"users.txt\"",
    )
    .unwrap();
    c.resolve_paths(Path::new("/robots"));
    let tls = c.tls.as_ref().unwrap();
    assert_eq!(tls.root_ca_path, Path::new("/robots/keys/ca.pem"));
    assert_eq!(tls.cert_path, Path::new("/abs/c.pem"));
    assert_eq!(tls.key_path, Path::new("/robots/k.pem"));
    assert_eq!(
        c.auth.as_ref().unwrap().dictionary_path.as_deref(),
        Some(Path::new("/robots/users.txt"))
    );
}

#[test]
fn access_control_and_size_limit_reach_zenohs_configuration() {
    let users = temp_file("acl-users.txt", "robot0:a\nrobot1:b\n");
    let c: ZenohConfig = toml::from_str(&format!(
        "listen = [\"tcp/0.0.0.0:1\"]\n[auth]\nuser = \"robot0\"\npassword = \"a\"\n\
         dictionary_path = \"{}\"\n[access]\nids = [0, 1]\nrouters = [\"router\"]",
        users.display()
    ))
    .unwrap();
    let z = c.to_zenoh().unwrap();
    let acl = z.get_json("access_control").unwrap();
    assert!(acl.contains("\"default_permission\":\"deny\""), "{acl}");
    assert!(acl.contains("troupe/*/1/*"), "{acl}");
    assert!(acl.contains("\"usernames\":[\"robot1\"]"), "{acl}");
    assert!(!acl.contains("\"cert_common_names\":["), "{acl}");
    assert_eq!(
        z.get_json("transport/link/rx/max_message_size").unwrap(),
        DEFAULT_MAX_MESSAGE_BYTES.to_string()
    );
    let _ = std::fs::remove_file(users);
}

/// The accept limits reach zenoh (defaults, and a file's values); a timeout zenoh
/// could not wait out, or one without end, is refused.
#[test]
fn accept_limits_reach_zenohs_configuration() {
    let accept = |c: ZenohConfig| {
        let z = c.to_zenoh().unwrap();
        let get = |key: &str| z.get_json(&format!("transport/unicast/{key}")).unwrap();
        (get("accept_timeout"), get("accept_pending"))
    };
    assert_eq!(
        accept(ZenohConfig::default()),
        ("5000".into(), "1000".into())
    );
    let c: ZenohConfig = toml::from_str("accept_timeout_s = 2.5\naccept_pending = 50").unwrap();
    assert_eq!(accept(c), ("2500".into(), "50".into()));
    for bad in ["0.01", "61.0", "nan", "-1.0"] {
        let c: ZenohConfig = toml::from_str(&format!("accept_timeout_s = {bad}")).unwrap();
        assert!(
            matches!(c.validate(), Err(TransportError::Config { ref key, .. }) if key == "accept_timeout_s"),
            "{bad}"
        );
    }
}

/// The workspace's builds lower zenoh's pause after a failed TLS handshake
/// (`.cargo/config.toml`); a build without it warns when it listens on TLS.
#[test]
fn this_build_lowers_zenohs_pause_after_a_failed_tls_handshake() {
    assert_eq!(super::TLS_ACCEPT_THROTTLE_US, Some("100"));
}

/// Issue 45 item 2: frame signatures between two sessions, and a session with a
/// router's rights (it may put any key) that holds no robot's key.
#[test]
fn signing_sessions_accept_their_peers_and_refuse_frames_their_sender_did_not_sign() {
    let dir = tempfile::tempdir().unwrap();
    let (k0, p0) = member_key(dir.path(), "robot0");
    let (k1, p1) = member_key(dir.path(), "robot1");
    let (k2, p2) = member_key(dir.path(), "router");
    let signers = [(0, p0.as_str()), (1, p1.as_str())];
    let p = port(7);
    let listen = ZenohConfig {
        listen: vec![format!("tcp/127.0.0.1:{p}")],
        signing: Some(signing(&k0, &signers)),
        ..ZenohConfig::default()
    };
    let connect = |signing: Option<ZenohSigning>| ZenohConfig {
        connect: vec![format!("tcp/127.0.0.1:{p}")],
        signing,
        ..ZenohConfig::default()
    };
    let a = ZenohTransport::open(&listen, 1, vec![0]).unwrap();
    let b = ZenohTransport::open(&connect(Some(signing(&k1, &signers))), 1, vec![1]).unwrap();
    let (seen_a, seen_b): (Seen, Seen) = Default::default();
    a.start(sink(&seen_a)).unwrap();
    b.start(sink(&seen_b)).unwrap();
    let [frame, forged]: [Vec<u8>; 2] = frames(2).try_into().unwrap();
    wait_for("a signed frame", || {
        a.send(0, None, &frame).unwrap();
        std::thread::sleep(Duration::from_millis(50));
        !seen_b.lock().unwrap().is_empty()
    });
    b.send(1, Some(0), &frame).unwrap();
    wait_for("an addressed signed frame", || {
        !seen_a.lock().unwrap().is_empty()
    });
    assert_eq!(seen_a.lock().unwrap()[0], (1, Some(0), frame.clone()));
    // A session that may put any key (a router's rights), without robot 1's key:
    // unsigned, junk-signed, signed by another key, or robot 1's real signature of
    // another frame. None reaches A.
    let raw = ::zenoh::open(connect(None).to_zenoh().unwrap())
        .wait()
        .unwrap();
    let (other, _) = signing(&k2, &[(1, &p2)]).open(&[1]).unwrap();
    let (real, _) = signing(&k1, &signers).open(&[1]).unwrap();
    let message = signed_bytes(1, 1, Class::Plan, None, &forged);
    let attachments: Vec<Vec<u8>> = vec![
        vec![],
        vec![0; SIGNATURE_BYTES],
        other.sign(&message).unwrap().to_vec(),
        real.sign(&signed_bytes(1, 1, Class::Plan, None, &frame))
            .unwrap()
            .to_vec(),
        [
            0u32.to_le_bytes().to_vec(),
            real.sign(&message).unwrap().to_vec(),
        ]
        .concat(),
    ];
    let received = a.stats().received_frames;
    wait_for("the forgeries to be refused", || {
        for attachment in &attachments {
            let put = raw.put("troupe/1/1/plan", forged.clone());
            let put = if attachment.is_empty() {
                put
            } else {
                put.attachment(attachment.clone())
            };
            put.wait().unwrap();
        }
        std::thread::sleep(Duration::from_millis(20));
        a.stats().rejected_signature >= 5
    });
    // The control: the same session with robot 1's true signature is accepted.
    raw.put("troupe/1/1/plan", forged.clone())
        .attachment(real.sign(&message).unwrap().to_vec())
        .wait()
        .unwrap();
    wait_for("the control", || a.stats().received_frames > received);
    assert_eq!(a.stats().received_frames, received + 1);
    assert!(seen_a.lock().unwrap().iter().all(|(from, _, _)| *from == 1));
    raw.close().wait().unwrap();
    a.close().unwrap();
    b.close().unwrap();
}
