//! Wire codec and shaper throughput.
//!
//! `cargo bench -p troupe-comms --bench codec`

// criterion_group! generates an undocumented function.
#![allow(missing_docs)]

use std::hint::black_box;

use criterion::{BatchSize, Criterion, Throughput, criterion_group, criterion_main};
use troupe_comms::shaping::{LinkShaper, ShaperConfig};
use troupe_comms::wire::{
    self, Class, Component4, Envelope, Keyframe, Mixture, Payload, SensorPose,
};

/// A valid 100-component 4D keyframe (deterministic, mildly correlated covariances).
fn keyframe(n: usize) -> Envelope {
    let components = (0..n)
        .map(|i| {
            let f = i as f32;
            let s = 0.01 + 0.0001 * (i % 7) as f32;
            Component4 {
                mean: [f * 0.05, (f * 0.37).sin(), 1.0 + 0.01 * f, 0.5],
                covariance: [
                    s,
                    0.001,
                    0.0,
                    0.0005,
                    2.0 * s,
                    0.001,
                    0.0,
                    1.5 * s,
                    0.0,
                    0.01,
                ],
                weight: 1.0 / n as f32,
            }
        })
        .collect();
    Envelope::new(
        1,
        0,
        1,
        1_000_000_000,
        Payload::Keyframe(Keyframe {
            keyframe_id: 1,
            sensor_pose: SensorPose {
                position_m: [0.0, 0.0, 1.0],
                orientation_xyzw: [0.0, 0.0, 0.0, 1.0],
            },
            support_size: 19_200,
            mixture: Mixture::SpatialIntensity(components),
        }),
    )
}

fn compact(e: &Envelope) -> Envelope {
    let mut e = e.clone();
    if let Payload::Keyframe(k) = &mut e.payload {
        k.mixture = k.mixture.compact().expect("valid mixture");
    }
    e
}

fn codec(c: &mut Criterion) {
    let exact = keyframe(100);
    let compact = compact(&exact);
    for (name, e) in [("exact", &exact), ("compact", &compact)] {
        let bytes = wire::encode(e).expect("valid");
        let mut g = c.benchmark_group(format!("keyframe_4d_100/{name}"));
        g.throughput(Throughput::Bytes(bytes.len() as u64));
        g.bench_function("encode", |b| b.iter(|| wire::encode(black_box(e))));
        g.bench_function("decode", |b| b.iter(|| wire::decode(black_box(&bytes))));
        g.finish();
    }
    let mixture = match &exact.payload {
        Payload::Keyframe(k) => k.mixture.clone(),
        _ => unreachable!(),
    };
    let small = mixture.compact().expect("valid");
    c.bench_function("keyframe_4d_100/compact_from_exact", |b| {
        b.iter(|| black_box(&mixture).compact())
    });
    c.bench_function("keyframe_4d_100/expand_compact", |b| {
        b.iter(|| black_box(&small).expand())
    });
}

fn shaper(c: &mut Criterion) {
    let keyframe = wire::encode(&keyframe(100)).expect("valid");
    let mut g = c.benchmark_group("shaper");
    // Offer one 6 kB keyframe and drain its 6 frames on an unlimited link.
    g.throughput(Throughput::Bytes(keyframe.len() as u64));
    g.bench_function("offer_poll_keyframe_6kB", |b| {
        let mut s = LinkShaper::new(ShaperConfig::default()).expect("valid config");
        b.iter_batched(
            || keyframe.clone(),
            |k| {
                s.offer(0, Class::Keyframe, k).expect("accepted");
                while let Some(f) = s.poll(0) {
                    black_box(f);
                }
            },
            BatchSize::SmallInput,
        )
    });
    g.throughput(Throughput::Elements(1));
    g.bench_function("offer_poll_odometry_90B", |b| {
        let mut s = LinkShaper::new(ShaperConfig::default()).expect("valid config");
        b.iter_batched(
            || vec![0u8; 90],
            |m| {
                s.offer(0, Class::Odometry, m).expect("accepted");
                black_box(s.poll(0))
            },
            BatchSize::SmallInput,
        )
    });
    g.finish();
}

criterion_group!(benches, codec, shaper);
criterion_main!(benches);
