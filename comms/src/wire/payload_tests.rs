//! Sizes, validation and round trips of keyframe, plan and grid payloads.

use proptest::prelude::*;

use super::testutil::{self, keyframe};
use super::*;

/// Bytes of a postcard varint for `n`.
fn varint_len(n: usize) -> usize {
    postcard::to_allocvec(&(n as u64)).unwrap().len()
}

fn payload_len(e: &Envelope) -> usize {
    postcard::to_allocvec(&e.payload).unwrap().len()
}

fn round_trip(e: &Envelope) -> Vec<u8> {
    let bytes = encode(e).unwrap();
    let back = decode(&bytes).unwrap();
    assert_eq!(&back, e);
    assert_eq!(encode(&back).unwrap(), bytes, "re-encoding is bit-exact");
    bytes
}

/// Keyframe overhead besides the components: id 4 + pose 28 + support 4 +
/// mixture variant 1 (see `keyframe.rs`).
const KEYFRAME_FIXED: usize = 4 + 28 + 4 + 1;

#[test]
fn keyframe_sizes_match_the_thesis_accounting() {
    for n in [1usize, 2, 10, 100, 127, 128, 500] {
        let e3 = keyframe(Mixture::Spatial(testutil::mixture3(n as u64, n, 0.01, 0.2)));
        let e4 = keyframe(Mixture::SpatialIntensity(testutil::mixture4(
            n as u64, n, 0.01, 0.2,
        )));
        for (e, per_component) in [(&e3, 40), (&e4, 60)] {
            let bytes = round_trip(e);
            let header = bytes.len() - payload_len(e);
            // 1 byte names the payload variant.
            assert_eq!(
                bytes.len(),
                header + 1 + KEYFRAME_FIXED + varint_len(n) + per_component * n,
                "{n} components"
            );
        }
    }
    let e = keyframe(Mixture::SpatialIntensity(testutil::mixture4(
        1, 100, 0.01, 0.2,
    )));
    let bytes = encode(&e).unwrap();
    eprintln!(
        "100-component 4D keyframe: {} B envelope, {} B payload (thesis: 100·60 + 28 = 6028 B)",
        bytes.len(),
        payload_len(&e)
    );
    let e = keyframe(Mixture::Spatial(testutil::mixture3(1, 100, 0.01, 0.2)));
    let bytes = encode(&e).unwrap();
    eprintln!(
        "100-component 3D keyframe: {} B envelope, {} B payload (thesis: 100·40 + 28 = 4028 B)",
        bytes.len(),
        payload_len(&e)
    );
}

#[test]
fn compact_keyframe_sizes_are_30_and_44_bytes_per_component() {
    for n in [1usize, 100, 200] {
        let c3 = Mixture::Spatial(testutil::mixture3(7, n, 0.01, 0.2))
            .compact()
            .unwrap();
        let c4 = Mixture::SpatialIntensity(testutil::mixture4(7, n, 0.01, 0.2))
            .compact()
            .unwrap();
        for (m, per_component) in [(c3, 30), (c4, 44)] {
            let e = keyframe(m);
            let bytes = round_trip(&e);
            let header = bytes.len() - payload_len(&e);
            assert_eq!(
                bytes.len(),
                header + 1 + KEYFRAME_FIXED + varint_len(n) + per_component * n
            );
            if n == 100 {
                eprintln!(
                    "100-component compact {}D keyframe: {} B payload",
                    e.payload_dimension(),
                    payload_len(&e)
                );
            }
        }
    }
}

impl Envelope {
    fn payload_dimension(&self) -> usize {
        match &self.payload {
            Payload::Keyframe(k) => k.mixture.dimension(),
            _ => 0,
        }
    }
}

#[test]
fn grid_change_set_is_8n_plus_24_bytes() {
    for n in [0usize, 1, 100, 127, 128, 1000, 20_000] {
        let g = testutil::grid(n as u64, n);
        let n = g.changes.len(); // duplicates merged
        let body = postcard::to_allocvec(&g).unwrap().len();
        assert_eq!(body - varint_len(n), 8 * n + 24, "{n} voxels");
        assert_eq!(g.thesis_bytes(), 8 * n + 24);
        let e = Envelope::new(0, 0, 0, 0, Payload::GridChanges(g));
        round_trip(&e);
        // Variant byte + length prefix + the thesis' 8N + 24.
        assert_eq!(payload_len(&e), 1 + varint_len(n) + 8 * n + 24);
    }
}

