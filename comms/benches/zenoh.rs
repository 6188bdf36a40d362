//! Zenoh transport latency: one 4 KB frame from one session to another in the
//! same process over loopback TCP, timed from `send` until the receiving sink
//! runs (one way; both ends read the same clock), unsigned and with
//! `[zenoh.signing]`; and signing and verifying one such frame alone. Reported as
//! criterion's median.
//!
//! `cargo bench -p troupe-comms --bench zenoh`

// criterion_group! generates an undocumented function.
#![allow(missing_docs)]

use std::sync::Arc;
use std::sync::mpsc::{Receiver, channel};
use std::time::{Duration, Instant};

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use troupe_comms::shaping::{LinkShaper, ShaperConfig};
use troupe_comms::transport::{PacketTransport, ReceivedPacket};
use troupe_comms::wire::Class;
use troupe_comms::zenoh::signing::{signed_bytes, to_hex};
use troupe_comms::zenoh::{ZenohConfig, ZenohSigner, ZenohSigning, ZenohTransport};

/// Payload of the timed frame, bytes.
const PAYLOAD_BYTES: usize = 4096;

/// One unfragmented frame carrying `PAYLOAD_BYTES` of plan bytes.
fn frame() -> Vec<u8> {
    let config = ShaperConfig {
        mtu_bytes: 8192,
        burst_bytes: 16 * 1024,
        ..ShaperConfig::default()
    };
    let mut shaper = LinkShaper::new(config).expect("bench shaper config is valid");
    shaper
        .offer(0, Class::Plan, vec![7_u8; PAYLOAD_BYTES])
        .expect("the shaper takes one plan");
    shaper.poll(0).expect("the plan is ready at once").bytes
}

/// The `[zenoh.signing]` tables of robots 0 and 1, with new keys written into `dir`.
fn signing_tables(dir: &std::path::Path) -> [ZenohSigning; 2] {
    let keys = [0, 1].map(|i| {
        let pair = rcgen::KeyPair::generate().expect("a P-256 key");
        let path = dir.join(format!("robot{i}.key"));
        std::fs::write(&path, pair.serialize_pem()).expect("writing a key");
        (path, to_hex(pair.public_key_raw()))
    });
    let signers: Vec<ZenohSigner> = (0..2)
        .map(|i| ZenohSigner {
            id: i,
            public_key: keys[i as usize].1.clone(),
        })
        .collect();
    keys.map(|(key_path, _)| ZenohSigning {
        key_path,
        signers: signers.clone(),
    })
}

/// Two connected transports (robot 0 listens on `port`, robot 1 connects), signing
/// with `signing` if given, and the channel on which robot 1's sink reports each
/// frame's arrival.
fn pair(
    port: u16,
    signing: Option<[ZenohSigning; 2]>,
) -> (ZenohTransport, ZenohTransport, Receiver<Instant>) {
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let [signing_a, signing_b] = signing.map_or([None, None], |s| s.map(Some));
    let a = ZenohTransport::open(
        &ZenohConfig {
            listen: vec![endpoint.clone()],
            signing: signing_a,
            ..ZenohConfig::default()
        },
        1,
        vec![0],
    )
    .expect("opening the listening session");
    let b = ZenohTransport::open(
        &ZenohConfig {
            connect: vec![endpoint],
            signing: signing_b,
            ..ZenohConfig::default()
        },
        1,
        vec![1],
    )
    .expect("opening the connecting session");
    let (tx, rx) = channel();
    let tx = std::sync::Mutex::new(tx);
    a.start(Arc::new(|_: ReceivedPacket<'_>| {}))
        .expect("starting A");
    b.start(Arc::new(move |_: ReceivedPacket<'_>| {
        if let Ok(tx) = tx.lock() {
            let _ = tx.send(Instant::now());
        }
    }))
    .expect("starting B");
    (a, b, rx)
}

fn zenoh_latency(c: &mut Criterion) {
    let keys = tempfile::tempdir().expect("a temporary directory");
    let bytes = frame();
    let mut group = c.benchmark_group("zenoh");
    group.throughput(Throughput::Bytes(bytes.len() as u64));
    let port = 30_000 + (std::process::id() % 20_000) as u16;
    for (name, port, signing) in [
        ("one_way_4KB_loopback", port, None),
        (
            "one_way_4KB_loopback_signed",
            port + 1,
            Some(signing_tables(keys.path())),
        ),
    ] {
        let (a, _b, rx) = pair(port, signing);
        // Subscriptions propagate asynchronously: send until the first frame lands.
        let start = Instant::now();
        loop {
            a.send(0, Some(1), &bytes).expect("queueing a frame");
            if rx.recv_timeout(Duration::from_millis(100)).is_ok() {
                break;
            }
            assert!(start.elapsed() < Duration::from_secs(10), "no route A → B");
        }
        while rx.try_recv().is_ok() {}
        group.bench_function(name, |bench| {
            bench.iter_custom(|iters| {
                let mut total = Duration::ZERO;
                for _ in 0..iters {
                    let sent = Instant::now();
                    a.send(0, Some(1), &bytes).expect("queueing a frame");
                    let arrived = rx
                        .recv_timeout(Duration::from_secs(5))
                        .expect("the frame arrives");
                    total += arrived.saturating_duration_since(sent);
                }
                total
            });
        });
    }
    // The cryptography alone, on the same frame.
    let [table, _] = signing_tables(keys.path());
    let (signer, verifier) = table.open(&[0]).expect("robot 0's table");
    let message = signed_bytes(1, 0, Class::Plan, Some(1), &bytes);
    group.bench_function("sign_4KB", |bench| bench.iter(|| signer.sign(&message)));
    let signature = signer.sign(&message).expect("a signature");
    group.bench_function("verify_4KB", |bench| {
        bench.iter(|| assert!(verifier.verify(0, &message, &signature)));
    });
    group.finish();
}

criterion_group!(benches, zenoh_latency);
criterion_main!(benches);
