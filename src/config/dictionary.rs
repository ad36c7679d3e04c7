//! Drive dictionaries: loading the object dictionary of a drive type from TOML into the model of
//! [`crate::canopen::dictionary`] (re-exported here), with strict validation.
//!
//! ```toml
//! [device]
//! name = "canmotion simulated CiA 402 servo"
//! vendor_id = 0x00000CA7
//! product_code = 0x00000402
//! revision = 0x00010000
//! device_type = 0x00020192
//!
//! [[object]]              # a variable: the value lives at sub-index 0
//! index = 0x6040
//! name = "Controlword"
//! type = "u16"            # bool i8 i16 i32 i64 u8 u16 u32 u64 f32 f64 string octets domain
//! access = "rw"           # const | ro | wo | rw
//! pdo = true              # PDO-mappable (default false)
//! default = 0
//! min = 0                 # optional inclusive range
//! max = 0xFFFF
//!
//! [[object]]              # a record or array: its sub-indices
//! index = 0x1018
//! name = "Identity object"
//! [[object.sub]]
//! sub = 0
//! name = "Highest sub-index supported"
//! type = "u8"
//! access = "const"
//! default = 4
//! ```
//!
//! Defaults that depend on the node id use the EDS form `"$NODEID+0x180"`.

use std::collections::BTreeMap;
use std::path::Path;

use canopen_rs::{DataType, Value};
use serde::Deserialize;

pub use crate::canopen::dictionary::{
    Access, DefaultValue, DriveDictionary, Identity, MAX_OBJECT_BYTES, ObjectDef, SubDef,
    int_value, parse_type, type_name, type_range, value_as_f64, value_as_i128,
};
use crate::canopen::index;

use super::{ConfigError, read_toml};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFile {
    device: RawDevice,
    object: Vec<RawObject>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDevice {
    name: String,
    vendor_id: u32,
    product_code: u32,
    revision: u32,
    device_type: u32,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawObject {
    index: u16,
    name: String,
    #[serde(rename = "type")]
    data_type: Option<String>,
    access: Option<Access>,
    #[serde(default)]
    pdo: bool,
    default: Option<toml::Value>,
    min: Option<toml::Value>,
    max: Option<toml::Value>,
    unit: Option<String>,
    sub: Option<Vec<RawSub>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSub {
    sub: u8,
    name: String,
    #[serde(rename = "type")]
    data_type: String,
    access: Access,
    #[serde(default)]
    pdo: bool,
    default: toml::Value,
    min: Option<toml::Value>,
    max: Option<toml::Value>,
    unit: Option<String>,
}

struct Ctx<'a> {
    file: &'a Path,
    table: String,
}

impl Ctx<'_> {
    fn err(&self, key: &str, message: impl Into<String>) -> ConfigError {
        ConfigError::Invalid {
            file: self.file.to_path_buf(),
            table: self.table.clone(),
            key: key.to_string(),
            message: message.into(),
        }
    }
}

fn parse_value(
    ctx: &Ctx,
    key: &str,
    t: DataType,
    v: &toml::Value,
) -> Result<DefaultValue, ConfigError> {
    match v {
        toml::Value::Integer(i) => int_value(t, i128::from(*i))
            .map(DefaultValue::Fixed)
            .ok_or_else(|| ctx.err(key, format!("{i} does not fit {}", type_name(t)))),
        toml::Value::Boolean(b) if t == DataType::Boolean => {
            Ok(DefaultValue::Fixed(Value::Boolean(*b)))
        }
        toml::Value::Float(f) => match t {
            DataType::Real32 => Ok(DefaultValue::Fixed(Value::Real32(*f as f32))),
            DataType::Real64 => Ok(DefaultValue::Fixed(Value::Real64(*f))),
            _ => Err(ctx.err(key, format!("a float for an integer type {}", type_name(t)))),
        },
        toml::Value::String(s) => {
            if let Some(rest) = s.strip_prefix("$NODEID") {
                if type_range(t).is_none() || matches!(t, DataType::Real32 | DataType::Real64) {
                    return Err(ctx.err(key, "$NODEID is only allowed for integer types"));
                }
                let rest = rest.trim();
                let off = if rest.is_empty() {
                    0
                } else {
                    let n = rest.strip_prefix('+').map(str::trim).ok_or_else(|| {
                        ctx.err(key, format!("expected \"$NODEID+0x...\", found {s:?}"))
                    })?;
                    parse_int_text(n).ok_or_else(|| {
                        ctx.err(
                            key,
                            format!("expected a number after \"$NODEID+\", found {n:?}"),
                        )
                    })?
                };
                return Ok(DefaultValue::NodeIdPlus(off));
            }
            match t {
                DataType::VisibleString | DataType::OctetString | DataType::Domain => {
                    if s.len() > MAX_OBJECT_BYTES {
                        return Err(
                            ctx.err(key, format!("string longer than {MAX_OBJECT_BYTES} bytes"))
                        );
                    }
                    Ok(DefaultValue::Bytes(s.as_bytes().to_vec()))
                }
                _ => Err(ctx.err(key, format!("a string for type {}", type_name(t)))),
            }
        }
        other => Err(ctx.err(
            key,
            format!("unexpected {} for type {}", other.type_str(), type_name(t)),
        )),
    }
}

fn parse_int_text(s: &str) -> Option<u64> {
    if let Some(h) = s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        u64::from_str_radix(&h.replace('_', ""), 16).ok()
    } else {
        s.replace('_', "").parse().ok()
    }
}

