//! EDS/DCF import (CiA 306): `canmotion dict import FILE.eds -o dictionaries/drives/NAME.toml`.
//!
//! An EDS (electronic data sheet) describes a device type's object dictionary as an INI file; a
//! DCF (device configuration file) is the same format for one configured device, with
//! `ParameterValue`s and a `[DeviceComissioning]` section. [`import_file`] reads either and
//! produces the drive dictionary TOML of [`crate::config::dictionary`]; every generated text is
//! loaded back with [`DriveDictionary::parse`] before it is returned, so the importer never hands
//! out a file the loader refuses.
//!
//! ## What is read
//!
//! - INI syntax: `[section]`, `key=value`, `;` and `#` comment lines, section names and keys
//!   case-insensitive, a UTF-8 BOM, CRLF; a file that is not UTF-8 is read as Latin-1. Duplicate
//!   sections or keys are errors.
//! - `[DeviceInfo]` `VendorName`, `ProductName`, `VendorNumber`, `ProductNumber`,
//!   `RevisionNumber`; `[FileInfo]` and `[Comments]` go into the header comment; `[DummyUsage]`
//!   is noted (our format has no dummy entries).
//! - `[MandatoryObjects]`, `[OptionalObjects]`, `[ManufacturerObjects]`: a listed object without
//!   its section, and a section in no list, are noted (the sections are what is imported).
//! - `[XXXX]` objects and `[XXXXsubY]` sub-objects (Y in hex): `ObjectType` (0x7 VAR, 0x8 ARRAY,
//!   0x9 RECORD, 0x2 DOMAIN; 0x0 NULL, 0x5 DEFTYPE, 0x6 DEFSTRUCT and indices below 0x1000 are
//!   type definitions and skipped), `ParameterName`, `DataType`, `AccessType`, `DefaultValue`,
//!   `ParameterValue` (a DCF's value: it wins over `DefaultValue`), `LowLimit`, `HighLimit`,
//!   `PDOMapping`, `Unit` (→ `unit`), `CompactSubObj` with `[XXXXName]` and `[XXXXValue]`.
//!   `ObjFlags`, `Denotation`, `SubNumber`, `Factor`, `Description` and the rest are ignored.
//! - Numbers per CiA 306: decimal, `0x` hexadecimal, octal with a leading `0`, optional sign; a
//!   hexadecimal value of a signed type is a two's-complement bit pattern (`0xFFFFFFFF` on an
//!   INTEGER32 is -1); a hexadecimal value of a REAL type is its IEEE 754 bit pattern.
//! - `$NODEID`, `$NODEID+n` and `n+$NODEID` (any case, spaces allowed). With a node id (the
//!   `--node` option, else a DCF's `[DeviceComissioning] NodeID`) they are resolved to numbers;
//!   without one they stay relative (`"$NODEID+0x180"`), which the dictionary format supports.
//!
//! ## Decisions where EDS and our format differ
//!
//! Each one is a `# EDS line N: ...` comment in the output, next to the entry concerned.
//!
//! - **Odd-width integers** (INTEGER24/40/48/56, UNSIGNED24/40/48/56) are widened to the next
//!   width of the format (i32, i64, u32, u64) and keep their value range with `min`/`max`; their
//!   PDO-mappable flag is dropped, because the sizes on the wire differ from the real device's
//!   (a 24-bit mapping entry could not be checked against a 32-bit entry).
//! - UNICODE_STRING becomes `string` (the text in UTF-8); TIME_OF_DAY and TIME_DIFFERENCE become
//!   `octets`; OCTET_STRING and DOMAIN defaults are hex digits (CiA 306), any other text is taken
//!   as its bytes; strings of any length are kept whole (up to 64 KiB); a default the format
//!   cannot carry (bytes ≥ 0x80 in an octet string, longer than 64 KiB, a u64 above i64::MAX) is
//!   replaced (empty, truncated, 0) with a note.
//!   Other data types (complex 0x20–0x25, manufacturer types 0x40…) are skipped with a note.
//! - `rwr` and `rww` become `rw` (they only say which PDO direction may map the entry).
//! - A PDO-mappable variable-length entry loses the flag (our loader cannot map it).
//! - Limits: a bound on a non-numeric type, a bound outside its type, a `$NODEID` bound without a
//!   node id are dropped; `LowLimit > HighLimit` drops both; a given default outside the range
//!   drops the bound it breaks (the default is the manufacturer's value).
//! - A missing default is 0 (false, 0.0, empty text), moved into `[LowLimit, HighLimit]` when 0
//!   is outside it.
//! - Identity: `[device]` takes 0x1000's default and 0x1018:1..3, filled from `[DeviceInfo]`
//!   where the objects lack them (0x1000 and 0x1018 are added when missing; no information at
//!   all gives 0). When `[DeviceInfo]` and a 0x1018 default disagree, `[DeviceInfo]` wins with a
//!   note naming both lines, or it is an error naming both with
//!   [`ImportOptions::strict_identity`].
//!
//! Malformed files are errors `file:line: what` (a sub-object without its parent, a bad number,
//! a VAR without `DataType`, an unknown `AccessType`, ...).

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use canopen_rs::DataType;

use crate::canopen::dictionary::{DriveDictionary, type_name};
use crate::canopen::index;

/// Longest string value the dictionary format holds ([`crate::canopen::MAX_OBJECT_BYTES`]).
const MAX_STRING: usize = crate::canopen::MAX_OBJECT_BYTES;

