use proptest::prelude::*;

use super::*;

fn odometry() -> Envelope {
    Envelope::new(
        7,
        1,
        42,
        123_456_789,
        Payload::Odometry(Odometry {
            position_m: [1.0, -2.0, 0.5],
            orientation_xyzw: [
                0.0,
                0.0,
                std::f64::consts::FRAC_1_SQRT_2,
                std::f64::consts::FRAC_1_SQRT_2,
            ],
            velocity_mps: [0.5, 0.0, 0.0],
        }),
    )
}

#[test]
fn odometry_round_trips_and_has_a_fixed_size() {
    let e = odometry();
    let bytes = encode(&e).unwrap();
    assert_eq!(decode(&bytes).unwrap(), e);
    // 1 (version) + 1 (team) + 1 (sender) + 1 (run start varint: 0) + 1 (seq)
    // + 1 (class) + 4 (stamp varint) + 1 (variant) + 10 × 8 (f64s).
    assert_eq!(bytes.len(), 91);
}

#[test]
fn golden_header_bytes() {
    let bytes = encode(&odometry()).unwrap();
    assert_eq!(&bytes[..6], &[FORMAT_VERSION as u8, 7, 1, 0, 42, 0]);
}

#[test]
fn a_run_start_travels_and_no_stamp_precedes_it() {
    let unix_ns = 1_790_000_000_000_000_000;
    let later = Envelope {
        stamp_ns: unix_ns + 5,
        ..odometry()
    }
    .from_run(unix_ns);
    assert_eq!(decode(&encode(&later).unwrap()).unwrap(), later);
    let before = Envelope {
        stamp_ns: unix_ns - 1,
        ..later.clone()
    };
    assert!(matches!(encode(&before), Err(EncodeError::Invalid(_))));
    // Bytes that claim a run starting after the message: refused on receipt.
    let forged = postcard::to_allocvec(&Envelope {
        run_start_ns: unix_ns + 6,
        ..later
    })
    .unwrap();
    assert!(matches!(decode(&forged), Err(DecodeError::Invalid(_))));
}

#[test]
fn rejects_bad_input_with_reasons() {
    let good = encode(&odometry()).unwrap();
    assert_eq!(decode(&[]), Err(DecodeError::Empty));
    assert!(matches!(
        decode(&good[..good.len() - 3]),
        Err(DecodeError::Malformed(_))
    ));
    let mut trailing = good.clone();
    trailing.push(0);
    assert_eq!(decode(&trailing), Err(DecodeError::TrailingBytes(1)));
    let mut version = good.clone();
    version[0] = 9;
    assert_eq!(decode(&version), Err(DecodeError::UnsupportedVersion(9)));
    let mut class = good.clone();
    class[5] = 2;
    assert!(matches!(
        decode(&class),
        Err(DecodeError::ClassMismatch { .. })
    ));
    let mut nan = odometry();
    if let Payload::Odometry(o) = &mut nan.payload {
        o.position_m[0] = f64::NAN;
    }
    assert!(matches!(
        decode(&postcard::to_allocvec(&nan).unwrap()),
        Err(DecodeError::Invalid(_))
    ));
    let mut skew = odometry();
    if let Payload::Odometry(o) = &mut skew.payload {
        o.orientation_xyzw = [0.0, 0.0, 0.0, 2.0];
    }
    assert!(matches!(
        decode(&postcard::to_allocvec(&skew).unwrap()),
        Err(DecodeError::Invalid(_))
    ));
    assert!(matches!(
        decode(&vec![1u8; MAX_MESSAGE_BYTES + 1]),
        Err(DecodeError::TooLarge(_))
    ));
}

/// Found by `cargo fuzz` (fuzz/, target `envelope_decode`): a grid change set whose
/// dimensions multiply past `u64` overflowed in `GridDims::cells` (a panic with
/// overflow checks, a wrapped and wrong cell count without).
#[test]
fn fuzz_regression_grid_dims_overflow() {
    let crash: [u8; 52] = [
        1, 1, 2, 3, 2, 128, 148, 235, 220, 3, 4, 4, 0, 0, 167, 176, 164, 193, 218, 3, 0, 0, 0, 0,
        0, 144, 191, 0, 0, 128, 191, 0, 0, 0, 0, 2, 1, 2, 0, 0, 205, 204, 76, 63, 7, 0, 0, 0, 205,
        204, 204, 190,
    ];
    assert!(decode(&crash).is_err());
    let huge = GridDims {
        width: u32::MAX,
        height: u32::MAX,
        length: u32::MAX,
    };
    assert_eq!(huge.cells(), u64::MAX);
    // A huge grid is valid, and its largest u32 index is inside it.
    let set = GridChangeSet {
        dims: huge,
        origin_m: [0.0; 3],
        changes: vec![CellChange {
            index: u32::MAX,
            log_odds: 0.5,
        }],
    };
    let e = Envelope::new(1, 2, 3, 4, Payload::GridChanges(set));
    assert_eq!(decode(&encode(&e).unwrap()).unwrap(), e);
}

proptest! {
    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..256)) {
        let _ = decode(&bytes);
    }

    #[test]
    fn mutated_messages_never_panic(index in 0usize..90, value in any::<u8>()) {
        let mut bytes = encode(&odometry()).unwrap();
        let i = index % bytes.len();
        bytes[i] = value;
        let _ = decode(&bytes);
    }

    #[test]
    fn heartbeats_round_trip(team in any::<u32>(), sender in any::<u32>(), seq in any::<u64>(), stamp in any::<u64>(), uptime in 0.0f64..1e9) {
        let e = Envelope::new(team, sender, seq, stamp, Payload::Heartbeat(Heartbeat { uptime_s: uptime }));
        prop_assert_eq!(decode(&encode(&e).unwrap()).unwrap(), e);
    }
}
