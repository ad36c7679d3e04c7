//! Command-line argument types of the commissioning commands, and how values are parsed from
//! and printed as text.

use std::fmt;
use std::str::FromStr;

use canopen_rs::{ByteString, DataType, Value};

use super::hex_bytes;
use crate::canopen::dictionary::int_value;
use crate::canopen::nmt;

/// Parse an integer: decimal, or hexadecimal with `0x`; an optional sign; `_` separators.
pub fn parse_int(s: &str) -> Option<i128> {
    let s = s.trim().replace('_', "");
    let (neg, body) = match s.strip_prefix('-') {
        Some(rest) => (true, rest),
        None => (false, s.strip_prefix('+').unwrap_or(&s)),
    };
    if body.is_empty() || body.starts_with(['+', '-']) {
        return None;
    }
    let v = match body.strip_prefix("0x").or_else(|| body.strip_prefix("0X")) {
        Some(h) if !h.is_empty() => i128::from_str_radix(h, 16).ok()?,
        Some(_) => return None,
        None => body.parse::<i128>().ok()?,
    };
    Some(if neg { -v } else { v })
}

fn parse_hex(s: &str) -> Option<u32> {
    let h = s
        .strip_prefix("0x")
        .or_else(|| s.strip_prefix("0X"))
        .unwrap_or(s);
    if h.is_empty() || h.len() > 8 || !h.bytes().all(|b| b.is_ascii_hexdigit()) {
        return None;
    }
    u32::from_str_radix(h, 16).ok()
}

/// A CANopen node id, 1–127 (decimal, or hexadecimal with `0x`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Node(pub u8);

impl FromStr for Node {
    type Err = String;
    fn from_str(s: &str) -> Result<Node, String> {
        match parse_int(s) {
            Some(n @ 1..=127) => Ok(Node(n as u8)),
            Some(n) => Err(format!("node id {n} is outside 1..=127")),
            None => Err(format!(
                "{s:?} is not a node id (1..=127, decimal or 0x hex)"
            )),
        }
    }
}

impl fmt::Display for Node {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.0)
    }
}

/// An object dictionary address `INDEX[:SUB]`, both hexadecimal (`0x` optional): `6040`,
/// `0x6040:00`, `1018:4`. The sub-index defaults to 0.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ObjectAddress {
    /// Object index.
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
}

impl FromStr for ObjectAddress {
    type Err = String;
    fn from_str(s: &str) -> Result<ObjectAddress, String> {
        let bad = || {
            format!("{s:?} is not an object address: INDEX[:SUB] in hex, e.g. 0x6040:00 or 1018:4")
        };
        let (i, sub) = match s.split_once(':') {
            Some((i, sub)) => (i, Some(sub)),
            None => (s, None),
        };
        let index = parse_hex(i)
            .and_then(|v| u16::try_from(v).ok())
            .ok_or_else(bad)?;
        let sub = match sub {
            Some(x) => parse_hex(x)
                .and_then(|v| u8::try_from(v).ok())
                .ok_or_else(bad)?,
            None => 0,
        };
        Ok(ObjectAddress { index, sub })
    }
}

impl fmt::Display for ObjectAddress {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:04X}:{:02X}", self.index, self.sub)
    }
}

/// The value types `canmotion sdo` reads and writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SdoType {
    /// UNSIGNED8.
    U8,
    /// UNSIGNED16.
    U16,
    /// UNSIGNED32.
    U32,
    /// UNSIGNED64.
    U64,
    /// INTEGER8.
    I8,
    /// INTEGER16.
    I16,
    /// INTEGER32.
    I32,
    /// INTEGER64.
    I64,
    /// REAL32.
    F32,
    /// REAL64.
    F64,
    /// VISIBLE_STRING (at most 32 bytes).
    String,
}

impl SdoType {
    /// Every type, in the order of the usage message.
    pub const ALL: [SdoType; 11] = [
        SdoType::U8,
        SdoType::U16,
        SdoType::U32,
        SdoType::U64,
        SdoType::I8,
        SdoType::I16,
        SdoType::I32,
        SdoType::I64,
        SdoType::F32,
        SdoType::F64,
        SdoType::String,
    ];

