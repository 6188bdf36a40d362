//! `troupe keys`: a team's credentials for mutual TLS with zenoh's access control
//! (issue 23, `docs/security.md`).
//!
//! Writes into one directory:
//!
//! - `ca.pem` (the team's certificate authority, which every member trusts) and
//!   `ca.key` (its private key: keep it off the robots; it only signs new members);
//! - `robot<i>.pem` / `robot<i>.key` for each robot, `base.pem` / `base.key` for the
//!   base station (link id = team size) and, for a team with a `troupe router`,
//!   `router.pem` / `router.key`: ECDSA P-256 certificates signed by the CA whose common name is
//!   the member's name ([`identity_name`]: `robot<id>`; the router's is `router`),
//!   usable as TLS server and client;
//! - `robot<i>.zenoh.toml`, `base.zenoh.toml` (and `router.zenoh.toml`): the `[zenoh]`
//!   tables that use them (`tls/` endpoints to fill in, `[zenoh.tls]` with
//!   `mutual = true`, `[zenoh.access]` naming every id and the router, if any, and,
//!   for the robots and the base, `[zenoh.signing]`: every frame signed with the
//!   member's key and only frames signed by their sender accepted, each id's public
//!   key listed), with paths relative to the snippet itself (a router runs on
//!   `router.zenoh.toml` as it is; in a robot file elsewhere, prefix the keys
//!   directory).
//!
//! Private keys are written with mode 0600 (on Unix).

use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

use rcgen::{
    BasicConstraints, CertificateParams, DnType, ExtendedKeyUsagePurpose, IsCa, Issuer, KeyPair,
    KeyUsagePurpose,
};
use troupe_comms::zenoh::ZenohSigner;
use troupe_comms::zenoh::security::identity_name;
use troupe_comms::zenoh::signing::to_hex;

/// The name (certificate common name) of the router that `troupe keys` writes.
pub const ROUTER_NAME: &str = "router";

/// Years a member certificate is valid from the year it is written.
const VALID_YEARS: i32 = 10;

/// Why credentials could not be written.
#[derive(Debug, thiserror::Error)]
pub enum KeysError {
    /// A key or certificate could not be made.
    #[error("making the certificate of {name}")]
    Certificate {
        /// The member (`ca`, `robot0`, ...).
        name: String,
        /// rcgen's error.
        #[source]
        source: rcgen::Error,
    },
    /// A file could not be written.
    #[error("writing {}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The error.
        #[source]
        source: std::io::Error,
    },
    /// The team has no robot.
    #[error("a team needs at least one robot")]
    EmptyTeam,
}

/// What [`write_team_keys`] wrote.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TeamKeys {
    /// The directory.
    pub dir: PathBuf,
    /// Robots in the team (ids `0..robots`); the base station's id is `robots`.
    pub robots: u32,
    /// Every file written.
    pub files: Vec<PathBuf>,
    /// The public key that signs each id's frames (robots and base; not the router,
    /// which signs nothing: `[zenoh.signing]`).
    pub signers: Vec<ZenohSigner>,
}

/// One member of the team: its file stem, its certificate's common name and its
/// link id (none for the router, which sends nothing of its own).
struct Member {
    stem: String,
    name: String,
    id: Option<u32>,
}

fn members(robots: u32, router: bool) -> Vec<Member> {
    let mut members: Vec<Member> = (0..robots)
        .map(|i| Member {
            stem: identity_name(i),
            name: identity_name(i),
            id: Some(i),
        })
        .collect();
    members.push(Member {
        stem: "base".into(),
        name: identity_name(robots),
        id: Some(robots),
    });
    if router {
        members.push(Member {
            stem: ROUTER_NAME.into(),
            name: ROUTER_NAME.into(),
            id: None,
        });
    }
    members
}

/// The current year (UTC), from the system clock.
fn this_year() -> i32 {
    let secs = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    // 365.2425 days a year: at worst a day off at the turn of a year, which the
    // validity's start a year back absorbs.
    1970 + i32::try_from(secs / 31_556_952).unwrap_or(0)
}

fn params(name: &str, year: i32) -> Result<CertificateParams, rcgen::Error> {
    let mut p = CertificateParams::new(vec![name.to_owned()])?;
    p.distinguished_name.push(DnType::CommonName, name);
    p.distinguished_name
        .push(DnType::OrganizationName, "troupe team");
    p.not_before = rcgen::date_time_ymd(year - 1, 1, 1);
    p.not_after = rcgen::date_time_ymd(year + VALID_YEARS, 1, 1);
    Ok(p)
}