/// Why an import failed.
#[derive(Debug, thiserror::Error)]
pub enum EdsError {
    /// The file could not be read.
    #[error("{}: cannot read: {source}", file.display())]
    Read {
        /// The file.
        file: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file is not a regular file or is too large, or the output cannot be written there
    /// (see [`crate::files`]).
    #[error(transparent)]
    File(#[from] crate::files::FileError),
    /// The EDS is malformed at a line.
    #[error("{}:{line}: {message}", file.display())]
    Line {
        /// The EDS file.
        file: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// The dictionary could not be written.
    #[error("{}: cannot write: {source}", file.display())]
    Write {
        /// The output file.
        file: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The generated dictionary does not load: a bug of the importer.
    #[error("{}: internal error, the generated dictionary does not load: {message}", file.display())]
    Rejected {
        /// The EDS file.
        file: PathBuf,
        /// The loader's message.
        message: String,
    },
}

/// Options of an import.
#[derive(Debug, Clone, Copy, Default)]
pub struct ImportOptions {
    /// Resolve `$NODEID` for this node (1..=127). Without it a DCF's
    /// `[DeviceComissioning] NodeID` is used, and without that the values stay relative.
    pub node: Option<u8>,
    /// A contradiction between `[DeviceInfo]` and a 0x1018 default is an error (naming both
    /// lines) instead of `[DeviceInfo]` winning with a note.
    pub strict_identity: bool,
}

/// Something the import decided, at a line of the EDS (`None`: the file as a whole).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Note {
    /// 1-based line of the EDS.
    pub line: Option<usize>,
    /// What was decided.
    pub text: String,
}

/// A successful import.
#[derive(Debug, Clone)]
pub struct Imported {
    /// The dictionary as TOML text, in the format of `dictionaries/drives/*.toml`.
    pub toml: String,
    /// The same dictionary, as the loader reads it.
    pub dictionary: DriveDictionary,
    /// Objects written.
    pub objects: usize,
    /// Entries (sub-indices) written.
    pub entries: usize,
    /// Objects or sub-objects of the EDS that were skipped (each has a note).
    pub skipped: usize,
    /// Whether the file is a DCF (has `[DeviceComissioning]`).
    pub dcf: bool,
    /// The node id `$NODEID` was resolved with, if any.
    pub node: Option<u8>,
    /// Every decision, in line order: the header and `# EDS line N:` comments of the output.
    pub notes: Vec<Note>,
    /// The decisions about the file as a whole (identity, skipped objects, object lists): the
    /// header's "Import notes", also printed by the command line.
    pub file_notes: Vec<Note>,
}

impl Imported {
    /// A few lines for the command line.
    pub fn summary(&self) -> String {
        let mut s = format!(
            "imported          {} '{}': {} objects, {} entries, {} skipped, {} notes",
            if self.dcf { "DCF" } else { "EDS" },
            self.dictionary.name,
            self.objects,
            self.entries,
            self.skipped,
            self.notes.len()
        );
        let _ = write!(
            s,
            "\nnode id           {}",
            match self.node {
                Some(n) => format!("$NODEID resolved for node {n}"),
                None => "$NODEID values kept relative".to_string(),
            }
        );
        for n in &self.file_notes {
            let _ = match n.line {
                Some(l) => write!(s, "\nnote              line {l}: {}", n.text),
                None => write!(s, "\nnote              {}", n.text),
            };
        }
        if self.notes.len() > self.file_notes.len() {
            s.push_str("\nnotes             see the `# EDS line N:` comments in the output");
        }
        s
    }
}

/// Import an EDS or DCF file.
pub fn import_file(path: &Path, opts: &ImportOptions) -> Result<Imported, EdsError> {
    let bytes = crate::files::read_bounded(path, crate::files::MAX_CONFIG_BYTES)?;
    import_bytes(path, &bytes, opts)
}

/// Import EDS or DCF bytes (UTF-8, or else Latin-1); `file` names them in messages.
pub fn import_bytes(file: &Path, bytes: &[u8], opts: &ImportOptions) -> Result<Imported, EdsError> {
    import_str(file, &decode(bytes), opts)
}

/// Import an EDS or DCF file and write the dictionary to `output` (its folder is created when
/// missing); the written file is loaded back with [`DriveDictionary::load`].
pub fn import_to_file(
    input: &Path,
    output: &Path,
    opts: &ImportOptions,
) -> Result<Imported, EdsError> {
    let imported = import_file(input, opts)?;
    let werr = |source| EdsError::Write {
        file: output.to_path_buf(),
        source,
    };
    if let Some(dir) = output.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(werr)?;
    }
    crate::files::write_output(output, imported.toml.as_bytes())?;
    DriveDictionary::load(output).map_err(|e| EdsError::Rejected {
        file: input.to_path_buf(),
        message: e.to_string(),
    })?;
    Ok(imported)
}

/// Import EDS or DCF text; `file` names it in messages and in the output's header.
pub fn import_str(file: &Path, text: &str, opts: &ImportOptions) -> Result<Imported, EdsError> {
    let ini = parse_ini(text).map_err(|(line, message)| EdsError::Line {
        file: file.to_path_buf(),
        line,
        message,
    })?;
    let mut cx = Cx {
        file,
        node: None,
        notes: Vec::new(),
        strict_identity: opts.strict_identity,
        skipped: 0,
    };
    let (toml, stats) = cx.convert(&ini, opts)?;
    let dictionary = DriveDictionary::parse(file, &toml).map_err(|e| EdsError::Rejected {
        file: file.to_path_buf(),
        message: e.to_string(),
    })?;
    let file_notes = cx.notes.clone();
    let mut notes = cx.notes;
    notes.extend(stats.entry_notes);
    notes.sort_by_key(|n| n.line.unwrap_or(0));
    Ok(Imported {
        toml,
        dictionary,
        objects: stats.objects,
        entries: stats.entries,
        skipped: cx.skipped,
        dcf: stats.dcf,
        node: cx.node,
        notes,
        file_notes,
    })
}

/// UTF-8 when valid, else Latin-1 (EDS files from Windows tools often are).
fn decode(bytes: &[u8]) -> String {
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
struct Entry {
    key: String,
    value: String,
    line: usize,
}

/// One `[section]` and its keys in file order.
#[derive(Debug)]
struct Section {
    name: String,
    line: usize,
    entries: Vec<Entry>,
}

impl Section {
    /// The entry of `key` (case-insensitive).
    fn get(&self, key: &str) -> Option<&Entry> {
        self.entries
            .iter()
            .find(|e| e.key.eq_ignore_ascii_case(key))
    }
    /// The entry of `key` when it has a non-blank value.
    fn value(&self, key: &str) -> Option<&Entry> {
        self.get(key).filter(|e| !e.value.is_empty())
    }
}

/// An INI file: sections in file order, found case-insensitively.
#[derive(Debug)]
struct Ini {
    sections: Vec<Section>,
    by_name: HashMap<String, usize>,
}

impl Ini {
    fn section(&self, name: &str) -> Option<&Section> {
        self.by_name
            .get(&name.to_ascii_lowercase())
            .map(|&i| &self.sections[i])
    }
}

fn parse_ini(text: &str) -> Result<Ini, (usize, String)> {
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

/// Parse a CiA 306 integer: decimal, `0x` hexadecimal, or octal with a leading `0`, with an
/// optional sign. Returns the value and whether it was written in hexadecimal.
pub fn parse_int(s: &str) -> Option<(i128, bool)> {
    let s = s.trim();
    let (neg, body) = match s.as_bytes().first()? {
        b'-' => (true, &s[1..]),
        b'+' => (false, &s[1..]),
        _ => (false, s),
    };
    let (radix, digits, hex) =
        if let Some(h) = body.strip_prefix("0x").or_else(|| body.strip_prefix("0X")) {
            (16, h, true)
        } else if body.len() > 1 && body.starts_with('0') {
            (8, &body[1..], false)
        } else {
            (10, body, false)
        };
    if digits.is_empty() || !digits.chars().all(|c| c.is_digit(radix)) {
        return None;
    }
    let v = i128::try_from(u128::from_str_radix(digits, radix).ok()?).ok()?;
    Some((if neg { -v } else { v }, hex))
}

/// The message for a number that does not parse.
fn bad_number(s: &str) -> String {
    let t = s.trim().trim_start_matches(['-', '+']);
    if t.len() > 1 && t.starts_with('0') && t[1..].chars().all(|c| c.is_ascii_digit()) {
        format!("bad number {s:?} (a leading 0 means octal in CiA 306)")
    } else {
        format!("bad number {s:?} (expected decimal, 0x hexadecimal or 0 octal)")
    }
}

/// A `$NODEID` expression: `$NODEID`, `$NODEID+n` or `n+$NODEID` (case and spaces ignored).
/// `Ok(None)` when the text has no `$NODEID`, else the offset `n`.
pub fn parse_node_id_expr(s: &str) -> Result<Option<u64>, String> {
    let compact: String = s.chars().filter(|c| !c.is_whitespace()).collect();
    let Some(pos) = compact.to_ascii_uppercase().find("$NODEID") else {
        return Ok(None);
    };
    let (before, after) = (&compact[..pos], &compact[pos + "$NODEID".len()..]);
    let off = match (before.is_empty(), after.is_empty()) {
        (true, true) => return Ok(Some(0)),
        (true, false) => after.strip_prefix('+'),
        (false, true) => before.strip_suffix('+'),
        (false, false) => None,
    }
    .ok_or_else(|| format!("bad $NODEID expression {s:?} (expected $NODEID+n or n+$NODEID)"))?;
    match parse_int(off) {
        Some((v, _)) if v >= 0 => u64::try_from(v)
            .map(Some)
            .map_err(|_| format!("$NODEID offset {off} is too large")),
        Some(_) => Err(format!("negative $NODEID offset in {s:?}")),
        None => Err(format!("in {s:?}: {}", bad_number(off))),
    }
}

// ---------------------------------------------------------------------------------------------
// Data types and values
// ---------------------------------------------------------------------------------------------

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Bool,
    Int { bits: u32, signed: bool },
    Real32,
    Real64,
    Text,
    Bytes,
}

/// A CiA 301 basic data type and the type of our format that holds it.
#[derive(Debug, Clone, Copy)]
struct Ty {
    code: u16,
    cia: &'static str,
    kind: Kind,
    out: DataType,
}

impl Ty {
    fn from_code(code: u16) -> Option<Ty> {
        use DataType as D;
        let int = |bits, signed| Kind::Int { bits, signed };
        let (cia, kind, out) = match code {
            0x01 => ("BOOLEAN", Kind::Bool, D::Boolean),
            0x02 => ("INTEGER8", int(8, true), D::Integer8),
            0x03 => ("INTEGER16", int(16, true), D::Integer16),
            0x04 => ("INTEGER32", int(32, true), D::Integer32),
            0x05 => ("UNSIGNED8", int(8, false), D::Unsigned8),
            0x06 => ("UNSIGNED16", int(16, false), D::Unsigned16),
            0x07 => ("UNSIGNED32", int(32, false), D::Unsigned32),
            0x08 => ("REAL32", Kind::Real32, D::Real32),
            0x09 => ("VISIBLE_STRING", Kind::Text, D::VisibleString),
            0x0A => ("OCTET_STRING", Kind::Bytes, D::OctetString),
            0x0B => ("UNICODE_STRING", Kind::Text, D::VisibleString),
            0x0C => ("TIME_OF_DAY", Kind::Bytes, D::OctetString),
            0x0D => ("TIME_DIFFERENCE", Kind::Bytes, D::OctetString),
            0x0F => ("DOMAIN", Kind::Bytes, D::Domain),
            0x10 => ("INTEGER24", int(24, true), D::Integer32),
            0x11 => ("REAL64", Kind::Real64, D::Real64),
            0x12 => ("INTEGER40", int(40, true), D::Integer64),
            0x13 => ("INTEGER48", int(48, true), D::Integer64),
            0x14 => ("INTEGER56", int(56, true), D::Integer64),
            0x15 => ("INTEGER64", int(64, true), D::Integer64),
            0x16 => ("UNSIGNED24", int(24, false), D::Unsigned32),
            0x18 => ("UNSIGNED40", int(40, false), D::Unsigned64),
            0x19 => ("UNSIGNED48", int(48, false), D::Unsigned64),
            0x1A => ("UNSIGNED56", int(56, false), D::Unsigned64),
            0x1B => ("UNSIGNED64", int(64, false), D::Unsigned64),
            _ => return None,
        };
        Some(Ty {
            code,
            cia,
            kind,
            out,
        })
    }

    fn u8() -> Ty {
        Ty::from_code(0x05).expect("UNSIGNED8")
    }
    fn u32() -> Ty {
        Ty::from_code(0x07).expect("UNSIGNED32")
    }

    /// The value range of an integer or boolean type.
    fn int_range(self) -> Option<(i128, i128)> {
        match self.kind {
            Kind::Bool => Some((0, 1)),
            Kind::Int { bits, signed: true } => {
                Some((-(1i128 << (bits - 1)), (1i128 << (bits - 1)) - 1))
            }
            Kind::Int {
                bits,
                signed: false,
            } => Some((0, (1i128 << bits) - 1)),
            _ => None,
        }
    }

    /// An odd-width integer, held by a wider type of the format.
    fn widened(self) -> bool {
        matches!(self.kind, Kind::Int { bits, .. } if !matches!(bits, 8 | 16 | 32 | 64))
    }

    fn numeric(self) -> bool {
        matches!(
            self.kind,
            Kind::Bool | Kind::Int { .. } | Kind::Real32 | Kind::Real64
        )
    }

    /// Hex digits to write a value of this type with.
    fn hex_digits(self) -> usize {
        match self.kind {
            Kind::Int { bits, .. } => bits as usize / 4,
            _ => 2,
        }
    }
}

/// A value as it will be written.
#[derive(Debug, Clone, PartialEq)]
enum Val {
    Int(i128),
    Real(f64),
    Bool(bool),
    Text(String),
    NodeId(u64),
}

impl Val {
    /// The number the loader compares with min/max (REAL32 rounded to f32, as it stores it).
    fn as_f64(&self, ty: Ty) -> Option<f64> {
        match *self {
            Val::Int(i) => Some(i as f64),
            Val::Bool(b) => Some(f64::from(u8::from(b))),
            Val::Real(r) if ty.kind == Kind::Real32 => Some(f64::from(r as f32)),
            Val::Real(r) => Some(r),
            _ => None,
        }
    }
}

/// Why a value does not parse: its syntax, or its range (a bound may be dropped for that).
#[derive(Debug)]
enum VErr {
    Syntax(String),
    Range(String),
}

impl VErr {
    fn message(self) -> String {
        match self {
            VErr::Syntax(m) | VErr::Range(m) => m,
        }
    }
}

/// A parsed value with how to show it.
#[derive(Debug)]
struct Parsed {
    val: Val,
    hex: bool,
    /// A trailing comment (how the EDS wrote it).
    comment: Option<String>,
    /// Decisions taken on it.
    notes: Vec<String>,
}

impl Parsed {
    fn plain(val: Val) -> Parsed {
        Parsed {
            val,
            hex: false,
            comment: None,
            notes: Vec::new(),
        }
    }
}

/// `"$NODEID+0x180"` as the dictionary format writes it.
fn node_text(off: u64) -> String {
    if off == 0 {
        "$NODEID".to_string()
    } else {
        format!("$NODEID+0x{off:X}")
    }
}

/// Parse a `DefaultValue`, `ParameterValue` or limit of type `ty`.
fn parse_value(ty: Ty, text: &str, node: Option<u8>) -> Result<Parsed, VErr> {
    let text = text.trim();
    match ty.kind {
        Kind::Bool | Kind::Int { .. } => {
            let (lo, hi) = ty.int_range().expect("integer type");
            if let Some(off) = parse_node_id_expr(text).map_err(VErr::Syntax)? {
                if ty.kind == Kind::Bool {
                    return Err(VErr::Syntax(format!("$NODEID in a BOOLEAN: {text:?}")));
                }
                return match node {
                    Some(n) => {
                        let v = i128::from(off) + i128::from(n);
                        if v > hi {
                            return Err(VErr::Range(format!(
                                "{text} for node {n} is {v}, which does not fit {} [{lo}, {hi}]",
                                ty.cia
                            )));
                        }
                        Ok(Parsed {
                            val: Val::Int(v),
                            hex: true,
                            comment: Some(format!("{} in the EDS", node_text(off))),
                            notes: Vec::new(),
                        })
                    }
                    None => {
                        if i128::from(off) + 1 > hi {
                            return Err(VErr::Range(format!(
                                "{text} does not fit {} [{lo}, {hi}]",
                                ty.cia
                            )));
                        }
                        Ok(Parsed::plain(Val::NodeId(off)))
                    }
                };
            }
            if ty.kind == Kind::Bool {
                if text.eq_ignore_ascii_case("true") {
                    return Ok(Parsed::plain(Val::Bool(true)));
                }
                if text.eq_ignore_ascii_case("false") {
                    return Ok(Parsed::plain(Val::Bool(false)));
                }
            }
            let (mut v, hex) = parse_int(text).ok_or_else(|| VErr::Syntax(bad_number(text)))?;
            let mut comment = None;
            if let Kind::Int { bits, signed: true } = ty.kind
                && hex
                && !text.starts_with('-')
                && v > hi
                && v < (1i128 << bits)
            {
                v -= 1i128 << bits;
                comment = Some(format!("{text} in the EDS (two's complement)"));
            }
            if v < lo || v > hi {
                return Err(VErr::Range(format!(
                    "{text} does not fit {} [{lo}, {hi}]",
                    ty.cia
                )));
            }
            Ok(Parsed {
                val: if ty.kind == Kind::Bool {
                    Val::Bool(v == 1)
                } else {
                    Val::Int(v)
                },
                hex,
                comment,
                notes: Vec::new(),
            })
        }
        Kind::Real32 | Kind::Real64 => {
            if text.to_ascii_uppercase().contains("$NODEID") {
                return Err(VErr::Syntax(format!("$NODEID in a {}: {text:?}", ty.cia)));
            }
            let mut comment = None;
            let r = if let Some(h) = text.strip_prefix("0x").or_else(|| text.strip_prefix("0X")) {
                let bits = if !h.is_empty() && h.chars().all(|c| c.is_ascii_hexdigit()) {
                    u64::from_str_radix(h, 16).ok()
                } else {
                    None
                }
                .ok_or_else(|| VErr::Syntax(bad_number(text)))?;
                comment = Some(format!("IEEE 754 bit pattern {text} in the EDS"));
                if ty.kind == Kind::Real32 {
                    let b = u32::try_from(bits).map_err(|_| {
                        VErr::Range(format!("{text} is wider than a REAL32 bit pattern"))
                    })?;
                    f64::from(f32::from_bits(b))
                } else {
                    f64::from_bits(bits)
                }
            } else {
                text.parse::<f64>()
                    .map_err(|_| VErr::Syntax(format!("bad REAL number {text:?}")))?
            };
            if ty.kind == Kind::Real32 && r.is_finite() && r.abs() > f64::from(f32::MAX) {
                return Err(VErr::Range(format!("{text} does not fit REAL32")));
            }
            Ok(Parsed {
                val: Val::Real(r),
                hex: false,
                comment,
                notes: Vec::new(),
            })
        }
        Kind::Text => {
            let mut p = Parsed::plain(Val::Text(String::new()));
            if text.starts_with("$NODEID") {
                p.notes.push(format!(
                    "text {text:?} would read as a node-id expression: default empty"
                ));
                return Ok(p);
            }
            let mut s = text.to_string();
            if s.len() > MAX_STRING {
                let mut end = MAX_STRING;
                while !s.is_char_boundary(end) {
                    end -= 1;
                }
                s.truncate(end);
                p.notes.push(format!(
                    "default {text:?} is longer than {MAX_STRING} bytes: truncated"
                ));
            }
            p.val = Val::Text(s);
            Ok(p)
        }
        Kind::Bytes => {
            let mut p = Parsed::plain(Val::Text(String::new()));
            let compact: String = text.chars().filter(|c| !c.is_whitespace()).collect();
            let digits = compact
                .strip_prefix("0x")
                .or_else(|| compact.strip_prefix("0X"))
                .unwrap_or(&compact);
            let mut bytes = if !digits.is_empty()
                && digits.len().is_multiple_of(2)
                && digits.chars().all(|c| c.is_ascii_hexdigit())
            {
                (0..digits.len())
                    .step_by(2)
                    .map(|i| u8::from_str_radix(&digits[i..i + 2], 16).expect("hex digits"))
                    .collect::<Vec<u8>>()
            } else {
                p.notes.push(format!(
                    "default {text:?} is not hex digits: its characters are the bytes"
                ));
                text.as_bytes().to_vec()
            };
            if bytes.len() > MAX_STRING {
                bytes.truncate(MAX_STRING);
                p.notes.push(format!(
                    "default {text:?} is longer than {MAX_STRING} bytes: truncated"
                ));
            }
            if bytes.iter().any(|&b| b >= 0x80) {
                p.notes.push(format!(
                    "default {text:?} has bytes >= 0x80, which this format cannot write: default empty"
                ));
                return Ok(p);
            }
            let s = String::from_utf8(bytes).expect("ASCII");
            if s.starts_with("$NODEID") {
                p.notes.push(format!(
                    "default {text:?} would read as a node-id expression: default empty"
                ));
                return Ok(p);
            }
            p.val = Val::Text(s);
            Ok(p)
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Output model
// ---------------------------------------------------------------------------------------------

/// One entry of the output.
#[derive(Debug, Clone)]
struct OutSub {
    sub: u8,
    name: String,
    ty: Ty,
    type_comment: Option<String>,
    access: &'static str,
    access_comment: Option<String>,
    pdo: bool,
    default: Val,
    default_hex: bool,
    default_comment: Option<String>,
    /// The EDS line the default came from (the section's when there was none).
    default_line: usize,
    /// The default was invented (none in the EDS).
    synthesized: bool,
    /// Why the default is what it is, when the import chose it: a trailing comment.
    default_note: Option<(usize, String)>,
    min: Option<Bound>,
    max: Option<Bound>,
    unit: Option<String>,
    notes: Vec<(usize, String)>,
}

/// A `min` or `max`.
#[derive(Debug, Clone, Copy)]
struct Bound {
    val: Num,
    hex: bool,
}

/// An integer bound is written as an integer, a real bound as a float.
#[derive(Debug, Clone, Copy)]
enum Num {
    Int(i128),
    Real(f64),
}

impl Bound {
    fn f64(self) -> f64 {
        match self.val {
            Num::Int(i) => i as f64,
            Num::Real(r) => r,
        }
    }
}

/// One object of the output.
#[derive(Debug, Clone)]
struct OutObj {
    name: String,
    line: usize,
    section: String,
    notes: Vec<(usize, String)>,
    /// A variable: exactly one entry, sub 0, written inline.
    var: bool,
    subs: Vec<OutSub>,
}

#[derive(Debug, Default)]
struct Stats {
    objects: usize,
    entries: usize,
    dcf: bool,
    entry_notes: Vec<Note>,
}

/// The keys of a VAR (or of a compact array's template).
struct VarSpec<'a> {
    name: String,
    name_note: Option<(usize, String)>,
    ty: Result<Ty, (u16, usize)>,
    access: &'static str,
    access_comment: Option<String>,
    pdo: bool,
    pdo_line: usize,
    default: Option<&'a Entry>,
    pvalue: Option<&'a Entry>,
    low: Option<&'a Entry>,
    high: Option<&'a Entry>,
    unit: Option<String>,
    line: usize,
}

struct Cx<'a> {
    file: &'a Path,
    node: Option<u8>,
    notes: Vec<Note>,
    strict_identity: bool,
    skipped: usize,
}

/// What a `[XXXX...]` section name is.
enum SecName {
    Object(u16),
    Sub(u16, u8),
    Names(u16),
    Values(u16),
    Other,
}

fn classify(name: &str) -> Result<SecName, String> {
    let b = name.as_bytes();
    if b.len() < 4 || !b[..4].iter().all(u8::is_ascii_hexdigit) {
        return Ok(SecName::Other);
    }
    let index = u16::from_str_radix(&name[..4], 16).expect("hex");
    let rest = &name[4..];
    if rest.is_empty() {
        return Ok(SecName::Object(index));
    }
    let lower = rest.to_ascii_lowercase();
    if let Some(sub) = lower.strip_prefix("sub") {
        return match u32::from_str_radix(sub, 16) {
            Ok(s) if sub.chars().all(|c| c.is_ascii_hexdigit()) && s <= 0xFF => {
                Ok(SecName::Sub(index, s as u8))
            }
            _ => Err(format!(
                "bad sub-index in section name [{name}] (expected [{}subN], N hexadecimal 0..FF)",
                &name[..4]
            )),
        };
    }
    Ok(match lower.as_str() {
        "name" => SecName::Names(index),
        "value" => SecName::Values(index),
        _ => SecName::Other,
    })
}

fn map_access(text: &str) -> Option<(&'static str, Option<String>)> {
    Some(match text.to_ascii_lowercase().as_str() {
        "ro" => ("ro", None),
        "wo" => ("wo", None),
        "rw" => ("rw", None),
        "const" => ("const", None),
        a @ ("rwr" | "rww") => ("rw", Some(format!("{a} in the EDS"))),
        _ => return None,
    })
}

impl Cx<'_> {
    fn err(&self, line: usize, message: impl Into<String>) -> EdsError {
        EdsError::Line {
            file: self.file.to_path_buf(),
            line,
            message: message.into(),
        }
    }

    fn note(&mut self, line: Option<usize>, text: impl Into<String>) {
        self.notes.push(Note {
            line,
            text: text.into(),
        });
    }

    fn skip(&mut self, line: usize, text: impl Into<String>) {
        self.skipped += 1;
        self.note(Some(line), text);
    }

    fn convert(&mut self, ini: &Ini, opts: &ImportOptions) -> Result<(String, Stats), EdsError> {
        let mut stats = Stats::default();
        // Sections by role.
        let mut objects: BTreeMap<u16, &Section> = BTreeMap::new();
        let mut subs: BTreeMap<u16, BTreeMap<u8, &Section>> = BTreeMap::new();
        let mut names: BTreeMap<u16, &Section> = BTreeMap::new();
        let mut values: BTreeMap<u16, &Section> = BTreeMap::new();
        for s in &ini.sections {
            match classify(&s.name).map_err(|m| self.err(s.line, m))? {
                SecName::Object(i) => {
                    objects.insert(i, s);
                }
                SecName::Sub(i, n) => {
                    let m = subs.entry(i).or_default();
                    if let Some(prev) = m.get(&n) {
                        return Err(self.err(
                            s.line,
                            format!(
                                "section [{}] is sub-index {n} of 0x{i:04X} again (first [{}] at line {})",
                                s.name, prev.name, prev.line
                            ),
                        ));
                    }
                    m.insert(n, s);
                }
                SecName::Names(i) => {
                    names.insert(i, s);
                }
                SecName::Values(i) => {
                    values.insert(i, s);
                }
                // `[0x6040]`, `[-6040]`, `[16040]`: meant as an object, but not CiA 306's
                // four hex digits. Skipped, counted and named, never dropped silently.
                SecName::Other
                    if s.name
                        .starts_with(|c: char| c.is_ascii_digit() || c == '-' || c == '+') =>
                {
                    self.skip(
                        s.line,
                        format!(
                            "section [{}] is not an object section ([XXXX], [XXXXsubN], [XXXXName] or [XXXXValue], XXXX four hex digits): skipped",
                            s.name
                        ),
                    );
                }
                SecName::Other => {}
            }
        }
        for (i, m) in &subs {
            if !objects.contains_key(i) {
                let s = m.values().next().expect("non-empty");
                return Err(self.err(
                    s.line,
                    format!(
                        "sub-object section [{}] without its parent [{i:04X}]",
                        s.name
                    ),
                ));
            }
        }
        if objects.is_empty() {
            return Err(self.err(1, "no object sections ([1000], [1018], ...): not an EDS"));
        }

        // Node id.
        let commissioning = ini
            .section("DeviceComissioning")
            .or_else(|| ini.section("DeviceCommissioning"));
        stats.dcf = commissioning.is_some()
            || self
                .file
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("dcf"));
        let node_from = match (opts.node, commissioning.and_then(|s| s.value("NodeID"))) {
            (Some(n), _) => {
                if !(1..=127).contains(&n) {
                    return Err(self.err(1, format!("--node {n} is not a node id (1..127)")));
                }
                self.node = Some(n);
                Some(format!("--node {n}"))
            }
            (None, Some(e)) => {
                let n = parse_int(&e.value)
                    .map(|(v, _)| v)
                    .ok_or_else(|| self.err(e.line, format!("NodeID: {}", bad_number(&e.value))))?;
                if !(1..=127).contains(&n) {
                    return Err(self.err(e.line, format!("NodeID {n} is not a node id (1..127)")));
                }
                self.node = Some(n as u8);
                Some(format!("[DeviceComissioning] NodeID, line {}", e.line))
            }
            (None, None) => None,
        };

        self.check_lists(ini, &objects)?;

        if let Some(d) = ini.section("DummyUsage") {
            let mut used = Vec::new();
            for e in &d.entries {
                let on = parse_int(&e.value)
                    .filter(|(v, _)| *v == 0 || *v == 1)
                    .ok_or_else(|| self.err(e.line, format!("{}: expected 0 or 1", e.key)))?;
                if on.0 == 1 {
                    used.push(e.key.trim_start_matches(|c: char| c.is_ascii_alphabetic()));
                }
            }
            if !used.is_empty() {
                let list = used
                    .iter()
                    .map(|k| format!("0x{k}"))
                    .collect::<Vec<_>>()
                    .join(" ");
                self.note(
                    Some(d.line),
                    format!(
                        "[DummyUsage]: the device accepts dummy mapping of {list}; this format has no dummy entries"
                    ),
                );
            }
        }

        // Objects.
        let mut out: BTreeMap<u16, OutObj> = BTreeMap::new();
        for (&index, sec) in &objects {
            if let Some(o) = self.object(index, sec, &subs, &names, &values)? {
                out.insert(index, o);
            }
        }

        // Identity.
        let info = ini.section("DeviceInfo");
        let identity = self.identity(&mut out, info)?;

        // Name.
        let name = {
            let get = |k: &str| info.and_then(|s| s.value(k)).map(|e| e.value.clone());
            match (get("VendorName"), get("ProductName")) {
                (Some(v), Some(p)) => format!("{v} {p}"),
                (None, Some(p)) => p,
                (v, None) => ini
                    .section("FileInfo")
                    .and_then(|s| s.value("Description"))
                    .map(|e| e.value.clone())
                    .or(v)
                    .unwrap_or_else(|| {
                        self.file
                            .file_stem()
                            .map(|s| s.to_string_lossy().into_owned())
                            .unwrap_or_else(|| "imported drive".to_string())
                    }),
            }
        };

        stats.objects = out.len();
        stats.entries = out.values().map(|o| o.subs.len()).sum();
        for o in out.values() {
            for (l, t) in &o.notes {
                stats.entry_notes.push(Note {
                    line: Some(*l),
                    text: t.clone(),
                });
            }
            for s in &o.subs {
                for (l, t) in s.notes.iter().chain(&s.default_note) {
                    stats.entry_notes.push(Note {
                        line: Some(*l),
                        text: t.clone(),
                    });
                }
            }
        }
        let text = self.render(ini, &name, identity, node_from.as_deref(), &out, &stats);
        Ok((text, stats))
    }

    /// The object lists: listed objects without a section and sections in no list are noted.
    fn check_lists(
        &mut self,
        ini: &Ini,
        objects: &BTreeMap<u16, &Section>,
    ) -> Result<(), EdsError> {
        let mut listed: BTreeSet<u16> = BTreeSet::new();
        for list in ["MandatoryObjects", "OptionalObjects", "ManufacturerObjects"] {
            let Some(s) = ini.section(list) else { continue };
            let mut count = None;
            let mut n = 0usize;
            for e in &s.entries {
                if e.key.eq_ignore_ascii_case("SupportedObjects") {
                    count = Some(parse_int(&e.value).map(|(v, _)| v).ok_or_else(|| {
                        self.err(
                            e.line,
                            format!("SupportedObjects: {}", bad_number(&e.value)),
                        )
                    })?);
                    continue;
                }
                if parse_int(&e.key).is_none() {
                    return Err(self.err(
                        e.line,
                        format!(
                            "unexpected key {:?} in [{}] (expected n=0xIIII)",
                            e.key, s.name
                        ),
                    ));
                }
                let index = parse_int(&e.value)
                    .and_then(|(v, _)| u16::try_from(v).ok())
                    .ok_or_else(|| {
                        self.err(
                            e.line,
                            format!("{}: bad object index {:?} in [{}]", e.key, e.value, s.name),
                        )
                    })?;
                if !objects.contains_key(&index) {
                    self.note(
                        Some(e.line),
                        format!(
                            "object 0x{index:04X} is listed in [{}] but has no [{index:04X}] section: not imported",
                            s.name
                        ),
                    );
                }
                listed.insert(index);
                n += 1;
            }
            if let Some(c) = count
                && c != n as i128
            {
                self.note(
                    Some(s.line),
                    format!("[{}] says SupportedObjects={c} but lists {n}", s.name),
                );
            }
        }
        let unlisted: Vec<String> = objects
            .keys()
            .filter(|i| **i >= *index::COMMUNICATION_AREA.start() && !listed.contains(i))
            .map(|i| format!("0x{i:04X}"))
            .collect();
        if !unlisted.is_empty() {
            let shown = if unlisted.len() > 12 {
                format!(
                    "{} ... ({} in all)",
                    unlisted[..12].join(" "),
                    unlisted.len()
                )
            } else {
                unlisted.join(" ")
            };
            self.note(
                None,
                format!("object sections in no object list, imported anyway: {shown}"),
            );
        }
        Ok(())
    }

    /// Read the keys of a VAR-like section.
    fn var_spec<'s>(
        &self,
        sec: &'s Section,
        fallback_name: String,
        domain: bool,
    ) -> Result<VarSpec<'s>, EdsError> {
        let (name, name_note) = match sec.value("ParameterName") {
            Some(e) => (e.value.clone(), None),
            None => (
                fallback_name.clone(),
                Some((
                    sec.line,
                    format!("no ParameterName: named {fallback_name:?}"),
                )),
            ),
        };
        let ty = match sec.value("DataType") {
            Some(e) => {
                let code = parse_int(&e.value)
                    .and_then(|(v, _)| u16::try_from(v).ok())
                    .ok_or_else(|| {
                        self.err(e.line, format!("DataType: {}", bad_number(&e.value)))
                    })?;
                Ty::from_code(code).ok_or((code, e.line))
            }
            None if domain => Ok(Ty::from_code(0x0F).expect("DOMAIN")),
            None => {
                return Err(self.err(
                    sec.line,
                    format!("[{}]: missing DataType for a VAR", sec.name),
                ));
            }
        };
        let (access, access_comment) = match sec.value("AccessType") {
            Some(e) => map_access(&e.value).ok_or_else(|| {
                self.err(
                    e.line,
                    format!(
                        "AccessType {:?} is not one of ro wo rw rwr rww const",
                        e.value
                    ),
                )
            })?,
            None if domain => ("rw", Some("no AccessType in the EDS".to_string())),
            None => {
                return Err(self.err(
                    sec.line,
                    format!("[{}]: missing AccessType for a VAR", sec.name),
                ));
            }
        };
        let (pdo, pdo_line) = match sec.value("PDOMapping") {
            Some(e) => {
                let v = if e.value.eq_ignore_ascii_case("true") {
                    1
                } else if e.value.eq_ignore_ascii_case("false") {
                    0
                } else {
                    parse_int(&e.value).map(|(v, _)| v).unwrap_or(-1)
                };
                if v != 0 && v != 1 {
                    return Err(
                        self.err(e.line, format!("PDOMapping {:?}: expected 0 or 1", e.value))
                    );
                }
                (v == 1, e.line)
            }
            None => (false, sec.line),
        };
        Ok(VarSpec {
            name,
            name_note,
            ty,
            access,
            access_comment,
            pdo,
            pdo_line,
            default: sec.value("DefaultValue"),
            pvalue: sec.value("ParameterValue"),
            low: sec.value("LowLimit"),
            high: sec.value("HighLimit"),
            unit: sec.value("Unit").map(|e| e.value.clone()),
            line: sec.line,
        })
    }

