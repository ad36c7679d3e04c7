//! Drive side: the power state machine a CiA 402 drive runs.

use core::fmt;

use super::{Command, State, controlword};

/// A numbered transition of the CiA 402 power state machine (CiA 402-2), so tests and logs
/// can name them. See the table in the [module docs](super).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Transition {
    /// Power on → Not ready to switch on (automatic).
    T0,
    /// Not ready to switch on → Switch on disabled (automatic, self-test done).
    T1,
    /// Switch on disabled → Ready to switch on (Shutdown).
    T2,
    /// Ready to switch on → Switched on (Switch on).
    T3,
    /// Switched on → Operation enabled (Enable operation).
    T4,
    /// Operation enabled → Switched on (Disable operation).
    T5,
    /// Switched on → Ready to switch on (Shutdown).
    T6,
    /// Ready to switch on → Switch on disabled (Disable voltage or Quick stop).
    T7,
    /// Operation enabled → Ready to switch on (Shutdown).
    T8,
    /// Operation enabled → Switch on disabled (Disable voltage).
    T9,
    /// Switched on → Switch on disabled (Disable voltage or Quick stop).
    T10,
    /// Operation enabled → Quick stop active (Quick stop).
    T11,
    /// Quick stop active → Switch on disabled (Disable voltage, or the stop completed with
    /// quick-stop option code 0–4).
    T12,
    /// Any state → Fault reaction active (fault detected).
    T13,
    /// Fault reaction active → Fault (automatic, reaction done).
    T14,
    /// Fault → Switch on disabled (fault reset edge, fault condition gone).
    T15,
    /// Quick stop active → Operation enabled (Enable operation, option code 5–8).
    T16,
}

impl Transition {
    /// The CiA 402 transition number, 0..=16.
    pub const fn number(self) -> u8 {
        self as u8
    }

    /// The state the transition starts from; `None` for T0 (power on) and T13 (any state).
    pub const fn from_state(self) -> Option<State> {
        use Transition::*;
        Some(match self {
            T0 | T13 => return None,
            T1 => State::NotReadyToSwitchOn,
            T2 => State::SwitchOnDisabled,
            T3 | T7 => State::ReadyToSwitchOn,
            T4 | T6 | T10 => State::SwitchedOn,
            T5 | T8 | T9 | T11 => State::OperationEnabled,
            T12 | T16 => State::QuickStopActive,
            T14 => State::FaultReactionActive,
            T15 => State::Fault,
        })
    }

    /// The state the transition leads to.
    pub const fn to_state(self) -> State {
        use Transition::*;
        match self {
            T0 => State::NotReadyToSwitchOn,
            T1 | T7 | T9 | T10 | T12 | T15 => State::SwitchOnDisabled,
            T2 | T6 | T8 => State::ReadyToSwitchOn,
            T3 | T5 => State::SwitchedOn,
            T4 | T16 => State::OperationEnabled,
            T11 => State::QuickStopActive,
            T13 => State::FaultReactionActive,
            T14 => State::Fault,
        }
    }
}

impl fmt::Display for Transition {
    /// E.g. "T4 (Switched on -> Operation enabled)".
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let from = match self.from_state() {
            Some(s) => s.name(),
            None if *self == Transition::T0 => "Power on",
            None => "Any",
        };
        write!(f, "T{} ({from} -> {})", self.number(), self.to_state())
    }
}

/// A quick-stop option code (0x605A) outside 0..=8 (negative codes are vendor-specific and
/// not supported). A drive answers such a write with SDO abort 0x06090030.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("quick-stop option code {0} (0x605A) is not supported: expected 0..=8")]
pub struct InvalidQuickStopOption(pub i16);

/// The CiA 402 power state machine as a drive runs it.
///
/// Feed it every received controlword ([`on_controlword`](Self::on_controlword)) and the drive's
/// own events ([`boot`](Self::boot), [`fault`](Self::fault),
/// [`fault_reaction_done`](Self::fault_reaction_done), [`quick_stop_done`](Self::quick_stop_done));
/// report [`statusword`](Self::statusword). Every method returns the transition it took, if any;
/// commands that do not apply to the current state leave it unchanged.
///
/// Quick stop (transition 11) goes to Quick stop active; what follows depends on the quick-stop
/// option code 0x605A ([`set_quick_stop_option`](Self::set_quick_stop_option), default 2):
///
/// | Code | Reaction (ramp) | After the stop |
/// |---|---|---|
/// | 0 | coast (disable drive function) | Switch on disabled at once (T11 + T12) |
/// | 1, 2 | slow-down ramp 0x6084 / quick-stop ramp 0x6085 | Switch on disabled (T12 on done) |
/// | 3, 4 | current / voltage limit | Switch on disabled (T12 on done) |
/// | 5–8 | as 1–4 | stays in Quick stop active; Enable operation (T16) is legal |
///
/// "Done" is [`quick_stop_done`](Self::quick_stop_done), called by the drive when the motor is at
/// rest. The ramp itself is the motion layer's job; this machine only tracks the state.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PowerStateMachine {
    state: State,
    /// The last controlword received, for the fault-reset edge.
    last_cw: u16,
    fault_active: bool,
    quick_stop_option: i16,
}

