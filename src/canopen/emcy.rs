//! EMCY (emergency) messages: COB-ID 0x80 + node, payload `code (LE u16), error register (0x1001),
//! 5 manufacturer bytes`. Codes per CiA 301 Table 21 and CiA 402 (IEC 61800-7-201 Annex).

use crate::bus::Frame;

/// EMCY codes the drive and the gateway use.
pub mod code {
    /// Error reset or no error.
    pub const RESET: u16 = 0x0000;
    /// Generic error.
    pub const GENERIC: u16 = 0x1000;
    /// Continuous over-current (device output side).
    pub const OVER_CURRENT: u16 = 0x2310;
    /// DC-link over-voltage.
    pub const DC_OVER_VOLTAGE: u16 = 0x3210;
    /// DC-link under-voltage.
    pub const DC_UNDER_VOLTAGE: u16 = 0x3220;
    /// Parameter error (a value the device cannot run with).
    pub const PARAMETER: u16 = 0x6320;
    /// Excess temperature device.
    pub const TEMPERATURE: u16 = 0x4310;
    /// Communication: generic.
    pub const COMMUNICATION: u16 = 0x8100;
    /// CAN overrun (objects lost).
    pub const CAN_OVERRUN: u16 = 0x8110;
    /// CAN in error passive mode.
    pub const ERROR_PASSIVE: u16 = 0x8120;
    /// Life guard error or heartbeat error.
    pub const HEARTBEAT: u16 = 0x8130;
    /// Recovered from bus off.
    pub const BUS_OFF_RECOVERED: u16 = 0x8140;
    /// PDO not processed due to length error.
    pub const PDO_LENGTH: u16 = 0x8210;
    /// PDO length exceeded.
    pub const PDO_TOO_LONG: u16 = 0x8220;
    /// Unexpected SYNC data length.
    pub const SYNC_LENGTH: u16 = 0x8240;
    /// RPDO timeout.
    pub const RPDO_TIMEOUT: u16 = 0x8250;
    /// Following error (CiA 402).
    pub const FOLLOWING_ERROR: u16 = 0x8611;
    /// Software position limit reached (CiA 402 0x8612 reference limit).
    pub const POSITION_LIMIT: u16 = 0x8612;
}

/// What an EMCY code means: the code itself where it is one of CiA 301 Table 21's or CiA 402's
/// (IEC 61800-7-201 Annex) named codes, otherwise its class (CiA 301 Table 21: the high byte, or
/// the high nibble for the classes that have sub-classes). Only a code of no class is unknown.
///
/// Whether the drive faulted is not the code's to say: the statusword's fault bit (CiA 402 bit 3)
/// says it; a drive reports a warning (bit 7) with the same kind of code.
pub fn meaning(code: u16) -> &'static str {
    named(code).unwrap_or_else(|| class(code))
}

/// The codes with a name of their own.
fn named(code: u16) -> Option<&'static str> {
    Some(match code {
        0x1000 => "generic error",
        0x2310 => "continuous over-current",
        0x3210 => "DC-link over-voltage",
        0x3220 => "DC-link under-voltage",
        0x4310 => "excess drive temperature",
        0x6320 => "parameter error",
        0x8100 => "communication error (SYNC missing or generic)",
        0x8110 => "CAN overrun (objects lost)",
        0x8120 => "CAN in error passive mode",
        0x8130 => "life guard or heartbeat error",
        0x8140 => "recovered from bus off",
        0x8150 => "CAN-ID collision",
        0x8210 => "PDO not processed due to length error",
        0x8220 => "PDO length exceeded",
        0x8230 => "DAM MPDO not processed, destination object not available",
        0x8240 => "unexpected SYNC data length",
        0x8250 => "RPDO timeout",
        0x8611 => "following error",
        0x8612 => "reference limit (software position limit)",
        _ => return None,
    })
}

