//! CiA 402 (IEC 61800-7-201) drive profile: the power state machine, sans-I/O.
//!
//! A CiA 402 drive is switched on and off through the *power state machine*. The master writes
//! commands into the controlword (0x6040) and reads the state back from the statusword (0x6041).
//! The transitions, numbered as in CiA 402-2 ([`Transition`]):
//!
//! ```text
//!  #  from                    to                      cause
//!  0  (power on)              Not ready to switch on  automatic
//!  1  Not ready to switch on  Switch on disabled      automatic (self-test done)
//!  2  Switch on disabled      Ready to switch on      Shutdown
//!  3  Ready to switch on      Switched on             Switch on
//!  4  Switched on             Operation enabled       Enable operation
//!  5  Operation enabled       Switched on             Disable operation
//!  6  Switched on             Ready to switch on      Shutdown
//!  7  Ready to switch on      Switch on disabled      Disable voltage, Quick stop
//!  8  Operation enabled       Ready to switch on      Shutdown
//!  9  Operation enabled       Switch on disabled      Disable voltage
//! 10  Switched on             Switch on disabled      Disable voltage, Quick stop
//! 11  Operation enabled       Quick stop active       Quick stop
//! 12  Quick stop active       Switch on disabled      Disable voltage; stop done (0x605A 0-4)
//! 13  any                     Fault reaction active   fault detected
//! 14  Fault reaction active   Fault                   automatic (reaction done)
//! 15  Fault                   Switch on disabled      Fault reset (bit 7 rising edge)
//! 16  Quick stop active       Operation enabled       Enable operation (0x605A 5-8 only)
//! ```
//!
//! The state is coded in statusword bits 0–3, 5 and 6 ([`State::from_statusword`], table
//! [`STATE_CODING`]); commands are coded in controlword bits 0–3 and 7 ([`Command`]). A fault
//! reset is the 0 → 1 *edge* of controlword bit 7, so a master must send a frame with bit 7 = 0
//! first (ros_canopen PR #138/#139; canopen#261). See also the project checklist
//! (`canopen-checklist.md`, section "CiA 402 state machine").
//!
//! The module has two sides, both pure functions of their inputs (no clock, no I/O, no
//! allocation, no panics), so they run identically in the simulated drive, the gateway's cyclic
//! loop and unit tests:
//!
//! - [`PowerStateMachine`]: what a drive runs; the simulated drive feeds it every received
//!   controlword and reports [`PowerStateMachine::statusword`].
//! - [`Enabler`]: what the master runs; fed the decoded state each cycle, it yields the
//!   controlword that walks the drive to Operation enabled (or back to Switch on disabled).
//!
//! How this module reads unclear spec text:
//! - Commands are levels, evaluated on every received controlword; a repeated command that
//!   does not apply to the current state is ignored. Only the fault reset is an edge.
//! - While bit 7 is 1 no other command decodes (all decode masks include bit 7), so a held
//!   fault reset also holds the drive where it is.
//! - A drive that has not yet seen any controlword treats bit 7 as already high, so the first
//!   frame can never be a fault-reset edge: a frame with bit 7 = 0 must come first (checklist).
//! - "Switch on + enable operation" (0x000F) in Ready to switch on takes transition 3 and then
//!   the automatic transition 4, as CiA 402 notes for that command.
//! - Quick-stop option code 0 ("disable drive function", coast) takes transition 11 and then 12
//!   at once; codes 1–4 take 12 when the stop completes; codes 5–8 stay in Quick stop active.

mod drive;
mod enabler;

pub use drive::{InvalidQuickStopOption, PowerStateMachine, Transition};
pub use enabler::{Action, Enabler, Target};

use core::fmt;

// The CiA 402 objects' indices are named with CiA 301's in `crate::canopen::index`.

