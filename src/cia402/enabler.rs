//! Master side: walking a drive through the power state machine.

use super::{State, controlword as cw};

/// Where an [`Enabler`] walks the drive.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Target {
    /// Operation enabled: torque on, following setpoints.
    OperationEnabled,
    /// Switch on disabled: power stage off, by the orderly path Disable operation → Shutdown →
    /// Disable voltage.
    SwitchOnDisabled,
}

impl Target {
    /// The [`State`] this target means.
    pub const fn state(self) -> State {
        match self {
            Target::OperationEnabled => State::OperationEnabled,
            Target::SwitchOnDisabled => State::SwitchOnDisabled,
        }
    }
}

/// What an [`Enabler`] asks of the caller this cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[must_use]
pub enum Action {
    /// The drive is in the target state; keep sending [`Enabler::controlword`] to hold it.
    Done,
    /// Send this controlword (extra bits included) and call again next cycle.
    Next(u16),
    /// A fault reset was sent and the drive stayed in Fault for the whole wait
    /// ([`Enabler::with_reset_wait`]): the fault did not clear. [`Enabler::controlword`] now has
    /// bit 7 low, so calling [`Enabler::update`] again retries the reset.
    Fault,
}

/// The master's side of the power state machine: fed the drive's decoded state once per cycle,
/// it yields the controlword that moves the drive one transition towards the [`Target`].
///
/// | Drive state | Towards Operation enabled | Towards Switch on disabled |
/// |---|---|---|
/// | Not ready to switch on, Fault reaction active | 0x0000 (wait) | 0x0000 (wait) |
/// | Switch on disabled | Shutdown 0x0006 (T2) | done |
/// | Ready to switch on | Switch on 0x0007 (T3) | Disable voltage 0x0000 (T7) |
/// | Switched on | Enable operation 0x000F (T4) | Shutdown 0x0006 (T6) |
/// | Operation enabled | done | Disable operation 0x0007 (T5) |
/// | Quick stop active | Disable voltage 0x0000 (T12) | Disable voltage 0x0000 (T12) |
/// | Fault | 0x0000, then 0x0080 (T15) | 0x0000, then 0x0080 (T15) |
///
/// Commands are levels, so a drive that answers a cycle or two late simply receives the same
/// command again. The fault reset is an edge: the Enabler makes sure the frame before 0x0080 had
/// bit 7 low, then holds 0x0080 until the drive leaves Fault or the wait runs out
/// ([`Action::Fault`]). The caller must send the returned controlword every cycle.
///
/// Bits outside the command bits (0–3, 7), e.g. IP enable (bit 4) or halt (bit 8), are the
/// caller's: set them with [`with_bits`](Self::with_bits) / [`set_bits`](Self::set_bits) and
/// they are ORed into every controlword.
///
/// ```
/// use canmotion::cia402::{Action, Enabler, PowerStateMachine, State, Target};
///
/// let mut drive = PowerStateMachine::new();
/// drive.boot();
/// let mut enabler = Enabler::new(Target::OperationEnabled);
/// for _cycle in 0..10 {
///     let state = State::from_statusword(drive.statusword()).expect("valid statusword");
///     match enabler.update(state) {
///         Action::Done => break,
///         Action::Fault => panic!("fault did not clear"),
///         Action::Next(_) => {}
///     }
///     drive.on_controlword(enabler.controlword()); // one RPDO per SYNC on a real bus
/// }
/// assert!(drive.is_operation_enabled());
/// ```
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Enabler {
    target: Target,
    bits: u16,
    /// Command bits of the last controlword handed out; `None` before the first.
    sent: Option<u16>,
    reset_wait: u16,
    /// Updates that saw Fault since the reset edge was sent.
    waited: u16,
}

impl Enabler {
    /// Default number of cycles a drive may stay in Fault after the reset edge, which covers
    /// the PDO round trip (command applied at the next SYNC, statusword back one cycle later)
    /// plus the drive's own reset time.
    pub const DEFAULT_RESET_WAIT: u16 = 10;

    /// An Enabler walking towards `target`, with no extra bits and the default reset wait.
    pub const fn new(target: Target) -> Self {
        Self {
            target,
            bits: 0,
            sent: None,
            reset_wait: Self::DEFAULT_RESET_WAIT,
            waited: 0,
        }
    }

    /// Sets the extra controlword bits (see [`set_bits`](Self::set_bits)).
    pub const fn with_bits(mut self, bits: u16) -> Self {
        self.bits = bits & !cw::COMMAND_MASK;
        self
    }

