//! Configuration values that break a rule.

use std::borrow::Cow;
use std::fmt;

/// A configuration value that is not acceptable: names the key, the rule and the value
/// (DESIGN §8: one clear sentence naming the key and the expected value).
///
/// Every `validate` of a troupe settings type returns it with the key relative to its
/// own table; the caller that owns the enclosing table prefixes it with
/// [`ConfigError::within`], so the user reads the full dotted path.
///
/// ```
/// use troupe_core::ConfigError;
/// let e = ConfigError::positive("rate_hz", -1.0).unwrap_err().within("planner");
/// assert_eq!(e.key, "planner.rate_hz");
/// assert_eq!(e.to_string(), "`planner.rate_hz` must be a finite number > 0, got -1");
/// ```
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ConfigError {
    /// Dotted key, relative to the table that was validated.
    pub key: String,
    /// What the value must be.
    pub rule: Cow<'static, str>,
    /// The value as given.
    pub value: String,
}

impl ConfigError {
    /// `key` breaks `rule` with `value`.
    #[must_use]
    pub fn new(
        key: impl Into<String>,
        rule: impl Into<Cow<'static, str>>,
        value: impl fmt::Display,
    ) -> Self {
        ConfigError {
            key: key.into(),
            rule: rule.into(),
            value: value.to_string(),
        }
    }

    /// The same error with its key inside `table` (`table.key`).
    #[must_use]
    pub fn within(mut self, table: &str) -> Self {
        self.key = if self.key.is_empty() {
            table.to_owned()
        } else {
            format!("{table}.{}", self.key)
        };
        self
    }

    /// Checks that `value` is a finite number > 0.
    pub fn positive(key: &str, value: f64) -> Result<(), ConfigError> {
        if value.is_finite() && value > 0.0 {
            Ok(())
        } else {
            Err(ConfigError::new(key, "must be a finite number > 0", value))
        }
    }

    /// Checks that `value` is a finite number ≥ 0.
    pub fn non_negative(key: &str, value: f64) -> Result<(), ConfigError> {
        if value.is_finite() && value >= 0.0 {
            Ok(())
        } else {
            Err(ConfigError::new(key, "must be a finite number ≥ 0", value))
        }
    }
}

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "`{}` {}, got {}", self.key, self.rule, self.value)
    }
}

impl std::error::Error for ConfigError {}
