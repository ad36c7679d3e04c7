//! CAN error frames: what a SocketCAN controller driver reports about the bus, decoded per
//! `linux/can/error.h` (Linux 6.1 UAPI; the table values below are that header's).
//!
//! An error frame is a `can_frame` whose identifier has `CAN_ERR_FLAG` (0x2000_0000) set; the
//! low 29 bits are a mask of error *classes*, and the eight data bytes carry the details of some
//! of them:
//!
//! | Class bit | Name | Details |
//! |---|---|---|
//! | 0x001 | TX timeout (by the driver) | |
//! | 0x002 | lost arbitration | data\[0\]: bit number (0 = unspecified) |
//! | 0x004 | controller problem | data\[1\]: RX/TX overflow, RX/TX warning, RX/TX error-passive, back to error-active |
//! | 0x008 | protocol violation | data\[2\]: type bits, data\[3\]: location |
//! | 0x010 | transceiver status | data\[4\] |
//! | 0x020 | no ACK on transmission | |
//! | 0x040 | bus-off | |
//! | 0x080 | bus error | |
//! | 0x100 | controller restarted | |
//! | 0x200 | error counters valid | data\[6\]: TX error counter, data\[7\]: RX error counter |
//!
//! data\[5\] is controller specific. A port receives error frames only for the classes of its
//! error mask (`CAN_RAW_ERR_FILTER`); any socket may also *send* one (vcan has no controller, so
//! this is how tests stand in for a real one: the receiving sockets cannot tell the difference).

use std::fmt;

/// `CAN_ERR_FLAG`: marks an error frame in `can_id`.
pub const CAN_ERR_FLAG: u32 = 0x2000_0000;
/// `CAN_ERR_MASK`: the class bits of an error frame's `can_id`.
pub const CAN_ERR_MASK: u32 = 0x1FFF_FFFF;

/// Error classes (the bits of an error frame's identifier and of an error mask).
pub mod class {
    /// TX timeout (by the netdevice driver).
    pub const TX_TIMEOUT: u32 = 0x0001;
    /// Lost arbitration, data\[0\].
    pub const LOST_ARBITRATION: u32 = 0x0002;
    /// Controller problems, data\[1\].
    pub const CONTROLLER: u32 = 0x0004;
    /// Protocol violations, data\[2..=3\].
    pub const PROTOCOL: u32 = 0x0008;
    /// Transceiver status, data\[4\].
    pub const TRANSCEIVER: u32 = 0x0010;
    /// Received no ACK on transmission.
    pub const NO_ACK: u32 = 0x0020;
    /// Bus-off.
    pub const BUS_OFF: u32 = 0x0040;
    /// Bus error (may flood).
    pub const BUS_ERROR: u32 = 0x0080;
    /// Controller restarted.
    pub const RESTARTED: u32 = 0x0100;
    /// TX/RX error counters in data\[6\], data\[7\].
    pub const COUNTERS: u32 = 0x0200;
    /// Every class.
    pub const ALL: u32 = super::CAN_ERR_MASK;
}

/// Controller problem bits, data\[1\].
pub mod controller {
    /// RX buffer overflow.
    pub const RX_OVERFLOW: u8 = 0x01;
    /// TX buffer overflow.
    pub const TX_OVERFLOW: u8 = 0x02;
    /// RX error counter reached the warning level (96).
    pub const RX_WARNING: u8 = 0x04;
    /// TX error counter reached the warning level (96).
    pub const TX_WARNING: u8 = 0x08;
    /// RX error counter above 127: error-passive.
    pub const RX_PASSIVE: u8 = 0x10;
    /// TX error counter above 127: error-passive.
    pub const TX_PASSIVE: u8 = 0x20;
    /// Recovered to error-active.
    pub const ACTIVE: u8 = 0x40;
}

/// An error frame as the kernel delivers it: the class mask and the eight data bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ErrorFrame {
    class: u32,
    data: [u8; 8],
}

impl ErrorFrame {
    /// An error frame with `class` bits (the flag and anything above the 29-bit mask are
    /// dropped) and `data`.
    pub fn new(class: u32, data: [u8; 8]) -> ErrorFrame {
        ErrorFrame {
            class: class & CAN_ERR_MASK,
            data,
        }
    }

    /// From a raw `can_id` and data, as read from a socket: `None` when `CAN_ERR_FLAG` is not
    /// set (not an error frame).
    pub fn from_raw(can_id: u32, data: &[u8]) -> Option<ErrorFrame> {
        if can_id & CAN_ERR_FLAG == 0 {
            return None;
        }
        let mut d = [0u8; 8];
        let n = data.len().min(8);
        d[..n].copy_from_slice(&data[..n]);
        Some(ErrorFrame::new(can_id, d))
    }

