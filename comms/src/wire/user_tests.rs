//! User payloads: golden bytes, size, rejection of bad names and hostile bytes.

use proptest::prelude::*;

use super::*;

fn report(body: Vec<u8>) -> Envelope {
    Envelope::new(
        7,
        1,
        3,
        1_000,
        Payload::User(UserMessage {
            class: Class::Plan,
            name: "artifacts/report".into(),
            version: 2,
            to: None,
            body,
        }),
    )
}

#[test]
fn golden_user_message_bytes() {
    let bytes = encode(&report(vec![0xAA, 0xBB, 0xCC])).unwrap();
    let mut expected = vec![
        FORMAT_VERSION as u8, // version
        7,                    // team
        1,                    // sender
        0,                    // run start (varint)
        3,                    // sequence
        1,                    // header class: Plan
        0xE8,
        0x07, // stamp 1000 (varint)
        5,    // payload variant: User
        1,    // class: Plan
        16,   // name length
    ];
    expected.extend_from_slice(b"artifacts/report");
    expected.extend_from_slice(&[2, 0]); // version 2, fixed little-endian
    expected.push(0); // to: None
    expected.extend_from_slice(&[3, 0xAA, 0xBB, 0xCC]); // body
    assert_eq!(bytes, expected);
    assert_eq!(decode(&bytes).unwrap(), report(vec![0xAA, 0xBB, 0xCC]));
}

#[test]
fn a_20_byte_report_costs_42_payload_bytes() {
    let e = report(vec![1; 20]);
    let payload = postcard::to_allocvec(&e.payload).unwrap();
    // 1 (variant) + the 42 bytes of the module docs.
    assert_eq!(payload.len(), 1 + 42);
}

#[test]
fn the_class_follows_the_share_policy() {
    let mut e = report(vec![]);
    assert_eq!(e.class, Class::Plan);
    if let Payload::User(u) = &mut e.payload {
        u.class = Class::Bulk;
    }
    assert!(matches!(encode(&e), Err(EncodeError::ClassMismatch { .. })));
}

#[test]
fn bad_names_are_refused_both_ways() {
    for name in ["", "with space", "ünïcode", &"x".repeat(65)] {
        let mut e = report(vec![1]);
        if let Payload::User(u) = &mut e.payload {
            u.name = name.into();
        }
        assert!(
            matches!(encode(&e), Err(EncodeError::Invalid(_))),
            "{name:?}"
        );
        let raw = postcard::to_allocvec(&e).unwrap();
        assert!(
            matches!(decode(&raw), Err(DecodeError::Invalid(_))),
            "{name:?}"
        );
    }
    assert!(valid_user_name("a/b_c-d.e9"));
    assert!(valid_user_name(&"x".repeat(64)));
}

#[test]
fn truncated_user_messages_are_malformed() {
    let bytes = encode(&report(vec![9; 40])).unwrap();
    for cut in 1..bytes.len() {
        assert!(
            matches!(decode(&bytes[..cut]), Err(DecodeError::Malformed(_))),
            "cut at {cut}"
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn user_messages_round_trip_and_mutations_never_panic(
        body in proptest::collection::vec(any::<u8>(), 0..300),
        version in any::<u16>(),
        to in proptest::option::of(any::<u32>()),
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6),
    ) {
        let mut e = report(body);
        if let Payload::User(u) = &mut e.payload {
            u.version = version;
            u.to = to;
        }
        let bytes = encode(&e).unwrap();
        prop_assert_eq!(&decode(&bytes).unwrap(), &e);
        let mut mutated = bytes.clone();
        for (i, v) in edits {
            let i = i.index(mutated.len());
            mutated[i] = v;
        }
        if let Ok(back) = decode(&mutated) {
            prop_assert_eq!(decode(&encode(&back).unwrap()).unwrap(), back);
        }
    }
}
