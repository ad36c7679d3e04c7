//! The object dictionary at run time: the current value of every entry of a drive dictionary,
//! with the generic SDO access rules (existence, access, length, range). Rules that depend on the
//! device (PDO remapping, device state) are the device's, layered on top.

use std::collections::BTreeMap;
use std::sync::Arc;

use canopen_rs::{DataType, Value};

use super::abort::AbortCode;
use super::dictionary::{DriveDictionary, SubDef, value_as_f64, value_as_i128};

/// The value of one entry: a number, or the bytes of a byte string of any length.
#[derive(Debug, Clone, PartialEq)]
pub enum Entry {
    /// Every type but the byte strings.
    Value(Value),
    /// `VISIBLE_STRING`, `OCTET_STRING`, `DOMAIN`: up to
    /// [`super::MAX_OBJECT_BYTES`].
    Bytes(Vec<u8>),
}

impl Entry {
    /// The bytes an SDO upload carries.
    pub fn to_bytes(&self) -> Vec<u8> {
        match self {
            Entry::Value(v) => super::value_bytes(v),
            Entry::Bytes(b) => b.clone(),
        }
    }
}

/// Current values of a node's object dictionary.
#[derive(Debug, Clone)]
pub struct Od {
    dict: Arc<DriveDictionary>,
    node: u8,
    values: BTreeMap<(u16, u8), Entry>,
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
                let entry = match dict.default_for(def, self.node) {
                    Some(v) => Entry::Value(v),
                    None => Entry::Bytes(dict.default_bytes(def, self.node)),
                };
                self.values.insert((idx, sub), entry);
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

    /// The current value of a numeric entry (`None` for a byte string: see [`Od::entry`]).
    pub fn get(&self, index: u16, sub: u8) -> Option<Value> {
        match self.values.get(&(index, sub))? {
            Entry::Value(v) => Some(*v),
            Entry::Bytes(_) => None,
        }
    }

    /// The current value of any entry.
    pub fn entry(&self, index: u16, sub: u8) -> Option<&Entry> {
        self.values.get(&(index, sub))
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
            self.values.insert((index, sub), Entry::Value(value));
        }
    }

    /// Store a value (already checked) from the device side.
    pub fn set(&mut self, index: u16, sub: u8, v: Value) {
        self.set_entry(index, sub, Entry::Value(v));
    }

    /// Store an entry (already checked) from the device side.
    pub fn set_entry(&mut self, index: u16, sub: u8, e: Entry) {
        if let Some(slot) = self.values.get_mut(&(index, sub)) {
            *slot = e;
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

    /// SDO upload rules: the entry's bytes, or the abort code.
    pub fn sdo_read(&self, index: u16, sub: u8) -> Result<Vec<u8>, AbortCode> {
        if let Some(a) = self.missing(index, sub) {
            return Err(a);
        }
        let def = self.def(index, sub).expect("exists");
        if !def.access.readable() {
            return Err(AbortCode::WRITE_ONLY);
        }
        Ok(self.entry(index, sub).expect("exists").to_bytes())
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
            && size > super::MAX_OBJECT_BYTES
        {
            return Err(AbortCode::LENGTH_TOO_HIGH);
        }
        Ok(())
    }

    /// SDO download rules on the data: decode to the entry's type and check its range. Does not
    /// store: the device applies its own rules, then calls [`Od::set_entry`].
    pub fn sdo_decode_write(&self, index: u16, sub: u8, data: &[u8]) -> Result<Entry, AbortCode> {
        self.sdo_check_write(index, sub, Some(data.len()))?;
        let def = self.def(index, sub).expect("exists");
        if def.data_type.fixed_size().is_none() {
            return Ok(Entry::Bytes(data.to_vec()));
        }
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
        Ok(Entry::Value(value))
    }
}