    /// What a controller reports when it goes bus-off (the TX error counter passed 255).
    pub fn bus_off() -> ErrorFrame {
        ErrorFrame::new(class::BUS_OFF, [0; 8])
    }

    /// What a controller reports when both error counters pass 127 (error-passive), with the
    /// counters `tx` and `rx`.
    pub fn error_passive(tx: u8, rx: u8) -> ErrorFrame {
        let mut d = [0u8; 8];
        d[1] = controller::TX_PASSIVE | controller::RX_PASSIVE;
        d[6] = tx;
        d[7] = rx;
        ErrorFrame::new(class::CONTROLLER | class::COUNTERS, d)
    }

    /// The class bits.
    pub fn class(&self) -> u32 {
        self.class
    }

    /// The data bytes.
    pub fn data(&self) -> &[u8; 8] {
        &self.data
    }

    /// The `can_id` to send it with (`CAN_ERR_FLAG` set).
    pub fn can_id(&self) -> u32 {
        self.class | CAN_ERR_FLAG
    }

    /// Whether the controller is bus-off: it takes no part in the bus any more.
    pub fn is_bus_off(&self) -> bool {
        self.class & class::BUS_OFF != 0
    }

    /// The errors this frame reports, in class-bit order.
    pub fn errors(&self) -> impl Iterator<Item = CanError> + '_ {
        (0..10u32)
            .map(|b| 1u32 << b)
            .filter(|bit| self.class & bit != 0)
            .map(|bit| match bit {
                class::TX_TIMEOUT => CanError::TxTimeout,
                class::LOST_ARBITRATION => CanError::LostArbitration {
                    bit: (self.data[0] != 0).then_some(self.data[0]),
                },
                class::CONTROLLER => CanError::Controller(ControllerStatus(self.data[1])),
                class::PROTOCOL => CanError::Protocol {
                    violation: ProtocolViolation(self.data[2]),
                    location: ProtocolLocation::from_byte(self.data[3]),
                },
                class::TRANSCEIVER => {
                    CanError::Transceiver(TransceiverStatus::from_byte(self.data[4]))
                }
                class::NO_ACK => CanError::NoAck,
                class::BUS_OFF => CanError::BusOff,
                class::BUS_ERROR => CanError::BusError,
                class::RESTARTED => CanError::Restarted,
                _ => CanError::Counters {
                    tx: self.data[6],
                    rx: self.data[7],
                },
            })
    }

    /// How much it matters to a master streaming setpoints.
    pub fn severity(&self) -> Severity {
        let ctrl = self.data[1];
        if self.is_bus_off() {
            Severity::BusOff
        } else if self.class
            & (class::TX_TIMEOUT
                | class::PROTOCOL
                | class::TRANSCEIVER
                | class::NO_ACK
                | class::BUS_ERROR)
            != 0
            || self.class & class::CONTROLLER != 0 && ctrl & !controller::ACTIVE != 0
        {
            Severity::Warning
        } else {
            // Lost arbitration is ordinary on a bus with several masters; a restart or a return
            // to error-active is good news; counters alone are a report.
            Severity::Info
        }
    }

    /// In `cansend` syntax, as candump logs error frames: `20000040#0000000000000000`.
    pub fn text(&self) -> String {
        let mut s = format!("{:08X}#", self.can_id());
        for b in self.data {
            s.push_str(&format!("{b:02X}"));
        }
        s
    }
}

impl fmt::Display for ErrorFrame {
    /// The errors, decoded, separated by "; ": `controller: RX error-passive, TX error-passive;
    /// error counters TX 128, RX 130`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut first = true;
        for e in self.errors() {
            if !first {
                f.write_str("; ")?;
            }
            first = false;
            write!(f, "{e}")?;
        }
        if first {
            f.write_str("error frame with no class bits")?;
        }
        Ok(())
    }
}

/// How an error frame matters to the gateway.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Severity {
    /// Nothing is wrong (lost arbitration, restarted, back to error-active, counters).
    Info,
    /// The bus is degraded but the controller still takes part (warning level, error-passive,
    /// protocol and transceiver errors, missing ACKs, TX timeouts, overflows).
    Warning,
    /// The controller is bus-off: it sends nothing more.
    BusOff,
}