#[test]
fn plan_size_is_14_bytes_plus_20_per_knot() {
    for k in [1usize, 30, 200] {
        let e = Envelope::new(0, 0, 0, 0, Payload::Plan(testutil::plan(k as u64, k)));
        round_trip(&e);
        assert_eq!(payload_len(&e), 1 + 14 + varint_len(k) + 20 * k);
    }
}

#[test]
fn classes_follow_the_payload() {
    let k = keyframe(Mixture::Spatial(testutil::mixture3(1, 3, 0.01, 0.2)));
    assert_eq!(k.class, Class::Keyframe);
    let p = Envelope::new(0, 0, 0, 0, Payload::Plan(testutil::plan(1, 3)));
    assert_eq!(p.class, Class::Plan);
    let g = Envelope::new(0, 0, 0, 0, Payload::GridChanges(testutil::grid(1, 3)));
    assert_eq!(g.class, Class::Keyframe);
}

/// Compact encoding: mean log-likelihood lost on points sampled from the exact
/// mixture (held out: the encoding never sees them).
///
/// Bound, to first order in the quantisation steps: each `ln σᵢ` is off by at
/// most 1/4096, moving `½ ln det Σ` by ≤ D/4096 (≤ 1.0·10⁻³ for D = 4) and the
/// Mahalanobis term, whose expectation is D, by a relative 2/4096 per axis
/// (≤ 2·4·4/4096 ≈ 7.8·10⁻³ summed); the correlation factor (steps of 1/32767,
/// re-normalised rows) and `ln w` (1/4096) add ≤ 10⁻³ more for covariances with
/// condition number ≤ 10⁴ (σ ratio ≤ 100). Those worst cases need every
/// rounding error to align; they are independent, so the observed mean is far
/// smaller. We assert the first-order worst case, 10⁻², and print the measured
/// value.
#[test]
fn compact_encoding_loses_little_log_likelihood() {
    for (label, sigma_min, sigma_max) in [("well-conditioned", 0.02, 0.2), ("thin", 0.001, 0.1)] {
        let exact4 = testutil::mixture4(11, 100, sigma_min, sigma_max);
        let m = Mixture::SpatialIntensity(exact4.clone());
        let Mixture::SpatialIntensity(decoded4) = m.compact().unwrap().expand() else {
            panic!("expected 4D");
        };
        let view = |c: &[Component4]| -> Vec<(f32, Vec<f32>, Vec<f32>)> {
            c.iter()
                .map(|c| (c.weight, c.mean.to_vec(), c.covariance.to_vec()))
                .collect()
        };
        let (a, b) = (view(&exact4), view(&decoded4));
        let a: Vec<(f32, &[f32], &[f32])> =
            a.iter().map(|(w, m, c)| (*w, &m[..], &c[..])).collect();
        let b: Vec<(f32, &[f32], &[f32])> =
            b.iter().map(|(w, m, c)| (*w, &m[..], &c[..])).collect();
        let points = testutil::sample::<4>(&a, 20_000, 99);
        let ll_exact = testutil::mean_log_likelihood::<4>(&a, &points);
        let ll_compact = testutil::mean_log_likelihood::<4>(&b, &points);
        let loss = ll_exact - ll_compact;
        eprintln!(
            "4D {label}: mean log-likelihood exact {ll_exact:.5}, compact {ll_compact:.5}, loss {loss:.2e} nats/point"
        );
        assert!(loss.abs() < 1e-2, "{label}: loss {loss}");

        let exact3 = testutil::mixture3(12, 100, sigma_min, sigma_max);
        let Mixture::Spatial(decoded3) =
            Mixture::Spatial(exact3.clone()).compact().unwrap().expand()
        else {
            panic!("expected 3D");
        };
        let a: Vec<(f32, &[f32], &[f32])> = exact3
            .iter()
            .map(|c| (c.weight, &c.mean[..], &c.covariance[..]))
            .collect();
        let b: Vec<(f32, &[f32], &[f32])> = decoded3
            .iter()
            .map(|c| (c.weight, &c.mean[..], &c.covariance[..]))
            .collect();
        let points = testutil::sample::<3>(&a, 20_000, 98);
        let loss = testutil::mean_log_likelihood::<3>(&a, &points)
            - testutil::mean_log_likelihood::<3>(&b, &points);
        eprintln!("3D {label}: loss {loss:.2e} nats/point");
        assert!(loss.abs() < 1e-2, "{label}: loss {loss}");
    }
}