    /// A limit, or `None` with a note when it cannot be kept.
    fn bound(
        &self,
        ty: Ty,
        e: Option<&Entry>,
        notes: &mut Vec<(usize, String)>,
    ) -> Result<Option<Bound>, EdsError> {
        let Some(e) = e else { return Ok(None) };
        if !ty.numeric() {
            notes.push((
                e.line,
                format!(
                    "{}={} on a {} dropped (ranges are for numbers)",
                    e.key, e.value, ty.cia
                ),
            ));
            return Ok(None);
        }
        let p = match parse_value(ty, &e.value, self.node) {
            Ok(p) => p,
            Err(VErr::Syntax(m)) => return Err(self.err(e.line, format!("{}: {m}", e.key))),
            Err(VErr::Range(m)) => {
                notes.push((e.line, format!("{} dropped: {m}", e.key)));
                return Ok(None);
            }
        };
        if let Val::Real(r) = p.val
            && !r.is_finite()
        {
            notes.push((
                e.line,
                format!("{}={} dropped: not a finite number", e.key, e.value),
            ));
            return Ok(None);
        }
        Ok(Some(match p.val {
            Val::Int(i) => Bound {
                val: Num::Int(i),
                hex: p.hex,
            },
            Val::Bool(b) => Bound {
                val: Num::Int(i128::from(b)),
                hex: false,
            },
            Val::Real(r) if ty.kind == Kind::Real32 => Bound {
                val: Num::Real(f64::from(r as f32)),
                hex: false,
            },
            Val::Real(r) => Bound {
                val: Num::Real(r),
                hex: false,
            },
            Val::NodeId(off) => {
                notes.push((
                    e.line,
                    format!(
                        "{}={} dropped: a bound must be a number, and there is no node id",
                        e.key,
                        node_text(off)
                    ),
                ));
                return Ok(None);
            }
            Val::Text(_) => unreachable!("numeric type"),
        }))
    }