    /// The name on the command line (`u16`, `string`, ...).
    pub fn name(self) -> &'static str {
        match self {
            SdoType::U8 => "u8",
            SdoType::U16 => "u16",
            SdoType::U32 => "u32",
            SdoType::U64 => "u64",
            SdoType::I8 => "i8",
            SdoType::I16 => "i16",
            SdoType::I32 => "i32",
            SdoType::I64 => "i64",
            SdoType::F32 => "f32",
            SdoType::F64 => "f64",
            SdoType::String => "string",
        }
    }

    /// The CANopen data type.
    pub fn data_type(self) -> DataType {
        match self {
            SdoType::U8 => DataType::Unsigned8,
            SdoType::U16 => DataType::Unsigned16,
            SdoType::U32 => DataType::Unsigned32,
            SdoType::U64 => DataType::Unsigned64,
            SdoType::I8 => DataType::Integer8,
            SdoType::I16 => DataType::Integer16,
            SdoType::I32 => DataType::Integer32,
            SdoType::I64 => DataType::Integer64,
            SdoType::F32 => DataType::Real32,
            SdoType::F64 => DataType::Real64,
            SdoType::String => DataType::VisibleString,
        }
    }

    /// Parse a value of this type: integers decimal or `0x` hex (negative for signed types),
    /// floats as Rust writes them, strings as given (at most 32 bytes).
    pub fn parse_value(self, s: &str) -> Result<Value, String> {
        let t = self.name();
        let int =
            || parse_int(s).ok_or_else(|| format!("{s:?} is not an integer (decimal or 0x hex)"));
        Ok(match self {
            SdoType::F32 => Value::Real32(
                s.trim()
                    .parse::<f32>()
                    .map_err(|_| format!("{s:?} is not a number for f32"))?,
            ),
            SdoType::F64 => Value::Real64(
                s.trim()
                    .parse::<f64>()
                    .map_err(|_| format!("{s:?} is not a number for f64"))?,
            ),
            SdoType::String => {
                Value::VisibleString(ByteString::from_bytes(s.as_bytes()).map_err(|_| {
                    format!(
                        "the string is {} bytes long, at most {} fit",
                        s.len(),
                        canopen_rs::MAX_STRING_LEN
                    )
                })?)
            }
            _ => {
                let v = int()?;
                int_value(self.data_type(), v).ok_or_else(|| format!("{v} does not fit {t}"))?
            }
        })
    }
}

impl FromStr for SdoType {
    type Err = String;
    fn from_str(s: &str) -> Result<SdoType, String> {
        SdoType::ALL
            .into_iter()
            .find(|t| t.name() == s)
            .ok_or_else(|| {
                format!(
                    "unknown type {s:?}; one of: {}",
                    SdoType::ALL.map(|t| t.name()).join(" ")
                )
            })
    }
}

impl fmt::Display for SdoType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A value as `canmotion sdo read` prints it: the value, then its hexadecimal form.
///
/// `6` as u16 prints `6 (0x0006)`, `-1` as i8 `-1 (0xFF)`, a string `"abc" (61 62 63)`.
pub fn format_value(v: &Value) -> String {
    match *v {
        Value::Boolean(b) => format!("{b} (0x{:02X})", u8::from(b)),
        Value::Unsigned8(x) => format!("{x} (0x{x:02X})"),
        Value::Unsigned16(x) => format!("{x} (0x{x:04X})"),
        Value::Unsigned32(x) => format!("{x} (0x{x:08X})"),
        Value::Unsigned64(x) => format!("{x} (0x{x:016X})"),
        Value::Integer8(x) => format!("{x} (0x{:02X})", x as u8),
        Value::Integer16(x) => format!("{x} (0x{:04X})", x as u16),
        Value::Integer32(x) => format!("{x} (0x{:08X})", x as u32),
        Value::Integer64(x) => format!("{x} (0x{:016X})", x as u64),
        Value::Real32(x) => format!("{x} (0x{:08X})", x.to_bits()),
        Value::Real64(x) => format!("{x} (0x{:016X})", x.to_bits()),
        Value::VisibleString(b) => match b.as_str() {
            Some(s) => format!("{s:?} ({})", hex_bytes(b.as_bytes())),
            None => hex_bytes(b.as_bytes()),
        },
        Value::OctetString(b) | Value::Domain(b) => hex_bytes(b.as_bytes()),
        ref other => format!("{other:?}"),
    }
}