fn parse_bound(
    ctx: &Ctx,
    key: &str,
    t: DataType,
    v: &Option<toml::Value>,
) -> Result<Option<f64>, ConfigError> {
    let Some(v) = v else { return Ok(None) };
    let Some((lo, hi)) = type_range(t) else {
        return Err(ctx.err(key, format!("a range on non-numeric type {}", type_name(t))));
    };
    let x = match v {
        toml::Value::Integer(i) => *i as f64,
        toml::Value::Float(f) => *f,
        other => {
            return Err(ctx.err(
                key,
                format!("expected a number, found {}", other.type_str()),
            ));
        }
    };
    if x < lo || x > hi {
        return Err(ctx.err(
            key,
            format!("{x} outside the range of {} [{lo}, {hi}]", type_name(t)),
        ));
    }
    Ok(Some(x))
}

#[allow(clippy::too_many_arguments)]
fn build_sub(
    ctx: &Ctx,
    name: &str,
    data_type: &str,
    access: Access,
    pdo: bool,
    default: &toml::Value,
    min: &Option<toml::Value>,
    max: &Option<toml::Value>,
    unit: &Option<String>,
) -> Result<SubDef, ConfigError> {
    let t = parse_type(data_type).ok_or_else(|| {
        ctx.err(
            "type",
            format!("unknown type {data_type:?} (bool i8 i16 i32 i64 u8 u16 u32 u64 f32 f64 string octets domain)"),
        )
    })?;
    let default = parse_value(ctx, "default", t, default)?;
    let min = parse_bound(ctx, "min", t, min)?;
    let max = parse_bound(ctx, "max", t, max)?;
    if let (Some(lo), Some(hi)) = (min, max)
        && lo > hi
    {
        return Err(ctx.err("min", format!("min {lo} is above max {hi}")));
    }
    if let DefaultValue::Fixed(v) = &default
        && let Some(x) = value_as_f64(v)
        && (min.is_some_and(|lo| x < lo) || max.is_some_and(|hi| x > hi))
    {
        return Err(ctx.err("default", format!("default {x} outside [min, max]")));
    }
    if pdo && t.fixed_size().is_none() {
        return Err(ctx.err("pdo", "a variable-length type cannot be PDO-mapped"));
    }
    Ok(SubDef {
        name: name.to_string(),
        data_type: t,
        access,
        pdo,
        default,
        min,
        max,
        unit: unit.clone(),
    })
}