/// Statusword (0x6041) bits, CiA 402-2.
pub mod statusword {
    /// Bit 0: ready to switch on.
    pub const READY_TO_SWITCH_ON: u16 = 1 << 0;
    /// Bit 1: switched on.
    pub const SWITCHED_ON: u16 = 1 << 1;
    /// Bit 2: operation enabled.
    pub const OPERATION_ENABLED: u16 = 1 << 2;
    /// Bit 3: fault.
    pub const FAULT: u16 = 1 << 3;
    /// Bit 4: voltage enabled (high voltage applied to the power stage).
    pub const VOLTAGE_ENABLED: u16 = 1 << 4;
    /// Bit 5: quick stop, **active low**: 0 means a quick stop is in progress.
    pub const QUICK_STOP: u16 = 1 << 5;
    /// Bit 6: switch on disabled.
    pub const SWITCH_ON_DISABLED: u16 = 1 << 6;
    /// Bit 7: warning.
    pub const WARNING: u16 = 1 << 7;
    /// Bit 9: remote (controlword is processed).
    pub const REMOTE: u16 = 1 << 9;
    /// Bit 10: target reached.
    pub const TARGET_REACHED: u16 = 1 << 10;
    /// Bit 11: internal limit active (e.g. software position limit 0x607D).
    pub const INTERNAL_LIMIT: u16 = 1 << 11;
    /// Bit 12: operation-mode specific (IP: interpolation active; CSP: following the command).
    pub const OP_MODE_SPECIFIC_12: u16 = 1 << 12;
    /// Bit 13: operation-mode specific (CSP/PP: following error).
    pub const OP_MODE_SPECIFIC_13: u16 = 1 << 13;
    /// Bit 12 in homing mode (6): homing attained (CiA 402-2, homing mode: statusword).
    pub const HOMING_ATTAINED: u16 = 1 << 12;
    /// Bit 13 in homing mode (6): homing error (CiA 402-2, homing mode: statusword).
    pub const HOMING_ERROR: u16 = 1 << 13;
    /// The bits that code the power state (0–3, 5, 6); see [`STATE_CODING`](super::STATE_CODING).
    pub const STATE_MASK: u16 = 0x006F;
}

/// Controlword (0x6040) bits and command values, CiA 402-2.
pub mod controlword {
    /// Bit 0: switch on.
    pub const SWITCH_ON: u16 = 1 << 0;
    /// Bit 1: enable voltage.
    pub const ENABLE_VOLTAGE: u16 = 1 << 1;
    /// Bit 2: quick stop, **active low**: 0 requests a quick stop.
    pub const QUICK_STOP: u16 = 1 << 2;
    /// Bit 3: enable operation.
    pub const ENABLE_OPERATION: u16 = 1 << 3;
    /// Bit 4, mode-specific: IP enable of interpolation; PP new setpoint.
    pub const IP_ENABLE: u16 = 1 << 4;
    /// Bit 4 under its profile-position name.
    pub const NEW_SETPOINT: u16 = 1 << 4;
    /// Bit 4 in homing mode (6): homing operation start; its rising edge starts homing,
    /// clearing it interrupts homing (CiA 402-2, homing mode: controlword).
    pub const HOMING_START: u16 = 1 << 4;
    /// Bit 7: fault reset, acts on the 0 → 1 edge.
    pub const FAULT_RESET: u16 = 1 << 7;
    /// Bit 8: halt.
    pub const HALT: u16 = 1 << 8;
    /// The bits that code a command (0–3, 7); all others are free for the caller.
    pub const COMMAND_MASK: u16 = 0x008F;

    /// Shutdown: transitions 2, 6, 8.
    pub const SHUTDOWN: u16 = 0x0006;
    /// Switch on: transition 3.
    pub const SWITCH_ON_CMD: u16 = 0x0007;
    /// Disable operation (same value as switch on): transition 5.
    pub const DISABLE_OPERATION: u16 = 0x0007;
    /// Enable operation: transitions 4, 16.
    pub const ENABLE_OPERATION_CMD: u16 = 0x000F;
    /// Disable voltage: transitions 7, 9, 10, 12.
    pub const DISABLE_VOLTAGE: u16 = 0x0000;
    /// Quick stop: transitions 7, 10, 11.
    pub const QUICK_STOP_CMD: u16 = 0x0002;
}

/// A state of the CiA 402 power state machine.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum State {
    /// Power-up self-test; not yet controllable.
    NotReadyToSwitchOn,
    /// Initialised, power stage off; the drive waits for Shutdown.
    SwitchOnDisabled,
    /// Ready for Switch on; power stage off.
    ReadyToSwitchOn,
    /// Power stage on, no torque.
    SwitchedOn,
    /// Torque on, following setpoints.
    OperationEnabled,
    /// Stopping (or stopped and holding, quick-stop codes 5–8) after a quick stop.
    QuickStopActive,
    /// A fault was detected and the drive is executing its fault reaction.
    FaultReactionActive,
    /// Fault reaction done, power stage off; leaves only by a fault reset.
    Fault,
}