/// One error an error frame reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CanError {
    /// The driver timed out transmitting a frame.
    TxTimeout,
    /// Arbitration lost, at this bit of the frame if known.
    LostArbitration {
        /// Bit number in the bit stream.
        bit: Option<u8>,
    },
    /// Controller status (warning, error-passive, overflow, back to error-active).
    Controller(ControllerStatus),
    /// A protocol violation, of what kind and where in the frame.
    Protocol {
        /// Type bits.
        violation: ProtocolViolation,
        /// Location in the frame.
        location: ProtocolLocation,
    },
    /// Transceiver (wiring) status.
    Transceiver(TransceiverStatus),
    /// No node acknowledged a frame we sent.
    NoAck,
    /// The controller went bus-off.
    BusOff,
    /// A bus error.
    BusError,
    /// The controller was restarted (after bus-off).
    Restarted,
    /// The controller's error counters.
    Counters {
        /// Transmit error counter.
        tx: u8,
        /// Receive error counter.
        rx: u8,
    },
}

impl fmt::Display for CanError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CanError::TxTimeout => f.write_str("transmit timeout (driver)"),
            CanError::LostArbitration { bit: Some(b) } => {
                write!(f, "arbitration lost at bit {b}")
            }
            CanError::LostArbitration { bit: None } => f.write_str("arbitration lost"),
            CanError::Controller(s) => write!(f, "controller: {s}"),
            CanError::Protocol {
                violation,
                location,
            } => write!(f, "protocol violation: {violation} at {location}"),
            CanError::Transceiver(t) => write!(f, "transceiver: {t}"),
            CanError::NoAck => f.write_str("no ACK on transmission (no other node listening?)"),
            CanError::BusOff => f.write_str("bus-off"),
            CanError::BusError => f.write_str("bus error"),
            CanError::Restarted => f.write_str("controller restarted"),
            CanError::Counters { tx, rx } => write!(f, "error counters TX {tx}, RX {rx}"),
        }
    }
}

/// data\[1\]: controller problem bits ([`controller`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ControllerStatus(pub u8);

impl ControllerStatus {
    /// Whether the controller reached error-passive (either counter above 127).
    pub fn is_error_passive(self) -> bool {
        self.0 & (controller::RX_PASSIVE | controller::TX_PASSIVE) != 0
    }
    /// Whether a counter reached the warning level (96).
    pub fn is_warning(self) -> bool {
        self.0 & (controller::RX_WARNING | controller::TX_WARNING) != 0
    }
}

impl fmt::Display for ControllerStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        const NAMES: [(u8, &str); 7] = [
            (controller::RX_OVERFLOW, "RX buffer overflow"),
            (controller::TX_OVERFLOW, "TX buffer overflow"),
            (controller::RX_WARNING, "RX error warning level"),
            (controller::TX_WARNING, "TX error warning level"),
            (controller::RX_PASSIVE, "RX error-passive"),
            (controller::TX_PASSIVE, "TX error-passive"),
            (controller::ACTIVE, "back to error-active"),
        ];
        write_flags(f, self.0, &NAMES)
    }
}

/// data\[2\]: protocol violation type bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ProtocolViolation(pub u8);

impl fmt::Display for ProtocolViolation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        const NAMES: [(u8, &str); 8] = [
            (0x01, "single bit error"),
            (0x02, "frame format error"),
            (0x04, "bit stuffing error"),
            (0x08, "unable to send dominant bit"),
            (0x10, "unable to send recessive bit"),
            (0x20, "bus overload"),
            (0x40, "active error announcement"),
            (0x80, "error on transmission"),
        ];
        write_flags(f, self.0, &NAMES)
    }
}

fn write_flags(f: &mut fmt::Formatter<'_>, bits: u8, names: &[(u8, &str)]) -> fmt::Result {
    if bits == 0 {
        return f.write_str("unspecified");
    }
    let mut first = true;
    let mut known = 0u8;
    for (bit, name) in names {
        known |= bit;
        if bits & bit != 0 {
            if !first {
                f.write_str(", ")?;
            }
            first = false;
            f.write_str(name)?;
        }
    }
    if bits & !known != 0 {
        if !first {
            f.write_str(", ")?;
        }
        write!(f, "unknown bits 0x{:02X}", bits & !known)?;
    }
    Ok(())
}

