//! The drive dictionary model: the object dictionary of a drive type (its identity, and every
//! object's sub-entries with type, access, PDO-mappability, default and range), and the value
//! helpers on CANopen data types that go with it.
//!
//! This is the CANopen layer's own description of a device; [`crate::config::dictionary`] loads
//! it from TOML and [`crate::eds`] converts it to and from EDS. [`super::od::Od`] holds a node's
//! current values against it.

use std::collections::BTreeMap;
use std::path::PathBuf;

use canopen_rs::{DataType, Value};
use serde::Deserialize;

pub use super::MAX_OBJECT_BYTES;
use super::value_bytes as encode;

/// How an entry may be accessed over SDO.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Access {
    /// Read-only and constant.
    Const,
    /// Read-only (the device may change it).
    Ro,
    /// Write-only.
    Wo,
    /// Read-write.
    Rw,
}

impl Access {
    /// Readable over SDO.
    pub fn readable(self) -> bool {
        self != Access::Wo
    }
    /// Writable over SDO.
    pub fn writable(self) -> bool {
        matches!(self, Access::Wo | Access::Rw)
    }
}

/// A default value, possibly depending on the node id.
#[derive(Debug, Clone, PartialEq)]
pub enum DefaultValue {
    /// A fixed value (every type but the byte strings).
    Fixed(Value),
    /// The bytes of a `VISIBLE_STRING`, `OCTET_STRING` or `DOMAIN`, of any length up to
    /// [`MAX_OBJECT_BYTES`].
    Bytes(Vec<u8>),
    /// `$NODEID + offset` (numeric types only).
    NodeIdPlus(u64),
}

/// One sub-entry of the dictionary.
#[derive(Debug, Clone)]
pub struct SubDef {
    /// Its name as the profile gives it.
    pub name: String,
    /// Data type.
    pub data_type: DataType,
    /// SDO access.
    pub access: Access,
    /// PDO-mappable.
    pub pdo: bool,
    /// Default (power-on) value.
    pub default: DefaultValue,
    /// Inclusive minimum, for numeric types.
    pub min: Option<f64>,
    /// Inclusive maximum, for numeric types.
    pub max: Option<f64>,
    /// Free-text unit.
    pub unit: Option<String>,
}

/// One object (index) of the dictionary.
#[derive(Debug, Clone)]
pub struct ObjectDef {
    /// Its name.
    pub name: String,
    /// Sub-entries by sub-index (a variable has only sub 0).
    pub subs: BTreeMap<u8, SubDef>,
}

/// Identity of the device type as configured in the dictionary.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Identity {
    /// 0x1018:1.
    pub vendor_id: u32,
    /// 0x1018:2.
    pub product_code: u32,
    /// 0x1018:3.
    pub revision: u32,
    /// 0x1000.
    pub device_type: u32,
}

/// A drive type's object dictionary, as loaded from TOML.
#[derive(Debug, Clone)]
pub struct DriveDictionary {
    /// Where it was loaded from.
    pub file: PathBuf,
    /// Display name.
    pub name: String,
    /// Identity the drive must report.
    pub identity: Identity,
    /// Objects by index.
    pub objects: BTreeMap<u16, ObjectDef>,
}

/// Parse a data type name.
pub fn parse_type(s: &str) -> Option<DataType> {
    Some(match s {
        "bool" => DataType::Boolean,
        "i8" => DataType::Integer8,
        "i16" => DataType::Integer16,
        "i32" => DataType::Integer32,
        "i64" => DataType::Integer64,
        "u8" => DataType::Unsigned8,
        "u16" => DataType::Unsigned16,
        "u32" => DataType::Unsigned32,
        "u64" => DataType::Unsigned64,
        "f32" => DataType::Real32,
        "f64" => DataType::Real64,
        "string" => DataType::VisibleString,
        "octets" => DataType::OctetString,
        "domain" => DataType::Domain,
        _ => return None,
    })
}