fn with_component(f: impl FnOnce(&mut Vec<Component4>)) -> Envelope {
    let mut c = testutil::mixture4(5, 4, 0.01, 0.2);
    f(&mut c);
    keyframe(Mixture::SpatialIntensity(c))
}

/// Encodes without validation (what a faulty or hostile sender could send).
fn raw(e: &Envelope) -> Vec<u8> {
    postcard::to_allocvec(e).unwrap()
}

fn rejected(e: &Envelope) -> ContentError {
    let Err(DecodeError::Invalid(reason)) = decode(&raw(e)) else {
        panic!("decoder accepted {e:?}");
    };
    assert!(
        matches!(encode(e), Err(EncodeError::Invalid(r)) if r == reason),
        "the encoder refuses it for the same reason"
    );
    reason
}

#[test]
fn invalid_keyframes_are_rejected_with_reasons() {
    let reason = |e| rejected(&e).to_string();
    assert!(reason(with_component(|c| c[1].mean[2] = f32::NAN)).contains("element 1"));
    assert!(reason(with_component(|c| c[0].covariance[4] = f32::INFINITY)).contains("NaN"));
    // Not positive definite: a negative variance, and a correlation above 1.
    assert!(reason(with_component(|c| c[2].covariance[0] = -1.0)).contains("positive definite"));
    assert!(
        reason(with_component(|c| {
            c[3].covariance[0] = 1.0;
            c[3].covariance[4] = 1.0;
            c[3].covariance[1] = 1.5;
        }))
        .contains("positive definite")
    );
    assert!(
        reason(with_component(|c| {
            let w = c[0].weight;
            c[0].weight = 0.0;
            c[1].weight += w;
        }))
        .contains("not positive")
    );
    assert!(reason(with_component(|c| c[0].weight *= 1.01)).contains("sum to 1"));
    assert!(reason(with_component(|c| c.truncate(3))).contains("sum to 1"));
    assert!(reason(keyframe(Mixture::Spatial(vec![]))).contains("no components"));
    let mut e = with_component(|_| {});
    if let Payload::Keyframe(k) = &mut e.payload {
        k.sensor_pose.orientation_xyzw = [0.0, 0.0, 0.0, 1.01];
    }
    assert!(reason(e).contains("unit quaternion"));
    // Within tolerance is fine.
    let ok = with_component(|c| c[0].weight += 5e-5);
    assert!(decode(&raw(&ok)).is_ok());
}