    /// Sets the number of updates a drive may still report Fault after the reset edge before
    /// [`Action::Fault`] (at least 1).
    pub const fn with_reset_wait(mut self, cycles: u16) -> Self {
        self.reset_wait = if cycles == 0 { 1 } else { cycles };
        self
    }

    /// Sets the extra bits ORed into every controlword, e.g. [`cw::IP_ENABLE`] once the drive is
    /// enabled and the IP setpoint is preloaded. The command bits (0–3, 7) are masked off.
    pub fn set_bits(&mut self, bits: u16) {
        self.bits = bits & !cw::COMMAND_MASK;
    }

    /// The extra bits in use.
    pub const fn bits(&self) -> u16 {
        self.bits
    }

    /// The current target.
    pub const fn target(&self) -> Target {
        self.target
    }

    /// Changes the target, e.g. to [`Target::SwitchOnDisabled`] for an orderly stop.
    pub fn set_target(&mut self, target: Target) {
        self.target = target;
    }

    /// The controlword to send this cycle, extra bits included: the value of the last
    /// [`Action::Next`], or the holding word after [`Action::Done`] (0x000F in Operation
    /// enabled, 0x0000 in Switch on disabled). Disable voltage (0x0000) before the first update.
    pub const fn controlword(&self) -> u16 {
        let command = match self.sent {
            Some(command) => command,
            None => cw::DISABLE_VOLTAGE,
        };
        command | self.bits
    }

    /// One cycle: given the drive's current state (decoded from its statusword), says what to
    /// send. Never blocks, allocates or panics.
    pub fn update(&mut self, state: State) -> Action {
        use {State as S, Target as T};
        let target = self.target;
        if state == target.state() {
            self.sent = Some(match target {
                T::OperationEnabled => cw::ENABLE_OPERATION_CMD,
                T::SwitchOnDisabled => cw::DISABLE_VOLTAGE,
            });
            return Action::Done;
        }
        let command = match (state, target) {
            (S::Fault, _) => return self.fault_step(),
            (S::NotReadyToSwitchOn | S::FaultReactionActive, _) => cw::DISABLE_VOLTAGE,
            (S::SwitchOnDisabled, _) => cw::SHUTDOWN,
            (S::ReadyToSwitchOn, T::OperationEnabled) => cw::SWITCH_ON_CMD,
            (S::ReadyToSwitchOn, T::SwitchOnDisabled) => cw::DISABLE_VOLTAGE,
            (S::SwitchedOn, T::OperationEnabled) => cw::ENABLE_OPERATION_CMD,
            (S::SwitchedOn, T::SwitchOnDisabled) => cw::SHUTDOWN,
            (S::OperationEnabled, _) => cw::DISABLE_OPERATION,
            // Re-enabling through T16 would depend on 0x605A; T12 then T2.. always works.
            (S::QuickStopActive, _) => cw::DISABLE_VOLTAGE,
        };
        self.send(command)
    }

    fn fault_step(&mut self) -> Action {
        match self.sent {
            // The edge is out and the drive is still in Fault: hold it while it may be in flight.
            Some(sent) if sent & cw::FAULT_RESET != 0 => {
                self.waited = self.waited.saturating_add(1);
                if self.waited >= self.reset_wait {
                    // Drop bit 7 so the next update can send a fresh edge.
                    self.sent = Some(cw::DISABLE_VOLTAGE);
                    Action::Fault
                } else {
                    Action::Next(self.controlword())
                }
            }
            // The last frame had bit 7 low: the next one is an edge.
            Some(_) => {
                self.waited = 0;
                self.send(cw::FAULT_RESET)
            }
            // Unknown what the drive saw last: send bit 7 low first.
            None => self.send(cw::DISABLE_VOLTAGE),
        }
    }

    fn send(&mut self, command: u16) -> Action {
        self.sent = Some(command);
        Action::Next(self.controlword())
    }
}

#[cfg(test)]
mod tests {
    use super::super::{PowerStateMachine, Transition};
    use super::*;
    use proptest::prelude::*;
    use std::collections::VecDeque;

    /// A simulated drive whose automatic transitions (self-test, fault reaction, quick stop)
    /// complete as soon as possible, and which applies each controlword `lag` cycles late.
    struct Drive {
        psm: PowerStateMachine,
        in_flight: VecDeque<u16>,
        lag: usize,
    }

    impl Drive {
        fn new(psm: PowerStateMachine, lag: usize) -> Self {
            Self {
                psm,
                in_flight: VecDeque::new(),
                lag,
            }
        }

