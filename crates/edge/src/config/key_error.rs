//! The one error shape of every section's check: the dotted key and what is wrong. The section
//! does not know where its values were written; [`super::Config::validate`]'s caller places the
//! error in the file (its line) or in the `--set` that gave the key.

/// A bad value of one key, e.g. `KeyError { key: "output.modbus.listen", message: "must be HOST:PORT, ..." }`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("key `{key}`: {message}")]
pub struct KeyError {
    /// Dotted key, e.g. `output.modbus.listen`.
    pub key: String,
    /// What is wrong, e.g. `must be HOST:PORT, got "nope"`.
    pub message: String,
}

impl KeyError {
    /// The error of `key`.
    pub fn new(key: impl Into<String>, message: impl Into<String>) -> Self {
        Self { key: key.into(), message: message.into() }
    }

    /// A message that starts with its dotted key (`motion.min_age_s must be ...`), as the core's
    /// stage sections phrase theirs; the whole message is kept.
    pub fn leading_key(message: impl Into<String>) -> Self {
        let message = message.into();
        Self { key: message.split_whitespace().next().unwrap_or("?").to_string(), message }
    }
}

/// `Err` naming `key` unless `ok`: the shape of most section checks.
pub fn ensure(ok: bool, key: &str, message: impl Into<String>) -> Result<(), KeyError> {
    if ok { Ok(()) } else { Err(KeyError::new(key, message)) }
}