/// data\[3\]: where in the frame a protocol violation happened.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ProtocolLocation {
    /// 0x00.
    Unspecified,
    /// 0x03 start of frame.
    StartOfFrame,
    /// 0x02 ID bits 28–21 (SFF: 10–3).
    Id28To21,
    /// 0x06 ID bits 20–18 (SFF: 2–0).
    Id20To18,
    /// 0x04 substitute RTR (SFF: RTR).
    Srtr,
    /// 0x05 identifier extension.
    Ide,
    /// 0x07 ID bits 17–13.
    Id17To13,
    /// 0x0F ID bits 12–5.
    Id12To05,
    /// 0x0E ID bits 4–0.
    Id04To00,
    /// 0x0C RTR.
    Rtr,
    /// 0x0D reserved bit 1.
    Reserved1,
    /// 0x09 reserved bit 0.
    Reserved0,
    /// 0x0B data length code.
    Dlc,
    /// 0x0A data section.
    Data,
    /// 0x08 CRC sequence.
    CrcSequence,
    /// 0x18 CRC delimiter.
    CrcDelimiter,
    /// 0x19 ACK slot.
    AckSlot,
    /// 0x1B ACK delimiter.
    AckDelimiter,
    /// 0x1A end of frame.
    EndOfFrame,
    /// 0x12 intermission.
    Intermission,
    /// A value the header does not define.
    Unknown(u8),
}

impl ProtocolLocation {
    /// Decode data\[3\].
    pub fn from_byte(b: u8) -> ProtocolLocation {
        use ProtocolLocation::*;
        match b {
            0x00 => Unspecified,
            0x03 => StartOfFrame,
            0x02 => Id28To21,
            0x06 => Id20To18,
            0x04 => Srtr,
            0x05 => Ide,
            0x07 => Id17To13,
            0x0F => Id12To05,
            0x0E => Id04To00,
            0x0C => Rtr,
            0x0D => Reserved1,
            0x09 => Reserved0,
            0x0B => Dlc,
            0x0A => Data,
            0x08 => CrcSequence,
            0x18 => CrcDelimiter,
            0x19 => AckSlot,
            0x1B => AckDelimiter,
            0x1A => EndOfFrame,
            0x12 => Intermission,
            other => Unknown(other),
        }
    }
}

impl fmt::Display for ProtocolLocation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use ProtocolLocation::*;
        let s = match self {
            Unspecified => "unspecified location",
            StartOfFrame => "start of frame",
            Id28To21 => "ID bits 28-21 (SFF: 10-3)",
            Id20To18 => "ID bits 20-18 (SFF: 2-0)",
            Srtr => "substitute RTR (SFF: RTR)",
            Ide => "identifier extension",
            Id17To13 => "ID bits 17-13",
            Id12To05 => "ID bits 12-5",
            Id04To00 => "ID bits 4-0",
            Rtr => "RTR",
            Reserved1 => "reserved bit 1",
            Reserved0 => "reserved bit 0",
            Dlc => "data length code",
            Data => "data section",
            CrcSequence => "CRC sequence",
            CrcDelimiter => "CRC delimiter",
            AckSlot => "ACK slot",
            AckDelimiter => "ACK delimiter",
            EndOfFrame => "end of frame",
            Intermission => "intermission",
            Unknown(b) => return write!(f, "location 0x{b:02X}"),
        };
        f.write_str(s)
    }
}

/// data\[4\]: transceiver status (wiring faults on CAN_H / CAN_L).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TransceiverStatus {
    /// 0x00.
    Unspecified,
    /// 0x04.
    CanHNoWire,
    /// 0x05.
    CanHShortToBattery,
    /// 0x06.
    CanHShortToVcc,
    /// 0x07.
    CanHShortToGround,
    /// 0x40.
    CanLNoWire,
    /// 0x50.
    CanLShortToBattery,
    /// 0x60.
    CanLShortToVcc,
    /// 0x70.
    CanLShortToGround,
    /// 0x80.
    CanLShortToCanH,
    /// A value the header does not define.
    Unknown(u8),
}

impl TransceiverStatus {
    /// Decode data\[4\].
    pub fn from_byte(b: u8) -> TransceiverStatus {
        use TransceiverStatus::*;
        match b {
            0x00 => Unspecified,
            0x04 => CanHNoWire,
            0x05 => CanHShortToBattery,
            0x06 => CanHShortToVcc,
            0x07 => CanHShortToGround,
            0x40 => CanLNoWire,
            0x50 => CanLShortToBattery,
            0x60 => CanLShortToVcc,
            0x70 => CanLShortToGround,
            0x80 => CanLShortToCanH,
            other => Unknown(other),
        }
    }
}

impl fmt::Display for TransceiverStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use TransceiverStatus::*;
        let s = match self {
            Unspecified => "unspecified",
            CanHNoWire => "CAN_H no wire",
            CanHShortToBattery => "CAN_H short to battery",
            CanHShortToVcc => "CAN_H short to VCC",
            CanHShortToGround => "CAN_H short to ground",
            CanLNoWire => "CAN_L no wire",
            CanLShortToBattery => "CAN_L short to battery",
            CanLShortToVcc => "CAN_L short to VCC",
            CanLShortToGround => "CAN_L short to ground",
            CanLShortToCanH => "CAN_L short to CAN_H",
            Unknown(b) => return write!(f, "status 0x{b:02X}"),
        };
        f.write_str(s)
    }
}

