//! The object dictionary at run time: the current value of every entry of a drive dictionary,
//! with the generic SDO access rules (existence, access, length, range). Rules that depend on the
//! device (PDO remapping, device state) are the device's, layered on top.

use std::collections::BTreeMap;
use std::sync::Arc;

use canopen_rs::{DataType, Value};

use super::abort::AbortCode;
use crate::config::DriveDictionary;
use crate::config::dictionary::{SubDef, value_as_f64, value_as_i128};

/// Current values of a node's object dictionary.
#[derive(Debug, Clone)]
pub struct Od {
    dict: Arc<DriveDictionary>,
    node: u8,
    values: BTreeMap<(u16, u8), Value>,
}

impl Od {
    /// Every entry at its default for `node`.
    pub fn new(dict: Arc<DriveDictionary>, node: u8) -> Od {
        let mut od = Od {
            dict,
            node,
            values: BTreeMap::new(),
        };
        od.reset_all();
        od
    }

    /// Restore every entry to its default (reset node).
    pub fn reset_all(&mut self) {
        self.reset_range(0x0000..=0xFFFF);
    }

    /// Restore the entries with index in `range` (reset communication: 0x1000–0x1FFF).
    pub fn reset_range(&mut self, range: std::ops::RangeInclusive<u16>) {
        let dict = self.dict.clone();
        for (&idx, obj) in dict.objects.range(range) {
            for (&sub, def) in &obj.subs {
                self.values
                    .insert((idx, sub), dict.default_for(def, self.node));
            }
        }
    }

    /// The dictionary behind it.
    pub fn dictionary(&self) -> &Arc<DriveDictionary> {
        &self.dict
    }

    /// The definition of an entry.
    pub fn def(&self, index: u16, sub: u8) -> Option<&SubDef> {
        self.dict.sub(index, sub)
    }

    /// Whether the entry exists.
    pub fn has(&self, index: u16, sub: u8) -> bool {
        self.values.contains_key(&(index, sub))
    }

    /// The current value.
    pub fn get(&self, index: u16, sub: u8) -> Option<Value> {
        self.values.get(&(index, sub)).copied()
    }

    /// The current value as an integer (0 when absent or not an integer).
    pub fn int(&self, index: u16, sub: u8) -> i64 {
        self.get(index, sub)
            .and_then(|v| value_as_i128(&v))
            .map(|v| v as i64)
            .unwrap_or(0)
    }

    /// Set an entry from the device side (no access rules). Integers are converted to the entry's
    /// type with wrap-around, as a device register would.
    pub fn set_int(&mut self, index: u16, sub: u8, v: i64) {
        if let Some(def) = self.dict.sub(index, sub) {
            let value = match def.data_type {
                DataType::Boolean => Value::Boolean(v != 0),
                DataType::Integer8 => Value::Integer8(v as i8),
                DataType::Integer16 => Value::Integer16(v as i16),
                DataType::Integer32 => Value::Integer32(v as i32),
                DataType::Integer64 => Value::Integer64(v),
                DataType::Unsigned8 => Value::Unsigned8(v as u8),
                DataType::Unsigned16 => Value::Unsigned16(v as u16),
                DataType::Unsigned32 => Value::Unsigned32(v as u32),
                DataType::Unsigned64 => Value::Unsigned64(v as u64),
                DataType::Real32 => Value::Real32(v as f32),
                DataType::Real64 => Value::Real64(v as f64),
                _ => return,
            };
            self.values.insert((index, sub), value);
        }
    }

    /// Store a value (already checked) from the device side.
    pub fn set(&mut self, index: u16, sub: u8, v: Value) {
        if self.values.contains_key(&(index, sub)) {
            self.values.insert((index, sub), v);
        }
    }

    /// The abort for an address that does not exist: no object, or no such sub-index.
    fn missing(&self, index: u16, sub: u8) -> Option<AbortCode> {
        match self.dict.objects.get(&index) {
            None => Some(AbortCode::NO_OBJECT),
            Some(o) if !o.subs.contains_key(&sub) => Some(AbortCode::NO_SUB),
            Some(_) => None,
        }
    }

    /// SDO upload rules: the value, or the abort code.
    pub fn sdo_read(&self, index: u16, sub: u8) -> Result<Value, AbortCode> {
        if let Some(a) = self.missing(index, sub) {
            return Err(a);
        }
        let def = self.def(index, sub).expect("exists");
        if !def.access.readable() {
            return Err(AbortCode::WRITE_ONLY);
        }
        Ok(self.get(index, sub).expect("exists"))
    }

    /// SDO download rules before any data arrives: the entry exists, is writable, and `size`
    /// (when indicated) fits its type.
    pub fn sdo_check_write(
        &self,
        index: u16,
        sub: u8,
        size: Option<usize>,
    ) -> Result<(), AbortCode> {
        if let Some(a) = self.missing(index, sub) {
            return Err(a);
        }
        let def = self.def(index, sub).expect("exists");
        if !def.access.writable() {
            return Err(AbortCode::READ_ONLY);
        }
        if let (Some(size), Some(fixed)) = (size, def.data_type.fixed_size())
            && size != fixed
        {
            return Err(AbortCode::LENGTH_MISMATCH);
        }
        if let Some(size) = size
            && size > canopen_rs::MAX_STRING_LEN
        {
            return Err(AbortCode::LENGTH_TOO_HIGH);
        }
        Ok(())
    }

    /// SDO download rules on the data: decode to the entry's type and check its range. Does not
    /// store: the device applies its own rules, then calls [`Od::set`].
    pub fn sdo_decode_write(&self, index: u16, sub: u8, data: &[u8]) -> Result<Value, AbortCode> {
        self.sdo_check_write(index, sub, Some(data.len()))?;
        let def = self.def(index, sub).expect("exists");
        let value =
            Value::decode_le(def.data_type, data).map_err(|_| AbortCode::LENGTH_MISMATCH)?;
        if let Some(x) = value_as_f64(&value) {
            if def.max.is_some_and(|hi| x > hi) {
                return Err(AbortCode::VALUE_TOO_HIGH);
            }
            if def.min.is_some_and(|lo| x < lo) {
                return Err(AbortCode::VALUE_TOO_LOW);
            }
        }
        Ok(value)
    }
}
