//! EDS values: numbers (decimal, hex, octal, `$NODEID+…`), data types, and the value of an entry
//! parsed against its type.

use super::*;

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
pub(super) fn bad_number(s: &str) -> String {
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
pub(super) enum Kind {
    Bool,
    Int { bits: u32, signed: bool },
    Real32,
    Real64,
    Text,
    Bytes,
}

/// A CiA 301 basic data type and the type of our format that holds it.
#[derive(Debug, Clone, Copy)]
pub(super) struct Ty {
    pub(super) code: u16,
    pub(super) cia: &'static str,
    pub(super) kind: Kind,
    pub(super) out: DataType,
}

impl Ty {
    pub(super) fn from_code(code: u16) -> Option<Ty> {
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

    pub(super) fn u8() -> Ty {
        Ty::from_code(0x05).expect("UNSIGNED8")
    }
    pub(super) fn u32() -> Ty {
        Ty::from_code(0x07).expect("UNSIGNED32")
    }

    /// The value range of an integer or boolean type.
    pub(super) fn int_range(self) -> Option<(i128, i128)> {
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
    pub(super) fn widened(self) -> bool {
        matches!(self.kind, Kind::Int { bits, .. } if !matches!(bits, 8 | 16 | 32 | 64))
    }

    pub(super) fn numeric(self) -> bool {
        matches!(
            self.kind,
            Kind::Bool | Kind::Int { .. } | Kind::Real32 | Kind::Real64
        )
    }

    /// Hex digits to write a value of this type with.
    pub(super) fn hex_digits(self) -> usize {
        match self.kind {
            Kind::Int { bits, .. } => bits as usize / 4,
            _ => 2,
        }
    }
}

/// A value as it will be written.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Val {
    Int(i128),
    Real(f64),
    Bool(bool),
    Text(String),
    NodeId(u64),
}

impl Val {
    /// The number the loader compares with min/max (REAL32 rounded to f32, as it stores it).
    pub(super) fn as_f64(&self, ty: Ty) -> Option<f64> {
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
pub(super) enum VErr {
    Syntax(String),
    Range(String),
}

impl VErr {
    pub(super) fn message(self) -> String {
        match self {
            VErr::Syntax(m) | VErr::Range(m) => m,
        }
    }
}

/// A parsed value with how to show it.
#[derive(Debug)]
pub(super) struct Parsed {
    pub(super) val: Val,
    pub(super) hex: bool,
    /// A trailing comment (how the EDS wrote it).
    pub(super) comment: Option<String>,
    /// Decisions taken on it.
    pub(super) notes: Vec<String>,
}

impl Parsed {
    pub(super) fn plain(val: Val) -> Parsed {
        Parsed {
            val,
            hex: false,
            comment: None,
            notes: Vec::new(),
        }
    }
}

/// `"$NODEID+0x180"` as the dictionary format writes it.
pub(super) fn node_text(off: u64) -> String {
    if off == 0 {
        "$NODEID".to_string()
    } else {
        format!("$NODEID+0x{off:X}")
    }
}

/// Parse a `DefaultValue`, `ParameterValue` or limit of type `ty`.
pub(super) fn parse_value(ty: Ty, text: &str, node: Option<u8>) -> Result<Parsed, VErr> {
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