impl Default for PowerStateMachine {
    fn default() -> Self {
        Self::new()
    }
}

impl PowerStateMachine {
    /// The default quick-stop option code (CiA 402-2): 2, quick-stop ramp then Switch on
    /// disabled.
    pub const DEFAULT_QUICK_STOP_OPTION: i16 = 2;

    /// A drive just powered on (transition 0): Not ready to switch on, no fault, option code 2.
    pub const fn new() -> Self {
        Self {
            state: State::NotReadyToSwitchOn,
            // No controlword seen yet: treat bit 7 as high so that the first frame cannot be
            // a fault-reset edge (the checklist's "bit 7 = 0 first").
            last_cw: controlword::FAULT_RESET,
            fault_active: false,
            quick_stop_option: Self::DEFAULT_QUICK_STOP_OPTION,
        }
    }

    /// The current state.
    pub const fn state(&self) -> State {
        self.state
    }

    /// Statusword bits 0–6 for the current state ([`State::statusword_bits`]): state pattern,
    /// voltage enabled (bit 4) and quick stop (bit 5, active low). Bits 7–15 (warning, remote,
    /// target reached, internal limit, mode-specific) are the caller's to OR in.
    pub const fn statusword(&self) -> u16 {
        self.state.statusword_bits()
    }

    /// Whether the drive follows setpoints (Operation enabled).
    pub const fn is_operation_enabled(&self) -> bool {
        matches!(self.state, State::OperationEnabled)
    }

    /// Whether the motor is powered and holds or produces torque: Operation enabled, Quick stop
    /// active (ramping or holding) and Fault reaction active (braking). Switched on has the
    /// power stage on but no torque.
    pub const fn power_enabled(&self) -> bool {
        matches!(
            self.state,
            State::OperationEnabled | State::QuickStopActive | State::FaultReactionActive
        )
    }

    /// The quick-stop option code in use (0x605A).
    pub const fn quick_stop_option(&self) -> i16 {
        self.quick_stop_option
    }

    /// Sets the quick-stop option code (a write to 0x605A). Codes outside 0..=8 are rejected
    /// and leave the code unchanged.
    pub fn set_quick_stop_option(&mut self, code: i16) -> Result<(), InvalidQuickStopOption> {
        if (0..=8).contains(&code) {
            self.quick_stop_option = code;
            Ok(())
        } else {
            Err(InvalidQuickStopOption(code))
        }
    }

    /// Whether a fault condition is present (it blocks the fault reset).
    pub const fn fault_active(&self) -> bool {
        self.fault_active
    }

    /// Transition 1: the self-test is done. Only from Not ready to switch on.
    pub fn boot(&mut self) -> Option<Transition> {
        self.take_if(State::NotReadyToSwitchOn, Transition::T1)
    }

