//! Configuration: drive dictionaries and machine files, both TOML.
//!
//! Loading is strict: unknown keys are errors (`deny_unknown_fields`), and after parsing every
//! value is validated. Every error names the file, the table and the key, and the bound that was
//! broken, so the integrator can fix the file without reading code.

pub mod dictionary;
pub mod machine;
pub mod operation;
pub mod tool_table;

use std::ops::Range;
use std::path::{Path, PathBuf};

pub use dictionary::{Access, DriveDictionary, ObjectDef, SubDef};
pub use machine::{AxisConfig, AxisKind, AxisMode, Machine, PdoConfig};

/// A configuration error: which file, which table and key, and what is wrong.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read, is not a regular file, too large, or not text (see
    /// [`crate::files`]).
    #[error(transparent)]
    File(#[from] crate::files::FileError),
    /// The file is not valid TOML or does not fit the schema (unknown key, wrong type, missing
    /// key). Displays as `file: line L, column C: [table] message`.
    #[error("{file}: {}{}{message}", at(line, column), TableTag(table.as_deref()))]
    Parse {
        /// The file.
        file: PathBuf,
        /// 1-based line of the error, when the parser gives its place.
        line: Option<usize>,
        /// 1-based column in characters, with `line`.
        column: Option<usize>,
        /// The table the error is in, e.g. `axis X`, `bus`, `object 0x1018 sub 0`; `None` at
        /// the top level (an unknown table, a missing one) or where the parser gives no place.
        table: Option<String>,
        /// The TOML parser's message (it names the key), without any excerpt of the file.
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
    toml::from_str(text).map_err(|e| parse_error(path, &e, text))
}

/// The parser's error with its line, column and table, and without the excerpt of the file
/// that the parser's own `Display` quotes: a path given by mistake (a key pointing at
/// `/etc/shadow`) must not have its contents printed.
fn parse_error(path: &Path, e: &toml::de::Error, text: &str) -> ConfigError {
    let span = e.span().filter(|s| text.get(..s.start).is_some());
    let (line, column) = match &span {
        Some(s) => {
            let before = &text[..s.start];
            let line = before.matches('\n').count() + 1;
            let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
            (Some(line), Some(column))
        }
        None => (None, None),
    };
    ConfigError::Parse {
        file: path.to_path_buf(),
        line,
        column,
        table: span.and_then(|s| table_at(text, s)),
        message: e.message().trim_end().to_string(),
    }
}

fn at(line: &Option<usize>, column: &Option<usize>) -> String {
    match (line, column) {
        (Some(l), Some(c)) => format!("line {l}, column {c}: "),
        (Some(l), None) => format!("line {l}: "),
        _ => String::new(),
    }
}

struct TableTag<'a>(Option<&'a str>);

impl std::fmt::Display for TableTag<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.0 {
            Some(t) => write!(f, "[{t}] "),
            None => Ok(()),
        }
    }
}

/// A `[table]` or `[[array]]` header of the document, with the name errors give it.
struct Header {
    span: Range<usize>,
    depth: usize,
    label: String,
    parent: Option<String>,
}

/// The table that the error at `span` of `text` is in, named as validation errors name it:
/// `bus`, `axis X` (an `[[axis]]` entry by its `name`), `object 0x1018 sub 0` (entries by
/// `index`, `sub` or `name`, else `#N`). Found from the document's own parse, not by scanning
/// lines, so a `[` in a multi-line string or array is not taken for a header. `None` at the
/// top level.
fn table_at(text: &str, span: Range<usize>) -> Option<String> {
    // A syntax error leaves the tables before it: enough to name the one it is in.
    let (doc, _) = toml::de::DeTable::parse_recoverable(text);
    let mut headers = Vec::new();
    collect_headers(doc.get_ref(), text, None, 0, &mut headers);
    // Inside a header's own brackets (an unknown `[table]`, a bad key of it): the key belongs
    // to the table above. The same span as a header: an error about that table as a whole
    // (a missing key).
    if let Some(h) = headers
        .iter()
        .filter(|h| h.span.contains(&span.start) && h.span != span)
        .min_by_key(|h| h.depth)
    {
        return h.parent.clone();
    }
    headers
        .iter()
        .filter(|h| h.span == span || h.span.end <= span.start)
        .max_by_key(|h| (h.span.start, h.depth))
        .map(|h| h.label.clone())
}

fn collect_headers(
    table: &toml::de::DeTable<'_>,
    text: &str,
    parent: Option<&str>,
    depth: usize,
    out: &mut Vec<Header>,
) {
    use toml::de::DeValue;
    let is_header = |s: &Range<usize>| text.get(s.clone()).is_some_and(|t| t.starts_with('['));
    let join = |name: String| match parent {
        Some(p) => format!("{p} {name}"),
        None => name,
    };
    for (key, value) in table.iter() {
        let key = crate::files::Escaped(key.get_ref()).to_string();
        match value.get_ref() {
            DeValue::Table(t) if is_header(&value.span()) => {
                let label = join(key);
                collect_headers(t, text, Some(&label), depth + 1, out);
                out.push(Header {
                    span: value.span(),
                    depth,
                    label,
                    parent: parent.map(str::to_string),
                });
            }
            DeValue::Array(entries) => {
                for (i, entry) in entries.iter().enumerate() {
                    let DeValue::Table(t) = entry.get_ref() else {
                        continue;
                    };
                    if !is_header(&entry.span()) {
                        continue;
                    }
                    let label = join(format!("{key} {}", entry_id(t, i)));
                    collect_headers(t, text, Some(&label), depth + 1, out);
                    out.push(Header {
                        span: entry.span(),
                        depth,
                        label,
                        parent: parent.map(str::to_string),
                    });
                }
            }
            _ => {}
        }
    }
}

/// How an `[[array]]` entry is named: `index = 0x1018` as `0x1018`, `sub = 1` as `1`,
/// `name = "X"` as `X` (short, its control characters escaped), else `#N` (1-based).
fn entry_id(t: &toml::de::DeTable<'_>, i: usize) -> String {
    let int = |key: &str| {
        let v = t.get(key)?.get_ref().as_integer()?;
        u64::from_str_radix(&v.as_str().replace('_', ""), v.radix()).ok()
    };
    if let Some(index) = int("index") {
        format!("0x{index:04X}")
    } else if let Some(sub) = int("sub") {
        sub.to_string()
    } else if let Some(name) = t.get("name").and_then(|v| v.get_ref().as_str()) {
        let mut short: String = name.chars().take(32).collect();
        if short.len() < name.len() {
            short.push('…');
        }
        crate::files::Escaped(&short).to_string()
    } else {
        format!("#{}", i + 1)
    }
}