impl DriveDictionary {
    /// Load and validate a dictionary file.
    pub fn load(path: &Path) -> Result<DriveDictionary, ConfigError> {
        let raw: RawFile = read_toml(path)?;
        Self::from_raw(path, raw)
    }

    /// Parse and validate a dictionary from text (`path` is used in messages).
    pub fn parse(path: &Path, text: &str) -> Result<DriveDictionary, ConfigError> {
        let raw: RawFile = super::parse_toml(path, text)?;
        Self::from_raw(path, raw)
    }

    fn from_raw(path: &Path, raw: RawFile) -> Result<DriveDictionary, ConfigError> {
        let mut objects = BTreeMap::new();
        for o in &raw.object {
            let mut ctx = Ctx {
                file: path,
                table: format!("object 0x{:04X}", o.index),
            };
            if objects.contains_key(&o.index) {
                return Err(ctx.err("index", "defined twice"));
            }
            let mut subs = BTreeMap::new();
            match &o.sub {
                Some(list) => {
                    if o.data_type.is_some() || o.access.is_some() || o.default.is_some() {
                        return Err(ctx.err(
                            "sub",
                            "an object has either type/access/default (a variable) or [[object.sub]] entries, not both",
                        ));
                    }
                    if list.is_empty() {
                        return Err(ctx.err("sub", "no sub-entries"));
                    }
                    for s in list {
                        ctx.table = format!("object 0x{:04X} sub {}", o.index, s.sub);
                        if subs.contains_key(&s.sub) {
                            return Err(ctx.err("sub", "defined twice"));
                        }
                        let d = build_sub(
                            &ctx,
                            &s.name,
                            &s.data_type,
                            s.access,
                            s.pdo,
                            &s.default,
                            &s.min,
                            &s.max,
                            &s.unit,
                        )?;
                        subs.insert(s.sub, d);
                    }
                }
                None => {
                    let t = o.data_type.as_deref().ok_or_else(|| {
                        ctx.err("type", "missing (or give [[object.sub]] entries)")
                    })?;
                    let a = o.access.ok_or_else(|| ctx.err("access", "missing"))?;
                    let d = o
                        .default
                        .as_ref()
                        .ok_or_else(|| ctx.err("default", "missing"))?;
                    subs.insert(
                        0,
                        build_sub(&ctx, &o.name, t, a, o.pdo, d, &o.min, &o.max, &o.unit)?,
                    );
                }
            }
            objects.insert(
                o.index,
                ObjectDef {
                    name: o.name.clone(),
                    subs,
                },
            );
        }
        let dict = DriveDictionary {
            file: path.to_path_buf(),
            name: raw.device.name.clone(),
            identity: Identity {
                vendor_id: raw.device.vendor_id,
                product_code: raw.device.product_code,
                revision: raw.device.revision,
                device_type: raw.device.device_type,
            },
            objects,
        };
        dict.validate()?;
        Ok(dict)
    }