    /// Applies a received controlword (transitions 2–12, 15, 16) and remembers it for the
    /// fault-reset edge. Returns the transition taken; when one frame takes two (0x000F in
    /// Ready to switch on: T3 then T4; quick stop with option code 0: T11 then T12) it returns
    /// the last, so [`Transition::to_state`] is always the new state.
    pub fn on_controlword(&mut self, cw: u16) -> Option<Transition> {
        use {Command as C, State as S, Transition as T};
        let command = Command::from_controlword(cw, self.last_cw);
        self.last_cw = cw;
        let holding = (5..=8).contains(&self.quick_stop_option);
        let t = match (self.state, command?) {
            (S::SwitchOnDisabled, C::Shutdown) => T::T2,
            (S::ReadyToSwitchOn, C::SwitchOn) => T::T3,
            // Switch on + enable operation: T3, then T4 automatically.
            (S::ReadyToSwitchOn, C::EnableOperation) => T::T4,
            (S::ReadyToSwitchOn, C::DisableVoltage | C::QuickStop) => T::T7,
            (S::SwitchedOn, C::EnableOperation) => T::T4,
            (S::SwitchedOn, C::Shutdown) => T::T6,
            (S::SwitchedOn, C::DisableVoltage | C::QuickStop) => T::T10,
            (S::OperationEnabled, C::SwitchOn) => T::T5,
            (S::OperationEnabled, C::Shutdown) => T::T8,
            (S::OperationEnabled, C::DisableVoltage) => T::T9,
            // Code 0 coasts: the stop is complete the moment it starts, so T12 follows at once.
            (S::OperationEnabled, C::QuickStop) if self.quick_stop_option == 0 => T::T12,
            (S::OperationEnabled, C::QuickStop) => T::T11,
            (S::QuickStopActive, C::DisableVoltage) => T::T12,
            (S::QuickStopActive, C::EnableOperation) if holding => T::T16,
            (S::Fault, C::FaultReset) if !self.fault_active => T::T15,
            _ => return None,
        };
        self.state = t.to_state();
        Some(t)
    }

    /// Transition 13: a fault was detected; starts the fault reaction. From any state except
    /// Fault reaction active and Fault (a second fault during the reaction changes nothing).
    pub fn fault(&mut self) -> Option<Transition> {
        match self.state {
            State::FaultReactionActive | State::Fault => None,
            _ => {
                self.state = State::FaultReactionActive;
                Some(Transition::T13)
            }
        }
    }

    /// Sets whether a fault condition is present. While it is, a fault reset leaves the drive in
    /// Fault. Raising it outside the fault states also starts the fault reaction (T13), so a
    /// drive with an active fault is always in Fault reaction active or Fault.
    pub fn set_fault_active(&mut self, active: bool) -> Option<Transition> {
        self.fault_active = active;
        if active { self.fault() } else { None }
    }

    /// Transition 14: the fault reaction is done. Only from Fault reaction active.
    pub fn fault_reaction_done(&mut self) -> Option<Transition> {
        self.take_if(State::FaultReactionActive, Transition::T14)
    }

    /// The quick stop has brought the motor to rest. With option codes 0–4 this is transition 12
    /// to Switch on disabled; with 5–8 the drive stays in Quick stop active, holding.
    pub fn quick_stop_done(&mut self) -> Option<Transition> {
        if (0..=4).contains(&self.quick_stop_option) {
            self.take_if(State::QuickStopActive, Transition::T12)
        } else {
            None
        }
    }