    /// Convert one VAR-like spec to an entry; `Ok(Err(reason))` skips it.
    fn entry(
        &self,
        spec: &VarSpec,
        sub: u8,
        name: String,
        value: Option<&Entry>,
    ) -> Result<Result<OutSub, String>, EdsError> {
        let ty = match spec.ty {
            Ok(t) => t,
            Err((code, _)) => {
                return Ok(Err(format!(
                    "DataType 0x{code:04X} is not a CiA 301 basic type"
                )));
            }
        };
        let mut notes: Vec<(usize, String)> = Vec::new();
        if let Some(n) = &spec.name_note {
            notes.push(n.clone());
        }
        let type_comment = if ty.widened() {
            Some(format!(
                "{} in the EDS: widened to {} bits, range kept by min/max",
                ty.cia,
                ty.out.size() * 8
            ))
        } else if ty.code == 0x0B {
            Some("UNICODE_STRING in the EDS: kept as UTF-8 text".to_string())
        } else if matches!(ty.code, 0x0C | 0x0D) {
            Some(format!("{} in the EDS: raw octets", ty.cia))
        } else {
            None
        };
        let mut pdo = spec.pdo;
        if pdo && ty.out.fixed_size().is_none() {
            pdo = false;
            notes.push((
                spec.pdo_line,
                format!(
                    "PDOMapping=1 on a variable-length {} dropped (our loader cannot map it)",
                    ty.cia
                ),
            ));
        }
        if pdo && ty.widened() {
            pdo = false;
            notes.push((
                spec.pdo_line,
                format!(
                    "PDOMapping=1 dropped: the {} is {} bits in a PDO of the real device, {} here",
                    ty.cia,
                    match ty.kind {
                        Kind::Int { bits, .. } => bits,
                        _ => 0,
                    },
                    ty.out.size() * 8
                ),
            ));
        }

        // Default, ParameterValue, [XXXXValue].
        let parse_at = |e: &Entry| -> Result<Parsed, EdsError> {
            parse_value(ty, &e.value, self.node)
                .map_err(|m| self.err(e.line, format!("{} {:?}: {}", e.key, e.value, m.message())))
        };
        let eds_default = spec.default.map(parse_at).transpose()?;
        let eds_default_val = eds_default.as_ref().map(|p| p.val.clone());
        let pvalue = spec.pvalue.map(parse_at).transpose()?;
        let over = value.map(parse_at).transpose()?;
        let (chosen, chosen_entry, source) = if let (Some(p), Some(e)) = (over, value) {
            (Some(p), Some(e), Some(format!("[{}] value", e.key)))
        } else if let (Some(p), Some(e)) = (pvalue, spec.pvalue) {
            (Some(p), Some(e), Some("ParameterValue".to_string()))
        } else {
            (eds_default, spec.default, None)
        };

        let mut min = self.bound(ty, spec.low, &mut notes)?;
        let mut max = self.bound(ty, spec.high, &mut notes)?;
        if let (Some(lo), Some(hi)) = (min, max)
            && lo.f64() > hi.f64()
        {
            notes.push((
                spec.low.map_or(spec.line, |e| e.line),
                format!(
                    "LowLimit {} is above HighLimit {}: both dropped",
                    spec.low.map_or("", |e| e.value.as_str()),
                    spec.high.map_or("", |e| e.value.as_str())
                ),
            ));
            min = None;
            max = None;
        }
        if ty.widened() {
            let (lo, hi) = ty.int_range().expect("integer");
            if min.is_none() && lo < 0 {
                min = Some(Bound {
                    val: Num::Int(lo),
                    hex: false,
                });
            }
            if max.is_none() {
                max = Some(Bound {
                    val: Num::Int(hi),
                    hex: true,
                });
            }
        }

        let (mut default, mut default_hex, mut default_comment, default_line, synthesized) =
            match chosen {
                Some(p) => {
                    let e = chosen_entry.expect("entry");
                    for n in p.notes {
                        notes.push((e.line, n));
                    }
                    let comment = match (source, p.comment) {
                        (Some(_), c) if eds_default_val.as_ref() == Some(&p.val) => c,
                        (Some(src), c) => {
                            let was = spec
                                .default
                                .map(|d| format!("; DefaultValue {}", d.value))
                                .unwrap_or_default();
                            Some(match c {
                                Some(c) => format!("{src} ({c}){was}"),
                                None => format!("{src}{was}"),
                            })
                        }
                        (None, c) => c,
                    };
                    (p.val, p.hex, comment, e.line, false)
                }
                None => {
                    let zero = match ty.kind {
                        Kind::Bool => Val::Bool(false),
                        Kind::Int { .. } => Val::Int(0),
                        Kind::Real32 | Kind::Real64 => Val::Real(0.0),
                        Kind::Text | Kind::Bytes => Val::Text(String::new()),
                    };
                    (zero, false, None, spec.line, true)
                }
            };
        let mut from_bound = |b: Bound| -> Val {
            match (b.val, ty.kind) {
                (Num::Int(i), Kind::Bool) => Val::Bool(i != 0),
                (Num::Int(i), Kind::Int { .. }) => {
                    default_hex = b.hex;
                    Val::Int(i)
                }
                (Num::Int(i), _) => Val::Real(i as f64),
                (Num::Real(r), _) => Val::Real(r),
            }
        };
        let mut default_note = None;
        if synthesized {
            let mut how = "0";
            if let Some(lo) = min.filter(|lo| lo.f64() > 0.0) {
                default = from_bound(lo);
                how = "the LowLimit, as 0 is below it";
            } else if let Some(hi) = max.filter(|hi| hi.f64() < 0.0) {
                default = from_bound(hi);
                how = "the HighLimit, as 0 is above it";
            }
            let how = if ty.numeric() { how } else { "empty" };
            default_note = Some((spec.line, format!("no DefaultValue in the EDS: {how}")));
        } else if let Some(x) = default.as_f64(ty) {
            if let Some(lo) = min.filter(|lo| x < lo.f64()) {
                notes.push((
                    spec.low.map_or(spec.line, |e| e.line),
                    format!(
                        "LowLimit {} dropped: the default is below it",
                        render_bound(lo, ty)
                    ),
                ));
                min = None;
            }
            if let Some(hi) = max.filter(|hi| x > hi.f64()) {
                notes.push((
                    spec.high.map_or(spec.line, |e| e.line),
                    format!(
                        "HighLimit {} dropped: the default is above it",
                        render_bound(hi, ty)
                    ),
                ));
                max = None;
            }
        }
        if let Val::Int(v) = default
            && v > i128::from(i64::MAX)
        {
            notes.push((
                default_line,
                format!(
                    "default 0x{v:X} is above what TOML integers hold (i64): default 0 instead"
                ),
            ));
            default = Val::Int(0);
            default_comment = None;
            if min.is_some_and(|lo| lo.f64() > 0.0) {
                min = None;
            }
        }
        Ok(Ok(OutSub {
            sub,
            name,
            ty,
            type_comment,
            access: spec.access,
            access_comment: spec.access_comment.clone(),
            pdo,
            default,
            default_hex,
            default_comment,
            default_line,
            synthesized,
            default_note,
            min,
            max,
            unit: spec.unit.clone(),
            notes,
        }))
    }