    fn validate(&self) -> Result<(), ConfigError> {
        let ctx = |table: &str| Ctx {
            file: &self.file,
            table: table.to_string(),
        };
        let fixed = |idx: u16, sub: u8| -> Option<i128> {
            match &self.objects.get(&idx)?.subs.get(&sub)?.default {
                DefaultValue::Fixed(v) => value_as_i128(v),
                DefaultValue::NodeIdPlus(_) | DefaultValue::Bytes(_) => None,
            }
        };
        for (idx, sub, key, want) in [
            (
                index::DEVICE_TYPE,
                0u8,
                "device_type",
                self.identity.device_type,
            ),
            (index::IDENTITY, 1, "vendor_id", self.identity.vendor_id),
            (
                index::IDENTITY,
                2,
                "product_code",
                self.identity.product_code,
            ),
            (index::IDENTITY, 3, "revision", self.identity.revision),
        ] {
            match fixed(idx, sub) {
                Some(v) if v == i128::from(want) => {}
                Some(v) => {
                    return Err(ctx("device").err(
                        key,
                        format!(
                            "0x{want:08X} differs from object 0x{idx:04X}:{sub} default 0x{v:08X}"
                        ),
                    ));
                }
                None => {
                    return Err(
                        ctx("device").err(key, format!("object 0x{idx:04X}:{sub} is missing"))
                    );
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEAD: &str = r#"
[device]
name = "t"
vendor_id = 1
product_code = 2
revision = 3
device_type = 0x192
[[object]]
index = 0x1000
name = "Device type"
type = "u32"
access = "const"
default = 0x192
[[object]]
index = 0x1018
name = "Identity"
[[object.sub]]
sub = 0
name = "n"
type = "u8"
access = "const"
default = 3
[[object.sub]]
sub = 1
name = "v"
type = "u32"
access = "ro"
default = 1
[[object.sub]]
sub = 2
name = "p"
type = "u32"
access = "ro"
default = 2
[[object.sub]]
sub = 3
name = "r"
type = "u32"
access = "ro"
default = 3
"#;

    fn load(extra: &str) -> Result<DriveDictionary, ConfigError> {
        DriveDictionary::parse(Path::new("d.toml"), &format!("{HEAD}{extra}"))
    }

    #[test]
    fn loads_variables_records_and_node_id_defaults() {
        let d = load(
            "[[object]]\nindex = 0x1800\nname = \"TPDO1\"\n[[object.sub]]\nsub = 1\nname = \"COB-ID\"\ntype = \"u32\"\naccess = \"rw\"\ndefault = \"$NODEID+0x180\"\n",
        )
        .unwrap();
        let s = d.sub(0x1800, 1).unwrap();
        assert_eq!(d.default_for(s, 5), Some(Value::Unsigned32(0x185)));
        assert_eq!(d.identity.device_type, 0x192);
    }

    #[test]
    fn errors_name_file_table_and_key() {
        let e = load("[[object]]\nindex = 0x6040\nname = \"CW\"\ntype = \"u16\"\naccess = \"rw\"\ndefault = 70000\n")
            .unwrap_err()
            .to_string();
        assert_eq!(e, "d.toml: [object 0x6040] default: 70000 does not fit u16");
        let e = load("[[object]]\nindex = 0x6040\nname = \"CW\"\ntype = \"u16\"\naccess = \"rw\"\ndefault = 0\ncolour = 1\n")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("d.toml: ") && e.contains("colour"), "{e}");
        let e = load("[[object]]\nindex = 0x6060\nname = \"M\"\ntype = \"i8\"\naccess = \"rw\"\ndefault = 9\nmax = 8\n")
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "d.toml: [object 0x6060] default: default 9 outside [min, max]"
        );
        let e = load("[[object]]\nindex = 0x1000\nname = \"again\"\ntype = \"u8\"\naccess = \"rw\"\ndefault = 0\n")
            .unwrap_err()
            .to_string();
        assert_eq!(e, "d.toml: [object 0x1000] index: defined twice");
    }

    #[test]
    fn identity_must_match_the_objects() {
        let text = HEAD.replace("revision = 3", "revision = 4");
        let e = DriveDictionary::parse(Path::new("d.toml"), &text)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("[device] revision") && e.contains("0x1018:3"),
            "{e}"
        );
    }

    #[test]
    fn schema_errors_name_the_object() {
        let e = load("[[object]]\nindex = 0x6040\nname = \"CW\"\ntype = \"u16\"\naccess = \"rw\"\ndefault = 0\ncolour = 1\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(": [object 0x6040] unknown field `colour`"),
            "{e}"
        );
        let e = load("[[object]]\nindex = 0x1800\nname = \"TPDO1\"\n[[object.sub]]\nsub = 1\nname = \"COB-ID\"\ntype = \"u32\"\naccess = \"rw\"\n")
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "d.toml: line 44, column 1: [object 0x1800 sub 1] missing field `default`"
        );
    }
}
