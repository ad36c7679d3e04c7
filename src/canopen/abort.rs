//! SDO abort codes (CiA 301 §7.2.4.3.17, Table 22) and their meanings.

/// An SDO abort code with its meaning.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AbortCode(pub u32);

impl AbortCode {
    /// Toggle bit not alternated.
    pub const TOGGLE: AbortCode = AbortCode(0x0503_0000);
    /// SDO protocol timed out.
    pub const TIMEOUT: AbortCode = AbortCode(0x0504_0000);
    /// Client/server command specifier not valid or unknown.
    pub const COMMAND: AbortCode = AbortCode(0x0504_0001);
    /// Out of memory.
    pub const OUT_OF_MEMORY: AbortCode = AbortCode(0x0504_0005);
    /// Unsupported access to an object.
    pub const UNSUPPORTED_ACCESS: AbortCode = AbortCode(0x0601_0000);
    /// Attempt to read a write-only object.
    pub const WRITE_ONLY: AbortCode = AbortCode(0x0601_0001);
    /// Attempt to write a read-only object.
    pub const READ_ONLY: AbortCode = AbortCode(0x0601_0002);
    /// Object does not exist in the object dictionary.
    pub const NO_OBJECT: AbortCode = AbortCode(0x0602_0000);
    /// Object cannot be mapped to the PDO.
    pub const NOT_MAPPABLE: AbortCode = AbortCode(0x0604_0041);
    /// The number and length of the objects to be mapped would exceed the PDO length.
    pub const PDO_TOO_LONG: AbortCode = AbortCode(0x0604_0042);
    /// General parameter incompatibility.
    pub const PARAM_INCOMPATIBLE: AbortCode = AbortCode(0x0604_0043);
    /// Data type does not match, length of service parameter does not match.
    pub const LENGTH_MISMATCH: AbortCode = AbortCode(0x0607_0010);
    /// Data type does not match, length of service parameter too high.
    pub const LENGTH_TOO_HIGH: AbortCode = AbortCode(0x0607_0012);
    /// Data type does not match, length of service parameter too low.
    pub const LENGTH_TOO_LOW: AbortCode = AbortCode(0x0607_0013);
    /// Sub-index does not exist.
    pub const NO_SUB: AbortCode = AbortCode(0x0609_0011);
    /// Invalid value for parameter (download only).
    pub const INVALID_VALUE: AbortCode = AbortCode(0x0609_0030);
    /// Value of parameter written too high.
    pub const VALUE_TOO_HIGH: AbortCode = AbortCode(0x0609_0031);
    /// Value of parameter written too low.
    pub const VALUE_TOO_LOW: AbortCode = AbortCode(0x0609_0032);
    /// General error.
    pub const GENERAL: AbortCode = AbortCode(0x0800_0000);
    /// Data cannot be transferred or stored to the application.
    pub const CANNOT_STORE: AbortCode = AbortCode(0x0800_0020);
    /// Data cannot be transferred because of the present device state.
    pub const DEVICE_STATE: AbortCode = AbortCode(0x0800_0022);

    /// What the code means, per CiA 301.
    pub fn meaning(self) -> &'static str {
        match self.0 {
            0x0503_0000 => "toggle bit not alternated",
            0x0504_0000 => "SDO protocol timed out",
            0x0504_0001 => "command specifier not valid or unknown",
            0x0504_0002 => "invalid block size",
            0x0504_0003 => "invalid sequence number",
            0x0504_0004 => "CRC error",
            0x0504_0005 => "out of memory",
            0x0601_0000 => "unsupported access to an object",
            0x0601_0001 => "attempt to read a write-only object",
            0x0601_0002 => "attempt to write a read-only object",
            0x0602_0000 => "object does not exist in the object dictionary",
            0x0604_0041 => "object cannot be mapped to the PDO",
            0x0604_0042 => "the mapped objects would exceed the PDO length",
            0x0604_0043 => "general parameter incompatibility",
            0x0604_0047 => "general internal incompatibility in the device",
            0x0606_0000 => "access failed due to a hardware error",
            0x0607_0010 => "data type does not match, length of service parameter does not match",
            0x0607_0012 => "data type does not match, length of service parameter too high",
            0x0607_0013 => "data type does not match, length of service parameter too low",
            0x0609_0011 => "sub-index does not exist",
            0x0609_0030 => "invalid value for parameter",
            0x0609_0031 => "value of parameter written too high",
            0x0609_0032 => "value of parameter written too low",
            0x0609_0036 => "maximum value is less than minimum value",
            0x060A_0023 => "resource not available: SDO connection",
            0x0800_0000 => "general error",
            0x0800_0020 => "data cannot be transferred or stored to the application",
            0x0800_0021 => "data cannot be transferred or stored because of local control",
            0x0800_0022 => {
                "data cannot be transferred or stored because of the present device state"
            }
            0x0800_0023 => "object dictionary not present or dynamic generation failed",
            0x0800_0024 => "no data available",
            _ => "unknown abort code",
        }
    }
}

impl std::fmt::Display for AbortCode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "0x{:08X} ({})", self.0, self.meaning())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_checklist_codes_decode() {
        for (code, text) in [
            (0x0504_0000, "timed out"),
            (0x0601_0000, "unsupported access"),
            (0x0601_0002, "read-only"),
            (0x0602_0000, "object does not exist"),
            (0x0604_0041, "cannot be mapped"),
            (0x0604_0042, "exceed the PDO length"),
            (0x0607_0010, "does not match"),
            (0x0609_0011, "sub-index does not exist"),
            (0x0609_0030, "invalid value"),
            (0x0609_0031, "too high"),
            (0x0609_0032, "too low"),
            (0x0800_0022, "device state"),
        ] {
            let s = AbortCode(code).to_string();
            assert!(s.contains(text), "{s}");
            assert!(s.starts_with(&format!("0x{code:08X}")));
        }
    }
}