    /// Convert one `[XXXX]` object; `None` when it is skipped.
    fn object(
        &mut self,
        index: u16,
        sec: &Section,
        subs: &BTreeMap<u16, BTreeMap<u8, &Section>>,
        names: &BTreeMap<u16, &Section>,
        values: &BTreeMap<u16, &Section>,
    ) -> Result<Option<OutObj>, EdsError> {
        let ot = match sec.value("ObjectType") {
            Some(e) => parse_int(&e.value)
                .and_then(|(v, _)| u8::try_from(v).ok())
                .ok_or_else(|| self.err(e.line, format!("ObjectType: {}", bad_number(&e.value))))?,
            None => 0x7,
        };
        let my_subs = subs.get(&index);
        let title = sec
            .value("ParameterName")
            .map(|e| e.value.clone())
            .unwrap_or_else(|| format!("Object 0x{index:04X}"));
        if index < *index::COMMUNICATION_AREA.start() || matches!(ot, 0x0 | 0x5 | 0x6) {
            self.skip(
                sec.line,
                format!(
                    "[{}] {title:?}: a data type definition (ObjectType 0x{ot:X}), not an object: skipped",
                    sec.name
                ),
            );
            return Ok(None);
        }
        let mut obj = OutObj {
            name: title.clone(),
            line: sec.line,
            section: sec.name.clone(),
            notes: Vec::new(),
            var: false,
            subs: Vec::new(),
        };
        match ot {
            0x7 | 0x2 => {
                if let Some(m) = my_subs {
                    let s = m.values().next().expect("non-empty");
                    return Err(self.err(
                        s.line,
                        format!(
                            "sub-object section [{}] of 0x{index:04X}, which is a VAR (line {})",
                            s.name, sec.line
                        ),
                    ));
                }
                if sec.value("CompactSubObj").is_some() {
                    obj.notes
                        .push((sec.line, "CompactSubObj on a VAR ignored".to_string()));
                }
                let spec = self.var_spec(sec, title.clone(), ot == 0x2)?;
                match self.entry(&spec, 0, spec.name.clone(), None)? {
                    Ok(s) => {
                        obj.var = true;
                        obj.subs.push(s);
                    }
                    Err(why) => {
                        let line = spec.ty.err().map_or(sec.line, |(_, l)| l);
                        self.skip(line, format!("0x{index:04X} {title:?}: {why}: skipped"));
                        return Ok(None);
                    }
                }
            }
            0x8 | 0x9 => {
                let compact = match sec.value("CompactSubObj") {
                    Some(e) => {
                        let n = parse_int(&e.value).map(|(v, _)| v).ok_or_else(|| {
                            self.err(e.line, format!("CompactSubObj: {}", bad_number(&e.value)))
                        })?;
                        if !(0..=254).contains(&n) {
                            return Err(
                                self.err(e.line, format!("CompactSubObj {n}: expected 0..254"))
                            );
                        }
                        (n > 0).then_some((n as u8, e.line))
                    }
                    None => None,
                };
                if let Some((n, cline)) = compact {
                    if let Some(m) = my_subs {
                        let s = m.values().next().expect("non-empty");
                        return Err(self.err(
                            s.line,
                            format!(
                                "sub-object section [{}] for 0x{index:04X}, which has CompactSubObj={n} (line {cline})",
                                s.name
                            ),
                        ));
                    }
                    self.compact(
                        index,
                        sec,
                        n,
                        cline,
                        names.get(&index),
                        values.get(&index),
                        &mut obj,
                    )?;
                } else {
                    for s in [names.get(&index), values.get(&index)]
                        .into_iter()
                        .flatten()
                    {
                        obj.notes.push((
                            s.line,
                            format!("[{}] ignored: 0x{index:04X} is not a compact array", s.name),
                        ));
                    }
                    if let Some(m) = my_subs {
                        for (&n, s) in m {
                            let spec = self.var_spec(s, format!("{title} {n}"), false)?;
                            match self.entry(&spec, n, spec.name.clone(), None)? {
                                Ok(e) => obj.subs.push(e),
                                Err(why) => {
                                    let line = spec.ty.err().map_or(s.line, |(_, l)| l);
                                    self.skip(
                                        line,
                                        format!(
                                            "0x{index:04X}:{n} {:?}: {why}: skipped",
                                            spec.name
                                        ),
                                    );
                                }
                            }
                        }
                    }
                }
                if obj.subs.is_empty() {
                    self.skip(
                        sec.line,
                        format!(
                            "0x{index:04X} {title:?}: {} without any sub-entry: skipped",
                            if ot == 0x8 { "ARRAY" } else { "RECORD" }
                        ),
                    );
                    return Ok(None);
                }
            }
            other => {
                return Err(self.err(
                    sec.value("ObjectType").map_or(sec.line, |e| e.line),
                    format!("unknown ObjectType 0x{other:X} (expected 0x7 VAR, 0x8 ARRAY, 0x9 RECORD, 0x2 DOMAIN, 0x5 DEFTYPE, 0x6 DEFSTRUCT)"),
                ));
            }
        }
        Ok(Some(obj))
    }