    fn take_if(&mut self, from: State, t: Transition) -> Option<Transition> {
        if self.state == from {
            self.state = t.to_state();
            Some(t)
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use State::*;
    use Transition::*;

    /// A machine in `state`, reached by legal transitions, whose last controlword had bit 7 = 0.
    fn machine_in(state: State, qs_option: i16) -> PowerStateMachine {
        let mut m = PowerStateMachine::new();
        m.set_quick_stop_option(qs_option).unwrap();
        let cws: &[u16] = match state {
            NotReadyToSwitchOn => &[0x00],
            SwitchOnDisabled => &[0x00],
            ReadyToSwitchOn => &[0x06],
            SwitchedOn => &[0x06, 0x07],
            OperationEnabled => &[0x06, 0x07, 0x0F],
            QuickStopActive => &[0x06, 0x07, 0x0F, 0x02],
            FaultReactionActive | Fault => &[0x00],
        };
        if state != NotReadyToSwitchOn {
            m.boot();
        }
        for &cw in cws {
            m.on_controlword(cw);
        }
        if matches!(state, FaultReactionActive | Fault) {
            m.fault();
        }
        if state == Fault {
            m.fault_reaction_done();
        }
        assert_eq!(m.state(), state, "setup");
        m
    }

    #[test]
    fn boots_to_switch_on_disabled() {
        let mut m = PowerStateMachine::new();
        assert_eq!(m.state(), NotReadyToSwitchOn);
        assert_eq!(m.on_controlword(0x06), None, "ignored before boot");
        assert_eq!(m.boot(), Some(T1));
        assert_eq!(m.state(), SwitchOnDisabled);
        assert_eq!(m.boot(), None);
    }

    #[test]
    fn controlword_transitions() {
        const DV: u16 = 0x00;
        const QS: u16 = 0x02;
        const SD: u16 = 0x06;
        const SO: u16 = 0x07;
        const EO: u16 = 0x0F;
        // (from, controlword, expected transition); every command in every state with the
        // default option code 2. `None` means the state must be unchanged.
        let cases: &[(State, u16, Option<Transition>)] = &[
            (NotReadyToSwitchOn, DV, None),
            (NotReadyToSwitchOn, QS, None),
            (NotReadyToSwitchOn, SD, None),
            (NotReadyToSwitchOn, SO, None),
            (NotReadyToSwitchOn, EO, None),
            (NotReadyToSwitchOn, 0x80, None),
            (SwitchOnDisabled, DV, None),
            (SwitchOnDisabled, QS, None),
            (SwitchOnDisabled, SD, Some(T2)),
            (SwitchOnDisabled, SO, None),
            (SwitchOnDisabled, EO, None),
            (SwitchOnDisabled, 0x80, None),
            (ReadyToSwitchOn, DV, Some(T7)),
            (ReadyToSwitchOn, QS, Some(T7)),
            (ReadyToSwitchOn, SD, None),
            (ReadyToSwitchOn, SO, Some(T3)),
            (ReadyToSwitchOn, EO, Some(T4)),
            (ReadyToSwitchOn, 0x80, None),
            (SwitchedOn, DV, Some(T10)),
            (SwitchedOn, QS, Some(T10)),
            (SwitchedOn, SD, Some(T6)),
            (SwitchedOn, SO, None),
            (SwitchedOn, EO, Some(T4)),
            (SwitchedOn, 0x8F, None),
            (OperationEnabled, DV, Some(T9)),
            (OperationEnabled, QS, Some(T11)),
            (OperationEnabled, SD, Some(T8)),
            (OperationEnabled, SO, Some(T5)),
            (OperationEnabled, EO, None),
            (OperationEnabled, 0x1F, None),
            (OperationEnabled, 0x8F, None),
            (QuickStopActive, DV, Some(T12)),
            (QuickStopActive, QS, None),
            (QuickStopActive, SD, None),
            (QuickStopActive, SO, None),
            (QuickStopActive, EO, None),
            (QuickStopActive, 0x80, None),
            (FaultReactionActive, DV, None),
            (FaultReactionActive, QS, None),
            (FaultReactionActive, SD, None),
            (FaultReactionActive, SO, None),
            (FaultReactionActive, EO, None),
            (FaultReactionActive, 0x80, None),
            (Fault, DV, None),
            (Fault, QS, None),
            (Fault, SD, None),
            (Fault, SO, None),
            (Fault, EO, None),
            (Fault, 0x80, Some(T15)),
        ];
        for &(from, cw, want) in cases {
            let mut m = machine_in(from, 2);
            let got = m.on_controlword(cw);
            assert_eq!(got, want, "{from} + {cw:#06x}");
            let expected_state = want.map_or(from, Transition::to_state);
            assert_eq!(m.state(), expected_state, "{from} + {cw:#06x}");
        }
    }

    #[test]
    fn fault_from_every_state() {
        for s in State::ALL {
            let mut m = machine_in(s, 2);
            let want = (!matches!(s, FaultReactionActive | Fault)).then_some(T13);
            assert_eq!(m.fault(), want, "{s}");
            if s != Fault {
                assert_eq!(m.state(), FaultReactionActive, "{s}");
                assert!(m.power_enabled(), "braking holds torque");
                assert_eq!(m.fault_reaction_done(), Some(T14));
            }
            assert_eq!(m.state(), Fault);
            assert!(!m.power_enabled());
            assert_eq!(m.fault_reaction_done(), None);
        }
    }

    #[test]
    fn fault_reset_needs_the_edge() {
        let mut m = machine_in(Fault, 2);
        // The fixture's last frame had bit 7 = 0: first 0x80 is an edge.
        assert_eq!(m.on_controlword(0x80), Some(T15));
        assert_eq!(m.state(), SwitchOnDisabled);
        // Faulting again while bit 7 is held: holding it does not reset a second time.
        m.fault();
        m.fault_reaction_done();
        assert_eq!(m.on_controlword(0x80), None);
        assert_eq!(m.on_controlword(0x8F), None);
        assert_eq!(m.state(), Fault);
        assert_eq!(m.on_controlword(0x00), None);
        assert_eq!(m.on_controlword(0x80), Some(T15));
    }

    #[test]
    fn first_frame_is_never_a_reset_edge() {
        let mut m = PowerStateMachine::new();
        m.fault();
        m.fault_reaction_done();
        assert_eq!(m.on_controlword(0x80), None, "no bit-7 = 0 frame seen yet");
        assert_eq!(m.on_controlword(0x00), None);
        assert_eq!(m.on_controlword(0x80), Some(T15));
    }

    #[test]
    fn edge_during_fault_reaction_is_lost() {
        let mut m = machine_in(FaultReactionActive, 2);
        assert_eq!(m.on_controlword(0x80), None);
        m.fault_reaction_done();
        assert_eq!(m.on_controlword(0x80), None, "held, not a new edge");
        assert_eq!(m.state(), Fault);
    }

    #[test]
    fn reset_while_fault_active_stays_in_fault() {
        let mut m = machine_in(OperationEnabled, 2);
        assert_eq!(m.set_fault_active(true), Some(T13));
        assert_eq!(m.set_fault_active(true), None, "already reacting");
        m.fault_reaction_done();
        assert_eq!(m.on_controlword(0x00), None);
        assert_eq!(m.on_controlword(0x80), None, "condition still present");
        assert_eq!(m.state(), Fault);
        m.set_fault_active(false);
        assert_eq!(m.on_controlword(0x80), None, "edge was used up");
        assert_eq!(m.on_controlword(0x00), None);
        assert_eq!(m.on_controlword(0x80), Some(T15));
    }

    #[test]
    fn quick_stop_option_codes() {
        // (code, state after Quick stop in Operation enabled, transition from
        // quick_stop_done, Enable operation legal in Quick stop active)
        let cases: &[(i16, State, Option<Transition>, bool)] = &[
            (0, SwitchOnDisabled, None, false),
            (1, QuickStopActive, Some(T12), false),
            (2, QuickStopActive, Some(T12), false),
            (3, QuickStopActive, Some(T12), false),
            (4, QuickStopActive, Some(T12), false),
            (5, QuickStopActive, None, true),
            (6, QuickStopActive, None, true),
            (7, QuickStopActive, None, true),
            (8, QuickStopActive, None, true),
        ];
        for &(code, after_qs, done, t16) in cases {
            let mut m = machine_in(OperationEnabled, code);
            let t = m.on_controlword(0x02);
            assert_eq!(m.state(), after_qs, "code {code}");
            assert_eq!(t.map(Transition::to_state), Some(after_qs), "code {code}");
            if after_qs != QuickStopActive {
                assert!(!m.power_enabled(), "coast: power off at once");
                continue;
            }
            assert!(m.power_enabled(), "code {code}: ramping");
            assert_eq!(m.statusword() & 0x20, 0, "bit 5 low in quick stop");

            // Enable operation before the stop completes.
            let mut early = m.clone();
            let t = early.on_controlword(0x0F);
            assert_eq!(t, t16.then_some(T16), "code {code}");

            assert_eq!(m.quick_stop_done(), done, "code {code}");
            let after_done = done.map_or(QuickStopActive, Transition::to_state);
            assert_eq!(m.state(), after_done, "code {code}");
            if after_done == QuickStopActive {
                let mut late = m.clone();
                assert_eq!(late.on_controlword(0x0F), Some(T16), "code {code}");
                assert_eq!(m.on_controlword(0x00), Some(T12), "code {code}");
            }
        }
    }

    #[test]
    fn quick_stop_option_rejects_reserved_codes() {
        let mut m = PowerStateMachine::new();
        assert_eq!(m.quick_stop_option(), 2);
        for code in [-1, 9, i16::MIN, i16::MAX] {
            assert_eq!(
                m.set_quick_stop_option(code),
                Err(InvalidQuickStopOption(code))
            );
        }
        assert_eq!(m.quick_stop_option(), 2);
    }

    #[test]
    fn power_enabled_states() {
        for s in State::ALL {
            let m = machine_in(s, 2);
            let want = matches!(s, OperationEnabled | QuickStopActive | FaultReactionActive);
            assert_eq!(m.power_enabled(), want, "{s}");
            assert_eq!(m.is_operation_enabled(), s == OperationEnabled, "{s}");
            assert_eq!(State::from_statusword(m.statusword()), Some(s));
        }
    }

    #[test]
    fn transition_endpoints() {
        let all = [
            T0, T1, T2, T3, T4, T5, T6, T7, T8, T9, T10, T11, T12, T13, T14, T15, T16,
        ];
        for (n, t) in all.into_iter().enumerate() {
            assert_eq!(usize::from(t.number()), n);
            assert_ne!(t.from_state(), Some(t.to_state()), "{t}");
        }
        assert_eq!(T4.to_string(), "T4 (Switched on -> Operation enabled)");
        assert_eq!(T13.to_string(), "T13 (Any -> Fault reaction active)");
    }
}
