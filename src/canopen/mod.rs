//! CANopen (CiA 301), sans-I/O: codecs, the object dictionary at run time, and the SDO server.
//!
//! canopen-rs supplies the data types and value codec, the NMT/SYNC/EMCY/SDO frame codecs and the
//! SDO *client* state machine; what it lacks for a motion master and a conformant drive (the
//! remap rules, the abort codes CiA 301 asks for, EMCY meanings) is here, and its gaps are pinned
//! by `tests/canopen_rs_gaps.rs`.

pub mod abort;
pub mod dictionary;
pub mod emcy;
pub mod index;
pub mod od;
pub mod sdo_client;
pub mod sdo_server;

/// The longest byte string (`VISIBLE_STRING`, `OCTET_STRING`, `DOMAIN`) an object dictionary
/// entry holds, as a default or written over SDO: 64 KiB, far above any device name or parameter
/// block, and a bound on what a misbehaving client can make a (simulated) drive keep.
pub const MAX_OBJECT_BYTES: usize = 64 * 1024;

/// A value's little-endian bytes, as an SDO transfer carries them.
pub fn value_bytes(v: &canopen_rs::Value) -> Vec<u8> {
    let mut buf = [0u8; canopen_rs::MAX_STRING_LEN];
    let n = v.encode_le(&mut buf).unwrap_or(0);
    buf[..n].to_vec()
}

pub use abort::AbortCode;
pub use emcy::Emcy;
pub use od::Od;
pub use sdo_server::{SdoServer, SdoTarget};

/// COB-ID function codes of the predefined connection set (CiA 301 §7.3.5).
pub mod cob {
    /// NMT node control.
    pub const NMT: u16 = 0x000;
    /// EMCY base (+ node).
    pub const EMCY: u16 = 0x080;
    /// TPDO1..4 bases (+ node).
    pub const TPDO: [u16; 4] = [0x180, 0x280, 0x380, 0x480];
    /// RPDO1..4 bases (+ node).
    pub const RPDO: [u16; 4] = [0x200, 0x300, 0x400, 0x500];
    /// SDO server→client base (+ node).
    pub const SDO_TX: u16 = 0x580;
    /// SDO client→server base (+ node).
    pub const SDO_RX: u16 = 0x600;
    /// Heartbeat / boot-up base (+ node).
    pub const HEARTBEAT: u16 = 0x700;
}

/// NMT command specifiers (CiA 301 §7.2.8.3.1).
pub mod nmt {
    /// Start remote node.
    pub const START: u8 = 0x01;
    /// Stop remote node.
    pub const STOP: u8 = 0x02;
    /// Enter pre-operational.
    pub const PRE_OPERATIONAL: u8 = 0x80;
    /// Reset node.
    pub const RESET_NODE: u8 = 0x81;
    /// Reset communication.
    pub const RESET_COMMUNICATION: u8 = 0x82;
}

/// NMT states as heartbeats carry them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NmtState {
    /// Boot-up (sent once).
    BootUp,
    /// Stopped.
    Stopped,
    /// Operational.
    Operational,
    /// Pre-operational.
    PreOperational,
}

impl NmtState {
    /// The heartbeat byte.
    pub fn byte(self) -> u8 {
        match self {
            NmtState::BootUp => 0x00,
            NmtState::Stopped => 0x04,
            NmtState::Operational => 0x05,
            NmtState::PreOperational => 0x7F,
        }
    }
    /// Decode a heartbeat byte (bit 7, the guarding toggle, ignored).
    pub fn from_byte(b: u8) -> Option<NmtState> {
        Some(match b & 0x7F {
            0x00 => NmtState::BootUp,
            0x04 => NmtState::Stopped,
            0x05 => NmtState::Operational,
            0x7F => NmtState::PreOperational,
            _ => return None,
        })
    }
}

impl std::fmt::Display for NmtState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            NmtState::BootUp => "boot-up",
            NmtState::Stopped => "stopped",
            NmtState::Operational => "operational",
            NmtState::PreOperational => "pre-operational",
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heartbeat_bytes_agree_with_canopen_rs() {
        for s in [
            NmtState::BootUp,
            NmtState::Stopped,
            NmtState::Operational,
            NmtState::PreOperational,
        ] {
            assert_eq!(NmtState::from_byte(s.byte()), Some(s));
            assert_eq!(
                canopen_rs::NmtState::from_wire(s.byte()).unwrap() as u8,
                s.byte()
            );
            assert_eq!(NmtState::from_byte(s.byte() | 0x80), Some(s));
        }
        assert_eq!(NmtState::from_byte(0x01), None);
        for (cs, theirs) in [
            (nmt::START, canopen_rs::NmtCommand::StartRemoteNode),
            (nmt::STOP, canopen_rs::NmtCommand::StopRemoteNode),
            (
                nmt::PRE_OPERATIONAL,
                canopen_rs::NmtCommand::EnterPreOperational,
            ),
            (nmt::RESET_NODE, canopen_rs::NmtCommand::ResetNode),
            (
                nmt::RESET_COMMUNICATION,
                canopen_rs::NmtCommand::ResetCommunication,
            ),
        ] {
            assert_eq!(cs, theirs as u8);
        }
    }
}
