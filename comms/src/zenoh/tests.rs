//! zenoh transport: settings, key expressions, and two sessions on loopback.

use std::sync::Mutex;
use std::time::{Duration, Instant};

use super::*;
use crate::shaping::{LinkShaper, ShaperConfig};

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
    ] {
        assert_eq!(parse_key_expr(bad, 1), Err(KeyError::Malformed), "{bad}");
    }
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
