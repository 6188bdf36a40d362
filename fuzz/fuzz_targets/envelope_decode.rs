//! Fuzz target: `troupe_comms::wire::decode` on arbitrary bytes.
//!
//! Properties checked on every input:
//! - decoding never panics (libFuzzer reports a panic as a crash);
//! - whatever decodes re-encodes (the encoder accepts everything the decoder
//!   accepts) and decodes again to an equal envelope;
//! - the re-encoded bytes are canonical: encoding them once more gives the same bytes;
//! - a user payload (shared topic) that decodes has a valid name and the class its
//!   header says (the seed corpus holds two user messages to start from).
#![no_main]

use libfuzzer_sys::fuzz_target;
use troupe_comms::wire;

fuzz_target!(|data: &[u8]| {
    let Ok(envelope) = wire::decode(data) else {
        return;
    };
    if let wire::Payload::User(user) = &envelope.payload {
        assert!(wire::valid_user_name(&user.name), "accepted a bad name");
        assert_eq!(user.class, envelope.class, "accepted a class mismatch");
    }
    let bytes = match wire::encode(&envelope) {
        Ok(bytes) => bytes,
        Err(error) => panic!("decoded envelope does not re-encode: {error}"),
    };
    let again = match wire::decode(&bytes) {
        Ok(again) => again,
        Err(error) => panic!("re-encoded envelope does not decode: {error}"),
    };
    assert_eq!(again, envelope, "round trip changed the envelope");
    match wire::encode(&again) {
        Ok(twice) => assert_eq!(twice, bytes, "encoding is not canonical"),
        Err(error) => panic!("second encode failed: {error}"),
    }
});