/// Writes a new CA, one certificate per member and the `[zenoh]` snippets for a
/// team of `robots` robots into `dir` (see the module docs); the router's
/// certificate, and the right of a router to forward every member's keys, only
/// when the team has a `router`: an identity that may publish as every robot
/// exists only where one is needed. Existing files of the same names are replaced.
pub fn write_team_keys(dir: &Path, robots: u32, router: bool) -> Result<TeamKeys, KeysError> {
    if robots == 0 {
        return Err(KeysError::EmptyTeam);
    }
    let cert_error = |name: &str| {
        let name = name.to_owned();
        move |source| KeysError::Certificate { name, source }
    };
    std::fs::create_dir_all(dir).map_err(|source| KeysError::Write {
        path: dir.to_path_buf(),
        source,
    })?;
    let year = this_year();
    let mut files = Vec::new();
    let ca_key = KeyPair::generate().map_err(cert_error("ca"))?;
    let mut ca_params = params("troupe team CA", year).map_err(cert_error("ca"))?;
    ca_params.subject_alt_names.clear();
    ca_params.not_after = rcgen::date_time_ymd(year + VALID_YEARS + 1, 1, 1);
    ca_params.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
    ca_params.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign];
    let ca_cert = ca_params.self_signed(&ca_key).map_err(cert_error("ca"))?;
    write(dir, "ca.pem", &ca_cert.pem(), false, &mut files)?;
    write(dir, "ca.key", &ca_key.serialize_pem(), true, &mut files)?;
    let issuer = Issuer::new(ca_params, ca_key);
    let ids: Vec<String> = (0..=robots).map(|i| i.to_string()).collect();
    let routers = if router {
        format!("routers = [\"{ROUTER_NAME}\"]  # may forward every member's keys\n")
    } else {
        String::new()
    };
    let members = members(robots, router);
    let keys = members
        .iter()
        .map(|m| KeyPair::generate().map_err(cert_error(&m.name)))
        .collect::<Result<Vec<_>, _>>()?;
    let signers: Vec<ZenohSigner> = members
        .iter()
        .zip(&keys)
        .filter_map(|(m, key)| {
            Some(ZenohSigner {
                id: m.id?,
                public_key: to_hex(key.public_key_raw()),
            })
        })
        .collect();
    let signer_lines: String = signers
        .iter()
        .map(|s| {
            format!(
                "  {{ id = {}, public_key = \"{}\" }},\n",
                s.id, s.public_key
            )
        })
        .collect();
    for (member, key) in members.iter().zip(keys) {
        let mut p = params(&member.name, year).map_err(cert_error(&member.name))?;
        p.key_usages = vec![KeyUsagePurpose::DigitalSignature];
        p.extended_key_usages = vec![
            ExtendedKeyUsagePurpose::ServerAuth,
            ExtendedKeyUsagePurpose::ClientAuth,
        ];
        let cert = p
            .signed_by(&key, &issuer)
            .map_err(cert_error(&member.name))?;
        let stem = &member.stem;
        write(dir, &format!("{stem}.pem"), &cert.pem(), false, &mut files)?;
        write(
            dir,
            &format!("{stem}.key"),
            &key.serialize_pem(),
            true,
            &mut files,
        )?;
        let snippet = format!(
            "# The [zenoh] tables of {stem} (certificate common name `{name}`), written by\n\
             # `troupe keys`. Paths are relative to the file they are in: in a robot file\n\
             # elsewhere, prefix this directory. Fill in the endpoints.\n\
             [zenoh]\n\
             listen = [\"tls/0.0.0.0:7447\"]\n\
             connect = []  # tls/<host>:<port> of the others (or of the router)\n\
             \n\
             [zenoh.tls]\n\
             root_ca_path = \"ca.pem\"\n\
             cert_path = \"{stem}.pem\"\n\
             key_path = \"{stem}.key\"\n\
             mutual = true\n\
             \n\
             [zenoh.access]  # robot<id> may publish only as <id>\n\
             ids = [{ids}]\n\
             {routers}{signing}",
            name = member.name,
            ids = ids.join(", "),
            signing = if member.id.is_some() {
                format!(
                    "\n[zenoh.signing]  # frames signed with this key; only frames signed by \
                     their sender accepted\n\
                     key_path = \"{stem}.key\"\n\
                     signers = [\n{signer_lines}]\n"
                )
            } else {
                String::new()
            },
        );
        write(
            dir,
            &format!("{stem}.zenoh.toml"),
            &snippet,
            false,
            &mut files,
        )?;
    }
    Ok(TeamKeys {
        dir: dir.to_path_buf(),
        robots,
        files,
        signers,
    })
}

