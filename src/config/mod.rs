//! Configuration: drive dictionaries and machine files, both TOML.
//!
//! Loading is strict: unknown keys are errors (`deny_unknown_fields`), and after parsing every
//! value is validated. Every error names the file, the table and the key, and the bound that was
//! broken, so the integrator can fix the file without reading code.

pub mod dictionary;
pub mod machine;

use std::path::{Path, PathBuf};

pub use dictionary::{Access, DriveDictionary, ObjectDef, SubDef};
pub use machine::{AxisConfig, AxisMode, Machine, PdoConfig};

/// A configuration error: which file, which table and key, and what is wrong.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read, is not a regular file, too large, or not text (see
    /// [`crate::files`]).
    #[error(transparent)]
    File(#[from] crate::files::FileError),
    /// The file is not valid TOML or does not fit the schema (unknown key, wrong type).
    #[error("{file}: {message}")]
    Parse {
        /// The file.
        file: PathBuf,
        /// The TOML parser's message (it names the line, column and key).
        message: String,
    },
    /// A value broke a rule.
    #[error("{file}: [{table}] {key}: {message}")]
    Invalid {
        /// The file.
        file: PathBuf,
        /// The table, e.g. `axis X` or `object 0x6040 sub 0`.
        table: String,
        /// The key.
        key: String,
        /// What is wrong, with the bound.
        message: String,
    },
    /// A file that a key names (a drive dictionary) could not be loaded: the key, then why.
    #[error("{file}: [{table}] {key}: {source}")]
    Referenced {
        /// The file that names it.
        file: PathBuf,
        /// The table, e.g. `axis X`.
        table: String,
        /// The key, e.g. `dictionary`.
        key: String,
        /// Why the named file could not be loaded (it names that file).
        source: Box<ConfigError>,
    },
}

pub(crate) fn read_toml<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T, ConfigError> {
    let text = crate::files::read_text(path, crate::files::MAX_CONFIG_BYTES)?;
    parse_toml(path, &text)
}

pub(crate) fn parse_toml<T: serde::de::DeserializeOwned>(
    path: &Path,
    text: &str,
) -> Result<T, ConfigError> {
    toml::from_str(text).map_err(|e| ConfigError::Parse {
        file: path.to_path_buf(),
        message: toml_message(&e, text),
    })
}

/// The parser's message with the line and column of the error, and without the excerpt of the
/// file that the parser's own `Display` quotes: a path given by mistake (a key pointing at
/// `/etc/shadow`) must not have its contents printed.
fn toml_message(e: &toml::de::Error, text: &str) -> String {
    let message = e.message().trim_end();
    match e.span().and_then(|s| text.get(..s.start)) {
        Some(before) => {
            let line = before.matches('\n').count() + 1;
            let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
            format!("line {line}, column {column}: {message}")
        }
        None => message.to_string(),
    }
}