/// Statusword state coding, `(state, mask, value)`: a statusword `sw` is in `state` when
/// `sw & mask == value` (CiA 402-2 statusword state coding; checklist "CiA 402 state machine").
/// The patterns are disjoint; bits outside the mask are free.
pub const STATE_CODING: [(State, u16, u16); 8] = [
    (State::NotReadyToSwitchOn, 0x4F, 0x00),
    (State::SwitchOnDisabled, 0x4F, 0x40),
    (State::ReadyToSwitchOn, 0x6F, 0x21),
    (State::SwitchedOn, 0x6F, 0x23),
    (State::OperationEnabled, 0x6F, 0x27),
    (State::QuickStopActive, 0x6F, 0x07),
    (State::FaultReactionActive, 0x4F, 0x0F),
    (State::Fault, 0x4F, 0x08),
];

impl State {
    /// All eight states, in the order of [`STATE_CODING`].
    pub const ALL: [State; 8] = [
        State::NotReadyToSwitchOn,
        State::SwitchOnDisabled,
        State::ReadyToSwitchOn,
        State::SwitchedOn,
        State::OperationEnabled,
        State::QuickStopActive,
        State::FaultReactionActive,
        State::Fault,
    ];

    /// Decodes the state from a statusword, ignoring bits outside each pattern's mask.
    /// `None` if the word matches no pattern (e.g. 0x0001), which a conforming drive never
    /// reports.
    pub fn from_statusword(sw: u16) -> Option<State> {
        STATE_CODING
            .iter()
            .find(|&&(_, mask, value)| sw & mask == value)
            .map(|&(state, _, _)| state)
    }

    /// The statusword bits 0–6 a drive reports in this state: the state pattern, bit 4
    /// (voltage enabled) while the power stage is supplied (Ready to switch on through Fault
    /// reaction active), and bit 5 (quick stop, active low) set in every state except Quick stop
    /// active. Bits 7–15 are left to the caller.
    pub const fn statusword_bits(self) -> u16 {
        use statusword::{QUICK_STOP as QS, VOLTAGE_ENABLED as VE};
        match self {
            State::NotReadyToSwitchOn => QS,
            State::SwitchOnDisabled => 0x40 | QS,
            State::ReadyToSwitchOn => 0x21 | VE,
            State::SwitchedOn => 0x23 | VE,
            State::OperationEnabled => 0x27 | VE,
            State::QuickStopActive => 0x07 | VE,
            State::FaultReactionActive => 0x0F | VE | QS,
            State::Fault => 0x08 | QS,
        }
    }

    /// The state's name as CiA 402 writes it, e.g. "Operation enabled".
    pub const fn name(self) -> &'static str {
        match self {
            State::NotReadyToSwitchOn => "Not ready to switch on",
            State::SwitchOnDisabled => "Switch on disabled",
            State::ReadyToSwitchOn => "Ready to switch on",
            State::SwitchedOn => "Switched on",
            State::OperationEnabled => "Operation enabled",
            State::QuickStopActive => "Quick stop active",
            State::FaultReactionActive => "Fault reaction active",
            State::Fault => "Fault",
        }
    }
}

impl fmt::Display for State {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A device-control command coded in controlword bits 0–3 and 7 (CiA 402-2 controlword
/// command coding; checklist "Controlword (0x6040) commands").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Command {
    /// `cw & 0x87 == 0x06`: transitions 2, 6, 8.
    Shutdown,
    /// `cw & 0x8F == 0x07`: Switch on (transition 3), which in Operation enabled means
    /// Disable operation (transition 5); see [`Command::DISABLE_OPERATION`].
    SwitchOn,
    /// `cw & 0x8F == 0x0F`: Enable operation (transitions 4, 16), in Ready to switch on
    /// "Switch on + enable operation" (3 then 4).
    EnableOperation,
    /// `cw & 0x82 == 0x00`: transitions 7, 9, 10, 12.
    DisableVoltage,
    /// `cw & 0x86 == 0x02`: transitions 7, 10, 11.
    QuickStop,
    /// 0 → 1 edge of bit 7: transition 15.
    FaultReset,
}

impl Command {
    /// Disable operation has the same coding as [`Command::SwitchOn`]; the state decides.
    pub const DISABLE_OPERATION: Command = Command::SwitchOn;

    /// Decodes the command in `cw`, given the previous controlword `prev_cw` for the
    /// fault-reset edge. With bit 7 low every word decodes to exactly one command; with bit 7
    /// high it is [`Command::FaultReset`] on the rising edge and `None` while held.
    pub const fn from_controlword(cw: u16, prev_cw: u16) -> Option<Command> {
        let reset = controlword::FAULT_RESET;
        if cw & reset != 0 {
            return if prev_cw & reset == 0 {
                Some(Command::FaultReset)
            } else {
                None
            };
        }
        // Bit 7 is 0 here, so the masks below reduce to bits 0–3 and cover every value.
        Some(if cw & 0x82 == 0x00 {
            Command::DisableVoltage
        } else if cw & 0x86 == 0x02 {
            Command::QuickStop
        } else if cw & 0x87 == 0x06 {
            Command::Shutdown
        } else if cw & 0x8F == 0x07 {
            Command::SwitchOn
        } else {
            Command::EnableOperation
        })
    }