/// Writes `text` to `dir/name` (mode 0600 when `private`, on Unix).
fn write(
    dir: &Path,
    name: &str,
    text: &str,
    private: bool,
    files: &mut Vec<PathBuf>,
) -> Result<(), KeysError> {
    use std::io::Write as _;
    let path = dir.join(name);
    let error = |source| KeysError::Write {
        path: path.clone(),
        source,
    };
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create(true).truncate(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt as _;
        options.mode(if private { 0o600 } else { 0o644 });
    }
    #[cfg(not(unix))]
    let _ = private;
    let mut file = options.open(&path).map_err(error)?;
    file.write_all(text.as_bytes()).map_err(error)?;
    files.push(path);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_a_ca_a_certificate_per_member_and_valid_snippets() {
        let dir = tempfile::tempdir().unwrap();
        let keys_dir = dir.path().join("keys");
        let keys = write_team_keys(&keys_dir, 2, true).unwrap();
        for name in [
            "ca.pem",
            "ca.key",
            "robot0.pem",
            "robot1.key",
            "base.pem",
            "router.key",
        ] {
            assert!(keys_dir.join(name).is_file(), "{name}");
        }
        assert_eq!(keys.files.len(), 2 + 4 * 3);
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt as _;
            let mode = std::fs::metadata(keys_dir.join("robot0.key"))
                .unwrap()
                .permissions()
                .mode();
            assert_eq!(mode & 0o777, 0o600);
        }
        // The base's snippet is a valid secure [zenoh] table as it is.
        #[derive(serde::Deserialize)]
        struct File {
            zenoh: troupe_comms::zenoh::ZenohConfig,
        }
        let text = std::fs::read_to_string(keys_dir.join("base.zenoh.toml")).unwrap();
        let mut file: File = toml::from_str(&text).unwrap();
        file.zenoh.resolve_paths(&keys_dir);
        file.zenoh.validate().unwrap();
        let access = file.zenoh.access.as_ref().unwrap();
        assert_eq!(access.ids, vec![0, 1, 2]);
        assert!(file.zenoh.tls.as_ref().unwrap().mutual);
        assert_eq!(access.routers, vec![ROUTER_NAME.to_owned()]);
        // Robots and the base sign with their own keys; the router signs nothing.
        let signing = file.zenoh.signing.as_ref().unwrap();
        assert_eq!(signing.key_path, keys_dir.join("base.key"));
        assert_eq!(signing.signers, keys.signers);
        assert_eq!(
            keys.signers.iter().map(|s| s.id).collect::<Vec<_>>(),
            [0, 1, 2]
        );
        let router: File =
            toml::from_str(&std::fs::read_to_string(keys_dir.join("router.zenoh.toml")).unwrap())
                .unwrap();
        assert!(router.zenoh.signing.is_none());
        assert!(matches!(
            write_team_keys(&keys_dir, 0, false),
            Err(KeysError::EmptyTeam)
        ));
    }

    /// Issue 45, item 2: without a router there is no router identity, and no
    /// member's access control lets anyone forward (publish as every robot).
    #[test]
    fn a_team_without_a_router_gets_no_router_identity() {
        #[derive(serde::Deserialize)]
        struct File {
            zenoh: troupe_comms::zenoh::ZenohConfig,
        }
        let dir = tempfile::tempdir().unwrap();
        let keys = write_team_keys(dir.path(), 2, false).unwrap();
        assert_eq!(keys.files.len(), 2 + 3 * 3);
        assert!(!dir.path().join("router.pem").exists());
        for stem in ["robot0", "robot1", "base"] {
            let text =
                std::fs::read_to_string(dir.path().join(format!("{stem}.zenoh.toml"))).unwrap();
            let file: File = toml::from_str(&text).unwrap();
            let access = file.zenoh.access.unwrap();
            assert!(access.routers.is_empty(), "{stem}: {:?}", access.routers);
        }
    }
}
