//! Frame signatures: the keys a table accepts, what a signature covers, and two
//! signing sessions on loopback refusing what their senders did not sign.

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use ::zenoh::Wait as _;

use super::*;
use crate::shaping::{LinkShaper, ShaperConfig};
use crate::transport::{PacketSink, PacketTransport, ReceivedPacket};
use crate::zenoh::{ZenohConfig, ZenohTransport};

/// A new P-256 key written as `troupe keys` writes it: the PEM file and the public
/// key's hex.
fn member_key(dir: &Path, name: &str) -> (PathBuf, String) {
    let pair = rcgen::KeyPair::generate().unwrap();
    let path = dir.join(format!("{name}.key"));
    std::fs::write(&path, pair.serialize_pem()).unwrap();
    (path, to_hex(pair.public_key_raw()))
}

fn signing(key_path: &Path, signers: &[(u32, &str)]) -> ZenohSigning {
    ZenohSigning {
        key_path: key_path.to_owned(),
        signers: signers
            .iter()
            .map(|(id, k)| ZenohSigner {
                id: *id,
                public_key: (*k).to_owned(),
            })
            .collect(),
    }
}

fn config_key(r: Result<impl Sized, TransportError>) -> String {
    match r {
        Err(TransportError::Config { key, reason }) => {
            assert!(!reason.contains('\n'), "one line: {reason}");
            key
        }
        Err(other) => panic!("{other:?}"),
        Ok(_) => panic!("accepted"),
    }
}

#[test]
fn a_table_is_accepted_only_with_its_own_key_and_well_formed_signers() {
    let dir = tempfile::tempdir().unwrap();
    let (k0, p0) = member_key(dir.path(), "robot0");
    let (_, p1) = member_key(dir.path(), "robot1");
    let table = signing(&k0, &[(0, &p0), (1, &p1)]);
    table.validate().unwrap();
    let (signer, _) = table.open(&[0]).unwrap();
    assert_eq!(to_hex(signer.public_key()), p0);
    // Robot 0's key may not send as robot 1, nor as an id nobody listed.
    assert_eq!(config_key(table.open(&[1])), "signing.key_path");
    assert_eq!(config_key(table.open(&[7])), "signing.signers");
    for bad in [&p0[..128], "zz", &p0.replace("04", "05")[..]] {
        assert_eq!(
            config_key(signing(&k0, &[(0, &p0), (1, bad)]).validate()),
            "signing.signers"
        );
    }
    assert_eq!(
        config_key(signing(&k0, &[(0, &p0), (0, &p1)]).validate()),
        "signing.signers"
    );
    let not_a_key = dir.path().join("junk.key");
    std::fs::write(
        &not_a_key,
        "-----BEGIN PRIVATE KEY-----\nAAAA\n-----END PRIVATE KEY-----\n",
    )
    .unwrap();
    for path in [not_a_key, dir.path().join("missing.key")] {
        assert_eq!(
            config_key(signing(&path, &[(0, &p0)]).validate()),
            "signing.key_path"
        );
    }
    // The table reads from a robot file, and its key path follows the file.
    let mut c: ZenohConfig = toml::from_str(&format!(
        "[signing]\nkey_path = \"robot0.key\"\n\
         [[signing.signers]]\nid = 0\npublic_key = \"{p0}\"\n"
    ))
    .unwrap();
    c.resolve_paths(dir.path());
    c.validate().unwrap();
}

#[test]
fn a_signature_covers_team_sender_class_addressee_and_every_byte() {
    let dir = tempfile::tempdir().unwrap();
    let (k0, p0) = member_key(dir.path(), "robot0");
    let (k1, p1) = member_key(dir.path(), "robot1");
    let (signer, verifier) = signing(&k0, &[(0, &p0), (1, &p1)]).open(&[0]).unwrap();
    let (signer1, _) = signing(&k1, &[(0, &p0), (1, &p1)]).open(&[1]).unwrap();
    let frame = vec![7u8; 300];
    let message = signed_bytes(3, 0, Class::Plan, Some(1), &frame);
    let signature = signer.sign(&message).unwrap();
    assert!(verifier.verify(0, &message, &signature));
    let mut flipped = frame.clone();
    flipped[299] ^= 1;
    for other in [
        signed_bytes(4, 0, Class::Plan, Some(1), &frame),
        signed_bytes(3, 1, Class::Plan, Some(1), &frame),
        signed_bytes(3, 0, Class::Keyframe, Some(1), &frame),
        signed_bytes(3, 0, Class::Plan, None, &frame),
        signed_bytes(3, 0, Class::Plan, Some(2), &frame),
        signed_bytes(3, 0, Class::Plan, Some(1), &flipped),
    ] {
        assert!(!verifier.verify(0, &other, &signature));
    }
    // Robot 1's signature is not robot 0's; an unlisted id has no signature.
    let by_1 = signer1.sign(&message).unwrap();
    assert!(!verifier.verify(0, &message, &by_1));
    assert!(verifier.verify(1, &message, &by_1));
    assert!(!verifier.verify(9, &message, &signature));
    assert!(!verifier.verify(0, &message, &signature[..63]));
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

fn plan_frame(fill: u8) -> Vec<u8> {
    let mut shaper = LinkShaper::new(ShaperConfig::default()).unwrap();
    shaper.offer(0, Class::Plan, vec![fill; 300]).unwrap();
    shaper.poll(0).unwrap().bytes
}

#[test]
fn signing_sessions_accept_their_peers_and_refuse_frames_their_sender_did_not_sign() {
    let dir = tempfile::tempdir().unwrap();
    let (k0, p0) = member_key(dir.path(), "robot0");
    let (k1, p1) = member_key(dir.path(), "robot1");
    let (k2, p2) = member_key(dir.path(), "router");
    let signers = [(0, p0.as_str()), (1, p1.as_str())];
    let port = 40_000 + (std::process::id() % 20_000) as u16;
    let listen = ZenohConfig {
        listen: vec![format!("tcp/127.0.0.1:{port}")],
        signing: Some(signing(&k0, &signers)),
        ..ZenohConfig::default()
    };
    let connect = |signing: Option<ZenohSigning>| ZenohConfig {
        connect: vec![format!("tcp/127.0.0.1:{port}")],
        signing,
        ..ZenohConfig::default()
    };
    let a = ZenohTransport::open(&listen, 1, vec![0]).unwrap();
    let b = ZenohTransport::open(&connect(Some(signing(&k1, &signers))), 1, vec![1]).unwrap();
    let (seen_a, seen_b): (Seen, Seen) = Default::default();
    a.start(sink(&seen_a)).unwrap();
    b.start(sink(&seen_b)).unwrap();
    let frame = plan_frame(1);
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
    let forged = plan_frame(2);
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