/// Parse an error frame in `cansend`/candump syntax: eight hex digits of identifier with
/// `CAN_ERR_FLAG` set, `#`, up to eight data bytes (`20000040#0000000000000000`). `None` for
/// anything else.
pub fn parse_error_frame(s: &str) -> Option<ErrorFrame> {
    let (id, data) = s.split_once('#')?;
    if id.len() != 8 {
        return None;
    }
    let id = u32::from_str_radix(id, 16).ok()?;
    let hex: Vec<u8> = data.bytes().filter(|&b| b != b'.').collect();
    if !hex.len().is_multiple_of(2) || hex.len() > 16 {
        return None;
    }
    let mut d = [0u8; 8];
    for (i, pair) in hex.chunks(2).enumerate() {
        d[i] = u8::from_str_radix(std::str::from_utf8(pair).ok()?, 16).ok()?;
    }
    ErrorFrame::from_raw(id, &d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn bus_off_is_fatal_and_says_so() {
        let e = ErrorFrame::bus_off();
        assert!(e.is_bus_off());
        assert_eq!(e.severity(), Severity::BusOff);
        assert_eq!(e.to_string(), "bus-off");
        assert_eq!(e.text(), "20000040#0000000000000000");
        assert_eq!(parse_error_frame(&e.text()), Some(e));
    }

    #[test]
    fn error_passive_with_counters_decodes_both() {
        let e = ErrorFrame::error_passive(136, 0);
        assert_eq!(e.severity(), Severity::Warning);
        assert_eq!(
            e.to_string(),
            "controller: RX error-passive, TX error-passive; error counters TX 136, RX 0"
        );
        let errs: Vec<CanError> = e.errors().collect();
        assert!(matches!(errs[0], CanError::Controller(s) if s.is_error_passive()));
    }

    #[test]
    fn a_protocol_error_frame_as_a_driver_sends_it() {
        // mttcan's ACK error: bus error + protocol class, location ACK slot, on transmission.
        let mut d = [0u8; 8];
        d[2] = 0x80 | 0x08;
        d[3] = 0x19;
        let e = ErrorFrame::new(class::PROTOCOL | class::BUS_ERROR | class::NO_ACK, d);
        assert_eq!(
            e.to_string(),
            "protocol violation: unable to send dominant bit, error on transmission at ACK slot; \
             no ACK on transmission (no other node listening?); bus error"
        );
        assert_eq!(e.severity(), Severity::Warning);
    }

    #[test]
    fn benign_reports_are_info() {
        let mut d = [0u8; 8];
        d[0] = 12;
        assert_eq!(
            ErrorFrame::new(class::LOST_ARBITRATION, d).to_string(),
            "arbitration lost at bit 12"
        );
        assert_eq!(
            ErrorFrame::new(class::LOST_ARBITRATION, d).severity(),
            Severity::Info
        );
        assert_eq!(
            ErrorFrame::new(class::RESTARTED, [0; 8]).severity(),
            Severity::Info
        );
        let mut d = [0u8; 8];
        d[1] = controller::ACTIVE;
        let e = ErrorFrame::new(class::CONTROLLER, d);
        assert_eq!(e.severity(), Severity::Info);
        assert_eq!(e.to_string(), "controller: back to error-active");
        let mut d = [0u8; 8];
        d[4] = 0x70;
        assert_eq!(
            ErrorFrame::new(class::TRANSCEIVER, d).to_string(),
            "transceiver: CAN_L short to ground"
        );
    }

    #[test]
    fn only_flagged_ids_are_error_frames() {
        assert_eq!(ErrorFrame::from_raw(0x040, &[0; 8]), None);
        assert_eq!(parse_error_frame("00000040#00"), None);
        assert_eq!(parse_error_frame("080#"), None);
        assert!(parse_error_frame("20000004#0010").is_some());
    }

    proptest! {
        #[test]
        fn any_error_frame_decodes_and_round_trips(class in 0u32..0x400, data in any::<[u8; 8]>()) {
            let e = ErrorFrame::new(class, data);
            prop_assert_eq!(e.errors().count(), class.count_ones() as usize);
            let _ = e.to_string();
            prop_assert_eq!(parse_error_frame(&e.text()), Some(e));
            prop_assert_eq!(e.is_bus_off(), e.severity() == Severity::BusOff);
        }

        #[test]
        fn the_parser_never_panics(s in "\\PC{0,40}") {
            let _ = parse_error_frame(&s);
        }
    }
}
