//! End-to-end frame signatures (issue 45 item 2, `docs/security.md`).
//!
//! zenoh's access control ([`super::security`]) judges the *session* a message
//! arrives from. A router forwards every member's frames, so it must be allowed to
//! put any id's key, and the robots behind it cannot tell its forwarding from its
//! own publishing: whoever holds the router's certificate could pose as any robot.
//! Signatures close that. With `[zenoh.signing]`, every frame a session sends
//! carries an ECDSA P-256 signature (64 bytes, in the zenoh attachment, after the
//! 4-byte addressee if any) by its member's private key (the key of its TLS
//! certificate, from `troupe keys`), and a receiver accepts a frame only if it is
//! signed by the key `signers` lists for the id the key expression names. The
//! router holds no robot's key, so it can forward but not forge.
//!
//! What is signed ([`signed_bytes`]): a domain tag, the team, the sender's id, the
//! frame's class, the addressee (or none) and the frame. A frame re-addressed,
//! moved to another team, id or class, or altered by one bit fails. A replayed
//! frame passes the signature and is the link's to refuse (message ids,
//! sequences, run starts: issue 45 item 5).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use ring::rand::SystemRandom;
use ring::signature::{
    ECDSA_P256_SHA256_FIXED, ECDSA_P256_SHA256_FIXED_SIGNING, EcdsaKeyPair, KeyPair as _,
    UnparsedPublicKey,
};
use rustls_pki_types::PrivatePkcs8KeyDer;
use rustls_pki_types::pem::PemObject as _;
use serde::{Deserialize, Serialize};

use super::config_error;
use crate::transport::TransportError;
use crate::wire::Class;

/// Bytes of a signature: P-256 `r ‖ s`, fixed length.
pub const SIGNATURE_BYTES: usize = 64;

/// Bytes of an uncompressed P-256 public key (SEC1: `04 ‖ x ‖ y`).
pub const PUBLIC_KEY_BYTES: usize = 65;

/// Tag in front of every signed message, so a signature made for a troupe frame
/// means nothing anywhere else (and a later format can change the tag).
const DOMAIN: &[u8] = b"troupe frame signature v1";

/// One member's public key in `[zenoh.signing]`.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ZenohSigner {
    /// The member's link id (a robot's index; the base station's id).
    pub id: u32,
    /// Its P-256 public key, uncompressed SEC1, hex (130 digits, starting `04`).
    pub public_key: String,
}

/// Frame signatures (a `[zenoh.signing]` table, written by `troupe keys`).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ZenohSigning {
    /// This member's private key (PKCS#8 PEM, P-256: its TLS key from `troupe keys`).
    pub key_path: PathBuf,
    /// Every member whose frames this session accepts, with its public key. Frames
    /// of ids not listed are refused.
    pub signers: Vec<ZenohSigner>,
}

/// Hex of `bytes`, lower case.
#[must_use]
pub fn to_hex(bytes: &[u8]) -> String {
    use std::fmt::Write as _;
    bytes.iter().fold(String::new(), |mut s, b| {
        let _ = write!(s, "{b:02x}");
        s
    })
}

fn from_hex(text: &str) -> Option<Vec<u8>> {
    if !text.len().is_multiple_of(2) || !text.is_ascii() {
        return None;
    }
    (0..text.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&text[i..i + 2], 16).ok())
        .collect()
}

impl ZenohSigning {
    /// Checks the table: a readable P-256 key, well-formed public keys, no id
    /// listed twice.
    pub fn validate(&self) -> Result<(), TransportError> {
        self.open(&[]).map(|_| ())
    }

    /// The public keys, ready to verify.
    fn verifier(&self) -> Result<FrameVerifier, TransportError> {
        let mut keys = BTreeMap::new();
        for s in &self.signers {
            let key = from_hex(&s.public_key)
                .filter(|k| k.len() == PUBLIC_KEY_BYTES && k[0] == 4)
                .ok_or_else(|| {
                    config_error(
                        "signing.signers",
                        format!(
                            "id {}: public_key is not {PUBLIC_KEY_BYTES} bytes of \
                             uncompressed P-256 key in hex",
                            s.id
                        ),
                    )
                })?;
            if keys.insert(s.id, key).is_some() {
                return Err(config_error(
                    "signing.signers",
                    format!("id {} is listed twice", s.id),
                ));
            }
        }
        Ok(FrameVerifier { keys })
    }

