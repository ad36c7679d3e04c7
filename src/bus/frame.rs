//! The CAN frame every layer above the bus exchanges: an 11-bit identifier and up to 8 data bytes.

use std::fmt;

/// A classic CAN frame with an 11-bit identifier (CANopen's predefined connection set).
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct Frame {
    id: u16,
    len: u8,
    rtr: bool,
    data: [u8; 8],
}

impl Frame {
    /// A data frame. Returns `None` when the identifier exceeds 11 bits or `data` exceeds 8 bytes.
    pub fn new(id: u16, data: &[u8]) -> Option<Frame> {
        if id > 0x7FF || data.len() > 8 {
            return None;
        }
        let mut buf = [0u8; 8];
        buf[..data.len()].copy_from_slice(data);
        Some(Frame {
            id,
            len: data.len() as u8,
            rtr: false,
            data: buf,
        })
    }

    /// A remote (RTR) frame asking for `len` bytes, as node guarding uses.
    pub fn remote(id: u16, len: u8) -> Option<Frame> {
        if id > 0x7FF || len > 8 {
            return None;
        }
        Some(Frame {
            id,
            len,
            rtr: true,
            data: [0; 8],
        })
    }

    /// The 11-bit identifier (COB-ID).
    pub fn id(&self) -> u16 {
        self.id
    }

    /// The data bytes (empty for a remote frame).
    pub fn data(&self) -> &[u8] {
        if self.rtr {
            &[]
        } else {
            &self.data[..self.len as usize]
        }
    }

    /// The data length code.
    pub fn dlc(&self) -> u8 {
        self.len
    }

    /// Whether this is a remote-transmission-request frame.
    pub fn is_remote(&self) -> bool {
        self.rtr
    }
}

impl fmt::Debug for Frame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // candump style: 181#0102 or 701#R
        write!(f, "{:03X}#", self.id)?;
        if self.rtr {
            return write!(f, "R{}", self.len);
        }
        for b in self.data() {
            write!(f, "{b:02X}")?;
        }
        Ok(())
    }
}

impl fmt::Display for Frame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(self, f)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_extended_ids_and_long_data() {
        assert!(Frame::new(0x800, &[]).is_none());
        assert!(Frame::new(0x7FF, &[0; 9]).is_none());
        let f = Frame::new(0x181, &[1, 2]).unwrap();
        assert_eq!(f.data(), &[1, 2]);
        assert_eq!(format!("{f}"), "181#0102");
    }
}