    /// The canonical controlword for this command (bits 0–3 and 7 only).
    pub const fn controlword(self) -> u16 {
        match self {
            Command::Shutdown => controlword::SHUTDOWN,
            Command::SwitchOn => controlword::SWITCH_ON_CMD,
            Command::EnableOperation => controlword::ENABLE_OPERATION_CMD,
            Command::DisableVoltage => controlword::DISABLE_VOLTAGE,
            Command::QuickStop => controlword::QUICK_STOP_CMD,
            Command::FaultReset => controlword::FAULT_RESET,
        }
    }
}

impl fmt::Display for Command {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Command::Shutdown => "Shutdown",
            Command::SwitchOn => "Switch on / Disable operation",
            Command::EnableOperation => "Enable operation",
            Command::DisableVoltage => "Disable voltage",
            Command::QuickStop => "Quick stop",
            Command::FaultReset => "Fault reset",
        })
    }
}

/// A mode of operation (0x6060 / 0x6061), CiA 402-2.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(i8)]
pub enum ModeOfOperation {
    /// PP.
    ProfilePosition = 1,
    /// PV.
    ProfileVelocity = 3,
    /// HM.
    Homing = 6,
    /// IP: setpoints in 0x60C1:01 every SYNC, enabled by controlword bit 4.
    InterpolatedPosition = 7,
    /// CSP: 0x607A every SYNC.
    CyclicSyncPosition = 8,
    /// CSV.
    CyclicSyncVelocity = 9,
    /// CST.
    CyclicSyncTorque = 10,
}

impl ModeOfOperation {
    /// Decodes 0x6060/0x6061; `None` for modes this project does not use (0 = no mode,
    /// 2/4/5 = velocity/torque/reserved, negative = vendor-specific).
    pub const fn from_i8(value: i8) -> Option<ModeOfOperation> {
        Some(match value {
            1 => ModeOfOperation::ProfilePosition,
            3 => ModeOfOperation::ProfileVelocity,
            6 => ModeOfOperation::Homing,
            7 => ModeOfOperation::InterpolatedPosition,
            8 => ModeOfOperation::CyclicSyncPosition,
            9 => ModeOfOperation::CyclicSyncVelocity,
            10 => ModeOfOperation::CyclicSyncTorque,
            _ => return None,
        })
    }

    /// The value written to 0x6060.
    pub const fn as_i8(self) -> i8 {
        self as i8
    }

    /// This mode's bit in supported drive modes (0x6502): bit (mode − 1).
    pub const fn supported_bit(self) -> u32 {
        1 << (self as u32 - 1)
    }

    /// The mode's name, e.g. "Interpolated position".
    pub const fn name(self) -> &'static str {
        match self {
            ModeOfOperation::ProfilePosition => "Profile position",
            ModeOfOperation::ProfileVelocity => "Profile velocity",
            ModeOfOperation::Homing => "Homing",
            ModeOfOperation::InterpolatedPosition => "Interpolated position",
            ModeOfOperation::CyclicSyncPosition => "Cyclic synchronous position",
            ModeOfOperation::CyclicSyncVelocity => "Cyclic synchronous velocity",
            ModeOfOperation::CyclicSyncTorque => "Cyclic synchronous torque",
        }
    }
}