    /// The entries of a `[XXXXName]` or `[XXXXValue]` section by sub-index 1..=n.
    fn per_sub<'s>(
        &self,
        s: Option<&'s Section>,
        n: u8,
    ) -> Result<BTreeMap<u8, &'s Entry>, EdsError> {
        let mut m = BTreeMap::new();
        if let Some(s) = s {
            for e in &s.entries {
                if e.key.eq_ignore_ascii_case("NrOfEntries") {
                    continue;
                }
                let k = parse_int(&e.key)
                    .and_then(|(v, _)| u8::try_from(v).ok())
                    .filter(|&k| k >= 1 && k <= n)
                    .ok_or_else(|| {
                        self.err(
                            e.line,
                            format!(
                                "[{}]: key {:?} is not a sub-index 1..{n} of the compact array",
                                s.name, e.key
                            ),
                        )
                    })?;
                m.insert(k, e);
            }
        }
        Ok(m)
    }

    /// The sub-entries of a compact array (CiA 306): sub 0 holds the count, subs 1..=n are built
    /// from the object's own keys, named by `[XXXXName]` and valued by `[XXXXValue]` if present.
    #[allow(clippy::too_many_arguments)]
    fn compact(
        &mut self,
        index: u16,
        sec: &Section,
        n: u8,
        cline: usize,
        names: Option<&&Section>,
        values: Option<&&Section>,
        obj: &mut OutObj,
    ) -> Result<(), EdsError> {
        let spec = self.var_spec(sec, obj.name.clone(), false)?;
        let names = self.per_sub(names.copied(), n)?;
        let values = self.per_sub(values.copied(), n)?;
        obj.notes.push((
            cline,
            format!("CompactSubObj={n}: sub-entries 0..{n} generated per CiA 306"),
        ));
        let count = OutSub {
            sub: 0,
            name: "Highest sub-index supported".to_string(),
            ty: Ty::u8(),
            type_comment: None,
            access: "ro",
            access_comment: None,
            pdo: false,
            default: Val::Int(i128::from(n)),
            default_hex: false,
            default_comment: None,
            default_line: cline,
            synthesized: false,
            default_note: None,
            min: None,
            max: None,
            unit: None,
            notes: Vec::new(),
        };
        obj.subs.push(count);
        for k in 1..=n {
            let name = names
                .get(&k)
                .map(|e| e.value.clone())
                .filter(|s| !s.is_empty())
                .unwrap_or_else(|| format!("{} {k}", spec.name));
            match self.entry(&spec, k, name, values.get(&k).copied())? {
                Ok(mut e) => {
                    if k > 1 {
                        // The template's notes are said once, on sub 1.
                        e.notes.clear();
                    }
                    obj.subs.push(e);
                }
                Err(why) => {
                    let line = spec.ty.err().map_or(sec.line, |(_, l)| l);
                    self.skip(
                        line,
                        format!("0x{index:04X} {:?}: {why}: skipped", obj.name),
                    );
                    obj.subs.clear();
                    return Ok(());
                }
            }
        }
        Ok(())
    }

    /// Fill and check the identity: 0x1000 and 0x1018:1..3 against `[DeviceInfo]`.
    fn identity(
        &mut self,
        out: &mut BTreeMap<u16, OutObj>,
        info: Option<&Section>,
    ) -> Result<[u32; 4], EdsError> {
        let new_sub =
            |sub: u8, name: &str, ty: Ty, access: &'static str, v: i128, line: usize| OutSub {
                sub,
                name: name.to_string(),
                ty,
                type_comment: None,
                access,
                access_comment: None,
                pdo: false,
                default: Val::Int(v),
                default_hex: ty.code == 0x07,
                default_comment: None,
                default_line: line,
                synthesized: false,
                default_note: None,
                min: None,
                max: None,
                unit: None,
                notes: Vec::new(),
            };
        // 0x1000.
        let device_type = match out.get_mut(&index::DEVICE_TYPE) {
            None => {
                self.note(
                    None,
                    "the EDS has no object 0x1000: added (UNSIGNED32, ro, device type 0)",
                );
                out.insert(
                    index::DEVICE_TYPE,
                    OutObj {
                        name: "Device type".to_string(),
                        line: 0,
                        section: String::new(),
                        notes: vec![],
                        var: true,
                        subs: vec![new_sub(0, "Device type", Ty::u32(), "ro", 0, 0)],
                    },
                );
                0
            }
            Some(o) => {
                let line = o.line;
                if !o.var {
                    return Err(self.err(line, "object 0x1000 (device type) must be a VAR"));
                }
                let s = &mut o.subs[0];
                s.default_hex = true;
                match s.default {
                    Val::Int(v) if (0..=i128::from(u32::MAX)).contains(&v) => {
                        if s.synthesized {
                            self.note(None, "0x1000 has no DefaultValue: device type 0");
                        }
                        v as u32
                    }
                    Val::NodeId(_) => {
                        return Err(self.err(
                            s.default_line,
                            "the device type (0x1000) cannot depend on $NODEID",
                        ));
                    }
                    _ => {
                        return Err(self.err(
                            line,
                            format!(
                                "object 0x1000 (device type) must be UNSIGNED32, not {}",
                                s.ty.cia
                            ),
                        ));
                    }
                }
            }
        };
        // 0x1018.
        let o = match out.get_mut(&index::IDENTITY) {
            Some(o) if o.var => {
                return Err(self.err(o.line, "object 0x1018 (identity) must be a RECORD"));
            }
            Some(o) => o,
            None => {
                self.note(
                    None,
                    "the EDS has no object 0x1018: added (sub 0 and 1..3, from [DeviceInfo])",
                );
                out.insert(
                    index::IDENTITY,
                    OutObj {
                        name: "Identity object".to_string(),
                        line: 0,
                        section: String::new(),
                        notes: vec![],
                        var: false,
                        subs: vec![new_sub(
                            0,
                            "Highest sub-index supported",
                            Ty::u8(),
                            "const",
                            3,
                            0,
                        )],
                    },
                );
                out.get_mut(&index::IDENTITY).expect("inserted")
            }
        };
        let mut ids = [0u32; 3];
        for (k, (key, sub_name)) in [
            ("VendorNumber", "Vendor-ID"),
            ("ProductNumber", "Product code"),
            ("RevisionNumber", "Revision number"),
        ]
        .into_iter()
        .enumerate()
        {
            let sub = k as u8 + 1;
            let di = match info.and_then(|s| s.value(key)) {
                Some(e) => Some((
                    parse_int(&e.value)
                        .map(|(v, _)| v)
                        .filter(|v| (0..=i128::from(u32::MAX)).contains(v))
                        .ok_or_else(|| {
                            self.err(e.line, format!("{key} {:?} is not an UNSIGNED32", e.value))
                        })?,
                    e.line,
                )),
                None => None,
            };
            let pos = o.subs.iter().position(|s| s.sub == sub);
            let Some(pos) = pos else {
                let (v, how) = match di {
                    Some((v, l)) => (v, format!("from [DeviceInfo] {key} (line {l})")),
                    None => (0, "0 (no [DeviceInfo] either)".to_string()),
                };
                self.note(
                    None,
                    format!("0x1018:{sub} ({sub_name}) is missing in the EDS: added, {how}"),
                );
                let at = o
                    .subs
                    .iter()
                    .position(|s| s.sub > sub)
                    .unwrap_or(o.subs.len());
                let mut s = new_sub(sub, sub_name, Ty::u32(), "ro", v, 0);
                s.default_comment = Some(format!("added: {how}"));
                o.subs.insert(at, s);
                ids[k] = v as u32;
                continue;
            };
            let s = &mut o.subs[pos];
            if s.ty.code != 0x07 {
                return Err(self.err(
                    s.default_line,
                    format!(
                        "0x1018:{sub} ({sub_name}) must be UNSIGNED32, not {}",
                        s.ty.cia
                    ),
                ));
            }
            s.default_hex = true;
            let obj_val = match s.default {
                Val::Int(v) => v,
                Val::NodeId(_) => {
                    return Err(self.err(
                        s.default_line,
                        format!("0x1018:{sub} ({sub_name}) cannot depend on $NODEID"),
                    ));
                }
                _ => unreachable!("UNSIGNED32"),
            };
            let v = match (s.synthesized, di) {
                (false, Some((d, dl))) if d != obj_val => {
                    let msg = format!(
                        "0x1018:{sub} ({sub_name}) default 0x{obj_val:08X} contradicts [DeviceInfo] {key} 0x{d:08X} at line {dl}"
                    );
                    if self.strict_identity {
                        return Err(self.err(s.default_line, msg));
                    }
                    self.note(Some(s.default_line), format!("{msg}: [DeviceInfo] wins"));
                    s.default = Val::Int(d);
                    s.default_comment = Some(format!(
                        "[DeviceInfo] {key}; the EDS default was 0x{obj_val:X}"
                    ));
                    d
                }
                (true, Some((d, dl))) => {
                    s.default_note = Some((
                        s.default_line,
                        format!("no DefaultValue in the EDS: [DeviceInfo] {key} (line {dl})"),
                    ));
                    s.default = Val::Int(d);
                    d
                }
                (true, None) => {
                    self.note(
                        None,
                        format!(
                            "0x1018:{sub} ({sub_name}) has no default and [DeviceInfo] no {key}: 0"
                        ),
                    );
                    s.default = Val::Int(0);
                    0
                }
                (false, _) => obj_val,
            };
            // An identity entry is read-only and its value is the device's: a range on it (an
            // EDS may give one, even a $NODEID-dependent one) cannot be honoured once the value
            // comes from [DeviceInfo], so it goes.
            if v != obj_val || s.synthesized {
                s.min = None;
                s.max = None;
            }
            ids[k] = v as u32;
        }
        Ok([ids[0], ids[1], ids[2], device_type])
    }

    #[allow(clippy::too_many_arguments)]
    fn render(
        &self,
        ini: &Ini,
        name: &str,
        [vendor, product, revision, device_type]: [u32; 4],
        node_from: Option<&str>,
        out: &BTreeMap<u16, OutObj>,
        stats: &Stats,
    ) -> String {
        let mut t = String::new();
        let file_name = self
            .file
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        comment_lines(
            &mut t,
            &format!(
                "Drive dictionary imported from the {} {} by `canmotion dict import` (canmotion {}).",
                if stats.dcf { "DCF" } else { "EDS" },
                file_name,
                env!("CARGO_PKG_VERSION")
            ),
            "# ",
            "#   ",
        );
        for (sec, keys) in [
            (
                "FileInfo",
                &[
                    "FileName",
                    "FileVersion",
                    "FileRevision",
                    "EDSVersion",
                    "Description",
                    "CreatedBy",
                    "CreationDate",
                    "ModifiedBy",
                    "ModificationDate",
                ][..],
            ),
            (
                "DeviceInfo",
                &[
                    "VendorName",
                    "VendorNumber",
                    "ProductName",
                    "ProductNumber",
                    "RevisionNumber",
                    "OrderCode",
                ][..],
            ),
        ] {
            if let Some(s) = ini.section(sec) {
                let items: Vec<String> = keys
                    .iter()
                    .filter_map(|k| s.value(k).map(|e| format!("{}={}", e.key, e.value)))
                    .collect();
                if !items.is_empty() {
                    comment_lines(
                        &mut t,
                        &format!("[{sec}] {}", items.join(", ")),
                        "# ",
                        "#   ",
                    );
                }
            }
        }
        let node = match node_from {
            Some(from) => format!(
                "Node id: $NODEID resolved for node {} ({from}).",
                self.node.unwrap_or(0)
            ),
            None => {
                "Node id: \"$NODEID+...\" defaults kept relative (the loader adds the node id)."
                    .to_string()
            }
        };
        comment_lines(&mut t, &node, "# ", "#   ");
        comment_lines(
            &mut t,
            &format!(
                "{} objects, {} entries; {} skipped; {} notes on entries (`# EDS line N:` comments).",
                stats.objects,
                stats.entries,
                self.skipped,
                stats.entry_notes.len()
            ),
            "# ",
            "#   ",
        );
        comment_lines(
            &mut t,
            "Format: see dictionaries/drives/cia402-servo.toml. Conversions: rwr/rww -> rw; \
             odd-width integers widened (range kept by min/max, not PDO-mappable); \
             UNICODE_STRING -> string; TIME_OF_DAY/TIME_DIFFERENCE -> octets.",
            "# ",
            "# ",
        );
        if !self.notes.is_empty() {
            t.push_str("#\n# Import notes:\n");
            let mut notes: Vec<&Note> = self.notes.iter().collect();
            notes.sort_by_key(|n| n.line.unwrap_or(usize::MAX));
            for n in notes {
                let text = match n.line {
                    Some(l) => format!("EDS line {l}: {}", n.text),
                    None => n.text.clone(),
                };
                comment_lines(&mut t, &text, "#   ", "#     ");
            }
        }
        if let Some(c) = ini.section("Comments") {
            let lines: Vec<&Entry> = c
                .entries
                .iter()
                .filter(|e| !e.key.eq_ignore_ascii_case("Lines"))
                .take(20)
                .collect();
            if !lines.is_empty() {
                t.push_str("#\n# [Comments] of the EDS:\n");
                for e in lines {
                    let _ = writeln!(t, "#   {}", comment_text(&e.value));
                }
            }
        }
        t.push_str("\n[device]\n");
        kv(&mut t, "name", &toml_str(name), None);
        kv(
            &mut t,
            "vendor_id",
            &format!("0x{vendor:08X}"),
            Some("0x1018:1"),
        );
        kv(
            &mut t,
            "product_code",
            &format!("0x{product:08X}"),
            Some("0x1018:2"),
        );
        kv(
            &mut t,
            "revision",
            &format!("0x{revision:08X}"),
            Some("0x1018:3"),
        );
        kv(
            &mut t,
            "device_type",
            &format!("0x{device_type:08X}"),
            Some("0x1000"),
        );

        for (&index, o) in out {
            t.push('\n');
            let mut notes = o.notes.clone();
            if o.var {
                notes.extend(o.subs[0].notes.iter().cloned());
            }
            notes.sort_by_key(|(l, _)| *l);
            for (l, n) in &notes {
                comment_lines(&mut t, &format!("EDS line {l}: {n}"), "# ", "#   ");
            }
            t.push_str("[[object]]\n");
            let origin = if o.line == 0 {
                "added by the import".to_string()
            } else {
                format!("[{}], EDS line {}", o.section, o.line)
            };
            kv(&mut t, "index", &format!("0x{index:04X}"), Some(&origin));
            kv(&mut t, "name", &toml_str(&o.name), None);
            if o.var {
                entry_keys(&mut t, index, &o.subs[0], out);
            } else {
                for s in &o.subs {
                    t.push('\n');
                    let mut notes = s.notes.clone();
                    notes.sort_by_key(|(l, _)| *l);
                    for (l, n) in &notes {
                        comment_lines(&mut t, &format!("EDS line {l}: {n}"), "# ", "#   ");
                    }
                    t.push_str("[[object.sub]]\n");
                    kv(&mut t, "sub", &s.sub.to_string(), None);
                    kv(&mut t, "name", &toml_str(&s.name), None);
                    entry_keys(&mut t, index, s, out);
                }
            }
        }
        t
    }
}

/// The keys of an entry after `name`.
fn entry_keys(t: &mut String, index: u16, s: &OutSub, out: &BTreeMap<u16, OutObj>) {
    kv(
        t,
        "type",
        &toml_str(type_name(s.ty.out)),
        s.type_comment.as_deref(),
    );
    kv(
        t,
        "access",
        &toml_str(s.access),
        s.access_comment.as_deref(),
    );
    if s.pdo {
        kv(t, "pdo", "true", None);
    }
    // Hex for unsigned values that read as codes: the EDS wrote them so, or a 32-bit entry of
    // the communication area (COB-IDs, mapping entries, identity).
    let unsigned = matches!(s.ty.kind, Kind::Int { signed: false, .. });
    let comm_code = index::COMMUNICATION_AREA.contains(&index) && s.ty.code == 0x07;
    let hex = unsigned && (s.default_hex || comm_code);
    let mut comment: Vec<String> = Vec::new();
    if let Val::Int(v) = s.default
        && v != 0
        && s.sub >= 1
        && (index::RPDO_MAPPING_AREA.contains(&index) || index::TPDO_MAPPING_AREA.contains(&index))
        && s.ty.code == 0x07
    {
        let (mi, ms, bits) = ((v >> 16) as u16, ((v >> 8) & 0xFF) as u8, (v & 0xFF) as u8);
        let what = out
            .get(&mi)
            .map(|o| {
                o.subs
                    .iter()
                    .find(|x| x.sub == ms)
                    .map_or(o.name.clone(), |x| x.name.clone())
            })
            .unwrap_or_else(|| "not in this dictionary".to_string());
        comment.push(format!("0x{mi:04X}:{ms}, {bits} bits ({what})"));
    }
    comment.extend(s.default_comment.clone());
    comment.extend(s.default_note.as_ref().map(|(_, n)| n.clone()));
    let comment = (!comment.is_empty()).then(|| comment.join("; "));
    kv(
        t,
        "default",
        &render_val(&s.default, s.ty, hex),
        comment.as_deref(),
    );
    if let Some(b) = s.min {
        kv(t, "min", &render_bound(b, s.ty), None);
    }
    if let Some(b) = s.max {
        kv(t, "max", &render_bound(b, s.ty), None);
    }
    if let Some(u) = &s.unit {
        kv(t, "unit", &toml_str(u), None);
    }
}

