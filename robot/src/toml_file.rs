//! Reading the TOML files a user writes (robot, scenario, base, study files) with
//! errors that name the file, the key, the line and the column, and the one error of a
//! settings file (a robot process's, a hardware robot's or a base station's):
//! [`SettingsFileError`].

use std::fmt;
use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;
use troupe_comms::transport::TransportError;

use crate::ConfigError;

/// Where in a TOML file something went wrong.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TomlPlace {
    /// Dotted key (`robot.link.class`), when the problem is a key's value.
    pub key: Option<String>,
    /// 1-based line and column, when TOML reports a position.
    pub line_column: Option<(usize, usize)>,
}

impl fmt::Display for TomlPlace {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut sep = "";
        if let Some(key) = &self.key {
            write!(f, "`{key}`")?;
            sep = ", ";
        }
        if let Some((line, column)) = self.line_column {
            write!(f, "{sep}line {line}, column {column}")?;
        }
        Ok(())
    }
}

/// A TOML file that could not be read or does not have the expected shape.
#[derive(Debug, thiserror::Error)]
pub enum TomlFileError {
    /// The file cannot be read.
    #[error("cannot read {}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// Not valid TOML, an unknown key, a missing key or a value of the wrong type.
    #[error("{}: {place}: {message}", path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// The key and position (boxed to keep the error small).
        place: Box<TomlPlace>,
        /// TOML's or serde's description of the problem.
        message: String,
    },
}

/// A settings file (robot process, hardware robot or base station) that cannot be
/// used: each of their errors wraps it.
#[derive(Debug, thiserror::Error)]
pub enum SettingsFileError {
    /// The file cannot be read or does not have the expected shape.
    #[error(transparent)]
    Toml(#[from] TomlFileError),
    /// A value breaks a rule.
    #[error("{}: invalid setting", path.display())]
    Config {
        /// The file.
        path: PathBuf,
        /// The key, the rule and the value.
        source: ConfigError,
    },
    /// A zenoh table is invalid.
    #[error("{}: invalid `[{table}]` table", path.display())]
    Zenoh {
        /// The file.
        path: PathBuf,
        /// The table (`zenoh`, `ros2.zenoh`).
        table: &'static str,
        /// The transport's error.
        source: TransportError,
    },
}

impl SettingsFileError {
    /// A value of the file at `path` breaks a rule.
    #[must_use]
    pub fn config(path: &Path, source: ConfigError) -> Self {
        SettingsFileError::Config {
            path: path.to_path_buf(),
            source,
        }
    }

    /// The zenoh table `table` of the file at `path` is invalid.
    #[must_use]
    pub fn zenoh(path: &Path, table: &'static str, source: TransportError) -> Self {
        SettingsFileError::Zenoh {
            path: path.to_path_buf(),
            table,
            source,
        }
    }
}

/// Reads and deserializes the TOML file at `path`.
pub fn read_toml<T: DeserializeOwned>(path: &Path) -> Result<T, TomlFileError> {
    let text = std::fs::read_to_string(path).map_err(|source| TomlFileError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    parse_toml(&text, path)
}

/// Deserializes TOML `text`; `path` names it in errors.
pub fn parse_toml<T: DeserializeOwned>(text: &str, path: &Path) -> Result<T, TomlFileError> {
    let error = |key: Option<String>, e: &toml::de::Error| TomlFileError::Parse {
        path: path.to_path_buf(),
        place: Box::new(TomlPlace {
            key,
            line_column: e.span().map(|span| line_column(text, span.start)),
        }),
        message: e.message().trim_end().to_owned(),
    };
    let de = toml::Deserializer::parse(text).map_err(|e| error(None, &e))?;
    serde_path_to_error::deserialize(de).map_err(|e| {
        let key = e.path().to_string();
        let key = (!key.is_empty() && key != ".").then_some(key);
        error(key, e.inner())
    })
}

/// The key of a robot's keyframe policy in a robot or scenario file: robot
/// processes make keyframes store-and-forward unless it is named
/// ([`LinkConfig::with_process_keyframes`](troupe_actors::link::LinkConfig::with_process_keyframes)).
pub const KEYFRAME_POLICY_KEY: &str = "robot.link.shaper.keyframe.policy";

/// Whether TOML `text` names the dotted `key` (`robot.link.shaper.keyframe.policy`),
/// for a default that depends on whether the user chose the value; `false` when the
/// text is not TOML (its parse reports that).
#[must_use]
pub fn names_key(text: &str, key: &str) -> bool {
    let Ok(table) = text.parse::<toml::Table>() else {
        return false;
    };
    let mut parts = key.split('.');
    let Some(first) = parts.next() else {
        return false;
    };
    let mut value = table.get(first);
    for part in parts {
        value = value.and_then(|v| v.as_table()).and_then(|t| t.get(part));
    }
    value.is_some()
}

/// The 1-based line and column of byte `offset` in `text`.
fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let column = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
    (line, column)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct File {
        id: u32,
        inner: Inner,
    }

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Inner {
        rate_hz: f64,
    }

    fn parse(text: &str) -> String {
        parse_toml::<File>(text, Path::new("f.toml"))
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn errors_name_the_file_key_and_position() {
        assert!(
            parse_toml::<File>("id = 1\n[inner]\nrate_hz = 2.0\n", Path::new("f.toml")).is_ok()
        );
        let e = parse("id = 1\n[inner]\nrate_hz = \"fast\"\n");
        assert!(
            e.starts_with("f.toml: `inner.rate_hz`, line 3, column 11: "),
            "{e}"
        );
        let e = parse("id = 1\nspeed = 2\n[inner]\nrate_hz = 2.0\n");
        assert!(
            e.contains("line 2, column 1") && e.contains("unknown field `speed`"),
            "{e}"
        );
        let e = parse("id = 1\n[inner\n");
        assert!(e.starts_with("f.toml: line 2"), "{e}");
        let e = parse("id = 1\n");
        assert!(
            e.starts_with("f.toml: ") && e.contains("missing field `inner`"),
            "{e}"
        );
        assert!(!e.contains('\n'));
        let missing = read_toml::<File>(Path::new("/nonexistent/f.toml")).unwrap_err();
        assert_eq!(missing.to_string(), "cannot read /nonexistent/f.toml");
    }

    #[test]
    fn names_key_finds_dotted_keys_in_tables_and_inline_tables() {
        let key = "robot.link.shaper.keyframe.policy";
        assert!(names_key(
            "[robot.link.shaper.keyframe]\npolicy = \"drop_oldest\"\n",
            key
        ));
        assert!(names_key(
            "[robot.link]\nshaper = { keyframe = { policy = \"keep_latest\" } }\n",
            key
        ));
        assert!(!names_key(
            "[robot.link.shaper.keyframe]\ncapacity_messages = 8\n",
            key
        ));
        assert!(!names_key("[robot]\nspeed_mps = 1.0\n", key));
        assert!(!names_key("[robot\n", key));
    }
}
