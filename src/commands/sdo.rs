//! `canmotion sdo read|write`: one SDO transfer with a node, through [`NodeIo`] (the sans-I/O
//! [`crate::canopen::sdo_client`]: expedited or segmented as the size requires, any length).
//!
//! An upload is always requested untyped and the bytes decoded afterwards, so a length that
//! does not fit the requested type is reported as such (instead of the client's generic abort).
//! Errors name the node, the object and, for an abort, its code and meaning:
//! `node 5: SDO 1000:00 aborted with 0x06010002 (attempt to write a read-only object)`.

use std::fmt;

use canopen_rs::Value;

use super::args::{Node, ObjectAddress, SdoType, format_raw, format_value};
use super::{ToolError, runtime};
use crate::bus::Bus;
use crate::canopen::sdo_client::Mode;
use crate::gateway::GatewayError;
use crate::gateway::io::NodeIo;

/// What an upload returned.
#[derive(Debug, Clone, PartialEq)]
pub enum ReadValue {
    /// Decoded as the requested type.
    Typed(Value),
    /// No type requested: the bytes.
    Raw(Vec<u8>),
    /// A `VISIBLE_STRING`, of any length (a `Value` holds at most 32 bytes).
    Text(Vec<u8>),
}

impl fmt::Display for ReadValue {
    /// `6 (0x0006)`, `"canmotion sim servo" (63 61 ...)`, `131474 (0x00020192)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ReadValue::Typed(v) => f.write_str(&format_value(v)),
            ReadValue::Raw(b) => f.write_str(&format_raw(b)),
            ReadValue::Text(b) => match std::str::from_utf8(b) {
                Ok(s) => write!(f, "{s:?} ({})", super::hex_bytes(b)),
                Err(_) => f.write_str(&super::hex_bytes(b)),
            },
        }
    }
}

/// Upload `index:sub` from `node` as raw bytes (any length).
pub async fn upload_bytes(
    io: &NodeIo,
    node: u8,
    index: u16,
    sub: u8,
) -> Result<Vec<u8>, GatewayError> {
    io.upload(node, index, sub).await
}

/// Decode uploaded bytes as `ty`.
pub fn decode_as(
    node: u8,
    addr: ObjectAddress,
    ty: SdoType,
    bytes: &[u8],
) -> Result<Value, ToolError> {
    let t = ty.data_type();
    if let Some(want) = t.fixed_size()
        && want != bytes.len()
    {
        return Err(ToolError::TypeMismatch {
            node,
            index: addr.index,
            sub: addr.sub,
            data_type: ty.name(),
            got: bytes.len(),
            want,
        });
    }
    Value::decode_le(t, bytes).map_err(|e| {
        ToolError::Value(format!(
            "node {node}: SDO {addr}: cannot decode {} byte(s) as {ty}: {e:?}",
            bytes.len()
        ))
    })
}

/// `canmotion sdo read`: upload `addr` from `node` (any length, segmented or block), decoded as
/// `ty` (raw bytes without a type).
pub fn read(
    bus: &Bus,
    node: Node,
    addr: ObjectAddress,
    ty: Option<SdoType>,
    mode: Mode,
) -> Result<ReadValue, ToolError> {
    runtime()?.block_on(async {
        let io = NodeIo::start(bus, &[node.0])?;
        let bytes = io.upload_with(node.0, addr.index, addr.sub, mode).await?;
        Ok(match ty {
            Some(SdoType::String) => ReadValue::Text(bytes),
            Some(t) => ReadValue::Typed(decode_as(node.0, addr, t, &bytes)?),
            None => ReadValue::Raw(bytes),
        })
    })
}

/// `canmotion sdo write`: download `value` to `addr` of `node`.
pub fn write(bus: &Bus, node: Node, addr: ObjectAddress, value: Value) -> Result<(), ToolError> {
    runtime()?.block_on(async {
        let io = NodeIo::start(bus, &[node.0])?;
        io.write(node.0, addr.index, addr.sub, value).await?;
        Ok(())
    })
}

/// Parse `text` as `ty` and download it; the value written.
pub fn write_text(
    bus: &Bus,
    node: Node,
    addr: ObjectAddress,
    ty: SdoType,
    text: &str,
) -> Result<Value, ToolError> {
    let value = ty
        .parse_value(text)
        .map_err(|e| ToolError::Value(format!("value for {addr}: {e}")))?;
    write(bus, node, addr, value)?;
    Ok(value)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_length_that_does_not_fit_the_type_is_named() {
        let a = ObjectAddress {
            index: 0x6041,
            sub: 0,
        };
        let e = decode_as(3, a, SdoType::U32, &[0x37, 0x02]).unwrap_err();
        assert_eq!(
            e.to_string(),
            "node 3: SDO 6041:00 answered 2 byte(s), type u32 has 4"
        );
        assert_eq!(
            decode_as(3, a, SdoType::U16, &[0x37, 0x02]).unwrap(),
            Value::Unsigned16(0x0237)
        );
        assert_eq!(
            ReadValue::Typed(Value::Unsigned16(0x0237)).to_string(),
            "567 (0x0237)"
        );
    }
}