fn render_val(v: &Val, ty: Ty, hex: bool) -> String {
    match v {
        Val::Bool(b) => b.to_string(),
        Val::Int(i) if hex && *i >= 0 => format!("0x{:0w$X}", i, w = ty.hex_digits()),
        Val::Int(i) => i.to_string(),
        Val::Real(r) => float(*r),
        Val::Text(s) => toml_str(s),
        Val::NodeId(off) => toml_str(&node_text(*off)),
    }
}

fn render_bound(b: Bound, ty: Ty) -> String {
    match b.val {
        Num::Int(i) if i > i128::from(i64::MAX) || i < i128::from(i64::MIN) => float(i as f64),
        Num::Int(i) if ty.kind == Kind::Real32 || ty.kind == Kind::Real64 => float(i as f64),
        Num::Int(i) if b.hex && matches!(ty.kind, Kind::Int { signed: false, .. }) => {
            format!("0x{:0w$X}", i, w = ty.hex_digits())
        }
        Num::Int(i) => i.to_string(),
        Num::Real(r) => float(r),
    }
}

/// A TOML float.
fn float(r: f64) -> String {
    if r.is_nan() {
        "nan".to_string()
    } else if r.is_infinite() {
        if r > 0.0 { "inf" } else { "-inf" }.to_string()
    } else {
        format!("{r:?}")
    }
}

/// A TOML basic string.
fn toml_str(s: &str) -> String {
    let mut o = String::with_capacity(s.len() + 2);
    o.push('"');
    for c in s.chars() {
        match c {
            '"' => o.push_str("\\\""),
            '\\' => o.push_str("\\\\"),
            '\n' => o.push_str("\\n"),
            '\t' => o.push_str("\\t"),
            '\r' => o.push_str("\\r"),
            c if (c as u32) < 0x20 || c as u32 == 0x7F => {
                let _ = write!(o, "\\u{:04X}", c as u32);
            }
            c => o.push(c),
        }
    }
    o.push('"');
    o
}

/// Text safe inside a `#` comment (no control characters).
fn comment_text(s: &str) -> String {
    s.chars()
        .map(|c| if c.is_control() { ' ' } else { c })
        .collect()
}

/// `text` as `#` comment lines of at most 100 columns, broken at spaces.
fn comment_lines(t: &mut String, text: &str, first: &str, rest: &str) {
    const WIDTH: usize = 100;
    let mut line = first.to_string();
    let mut empty = true;
    for word in comment_text(text).split(' ').filter(|w| !w.is_empty()) {
        if !empty && line.chars().count() + 1 + word.chars().count() > WIDTH {
            t.push_str(line.trim_end());
            t.push('\n');
            line = rest.to_string();
            empty = true;
        }
        if !empty {
            line.push(' ');
        }
        line.push_str(word);
        empty = false;
    }
    t.push_str(line.trim_end());
    t.push('\n');
}

