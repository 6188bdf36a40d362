//! Frame signatures: the keys a table accepts and what a signature covers (two
//! signing sessions on loopback are in `zenoh/tests.rs`).

use super::*;
use crate::zenoh::ZenohConfig;

/// A new P-256 key written as `troupe keys` writes it: the PEM file and the public
/// key's hex.
pub(crate) fn member_key(dir: &Path, name: &str) -> (PathBuf, String) {
    let pair = rcgen::KeyPair::generate().unwrap();
    let path = dir.join(format!("{name}.key"));
    std::fs::write(&path, pair.serialize_pem()).unwrap();
    (path, to_hex(pair.public_key_raw()))
}

/// The table of `key_path` accepting `signers` (id, public key hex).
pub(crate) fn signing(key_path: &Path, signers: &[(u32, &str)]) -> ZenohSigning {
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