/// Raw bytes of an untyped upload: 1, 2, 4 or 8 bytes as a little-endian unsigned number with
/// its hex form (`131474 (0x00020192)`), printable text also quoted; other lengths as hex bytes
/// (and quoted when printable).
pub fn format_raw(data: &[u8]) -> String {
    if data.is_empty() {
        return "(no data)".into();
    }
    let printable = data.len() >= 2 && data.iter().all(|b| (0x20..0x7F).contains(b));
    let text = String::from_utf8_lossy(data);
    let mut s = match data.len() {
        1 | 2 | 4 | 8 => {
            let mut buf = [0u8; 8];
            buf[..data.len()].copy_from_slice(data);
            let v = u64::from_le_bytes(buf);
            format!("{v} (0x{v:0w$X})", w = data.len() * 2)
        }
        _ if printable => format!("{text:?} ({})", hex_bytes(data)),
        _ => hex_bytes(data),
    };
    if printable && matches!(data.len(), 2 | 4 | 8) {
        s.push_str(&format!(" {text:?}"));
    }
    s
}

/// An NMT node-control command (CiA 301 §7.2.8.3.1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NmtCommand {
    /// `start`: start remote node (0x01), to Operational.
    Start,
    /// `stop`: stop remote node (0x02), to Stopped.
    Stop,
    /// `preop`: enter Pre-operational (0x80).
    PreOperational,
    /// `reset`: reset node (0x81), application and communication.
    ResetNode,
    /// `reset-comm`: reset communication (0x82).
    ResetCommunication,
}

impl NmtCommand {
    /// The command specifier byte.
    pub fn cs(self) -> u8 {
        match self {
            NmtCommand::Start => nmt::START,
            NmtCommand::Stop => nmt::STOP,
            NmtCommand::PreOperational => nmt::PRE_OPERATIONAL,
            NmtCommand::ResetNode => nmt::RESET_NODE,
            NmtCommand::ResetCommunication => nmt::RESET_COMMUNICATION,
        }
    }

    /// The command for a command specifier byte.
    pub fn from_cs(cs: u8) -> Option<NmtCommand> {
        Some(match cs {
            nmt::START => NmtCommand::Start,
            nmt::STOP => NmtCommand::Stop,
            nmt::PRE_OPERATIONAL => NmtCommand::PreOperational,
            nmt::RESET_NODE => NmtCommand::ResetNode,
            nmt::RESET_COMMUNICATION => NmtCommand::ResetCommunication,
            _ => return None,
        })
    }

    /// What it does, in words (`start`, `enter pre-operational`, `reset communication`, ...).
    pub fn describe(self) -> &'static str {
        match self {
            NmtCommand::Start => "start",
            NmtCommand::Stop => "stop",
            NmtCommand::PreOperational => "enter pre-operational",
            NmtCommand::ResetNode => "reset node",
            NmtCommand::ResetCommunication => "reset communication",
        }
    }
}

impl FromStr for NmtCommand {
    type Err = String;
    fn from_str(s: &str) -> Result<NmtCommand, String> {
        Ok(match s {
            "start" => NmtCommand::Start,
            "stop" => NmtCommand::Stop,
            "preop" | "pre-operational" | "preoperational" => NmtCommand::PreOperational,
            "reset" | "reset-node" => NmtCommand::ResetNode,
            "reset-comm" | "reset-communication" => NmtCommand::ResetCommunication,
            _ => {
                return Err(format!(
                    "unknown NMT command {s:?}; one of: start stop preop reset reset-comm"
                ));
            }
        })
    }
}

impl fmt::Display for NmtCommand {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.describe())
    }
}

/// Which nodes an NMT command addresses: one node, or `all` (node 0 on the wire).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NmtTarget {
    /// Every node.
    All,
    /// One node.
    Node(Node),
}

impl NmtTarget {
    /// The node byte of the NMT frame (0 = all).
    pub fn byte(self) -> u8 {
        match self {
            NmtTarget::All => 0,
            NmtTarget::Node(n) => n.0,
        }
    }
}

impl FromStr for NmtTarget {
    type Err = String;
    fn from_str(s: &str) -> Result<NmtTarget, String> {
        if s == "all" {
            Ok(NmtTarget::All)
        } else {
            s.parse()
                .map(NmtTarget::Node)
                .map_err(|e| format!("{e}, or all"))
        }
    }
}