        fn receive(&mut self, cw: u16) {
            self.in_flight.push_back(cw);
            if self.in_flight.len() > self.lag {
                let cw = self.in_flight.pop_front().unwrap();
                self.psm.on_controlword(cw);
            }
            self.psm.boot();
            self.psm.fault_reaction_done();
            self.psm.quick_stop_done();
        }
    }

    /// Runs the Enabler against the drive until it is not `Next` or `max` cycles have passed.
    /// Returns the final action and the controlwords sent while walking.
    fn run(en: &mut Enabler, drive: &mut Drive, max: usize) -> (Action, Vec<u16>) {
        let mut sent = Vec::new();
        for _ in 0..max {
            let action = en.update(drive.psm.state());
            match action {
                Action::Next(cw) => {
                    assert_eq!(cw, en.controlword());
                    sent.push(cw);
                }
                _ => {
                    drive.receive(en.controlword());
                    return (action, sent);
                }
            }
            drive.receive(en.controlword());
        }
        (Action::Next(en.controlword()), sent)
    }

    fn faulted_drive(fault_active: bool) -> PowerStateMachine {
        let mut psm = PowerStateMachine::new();
        psm.boot();
        psm.fault();
        psm.fault_reaction_done();
        psm.set_fault_active(fault_active);
        psm
    }

    #[test]
    fn enables_from_power_on() {
        let mut en = Enabler::new(Target::OperationEnabled);
        let mut drive = Drive::new(PowerStateMachine::new(), 0);
        let (action, sent) = run(&mut en, &mut drive, 20);
        assert_eq!(action, Action::Done);
        assert_eq!(sent, [0x0000, 0x0006, 0x0007, 0x000F]);
        assert_eq!(drive.psm.state(), State::OperationEnabled);
        assert_eq!(en.controlword(), 0x000F, "holding word");
    }

    #[test]
    fn enables_from_fault() {
        let mut en = Enabler::new(Target::OperationEnabled);
        let mut drive = Drive::new(faulted_drive(false), 0);
        let (action, sent) = run(&mut en, &mut drive, 20);
        assert_eq!(action, Action::Done);
        assert_eq!(sent, [0x0000, 0x0080, 0x0006, 0x0007, 0x000F]);
    }

    #[test]
    fn disables_in_order() {
        let mut en = Enabler::new(Target::OperationEnabled);
        let mut drive = Drive::new(PowerStateMachine::new(), 0);
        assert_eq!(run(&mut en, &mut drive, 20).0, Action::Done);
        en.set_target(Target::SwitchOnDisabled);
        let (action, sent) = run(&mut en, &mut drive, 20);
        assert_eq!(action, Action::Done);
        assert_eq!(sent, [0x0007, 0x0006, 0x0000]);
        assert_eq!(drive.psm.state(), State::SwitchOnDisabled);
        assert_eq!(en.controlword(), 0x0000);
    }

    #[test]
    fn leaves_quick_stop_through_switch_on_disabled() {
        let mut psm = PowerStateMachine::new();
        psm.set_quick_stop_option(6).unwrap();
        let mut en = Enabler::new(Target::OperationEnabled);
        let mut drive = Drive::new(psm, 0);
        assert_eq!(run(&mut en, &mut drive, 20).0, Action::Done);
        drive.receive(0x0002);
        assert_eq!(drive.psm.state(), State::QuickStopActive);
        let (action, sent) = run(&mut en, &mut drive, 20);
        assert_eq!(action, Action::Done);
        assert_eq!(sent, [0x0000, 0x0006, 0x0007, 0x000F]);
    }

    #[test]
    fn reports_a_fault_that_does_not_clear() {
        let mut en = Enabler::new(Target::OperationEnabled).with_reset_wait(3);
        let mut drive = Drive::new(faulted_drive(true), 0);
        let (action, sent) = run(&mut en, &mut drive, 20);
        assert_eq!(action, Action::Fault);
        assert_eq!(sent, [0x0000, 0x0080, 0x0080, 0x0080]);
        assert_eq!(en.controlword(), 0x0000, "bit 7 dropped for a retry");
        assert_eq!(drive.psm.state(), State::Fault);

        // The condition clears: the retry needs only the edge.
        drive.psm.set_fault_active(false);
        let (action, sent) = run(&mut en, &mut drive, 20);
        assert_eq!(action, Action::Done);
        assert_eq!(sent, [0x0080, 0x0006, 0x0007, 0x000F]);
    }