#[test]
fn invalid_compact_keyframes_are_rejected() {
    let e = keyframe(
        Mixture::Spatial(testutil::mixture3(2, 3, 0.01, 0.2))
            .compact()
            .unwrap(),
    );
    let bytes = encode(&e).unwrap();
    // The last component's last factor code (its third row's diagonal) sits just
    // before its 2-byte weight: set it to 0 and to a negative value.
    let diag = bytes.len() - 2 - 2;
    for code in [0i16, -5] {
        let mut b = bytes.clone();
        b[diag..diag + 2].copy_from_slice(&code.to_le_bytes());
        assert!(
            matches!(
                decode(&b),
                Err(DecodeError::Invalid(ContentError::Element { index: 2, .. }))
            ),
            "{:?}",
            decode(&b)
        );
    }
    // A NaN mean (first component's first mean value).
    let first = bytes.len() - 3 * 30;
    let mut b = bytes.clone();
    b[first..first + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    assert!(matches!(decode(&b), Err(DecodeError::Invalid(_))));
    // Out of range for the compact encoding: refused at encode time.
    let mut tiny = testutil::mixture3(2, 3, 0.01, 0.2);
    tiny[0].covariance = [1e-14, 0.0, 0.0, 1e-4, 0.0, 1e-4];
    assert!(Mixture::Spatial(tiny).compact().is_err());
}

#[test]
fn invalid_plans_and_grids_are_rejected() {
    let plan = |f: &dyn Fn(&mut Plan)| {
        let mut p = testutil::plan(3, 5);
        f(&mut p);
        Envelope::new(0, 0, 0, 0, Payload::Plan(p))
    };
    assert!(
        rejected(&plan(&|p| p.knots.clear()))
            .to_string()
            .contains("no knots")
    );
    assert!(
        rejected(&plan(&|p| p.knots[2].t_s = -1.0))
            .to_string()
            .contains("earlier")
    );
    assert!(
        rejected(&plan(&|p| p.knots[0].t_s = -0.5))
            .to_string()
            .contains("negative")
    );
    assert!(
        rejected(&plan(&|p| p.knots[4].yaw_rad = f32::NAN))
            .to_string()
            .contains("NaN")
    );

    let grid = |f: &dyn Fn(&mut GridChangeSet)| {
        let mut g = testutil::grid(3, 10);
        f(&mut g);
        Envelope::new(0, 0, 0, 0, Payload::GridChanges(g))
    };
    assert!(
        rejected(&grid(&|g| g.changes[9].index = 2_000_000))
            .to_string()
            .contains("outside")
    );
    assert!(
        rejected(&grid(&|g| g.changes.swap(1, 2)))
            .to_string()
            .contains("increasing")
    );
    assert!(
        rejected(&grid(&|g| g.changes[0].log_odds = f32::NAN))
            .to_string()
            .contains("NaN")
    );
    assert!(
        rejected(&grid(&|g| g.dims.height = 0))
            .to_string()
            .contains("zero")
    );
    assert!(
        rejected(&grid(&|g| g.origin_m[1] = f32::INFINITY))
            .to_string()
            .contains("origin")
    );
}

#[test]
fn normalise_sorts_and_keeps_the_last_value() {
    let mut g = GridChangeSet {
        dims: GridDims {
            width: 10,
            height: 10,
            length: 10,
        },
        origin_m: [0.0; 3],
        changes: vec![
            CellChange {
                index: 5,
                log_odds: 1.0,
            },
            CellChange {
                index: 2,
                log_odds: 2.0,
            },
            CellChange {
                index: 5,
                log_odds: 3.0,
            },
        ],
    };
    g.normalise();
    assert_eq!(
        g.changes,
        vec![
            CellChange {
                index: 2,
                log_odds: 2.0
            },
            CellChange {
                index: 5,
                log_odds: 3.0
            }
        ]
    );
}

#[test]
fn encoder_refuses_a_wrong_class_and_oversized_messages() {
    let mut e = Envelope::new(0, 0, 0, 0, Payload::Plan(testutil::plan(1, 2)));
    e.class = Class::Bulk;
    assert!(matches!(encode(&e), Err(EncodeError::ClassMismatch { .. })));
    // 100k 4D components = 6 MB > 4 MiB.
    let big = keyframe(Mixture::SpatialIntensity(testutil::mixture4(
        1, 70_000, 0.01, 0.2,
    )));
    assert!(matches!(encode(&big), Err(EncodeError::TooLarge(_))));
}

#[test]
fn truncated_keyframes_are_malformed() {
    let bytes = encode(&keyframe(Mixture::Spatial(testutil::mixture3(
        1, 5, 0.01, 0.2,
    ))))
    .unwrap();
    for cut in [1, 10, 40, bytes.len() - 1] {
        assert!(
            matches!(decode(&bytes[..cut]), Err(DecodeError::Malformed(_))),
            "cut at {cut}"
        );
    }
}

/// A 3D mixture as 4D with an independent unit intensity (for shared checks).
fn to4(m: &Mixture) -> Mixture {
    match m {
        Mixture::Spatial(c) => Mixture::SpatialIntensity(
            c.iter()
                .map(|c| {
                    let v = c.covariance;
                    Component4 {
                        mean: [c.mean[0], c.mean[1], c.mean[2], 0.0],
                        covariance: [v[0], v[1], v[2], 0.0, v[3], v[4], 0.0, v[5], 0.0, 1.0],
                        weight: c.weight,
                    }
                })
                .collect(),
        ),
        other => other.clone(),
    }
}

fn any_mixture() -> impl Strategy<Value = Mixture> {
    (any::<u64>(), 1usize..40, 0u8..4).prop_map(|(seed, n, kind)| match kind {
        0 => Mixture::Spatial(testutil::mixture3(seed, n, 0.005, 0.5)),
        1 => Mixture::SpatialIntensity(testutil::mixture4(seed, n, 0.005, 0.5)),
        2 => Mixture::Spatial(testutil::mixture3(seed, n, 0.005, 0.5))
            .compact()
            .unwrap(),
        _ => Mixture::SpatialIntensity(testutil::mixture4(seed, n, 0.005, 0.5))
            .compact()
            .unwrap(),
    })
}

fn any_envelope() -> impl Strategy<Value = Envelope> {
    (
        any::<u32>(),
        any::<u32>(),
        any::<u64>(),
        any::<u64>(),
        any::<u64>(),
        0u8..3,
        any_mixture(),
        0usize..60,
    )
        .prop_map(|(team, sender, seq, stamp, seed, kind, mixture, n)| {
            let payload = match kind {
                0 => Payload::Keyframe(Keyframe {
                    keyframe_id: seed as u32,
                    sensor_pose: testutil::pose(),
                    support_size: (seed >> 32) as u32,
                    mixture,
                }),
                1 => Payload::Plan(testutil::plan(seed, n + 1)),
                _ => Payload::GridChanges(testutil::grid(seed, n)),
            };
            Envelope::new(team, sender, seq, stamp, payload)
        })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 128, ..ProptestConfig::default() })]

    #[test]
    fn every_message_round_trips_bit_exactly(e in any_envelope()) {
        let bytes = encode(&e).unwrap();
        let back = decode(&bytes).unwrap();
        prop_assert_eq!(&back, &e);
        prop_assert_eq!(encode(&back).unwrap(), bytes);
    }

    #[test]
    fn compact_round_trip_is_stable(m in any_mixture()) {
        // Expanding and compacting again reproduces the same mixture, up to one
        // quantisation step (f32 rounding of the expanded covariance can move a
        // code by one; proptest-regressions holds such a case).
        let c = m.compact().unwrap();
        let again = c.expand().compact().unwrap();
        let (Mixture::SpatialIntensity(a), Mixture::SpatialIntensity(b)) =
            (to4(&c.expand()), to4(&again.expand()))
        else {
            unreachable!()
        };
        for (a, b) in a.iter().zip(&b) {
            prop_assert_eq!(a.mean, b.mean);
            prop_assert!((a.weight / b.weight - 1.0).abs() < 1e-3);
            let (ma, mb) = (a.covariance_matrix(), b.covariance_matrix());
            for i in 0..4 {
                for j in 0..4 {
                    let scale = (ma[i][i] * ma[j][j]).sqrt();
                    prop_assert!((ma[i][j] - mb[i][j]).abs() <= 2e-3 * scale, "{:?} vs {:?}", ma, mb);
                }
            }
        }
    }

    #[test]
    fn mutated_valid_messages_never_panic(
        e in any_envelope(),
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8),
        cut in any::<prop::sample::Index>(),
    ) {
        let mut bytes = encode(&e).unwrap();
        for (i, v) in edits {
            let i = i.index(bytes.len());
            bytes[i] = v;
        }
        let _ = decode(&bytes);
        let _ = decode(&bytes[..cut.index(bytes.len())]);
    }

    #[test]
    fn random_bodies_behind_a_valid_header_never_panic(
        variant in 0u8..8,
        body in proptest::collection::vec(any::<u8>(), 0..512),
    ) {
        // Header of a keyframe envelope, then a payload variant and random bytes.
        let mut bytes = vec![FORMAT_VERSION as u8, 1, 1, 0, 1, 2, 1, variant];
        bytes.extend(body);
        let _ = decode(&bytes);
    }
}
