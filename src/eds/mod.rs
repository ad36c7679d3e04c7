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

mod convert;
mod ini;
mod render;
mod value;

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use canopen_rs::DataType;

use crate::canopen::dictionary::{DriveDictionary, type_name};
use crate::canopen::index;
use convert::*;
use ini::*;
use value::*;

pub use value::{parse_int, parse_node_id_expr};

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