impl fmt::Display for NmtTarget {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            NmtTarget::All => f.write_str("all nodes"),
            NmtTarget::Node(n) => write!(f, "node {n}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn addresses_are_hex_with_an_optional_sub() {
        let a = |s: &str| s.parse::<ObjectAddress>().map(|a| (a.index, a.sub));
        assert_eq!(a("0x6040:00"), Ok((0x6040, 0)));
        assert_eq!(a("6040"), Ok((0x6040, 0)));
        assert_eq!(a("1018:4"), Ok((0x1018, 4)));
        assert_eq!(a("1018:0x10"), Ok((0x1018, 0x10)));
        assert_eq!(a("60C1:01"), Ok((0x60C1, 1)));
        for bad in [
            "", ":1", "6040:", "10000", "6040:100", "x", "6040:1:2", "0x",
        ] {
            assert!(a(bad).is_err(), "{bad:?}");
        }
        assert_eq!(
            ObjectAddress {
                index: 0x60C1,
                sub: 1
            }
            .to_string(),
            "60C1:01"
        );
    }

    #[test]
    fn nodes_and_targets() {
        assert_eq!("5".parse::<Node>(), Ok(Node(5)));
        assert_eq!("0x7F".parse::<Node>(), Ok(Node(127)));
        assert!("0".parse::<Node>().is_err());
        assert!("128".parse::<Node>().is_err());
        assert!("five".parse::<Node>().is_err());
        assert_eq!("all".parse::<NmtTarget>(), Ok(NmtTarget::All));
        assert_eq!("3".parse::<NmtTarget>(), Ok(NmtTarget::Node(Node(3))));
        assert_eq!(NmtTarget::All.byte(), 0);
    }

    #[test]
    fn nmt_commands_parse_to_their_specifiers() {
        for (s, cs) in [
            ("start", 0x01),
            ("stop", 0x02),
            ("preop", 0x80),
            ("reset", 0x81),
            ("reset-comm", 0x82),
        ] {
            let c: NmtCommand = s.parse().unwrap();
            assert_eq!(c.cs(), cs);
            assert_eq!(NmtCommand::from_cs(cs), Some(c));
        }
        assert!("go".parse::<NmtCommand>().is_err());
    }

    #[test]
    fn values_parse_by_type() {
        let p = |t: &str, v: &str| t.parse::<SdoType>().unwrap().parse_value(v);
        assert_eq!(p("u16", "0x000F"), Ok(Value::Unsigned16(15)));
        assert_eq!(p("u8", "255"), Ok(Value::Unsigned8(255)));
        assert!(p("u8", "256").unwrap_err().contains("does not fit u8"));
        assert!(p("u8", "-1").is_err());
        assert_eq!(p("i8", "-128"), Ok(Value::Integer8(-128)));
        assert_eq!(p("i32", "-0x10"), Ok(Value::Integer32(-16)));
        assert_eq!(
            p("u64", "18446744073709551615"),
            Ok(Value::Unsigned64(u64::MAX))
        );
        assert_eq!(p("f32", "1.5"), Ok(Value::Real32(1.5)));
        assert_eq!(p("f64", "-2e3"), Ok(Value::Real64(-2000.0)));
        assert!(p("u32", "1.5").is_err());
        assert!(p("u32", "--1").is_err());
        assert!(
            p("string", &"x".repeat(33))
                .unwrap_err()
                .contains("at most 32")
        );
        assert!("u128".parse::<SdoType>().unwrap_err().contains("u8 u16"));
    }

    #[test]
    fn values_print_with_their_hex() {
        assert_eq!(format_value(&Value::Unsigned16(6)), "6 (0x0006)");
        assert_eq!(format_value(&Value::Integer8(-1)), "-1 (0xFF)");
        assert_eq!(format_value(&Value::Real32(1.5)), "1.5 (0x3FC00000)");
        assert_eq!(
            format_value(&Value::VisibleString(ByteString::from_str("ab").unwrap())),
            "\"ab\" (61 62)"
        );
        assert_eq!(format_raw(&[0x92, 0x01, 0x02, 0x00]), "131474 (0x00020192)");
        assert_eq!(format_raw(&[0x07]), "7 (0x07)");
        assert_eq!(format_raw(b"abc"), "\"abc\" (61 62 63)");
        assert_eq!(format_raw(b"ab"), "25185 (0x6261) \"ab\"");
        assert_eq!(format_raw(&[1, 2, 3]), "01 02 03");
    }
}