/// `key = value`, with an aligned trailing comment.
fn kv(t: &mut String, key: &str, value: &str, comment: Option<&str>) {
    let line = format!("{key} = {value}");
    let _ = match comment {
        Some(c) => writeln!(t, "{line:<28} # {}", comment_text(c)),
        None => writeln!(t, "{line}"),
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEAD: &str = "[DeviceInfo]\nVendorNumber=0x1\nProductNumber=2\nRevisionNumber=3\n\
        [1000]\nParameterName=Device type\nObjectType=0x7\nDataType=0x0007\nAccessType=ro\nDefaultValue=0x20192\n";

    fn import(text: &str) -> Result<Imported, EdsError> {
        import_str(Path::new("t.eds"), text, &ImportOptions::default())
    }

    fn import_node(text: &str, node: u8) -> Result<Imported, EdsError> {
        import_str(
            Path::new("t.eds"),
            text,
            &ImportOptions {
                node: Some(node),
                ..Default::default()
            },
        )
    }

    fn err(text: &str) -> String {
        import(text).unwrap_err().to_string()
    }

    fn var(index: u16, ty: u16, extra: &str) -> String {
        format!(
            "[{index:04X}]\nParameterName=v\nObjectType=0x7\nDataType=0x{ty:04X}\nAccessType=rw\n{extra}\n"
        )
    }

    #[test]
    fn numbers_decimal_hex_octal() {
        assert_eq!(parse_int("42"), Some((42, false)));
        assert_eq!(parse_int("0x2A"), Some((42, true)));
        assert_eq!(parse_int("0X2a"), Some((42, true)));
        assert_eq!(parse_int("052"), Some((42, false)));
        assert_eq!(parse_int("0"), Some((0, false)));
        assert_eq!(parse_int("-2147483648"), Some((-2147483648, false)));
        assert_eq!(parse_int("+7"), Some((7, false)));
        assert_eq!(parse_int(" 0x10 "), Some((16, true)));
        for bad in [
            "",
            "0x",
            "08",
            "1.5",
            "0x+5",
            "12a",
            "--1",
            "0xFFFFFFFFFFFFFFFFFFFFFFFFFFFFFFFFFF",
        ] {
            assert_eq!(parse_int(bad), None, "{bad}");
        }
        assert!(bad_number("08").contains("octal"));
    }

    #[test]
    fn node_id_forms() {
        assert_eq!(parse_node_id_expr("$NODEID+0x180"), Ok(Some(0x180)));
        assert_eq!(parse_node_id_expr("0x180+$NODEID"), Ok(Some(0x180)));
        assert_eq!(parse_node_id_expr("$NodeID + 0x200"), Ok(Some(0x200)));
        assert_eq!(parse_node_id_expr("$NODEID"), Ok(Some(0)));
        assert_eq!(parse_node_id_expr("1280+$NODEID"), Ok(Some(1280)));
        assert_eq!(parse_node_id_expr("0x180"), Ok(None));
        assert!(parse_node_id_expr("$NODEID-1").is_err());
        assert!(parse_node_id_expr("$NODEID*2").is_err());
        assert!(parse_node_id_expr("1+$NODEID+2").is_err());
    }

    #[test]
    fn values_per_type() {
        let t = |c| Ty::from_code(c).unwrap();
        let v = |c, s| parse_value(t(c), s, None).map(|p| p.val);
        assert_eq!(v(0x04, "0xFFFFFFFF").unwrap(), Val::Int(-1));
        assert_eq!(v(0x04, "0x80000000").unwrap(), Val::Int(-2147483648));
        assert_eq!(v(0x15, "0xFFFFFFFFFFFFFFF6").unwrap(), Val::Int(-10));
        assert_eq!(v(0x10, "-1").unwrap(), Val::Int(-1));
        assert!(matches!(v(0x05, "256"), Err(VErr::Range(_))));
        assert!(matches!(v(0x05, "x"), Err(VErr::Syntax(_))));
        assert_eq!(v(0x01, "1").unwrap(), Val::Bool(true));
        assert_eq!(v(0x08, "1.5").unwrap(), Val::Real(1.5));
        assert_eq!(v(0x08, "0x3F800000").unwrap(), Val::Real(1.0));
        assert_eq!(v(0x07, "$NODEID+0x180").unwrap(), Val::NodeId(0x180));
        assert_eq!(
            parse_value(t(0x07), "0x180+$NODEID", Some(5)).unwrap().val,
            Val::Int(0x185)
        );
        assert!(matches!(v(0x08, "$NODEID"), Err(VErr::Syntax(_))));
        assert_eq!(v(0x0A, "4142").unwrap(), Val::Text("AB".into()));
        assert_eq!(v(0x0A, "ABCD").unwrap(), Val::Text(String::new()));
        assert_eq!(v(0x0F, "@AB").unwrap(), Val::Text("@AB".into()));
        // Strings of any length are kept whole (issue 13: a 34-byte device name was cut to 32).
        assert_eq!(v(0x09, &"x".repeat(40)).unwrap(), Val::Text("x".repeat(40)));
        let long = "y".repeat(crate::canopen::MAX_OBJECT_BYTES + 9);
        assert_eq!(
            parse_value(t(0x09), &long, None).unwrap().val,
            Val::Text("y".repeat(crate::canopen::MAX_OBJECT_BYTES))
        );
    }

    #[test]
    fn ini_comments_case_and_crlf() {
        let text = format!(
            "\u{feff}; comment\r\n{}# another\r\n[2000]\r\nparametername=Lower\r\nOBJECTTYPE=7\r\ndatatype=5\r\naccesstype=RO\r\ndefaultvalue=012\r\n",
            HEAD
        );
        let i = import(&text).unwrap();
        let s = i.dictionary.sub(0x2000, 0).unwrap();
        assert_eq!(s.name, "Lower");
        assert_eq!(
            s.default,
            crate::canopen::dictionary::DefaultValue::Fixed(canopen_rs::Value::Unsigned8(10))
        );
    }

    #[test]
    fn compact_arrays_generate_their_subs() {
        let text = format!(
            "{HEAD}[3004]\nParameterName=Status\nObjectType=8\nCompactSubObj=3\nDataType=0x6\nAccessType=ro\nDefaultValue=7\nPDOMapping=1\n\
             [3004Name]\nNrOfEntries=1\n2=Second\n[3004Value]\nNrOfEntries=1\n3=9\n"
        );
        let i = import(&text).unwrap();
        let o = &i.dictionary.objects[&0x3004];
        assert_eq!(o.subs.len(), 4);
        use crate::canopen::dictionary::DefaultValue::Fixed;
        use canopen_rs::Value::*;
        assert_eq!(o.subs[&0].default, Fixed(Unsigned8(3)));
        assert_eq!(o.subs[&1].name, "Status 1");
        assert_eq!(o.subs[&2].name, "Second");
        assert_eq!(o.subs[&1].default, Fixed(Unsigned16(7)));
        assert_eq!(o.subs[&3].default, Fixed(Unsigned16(9)));
        assert!(o.subs[&3].pdo && !o.subs[&0].pdo);
    }

    #[test]
    fn errors_have_line_numbers() {
        let e = err(&format!("{HEAD}[2000sub1]\nParameterName=x\n"));
        assert!(
            e.starts_with("t.eds:11: ") && e.contains("without its parent"),
            "{e}"
        );
        let e = err(&format!("{HEAD}{}", var(0x2000, 7, "DefaultValue=0xZZ")));
        assert!(
            e.starts_with("t.eds:16: DefaultValue") && e.contains("bad number"),
            "{e}"
        );
        let e = err(&format!("{HEAD}[2000]\nParameterName=x\nAccessType=rw\n"));
        assert!(
            e.starts_with("t.eds:11: ") && e.contains("missing DataType"),
            "{e}"
        );
        let e = err(&format!("{HEAD}{}", var(0x2000, 7, "").replace("rw", "rx")));
        assert!(e.starts_with("t.eds:15: AccessType"), "{e}");
        let e = err(&format!("{HEAD}[1000]\n"));
        assert!(
            e.starts_with("t.eds:11: section [1000] already defined at line 5"),
            "{e}"
        );
        let e = err("x=1\n");
        assert!(e.starts_with("t.eds:1: "), "{e}");
        let e = err("[DeviceInfo\n");
        assert!(e.starts_with("t.eds:1: section header"), "{e}");
        let e = err(&format!("{HEAD}[2000subX]\n"));
        assert!(e.starts_with("t.eds:11: bad sub-index"), "{e}");
        let e = err(&format!("{HEAD}{}", var(0x2000, 5, "DefaultValue=300")));
        assert!(
            e.starts_with("t.eds:16: ") && e.contains("does not fit UNSIGNED8"),
            "{e}"
        );
        let e = err(&format!(
            "{HEAD}[2000]\nParameterName=x\nObjectType=0x7\nDataType=0x0007\nAccessType=rw\nPDOMapping=2\n"
        ));
        assert!(e.starts_with("t.eds:16: PDOMapping"), "{e}");
        let e = err(&format!(
            "{HEAD}[MandatoryObjects]\nSupportedObjects=1\n1=0x10180\n"
        ));
        assert!(e.starts_with("t.eds:13: 1: bad object index"), "{e}");
    }

    #[test]
    fn loader_conflicts_are_resolved_with_notes() {
        let text = format!(
            "{HEAD}{}{}{}{}{}",
            var(0x2000, 0x09, "PDOMapping=1\nDefaultValue=abc"),
            var(0x2001, 0x05, "DefaultValue=9\nLowLimit=1\nHighLimit=5"),
            var(0x2002, 0x05, "LowLimit=6\nHighLimit=5"),
            var(0x2003, 0x05, "LowLimit=2\nHighLimit=10"),
            var(0x2004, 0x10, "PDOMapping=1\nDefaultValue=5"),
        ) + &var(
            0x2005,
            0x08,
            "LowLimit=-inf\nHighLimit=nan\nDefaultValue=1.2",
        ) + &var(
            0x2006,
            0x08,
            "LowLimit=1.2\nHighLimit=1.2\nDefaultValue=1.2",
        ) + &var(0x2007, 0x09, "LowLimit=1\nDefaultValue=x");
        let i = import(&text).unwrap();
        let d = &i.dictionary;
        assert!(!d.sub(0x2000, 0).unwrap().pdo);
        assert_eq!(d.sub(0x2001, 0).unwrap().max, None);
        assert_eq!(d.sub(0x2001, 0).unwrap().min, Some(1.0));
        assert_eq!(d.sub(0x2002, 0).unwrap().min, None);
        let s = d.sub(0x2003, 0).unwrap();
        assert_eq!(
            s.default,
            crate::canopen::dictionary::DefaultValue::Fixed(canopen_rs::Value::Unsigned8(2))
        );
        let s = d.sub(0x2004, 0).unwrap();
        assert_eq!(s.data_type, DataType::Integer32);
        assert_eq!((s.min, s.max), (Some(-8388608.0), Some(8388607.0)));
        assert!(!s.pdo);
        assert!(i.toml.contains("INTEGER24 in the EDS: widened to 32 bits"));
        let s = d.sub(0x2005, 0).unwrap();
        assert_eq!((s.min, s.max), (None, None));
        let s = d.sub(0x2006, 0).unwrap();
        assert_eq!(s.min, s.max);
        assert!(s.min.is_some());
        assert!(i.toml.contains("LowLimit=1 on a VISIBLE_STRING dropped"));
        assert!(
            i.toml
                .contains("PDOMapping=1 on a variable-length VISIBLE_STRING dropped")
        );
    }

    #[test]
    fn identity_filled_from_device_info_and_contradictions() {
        let i = import(HEAD).unwrap();
        let id = i.dictionary.identity;
        assert_eq!(
            (id.vendor_id, id.product_code, id.revision, id.device_type),
            (1, 2, 3, 0x20192)
        );
        assert!(i.toml.contains("0x1018: added"), "{}", i.toml);
        let text = format!(
            "{HEAD}[1018]\nParameterName=Identity\nObjectType=0x9\n[1018sub1]\nParameterName=Vendor\nObjectType=0x7\nDataType=0x7\nAccessType=ro\nDefaultValue=0x5\n"
        );
        let i = import(&text).unwrap();
        assert_eq!(i.dictionary.identity.vendor_id, 1);
        let e = import_str(
            Path::new("t.eds"),
            &text,
            &ImportOptions {
                strict_identity: true,
                ..Default::default()
            },
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.starts_with("t.eds:19: ") && e.contains("VendorNumber") && e.contains("line 2"),
            "{e}"
        );
    }

    #[test]
    fn node_id_resolution() {
        let cob = var(0x1800, 7, "DefaultValue=$NODEID+0x180");
        let text = format!("{HEAD}{cob}");
        let rel = import(&text).unwrap();
        assert!(
            rel.toml.contains("default = \"$NODEID+0x180\""),
            "{}",
            rel.toml
        );
        assert_eq!(
            rel.dictionary
                .default_for(rel.dictionary.sub(0x1800, 0).unwrap(), 3),
            Some(canopen_rs::Value::Unsigned32(0x183))
        );
        let fixed = import_node(&text, 5).unwrap();
        assert!(
            fixed.toml.contains("default = 0x00000185"),
            "{}",
            fixed.toml
        );
        let dcf = format!("{HEAD}[DeviceComissioning]\nNodeID=0x10\n{cob}");
        let d = import(&dcf).unwrap();
        assert!(d.dcf && d.node == Some(16));
        assert!(d.toml.contains("default = 0x00000190"));
        assert_eq!(import_node(&dcf, 2).unwrap().node, Some(2));
    }

    #[test]
    fn parameter_value_wins() {
        let text = format!(
            "{HEAD}{}",
            var(0x6060, 2, "DefaultValue=0\nParameterValue=7")
        );
        let i = import(&text).unwrap();
        assert_eq!(
            i.dictionary.sub(0x6060, 0).unwrap().default,
            crate::canopen::dictionary::DefaultValue::Fixed(canopen_rs::Value::Integer8(7))
        );
        assert!(i.toml.contains("ParameterValue; DefaultValue 0"));
    }

    use proptest::prelude::*;

    /// Lines that look like an EDS, to get past the INI layer.
    fn eds_line() -> impl Strategy<Value = String> {
        let num = prop_oneof![
            Just("0".to_string()),
            Just("$NODEID+0x180".to_string()),
            Just("0x180+$NODEID".to_string()),
            Just("".to_string()),
            Just("-1".to_string()),
            Just("0xFFFFFFFFFFFFFFFF".to_string()),
            Just("1.5".to_string()),
            Just("ABCD".to_string()),
            Just("inf".to_string()),
            Just("NaN".to_string()),
            Just("0x7F800000".to_string()),
            Just("1e39".to_string()),
            (-70000i64..70000).prop_map(|v| v.to_string()),
            (0u32..0x30).prop_map(|v| format!("0x{v:X}")),
            "[ -~]{0,12}",
        ];
        let key = prop_oneof![
            Just("ParameterName"),
            Just("ObjectType"),
            Just("DataType"),
            Just("AccessType"),
            Just("DefaultValue"),
            Just("ParameterValue"),
            Just("LowLimit"),
            Just("HighLimit"),
            Just("PDOMapping"),
            Just("CompactSubObj"),
            Just("SubNumber"),
            Just("NodeID"),
            Just("VendorNumber"),
            Just("1"),
            Just("SupportedObjects"),
        ];
        let access = prop_oneof![
            Just("ro"),
            Just("rw"),
            Just("wo"),
            Just("const"),
            Just("rww"),
            Just("rwr")
        ];
        let section = prop_oneof![
            Just("1000".to_string()),
            Just("1018".to_string()),
            Just("DeviceInfo".to_string()),
            Just("DeviceComissioning".to_string()),
            Just("MandatoryObjects".to_string()),
            (0x1000u16..0x1020).prop_map(|i| format!("{i:04X}")),
            (0x1016u16..0x1019, 0u8..6).prop_map(|(i, s)| format!("{i:04X}sub{s:X}")),
            (0x2000u16..0x2003).prop_map(|i| format!("{i:04X}Name")),
            (0x2000u16..0x2003).prop_map(|i| format!("{i:04X}Value")),
            (0x2000u16..0x2003, 0u8..3).prop_map(|(i, s)| format!("{i:04X}sub{s}")),
        ];
        prop_oneof![
            section.prop_map(|s| format!("[{s}]")),
            (key, num).prop_map(|(k, v)| format!("{k}={v}")),
            access.prop_map(|a| format!("AccessType={a}")),
            "[ -~]{0,20}",
        ]
    }

    /// `key=value` with a value from `pool`, `yes` times in `yes + no`; else the key left out.
    fn maybe(
        key: &'static str,
        pool: &'static [&'static str],
        yes: u32,
        no: u32,
    ) -> impl Strategy<Value = String> {
        prop_oneof![
            no => Just(String::new()),
            yes => proptest::sample::select(pool).prop_map(move |v| format!("{key}={v}\n")),
        ]
    }

    const VALUES: &[&str] = &[
        "0",
        "1",
        "2",
        "-1",
        "255",
        "256",
        "0x7F",
        "0x80",
        "0xFFFF",
        "0xFFFFFFFF",
        "0x8000000000000000",
        "-2147483648",
        "1.5",
        "-0.25",
        "inf",
        "nan",
        "0x3F800000",
        "1e39",
        "$NODEID+0x180",
        "0x200+$NODEID",
        "$NODEID",
        "ABCD",
        "414243",
        "@x",
        "",
        "010",
    ];

    /// The keys of a VAR section.
    fn var_keys() -> impl Strategy<Value = String> {
        (
            maybe("ParameterName", &["Name", "", "A \"quoted\" \\ name"], 3, 1),
            maybe(
                "DataType",
                &[
                    "0x1", "0x2", "0x3", "0x4", "0x5", "0x6", "0x7", "0x8", "0x9", "0xA", "0xB",
                    "0xC", "0xF", "0x10", "0x11", "0x12", "0x15", "0x16", "0x1A", "0x1B", "0x40",
                ],
                30,
                1,
            ),
            maybe(
                "AccessType",
                &["ro", "rw", "wo", "const", "rww", "rwr"],
                30,
                1,
            ),
            maybe("DefaultValue", VALUES, 1, 1),
            maybe("ParameterValue", VALUES, 1, 4),
            maybe("LowLimit", VALUES, 1, 4),
            maybe("HighLimit", VALUES, 1, 4),
            maybe("PDOMapping", &["0", "1"], 1, 1),
        )
            .prop_map(|(a, b, c, d, e, f, g, h)| format!("{a}{b}{c}{d}{e}{f}{g}{h}"))
    }

    /// A whole EDS of plausible objects (VAR, ARRAY, RECORD, compact), sections unique.
    fn eds_file() -> impl Strategy<Value = String> {
        let index = prop_oneof![
            Just(0x1000u16),
            Just(0x1018),
            0x1400u16..0x1403,
            0x2000u16..0x2008
        ];
        let object = (
            index,
            // Usually (empty) the object type that fits the sub-sections, sometimes not.
            prop_oneof![
                20 => Just(""),
                1 => Just("0x7"),
                1 => Just("0x8"),
                1 => Just("0x9"),
                1 => Just("0x2"),
                1 => Just("0x5"),
            ],
            var_keys(),
            prop_oneof![
                4 => Just(""),
                1 => Just("CompactSubObj=0\n"),
                1 => Just("CompactSubObj=3\n"),
            ],
            proptest::collection::btree_map(0u8..6, var_keys(), 0..4),
        );
        (
            maybe("VendorNumber", &["0", "1", "0x555", "-1"], 3, 1),
            maybe("ProductNumber", &["0", "2"], 1, 1),
            prop_oneof![Just(""), Just("[DeviceComissioning]\nNodeID=5\n")],
            proptest::collection::btree_map(any::<u16>(), object, 0..8),
        )
            .prop_map(|(v, p, dcf, objects)| {
                let mut t = format!("[DeviceInfo]\n{v}{p}{dcf}");
                let mut seen = std::collections::BTreeSet::new();
                for (index, ot, keys, compact, mut subs) in objects.into_values() {
                    if !seen.insert(index) {
                        continue;
                    }
                    let compact = if ot.is_empty() && !subs.is_empty() {
                        ""
                    } else {
                        compact
                    };
                    let ot = match ot {
                        "" if subs.is_empty() && compact.is_empty() => "0x7",
                        "" if index % 2 == 0 => "0x9",
                        "" => "0x8",
                        ot => ot,
                    };
                    if compact == "CompactSubObj=3\n" && ot != "0x7" {
                        subs.clear();
                    }
                    t.push_str(&format!("[{index:04X}]\nObjectType={ot}\n{keys}{compact}"));
                    for (sub, keys) in subs {
                        t.push_str(&format!("[{index:04X}sub{sub:X}]\n{keys}"));
                    }
                }
                t
            })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(512))]

        #[test]
        fn random_text_never_panics(text in "\\PC{0,300}") {
            let _ = import(&text);
        }

    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2048))]

        #[test]
        fn eds_like_text_never_panics_and_imports_load(lines in proptest::collection::vec(eds_line(), 0..60)) {
            let text = format!("{HEAD}{}", lines.join("\n"));
            // import_str loads its own output: Rejected would be a bug.
            if let Err(e) = import(&text) {
                prop_assert!(!matches!(e, EdsError::Rejected { .. }), "{e}");
            }
        }

        #[test]
        fn generated_eds_imports_load_or_fail_with_a_line(text in eds_file()) {
            // Either a line-numbered error, or a dictionary the loader accepted (import_str
            // loads its own output: Rejected would be a bug of the importer).
            match import(&text) {
                Ok(i) => prop_assert!(i.dictionary.objects.contains_key(&0x1018)),
                Err(e) => prop_assert!(matches!(e, EdsError::Line { .. }), "{e}\n{text}"),
            }
        }
    }
}