/// The numeric range of an integer type, as f64 (exact for everything up to 53 bits).
pub fn type_range(t: DataType) -> Option<(f64, f64)> {
    Some(match t {
        DataType::Boolean => (0.0, 1.0),
        DataType::Integer8 => (i8::MIN as f64, i8::MAX as f64),
        DataType::Integer16 => (i16::MIN as f64, i16::MAX as f64),
        DataType::Integer32 => (i32::MIN as f64, i32::MAX as f64),
        DataType::Integer64 => (i64::MIN as f64, i64::MAX as f64),
        DataType::Unsigned8 => (0.0, u8::MAX as f64),
        DataType::Unsigned16 => (0.0, u16::MAX as f64),
        DataType::Unsigned32 => (0.0, u32::MAX as f64),
        DataType::Unsigned64 => (0.0, u64::MAX as f64),
        DataType::Real32 => (f32::MIN as f64, f32::MAX as f64),
        DataType::Real64 => (f64::MIN, f64::MAX),
        _ => return None,
    })
}

/// Build a value of type `t` from an integer, if it fits.
pub fn int_value(t: DataType, v: i128) -> Option<Value> {
    Some(match t {
        DataType::Boolean => Value::Boolean(match v {
            0 => false,
            1 => true,
            _ => return None,
        }),
        DataType::Integer8 => Value::Integer8(i8::try_from(v).ok()?),
        DataType::Integer16 => Value::Integer16(i16::try_from(v).ok()?),
        DataType::Integer32 => Value::Integer32(i32::try_from(v).ok()?),
        DataType::Integer64 => Value::Integer64(i64::try_from(v).ok()?),
        DataType::Unsigned8 => Value::Unsigned8(u8::try_from(v).ok()?),
        DataType::Unsigned16 => Value::Unsigned16(u16::try_from(v).ok()?),
        DataType::Unsigned32 => Value::Unsigned32(u32::try_from(v).ok()?),
        DataType::Unsigned64 => Value::Unsigned64(u64::try_from(v).ok()?),
        DataType::Real32 => Value::Real32(v as f32),
        DataType::Real64 => Value::Real64(v as f64),
        _ => return None,
    })
}

/// A value as an integer (numeric types), for ranges and arithmetic.
pub fn value_as_i128(v: &Value) -> Option<i128> {
    Some(match *v {
        Value::Boolean(b) => b as i128,
        Value::Integer8(x) => x as i128,
        Value::Integer16(x) => x as i128,
        Value::Integer32(x) => x as i128,
        Value::Integer64(x) => x as i128,
        Value::Unsigned8(x) => x as i128,
        Value::Unsigned16(x) => x as i128,
        Value::Unsigned32(x) => x as i128,
        Value::Unsigned64(x) => x as i128,
        _ => return None,
    })
}

/// A numeric value as f64.
pub fn value_as_f64(v: &Value) -> Option<f64> {
    match *v {
        Value::Real32(x) => Some(x as f64),
        Value::Real64(x) => Some(x),
        _ => value_as_i128(v).map(|x| x as f64),
    }
}

/// The dictionary's name for a data type.
pub fn type_name(t: DataType) -> &'static str {
    match t {
        DataType::Boolean => "bool",
        DataType::Integer8 => "i8",
        DataType::Integer16 => "i16",
        DataType::Integer32 => "i32",
        DataType::Integer64 => "i64",
        DataType::Unsigned8 => "u8",
        DataType::Unsigned16 => "u16",
        DataType::Unsigned32 => "u32",
        DataType::Unsigned64 => "u64",
        DataType::Real32 => "f32",
        DataType::Real64 => "f64",
        DataType::VisibleString => "string",
        DataType::OctetString => "octets",
        _ => "domain",
    }
}

impl DriveDictionary {
    /// The definition of `index:sub`.
    pub fn sub(&self, index: u16, sub: u8) -> Option<&SubDef> {
        self.objects.get(&index)?.subs.get(&sub)
    }

    /// Default value of a sub-entry for a node.
    pub fn default_for(&self, def: &SubDef, node: u8) -> Option<Value> {
        match &def.default {
            DefaultValue::Fixed(v) => Some(*v),
            DefaultValue::NodeIdPlus(off) => Some(
                int_value(def.data_type, i128::from(*off) + i128::from(node))
                    .unwrap_or(Value::Unsigned32(0)),
            ),
            DefaultValue::Bytes(_) => None,
        }
    }

    /// The default of an entry for `node` as the bytes an SDO upload carries (little-endian for
    /// numbers; byte strings of any length as they are).
    pub fn default_bytes(&self, def: &SubDef, node: u8) -> Vec<u8> {
        match (&def.default, self.default_for(def, node)) {
            (DefaultValue::Bytes(b), _) => b.clone(),
            (_, Some(v)) => encode(&v),
            (_, None) => Vec::new(),
        }
    }
}