    #[test]
    fn fault_while_enabled_resets_with_one_edge() {
        let mut en = Enabler::new(Target::OperationEnabled);
        let mut drive = Drive::new(PowerStateMachine::new(), 0);
        assert_eq!(run(&mut en, &mut drive, 20).0, Action::Done);
        drive.psm.fault();
        drive.psm.fault_reaction_done();
        // The holding word 0x000F had bit 7 low, so the edge can go out at once.
        let (action, sent) = run(&mut en, &mut drive, 20);
        assert_eq!(action, Action::Done);
        assert_eq!(sent, [0x0080, 0x0006, 0x0007, 0x000F]);
    }

    #[test]
    fn extra_bits_ride_along() {
        let mut en = Enabler::new(Target::OperationEnabled).with_bits(cw::HALT | 0x00FF);
        assert_eq!(en.bits(), 0x0170, "command bits masked off");
        en.set_bits(cw::HALT);
        let mut drive = Drive::new(PowerStateMachine::new(), 0);
        let (action, sent) = run(&mut en, &mut drive, 20);
        assert_eq!(action, Action::Done);
        assert_eq!(sent, [0x0100, 0x0106, 0x0107, 0x010F]);
        en.set_bits(cw::IP_ENABLE);
        assert_eq!(en.controlword(), 0x001F, "IP start word");
    }

    #[derive(Debug, Clone)]
    enum Op {
        Cw(u16),
        Boot,
        Fault,
        FaultActive(bool),
        ReactionDone,
        QuickStopDone,
        QuickStopOption(i16),
    }

    fn op() -> impl Strategy<Value = Op> {
        let commands = vec![0x00u16, 0x02, 0x06, 0x07, 0x0F, 0x1F, 0x80, 0x8F, 0x0106];
        prop_oneof![
            8 => prop::sample::select(commands).prop_map(Op::Cw),
            3 => any::<u16>().prop_map(Op::Cw),
            1 => Just(Op::Boot),
            1 => Just(Op::Fault),
            1 => any::<bool>().prop_map(Op::FaultActive),
            1 => Just(Op::ReactionDone),
            1 => Just(Op::QuickStopDone),
            1 => (-2i16..=10).prop_map(Op::QuickStopOption),
        ]
    }

    fn apply(m: &mut PowerStateMachine, op: &Op) -> Option<Transition> {
        match *op {
            Op::Cw(cw) => m.on_controlword(cw),
            Op::Boot => m.boot(),
            Op::Fault => m.fault(),
            Op::FaultActive(active) => m.set_fault_active(active),
            Op::ReactionDone => m.fault_reaction_done(),
            Op::QuickStopDone => m.quick_stop_done(),
            Op::QuickStopOption(code) => {
                let _ = m.set_quick_stop_option(code);
                None
            }
        }
    }

    proptest! {
        #[test]
        fn statusword_always_decodes_to_the_state(
            ops in prop::collection::vec(op(), 0..200),
            high in any::<u16>(),
        ) {
            let mut m = PowerStateMachine::new();
            for op in &ops {
                let before = m.state();
                let t = apply(&mut m, op);
                let sw = m.statusword();
                prop_assert_eq!(State::from_statusword(sw), Some(m.state()));
                prop_assert_eq!(State::from_statusword(sw | (high & 0xFF80)), Some(m.state()));
                match t {
                    Some(t) => {
                        prop_assert_eq!(t.to_state(), m.state());
                        prop_assert_ne!(before, m.state());
                    }
                    None => prop_assert_eq!(before, m.state()),
                }
                if m.fault_active() {
                    prop_assert!(matches!(m.state(), State::FaultReactionActive | State::Fault));
                }
            }
        }

        #[test]
        fn enabler_reaches_its_target_from_anywhere(
            ops in prop::collection::vec(op(), 0..60),
            lag in 0usize..=2,
            to_disabled in any::<bool>(),
        ) {
            let mut m = PowerStateMachine::new();
            for op in &ops {
                apply(&mut m, op);
            }
            m.set_fault_active(false);
            let target = if to_disabled {
                Target::SwitchOnDisabled
            } else {
                Target::OperationEnabled
            };
            let mut en = Enabler::new(target);
            let mut drive = Drive::new(m, lag);
            // Six transitions at most (Fault -> .. -> Operation enabled), each up to `lag` late,
            // plus the bit-7-low frame before the edge.
            let (action, _) = run(&mut en, &mut drive, 7 * (lag + 1) + 2);
            prop_assert_eq!(action, Action::Done);
            prop_assert_eq!(drive.psm.state(), target.state());
        }
    }
}