    /// The signer for a session whose robots are `local`, and the verifier: the
    /// key must be the one `signers` lists for every local id (one member's
    /// key signs only its own frames).
    pub fn open(&self, local: &[u32]) -> Result<(FrameSigner, FrameVerifier), TransportError> {
        let signer = FrameSigner::from_pem_file(&self.key_path)?;
        let verifier = self.verifier()?;
        for id in local {
            match verifier.keys.get(id) {
                Some(key) if key.as_slice() == signer.public_key() => {}
                Some(_) => {
                    return Err(config_error(
                        "signing.key_path",
                        format!(
                            "{} is not the key `signers` lists for id {id}",
                            self.key_path.display()
                        ),
                    ));
                }
                None => {
                    return Err(config_error(
                        "signing.signers",
                        format!("this session sends as id {id}, which is not listed"),
                    ));
                }
            }
        }
        Ok((signer, verifier))
    }
}

/// The bytes a frame's signature covers (see the module docs).
#[must_use]
pub fn signed_bytes(team: u32, from: u32, class: Class, to: Option<u32>, frame: &[u8]) -> Vec<u8> {
    let mut m = Vec::with_capacity(DOMAIN.len() + 14 + frame.len());
    m.extend_from_slice(DOMAIN);
    m.extend_from_slice(&team.to_le_bytes());
    m.extend_from_slice(&from.to_le_bytes());
    m.push(class.index() as u8);
    match to {
        Some(to) => {
            m.push(1);
            m.extend_from_slice(&to.to_le_bytes());
        }
        None => m.push(0),
    }
    m.extend_from_slice(frame);
    m
}

/// A member's private key.
pub struct FrameSigner {
    key: EcdsaKeyPair,
    rng: SystemRandom,
}

impl FrameSigner {
    /// Reads a PKCS#8 PEM P-256 key (as `troupe keys` writes them).
    pub fn from_pem_file(path: &Path) -> Result<Self, TransportError> {
        let key = "signing.key_path";
        let der = PrivatePkcs8KeyDer::from_pem_file(path)
            .map_err(|e| config_error(key, format!("{}: {e}", path.display())))?;
        let rng = SystemRandom::new();
        let pair = EcdsaKeyPair::from_pkcs8(
            &ECDSA_P256_SHA256_FIXED_SIGNING,
            der.secret_pkcs8_der(),
            &rng,
        )
        .map_err(|e| {
            config_error(
                key,
                format!("{}: not a P-256 private key ({e})", path.display()),
            )
        })?;
        Ok(FrameSigner { key: pair, rng })
    }

    /// The public key (uncompressed SEC1).
    #[must_use]
    pub fn public_key(&self) -> &[u8] {
        self.key.public_key().as_ref()
    }

    /// The signature of `message`, or `None` if the system's random source failed.
    #[must_use]
    pub fn sign(&self, message: &[u8]) -> Option<[u8; SIGNATURE_BYTES]> {
        let sig = self.key.sign(&self.rng, message).ok()?;
        sig.as_ref().try_into().ok()
    }
}

/// The public keys of the members whose frames a session accepts.
pub struct FrameVerifier {
    keys: BTreeMap<u32, Vec<u8>>,
}

impl FrameVerifier {
    /// Whether `signature` is `from`'s over `message` (false for an id not listed).
    #[must_use]
    pub fn verify(&self, from: u32, message: &[u8], signature: &[u8]) -> bool {
        self.keys.get(&from).is_some_and(|key| {
            UnparsedPublicKey::new(&ECDSA_P256_SHA256_FIXED, key)
                .verify(message, signature)
                .is_ok()
        })
    }
}

#[cfg(test)]
#[path = "signing_tests.rs"]
pub(crate) mod tests;
