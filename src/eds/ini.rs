//! The INI layer of an EDS/DCF: text decoding (UTF-8 or Latin-1) and sections of keys, with
//! their line numbers.

use super::*;

/// UTF-8 when valid, else Latin-1 (EDS files from Windows tools often are).
pub(super) fn decode(bytes: &[u8]) -> String {
    match std::str::from_utf8(bytes) {
        Ok(s) => s.to_string(),
        Err(_) => bytes.iter().map(|&b| char::from(b)).collect(),
    }
}

// ---------------------------------------------------------------------------------------------
// INI
// ---------------------------------------------------------------------------------------------

/// One `key=value` line.
#[derive(Debug)]
pub(super) struct Entry {
    pub(super) key: String,
    pub(super) value: String,
    pub(super) line: usize,
}

/// One `[section]` and its keys in file order.
#[derive(Debug)]
pub(super) struct Section {
    pub(super) name: String,
    pub(super) line: usize,
    pub(super) entries: Vec<Entry>,
}

impl Section {
    /// The entry of `key` (case-insensitive).
    pub(super) fn get(&self, key: &str) -> Option<&Entry> {
        self.entries
            .iter()
            .find(|e| e.key.eq_ignore_ascii_case(key))
    }
    /// The entry of `key` when it has a non-blank value.
    pub(super) fn value(&self, key: &str) -> Option<&Entry> {
        self.get(key).filter(|e| !e.value.is_empty())
    }
}

/// An INI file: sections in file order, found case-insensitively.
#[derive(Debug)]
pub(super) struct Ini {
    pub(super) sections: Vec<Section>,
    pub(super) by_name: HashMap<String, usize>,
}

impl Ini {
    pub(super) fn section(&self, name: &str) -> Option<&Section> {
        self.by_name
            .get(&name.to_ascii_lowercase())
            .map(|&i| &self.sections[i])
    }
}

pub(super) fn parse_ini(text: &str) -> Result<Ini, (usize, String)> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut ini = Ini {
        sections: Vec::new(),
        by_name: HashMap::new(),
    };
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let t = raw.trim();
        if t.is_empty() || t.starts_with(';') || t.starts_with('#') {
            continue;
        }
        if let Some(rest) = t.strip_prefix('[') {
            let Some(end) = rest.find(']') else {
                return Err((line, format!("section header without ']': {t}")));
            };
            let name = rest[..end].trim();
            let after = rest[end + 1..].trim();
            if !(after.is_empty() || after.starts_with(';') || after.starts_with('#')) {
                return Err((line, format!("text after the section header: {after}")));
            }
            if name.is_empty() {
                return Err((line, "empty section name".to_string()));
            }
            let key = name.to_ascii_lowercase();
            if let Some(&j) = ini.by_name.get(&key) {
                return Err((
                    line,
                    format!(
                        "section [{name}] already defined at line {}",
                        ini.sections[j].line
                    ),
                ));
            }
            ini.by_name.insert(key, ini.sections.len());
            ini.sections.push(Section {
                name: name.to_string(),
                line,
                entries: Vec::new(),
            });
            continue;
        }
        let Some(sec) = ini.sections.last_mut() else {
            return Err((line, format!("{t:?} outside any [section]")));
        };
        let Some((k, v)) = t.split_once('=') else {
            return Err((
                line,
                format!("expected key=value in [{}], found {t:?}", sec.name),
            ));
        };
        let k = k.trim();
        if k.is_empty() {
            return Err((line, "missing key before '='".to_string()));
        }
        if let Some(prev) = sec.get(k) {
            return Err((
                line,
                format!(
                    "{k} given twice in [{}] (first at line {})",
                    sec.name, prev.line
                ),
            ));
        }
        sec.entries.push(Entry {
            key: k.to_string(),
            value: v.trim().to_string(),
            line,
        });
    }
    Ok(ini)
}

// ---------------------------------------------------------------------------------------------
// Numbers
// ---------------------------------------------------------------------------------------------