/// The class or sub-class of a code, CiA 301 Table 21 (CiA 402's where noted).
fn class(code: u16) -> &'static str {
    match code {
        0x0000..=0x00FF => "error reset or no error",
        0x1000..=0x10FF => "generic error",
        0x2000..=0x20FF => "current",
        0x2100..=0x21FF => "current, device input side",
        0x2200..=0x22FF => "current inside the device",
        0x2300..=0x23FF => "current, device output side",
        0x2400..=0x2FFF => "current",
        0x3000..=0x30FF => "voltage",
        0x3100..=0x31FF => "mains voltage",
        0x3200..=0x32FF => "voltage inside the device",
        0x3300..=0x33FF => "output voltage",
        0x3400..=0x3FFF => "voltage",
        0x4000..=0x40FF => "temperature",
        0x4100..=0x41FF => "ambient temperature",
        0x4200..=0x42FF => "device temperature",
        0x4300..=0x43FF => "drive temperature (CiA 402)",
        0x4400..=0x4FFF => "temperature",
        0x5000..=0x5FFF => "device hardware",
        0x6000..=0x60FF => "device software",
        0x6100..=0x61FF => "internal software",
        0x6200..=0x62FF => "user software",
        0x6300..=0x63FF => "data set",
        0x6400..=0x6FFF => "device software",
        0x7000..=0x7FFF => "additional modules",
        0x8000..=0x80FF => "monitoring",
        0x8100..=0x81FF => "communication",
        0x8200..=0x82FF => "protocol error",
        0x8300..=0x8FFF => "monitoring",
        0x9000..=0x9FFF => "external error",
        0xF000..=0xF0FF => "additional functions",
        0xFF00..=0xFFFF => "device specific",
        _ => "unknown EMCY code",
    }
}

/// A decoded EMCY message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Emcy {
    /// Node that sent it.
    pub node: u8,
    /// Error code.
    pub code: u16,
    /// Error register (0x1001).
    pub register: u8,
    /// Manufacturer-specific bytes.
    pub vendor: [u8; 5],
}

impl Emcy {
    /// Encode as a frame.
    pub fn to_frame(&self) -> Frame {
        let mut d = [0u8; 8];
        d[..2].copy_from_slice(&self.code.to_le_bytes());
        d[2] = self.register;
        d[3..].copy_from_slice(&self.vendor);
        Frame::new(0x080 + u16::from(self.node), &d).expect("valid EMCY id")
    }

    /// Decode an EMCY frame (COB-ID 0x81–0xFF, 8 bytes).
    pub fn from_frame(f: &Frame) -> Option<Emcy> {
        let node = f.id().checked_sub(0x080)?;
        if !(1..=127).contains(&node) || f.data().len() != 8 {
            return None;
        }
        let d = f.data();
        let mut vendor = [0u8; 5];
        vendor.copy_from_slice(&d[3..8]);
        Some(Emcy {
            node: node as u8,
            code: u16::from_le_bytes([d[0], d[1]]),
            register: d[2],
            vendor,
        })
    }
}

impl std::fmt::Display for Emcy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "EMCY from node {}: 0x{:04X} {} (error register 0x{:02X})",
            self.node,
            self.code,
            meaning(self.code),
            self.register
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn round_trip(node in 1u8..=127, code: u16, register: u8, vendor: [u8; 5]) {
            let e = Emcy { node, code, register, vendor };
            prop_assert_eq!(Emcy::from_frame(&e.to_frame()), Some(e));
        }

        #[test]
        fn decode_never_panics(id in 0u16..0x800, data in proptest::collection::vec(any::<u8>(), 0..=8)) {
            let _ = Emcy::from_frame(&Frame::new(id, &data).unwrap());
        }
    }

    #[test]
    fn agrees_with_canopen_rs() {
        let e = Emcy {
            node: 3,
            code: code::FOLLOWING_ERROR,
            register: 0x21,
            vendor: [1, 2, 3, 4, 5],
        };
        let theirs = canopen_rs::EmergencyMessage::decode(e.to_frame().data()).unwrap();
        assert_eq!(theirs.error_code, 0x8611);
        assert_eq!(theirs.error_register.0, 0x21);
        assert_eq!(theirs.vendor_specific, [1, 2, 3, 4, 5]);
        assert!(e.to_string().contains("following error"));
    }

    #[test]
    fn every_code_of_a_known_class_has_a_meaning() {
        assert_eq!(meaning(0x4210), "device temperature");
        assert_eq!(meaning(0x4310), "excess drive temperature");
        assert_eq!(meaning(0x8130), "life guard or heartbeat error");
        assert_eq!(meaning(0x8199), "communication");
        assert_eq!(meaning(0x2111), "current, device input side");
        for code in 0u16..=0xFFFF {
            // No class: 0x0100-0x0FFF, 0x1100-0x1FFF, 0xA000-0xEFFF, 0xF100-0xFEFF.
            let class_known = !(0x0100..=0x0FFF).contains(&code)
                && !(0x1100..=0x1FFF).contains(&code)
                && !matches!(code >> 12, 0xA..=0xE)
                && !(0xF100..=0xFEFF).contains(&code);
            assert_eq!(
                meaning(code) != "unknown EMCY code",
                class_known,
                "0x{code:04X}"
            );
        }
    }
}