impl fmt::Display for ModeOfOperation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use State::*;

    #[test]
    fn statusword_patterns_decode() {
        // (statusword, expected): the checklist values, typical drive words with bits 4, 7,
        // 9–13 set, and words that match no pattern.
        let cases: &[(u16, Option<State>)] = &[
            (0x0000, Some(NotReadyToSwitchOn)),
            (0x0020, Some(NotReadyToSwitchOn)),
            (0x0010, Some(NotReadyToSwitchOn)),
            (0x0040, Some(SwitchOnDisabled)),
            (0x0060, Some(SwitchOnDisabled)),
            (0x0250, Some(SwitchOnDisabled)),
            (0x0270, Some(SwitchOnDisabled)),
            (0x0021, Some(ReadyToSwitchOn)),
            (0x0031, Some(ReadyToSwitchOn)),
            (0x0231, Some(ReadyToSwitchOn)),
            (0x0023, Some(SwitchedOn)),
            (0x0233, Some(SwitchedOn)),
            (0x0027, Some(OperationEnabled)),
            (0x0237, Some(OperationEnabled)),
            (0x1637, Some(OperationEnabled)),
            (0x20B7, Some(OperationEnabled)),
            (0x0007, Some(QuickStopActive)),
            (0x0217, Some(QuickStopActive)),
            (0x000F, Some(FaultReactionActive)),
            (0x021F, Some(FaultReactionActive)),
            (0x003F, Some(FaultReactionActive)),
            (0x0008, Some(Fault)),
            (0x0218, Some(Fault)),
            (0x0238, Some(Fault)),
            (0x0001, None),
            (0x0003, None),
            (0x0041, None),
            (0x0048, None),
            (0x0067, None),
            (0xFFFF, None),
        ];
        for &(sw, want) in cases {
            assert_eq!(State::from_statusword(sw), want, "sw {sw:#06x}");
        }
    }

    #[test]
    fn statusword_bits_round_trip() {
        for s in State::ALL {
            let sw = s.statusword_bits();
            assert_eq!(sw & !0x7F, 0, "{s}: only bits 0-6");
            assert_eq!(State::from_statusword(sw), Some(s), "{s}");
            // Caller-owned bits 7-15 never change the decoded state.
            assert_eq!(State::from_statusword(sw | 0xFF80), Some(s), "{s}");
            let qs_bit = sw & statusword::QUICK_STOP != 0;
            assert_eq!(qs_bit, s != QuickStopActive, "{s}: bit 5 active low");
        }
        assert_eq!(OperationEnabled.statusword_bits(), 0x0037);
        assert_eq!(OperationEnabled.to_string(), "Operation enabled");
    }

    #[test]
    fn state_coding_is_disjoint() {
        for sw in 0..=0x7Fu16 {
            let n = STATE_CODING
                .iter()
                .filter(|&&(_, m, v)| sw & m == v)
                .count();
            assert!(n <= 1, "sw {sw:#04x} matches {n} patterns");
        }
    }

    #[test]
    fn controlword_commands_decode() {
        use Command::*;
        // (cw, prev_cw, expected)
        let cases: &[(u16, u16, Option<Command>)] = &[
            (0x0006, 0, Some(Shutdown)),
            (0x000E, 0, Some(Shutdown)),
            (0x0016, 0, Some(Shutdown)),
            (0x0007, 0, Some(SwitchOn)),
            (0x0107, 0, Some(SwitchOn)),
            (0x000F, 0, Some(EnableOperation)),
            (0x001F, 0, Some(EnableOperation)),
            (0x010F, 0, Some(EnableOperation)),
            (0x0000, 0, Some(DisableVoltage)),
            (0x0001, 0, Some(DisableVoltage)),
            (0x000D, 0, Some(DisableVoltage)),
            (0x0002, 0, Some(QuickStop)),
            (0x000B, 0, Some(QuickStop)),
            (0x0080, 0x0000, Some(FaultReset)),
            (0x008F, 0x000F, Some(FaultReset)),
            (0x0080, 0x0080, None),
            (0x008F, 0x0080, None),
        ];
        for &(cw, prev, want) in cases {
            assert_eq!(Command::from_controlword(cw, prev), want, "cw {cw:#06x}");
        }
        for c in [
            Shutdown,
            SwitchOn,
            EnableOperation,
            DisableVoltage,
            QuickStop,
        ] {
            assert_eq!(Command::from_controlword(c.controlword(), 0), Some(c));
        }
        assert_eq!(Command::DISABLE_OPERATION.controlword(), 0x0007);
    }

    #[test]
    fn every_controlword_without_bit7_decodes() {
        for cw in (0..=u16::MAX).filter(|cw| cw & controlword::FAULT_RESET == 0) {
            assert!(Command::from_controlword(cw, 0).is_some(), "cw {cw:#06x}");
        }
    }

    #[test]
    fn modes_of_operation() {
        use ModeOfOperation::*;
        let cases = [
            (1, ProfilePosition, 0x01),
            (3, ProfileVelocity, 0x04),
            (6, Homing, 0x20),
            (7, InterpolatedPosition, 0x40),
            (8, CyclicSyncPosition, 0x80),
            (9, CyclicSyncVelocity, 0x100),
            (10, CyclicSyncTorque, 0x200),
        ];
        for (v, m, bit) in cases {
            assert_eq!(ModeOfOperation::from_i8(v), Some(m));
            assert_eq!(m.as_i8(), v);
            assert_eq!(m.supported_bit(), bit, "{m}");
        }
        for v in [i8::MIN, -1, 0, 2, 4, 5, 11, i8::MAX] {
            assert_eq!(ModeOfOperation::from_i8(v), None, "{v}");
        }
    }
}
