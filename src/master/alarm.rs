//! Why a run stopped: typed alarms, each carrying what a person (or a test) needs to act on it,
//! and displayed as the gateway has always worded them.
//!
//! The alarms are the cyclic master's output, next to its frames: it raises them from the
//! process data ([`super::cyclic::CyclicMaster::cycle`]) and takes them from the supervision
//! around it (EMCY, heartbeat, boot-up, the bus, stop signals). This module depends only on what
//! the alarms name (CiA 402 states, EMCY codes, bus errors, signals), as the sans-I/O master must.
//!
//! The alarms raised inside a cycle carry only `Copy` data (axis letters are `&'static str`s from
//! [`AXIS_LETTERS`]), so raising one allocates nothing: the cyclic path stays allocation-free
//! even while it stops on a fault (tests/cyclic_alloc.rs). Those raised once from the bus side
//! may share heap data (`Arc`), so cloning them allocates nothing either.

use std::fmt;
use std::sync::Arc;

use crate::bus::{BusError, ErrorFrame};
use crate::canopen::emcy;
use crate::cia402::State;
use crate::config::machine::{AXIS_LETTERS, MAX_AXES};

/// The axis letter of `name` as a `&'static str` (names are validated against
/// [`AXIS_LETTERS`] when the machine file loads; anything else shows as `?`).
pub fn axis_letter(name: &str) -> &'static str {
    AXIS_LETTERS
        .iter()
        .copied()
        .find(|l| *l == name)
        .unwrap_or("?")
}

/// One axis that missed the enable time-out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LateAxis {
    /// Axis letter.
    pub axis: &'static str,
    /// Node id.
    pub node: u8,
    /// Its CiA 402 state from the last statusword (`None`: no statusword yet).
    pub state: Option<State>,
    /// Its `enable_timeout_ms`.
    pub enable_timeout_ms: u32,
}

/// The axes that missed a time-out, in machine order (at most [`MAX_AXES`], no allocation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LateAxes {
    axes: [Option<LateAxis>; MAX_AXES],
    len: usize,
}

impl LateAxes {
    /// Add an axis (beyond [`MAX_AXES`] it is dropped: a machine has no more).
    pub fn push(&mut self, a: LateAxis) {
        if let Some(slot) = self.axes.get_mut(self.len) {
            *slot = Some(a);
            self.len += 1;
        }
    }
    /// The axes.
    pub fn iter(&self) -> impl Iterator<Item = &LateAxis> {
        self.axes[..self.len].iter().flatten()
    }
    /// Whether there is none.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

/// A bus error shared between the run's result and its alarm (a [`BusError`] holds an
/// `io::Error` and cannot be cloned). Two are equal when they are the same error.
#[derive(Debug, Clone)]
pub struct SharedBusError(pub Arc<BusError>);

impl PartialEq for SharedBusError {
    fn eq(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.0, &other.0)
    }
}

impl fmt::Display for SharedBusError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.0.fmt(f)
    }
}

/// How the bus was lost.
#[derive(Debug, Clone, PartialEq)]
pub enum BusLoss {
    /// The port reported the bus gone (interface down, bus-off from the driver).
    Port(SharedBusError),
    /// The controller sent a bus-off error frame; `frame` when the frame says more than
    /// bus-off.
    BusOff {
        /// The interface.
        iface: Arc<str>,
        /// The error frame, when it carries more than the bus-off class.
        frame: Option<ErrorFrame>,
    },
}

impl fmt::Display for BusLoss {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BusLoss::Port(e) => e.fmt(f),
            BusLoss::BusOff { iface, frame } => {
                write!(f, "CAN interface '{iface}': controller bus-off")?;
                match frame {
                    Some(e) => write!(f, " ({e})"),
                    None => Ok(()),
                }
            }
        }
    }
}

/// A stop signal.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Signal {
    /// SIGINT (Ctrl-C).
    Int,
    /// SIGTERM.
    Term,
}

impl Signal {
    /// Its name, `SIGINT` or `SIGTERM`.
    pub fn name(self) -> &'static str {
        match self {
            Signal::Int => "SIGINT",
            Signal::Term => "SIGTERM",
        }
    }

    /// The signal number.
    pub fn number(self) -> i32 {
        match self {
            Signal::Int => libc::SIGINT,
            Signal::Term => libc::SIGTERM,
        }
    }

    /// The signal of number `n`, if it is a stop signal.
    pub fn from_number(n: i32) -> Option<Signal> {
        match n {
            libc::SIGINT => Some(Signal::Int),
            libc::SIGTERM => Some(Signal::Term),
            _ => None,
        }
    }

    /// The exit status of a run it stopped: 128 + its number (130, 143), as a shell reports a
    /// process the signal ended.
    pub fn exit_code(self) -> u8 {
        128 + self.number() as u8
    }
}

/// Why a run stopped.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Alarm {
    /// The drive's statusword shows Fault (bit 3).
    #[error(
        "axis {axis} (node {node}): drive reports fault (statusword bit 3), statusword 0x{statusword:04X}"
    )]
    DriveFault {
        /// Axis letter.
        axis: &'static str,
        /// Node id.
        node: u8,
        /// The statusword.
        statusword: u16,
    },
    /// The drive flags a following error (statusword bit 13) without faulting.
    #[error(
        "axis {axis} (node {node}): drive reports following error (statusword bit 13), statusword 0x{statusword:04X}"
    )]
    FollowingError {
        /// Axis letter.
        axis: &'static str,
        /// Node id.
        node: u8,
        /// The statusword.
        statusword: u16,
    },
    /// No feedback TPDO for too long (`silent_cycles`), or none at all since the start (`None`).
    #[error(
        "axis {axis} (node {node}): no process data (TPDO 0x{tpdo_cob:03X}) {}",
        match silent_cycles { Some(n) => format!("for {n} cycles"), None => "since start".to_string() }
    )]
    MissingProcessData {
        /// Axis letter.
        axis: &'static str,
        /// Node id.
        node: u8,
        /// COB-ID of the feedback TPDO.
        tpdo_cob: u16,
        /// Cycles since the last one; `None` when none arrived since the start.
        silent_cycles: Option<u64>,
    },
    /// The drive sent a boot-up message during the run: it reset.
    #[error(
        "axis {axis} (node {node}): boot-up during the run: the drive reset; no further setpoints to node {node}; {}",
        match completed_line { Some(l) => format!("last completed program line {l}"), None => "no program line completed".to_string() }
    )]
    BootUp {
        /// Axis letter.
        axis: &'static str,
        /// Node id.
        node: u8,
        /// The last program line completed before it.
        completed_line: Option<usize>,
    },
    /// A fault reset (controlword bit 7) did not clear the drive's fault.
    #[error("axis {axis} (node {node}): fault reset did not clear the fault")]
    FaultResetFailed {
        /// Axis letter.
        axis: &'static str,
        /// Node id.
        node: u8,
    },
    /// Drives did not reach Operation enabled within their `enable_timeout_ms`.
    #[error("drives did not reach Operation enabled: {}", EnableLate(late))]
    EnableTimeout {
        /// The late axes.
        late: LateAxes,
    },
    /// IP axes did not answer controlword bit 4 with statusword bit 12 (CSP: following) within
    /// their `enable_timeout_ms`.
    #[error(
        "statusword bit 12 (IP active / following) not set within the enable time-out on {}; check 0x60C2 equals the SYNC period",
        Bit12Late(late)
    )]
    Bit12Timeout {
        /// The late axes.
        late: LateAxes,
    },
    /// The interpolator ran out of motion mid-path.
    #[error("the motion queue ran dry (planner underrun): stopping")]
    PlannerUnderrun,
    /// A setpoint outside the axis's travel (the last line of defence).
    #[error(
        "axis {axis}: setpoint {setpoint_mm:.4} mm outside the travel limits [{min_mm}, {max_mm}] mm"
    )]
    OutsideTravel {
        /// Axis letter.
        axis: &'static str,
        /// The setpoint, mm.
        setpoint_mm: f64,
        /// Travel minimum, mm.
        min_mm: f64,
        /// Travel maximum, mm.
        max_mm: f64,
    },
    /// A setpoint step larger than max velocity × period.
    #[error("axis {axis}: setpoint step {step_mm:.4} mm exceeds max_vel × period")]
    StepTooLarge {
        /// Axis letter.
        axis: &'static str,
        /// The step, mm.
        step_mm: f64,
    },
    /// The axes did not settle at the end point.
    #[error("axes did not settle within one count of the end point in {timeout_s} s")]
    SettleTimeout {
        /// The time allowed, s.
        timeout_s: f64,
    },
    /// A fault EMCY (the statusword shows the fault bit).
    #[error("axis {axis} (node {node}): EMCY 0x{code:04X} {}", emcy::meaning(*code))]
    Emcy {
        /// Axis letter.
        axis: &'static str,
        /// Node id.
        node: u8,
        /// EMCY error code.
        code: u16,
    },
    /// The drive's heartbeat stopped.
    #[error(
        "axis {axis} (node {node}): heartbeat lost (none for {silent_ms} ms, consumer time {consumer_ms} ms)"
    )]
    HeartbeatLost {
        /// Axis letter.
        axis: &'static str,
        /// Node id.
        node: u8,
        /// Time since its last heartbeat, ms.
        silent_ms: u64,
        /// The gateway's consumer time, ms.
        consumer_ms: u64,
    },
    /// A stop signal: a stop on the path.
    #[error("stopped by signal {}", signal_name(*signal))]
    Signal {
        /// The first signal.
        signal: Option<Signal>,
    },
    /// A second stop signal during the stop on the path: the fault stop.
    #[error(
        "stopped by signal {}; a second signal ({}) during the stop escalated to the fault stop",
        signal_name(*first), signal_name(*latest)
    )]
    SignalEscalated {
        /// The first signal.
        first: Option<Signal>,
        /// The latest.
        latest: Option<Signal>,
    },
    /// Planning failed on the other side (its error is reported there): nothing to run.
    #[error("no motion to run: planning failed")]
    PlanningFailed,
    /// The plan could not be made into a motion.
    #[error("{0}")]
    Interpolator(#[from] crate::interpolator::InterpError),
    /// The port failed.
    #[error("bus error: {error}")]
    Bus {
        /// The error.
        error: SharedBusError,
    },
    /// The transmit queue stayed full for more consecutive cycles than the drives tolerate.
    #[error(
        "CAN interface '{iface}': transmit queue full (ENOBUFS): the setpoints of {run} consecutive cycles could not be sent (the drives tolerate {tolerated_run}: following-error window / (max velocity × cycle)); {lost_cycles} cycles lost in all"
    )]
    TxQueueFull {
        /// The interface.
        iface: Arc<str>,
        /// Consecutive cycles lost.
        run: u32,
        /// Consecutive cycles the drives tolerate.
        tolerated_run: u32,
        /// Cycles lost in all.
        lost_cycles: u64,
    },
    /// The bus is gone: nothing more can be sent.
    #[error(
        "{cause}, detected in cycle {cycle}, {t_s:.3} s after the first; nothing more can be sent, so the \
         gateway cannot stop the drives: each stops by its heartbeat consumer (0x1016) once \
         the gateway's heartbeat is missing; setpoints held; last completed program line: {}",
        match completed_line { Some(l) => format!("line {l}"), None => "none".to_string() }
    )]
    BusLost {
        /// How.
        cause: BusLoss,
        /// The cycle that saw it.
        cycle: u64,
        /// Time since the first cycle, s.
        t_s: f64,
        /// The last program line completed.
        completed_line: Option<usize>,
    },
}

impl Alarm {
    /// The node the alarm concerns, when it concerns one drive.
    pub fn node(&self) -> Option<u8> {
        match self {
            Alarm::DriveFault { node, .. }
            | Alarm::FollowingError { node, .. }
            | Alarm::MissingProcessData { node, .. }
            | Alarm::BootUp { node, .. }
            | Alarm::FaultResetFailed { node, .. }
            | Alarm::Emcy { node, .. }
            | Alarm::HeartbeatLost { node, .. } => Some(*node),
            _ => None,
        }
    }
}

fn signal_name(s: Option<Signal>) -> &'static str {
    s.map_or("?", Signal::name)
}

struct EnableLate<'a>(&'a LateAxes);

impl fmt::Display for EnableLate<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (k, a) in self.0.iter().enumerate() {
            if k > 0 {
                f.write_str(", ")?;
            }
            write!(
                f,
                "{} (node {}) in {} after its enable_timeout_ms of {} ms",
                a.axis,
                a.node,
                a.state.map_or("no statusword", |s| s.name()),
                a.enable_timeout_ms
            )?;
        }
        Ok(())
    }
}

struct Bit12Late<'a>(&'a LateAxes);

impl fmt::Display for Bit12Late<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (k, a) in self.0.iter().enumerate() {
            if k > 0 {
                f.write_str(", ")?;
            }
            write!(
                f,
                "{} (node {}, enable_timeout_ms {} ms)",
                a.axis, a.node, a.enable_timeout_ms
            )?;
        }
        Ok(())
    }
}

/// A run's failure: the alarm, and the program line in execution when it was raised.
#[derive(Debug, Clone, PartialEq)]
pub struct Failure {
    /// What happened.
    pub alarm: Alarm,
    /// The program line in execution, once streaming.
    pub line: Option<usize>,
}

impl fmt::Display for Failure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.alarm.fmt(f)?;
        match self.line {
            Some(l) => write!(f, " (last program line {l})"),
            None => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_read_as_before() {
        let f = Failure {
            alarm: Alarm::BootUp {
                axis: "X",
                node: 1,
                completed_line: Some(1),
            },
            line: Some(2),
        };
        assert_eq!(
            f.to_string(),
            "axis X (node 1): boot-up during the run: the drive reset; no further setpoints to node 1; last completed program line 1 (last program line 2)"
        );
        let mut late = LateAxes::default();
        for (axis, node) in [("X", 1), ("Z", 3)] {
            late.push(LateAxis {
                axis,
                node,
                state: Some(State::SwitchOnDisabled),
                enable_timeout_ms: 2000,
            });
        }
        assert_eq!(
            Alarm::EnableTimeout { late }.to_string(),
            "drives did not reach Operation enabled: X (node 1) in Switch on disabled after its enable_timeout_ms of 2000 ms, Z (node 3) in Switch on disabled after its enable_timeout_ms of 2000 ms"
        );
        assert_eq!(
            Alarm::Bit12Timeout { late }.to_string(),
            "statusword bit 12 (IP active / following) not set within the enable time-out on X (node 1, enable_timeout_ms 2000 ms), Z (node 3, enable_timeout_ms 2000 ms); check 0x60C2 equals the SYNC period"
        );
        assert_eq!(
            Alarm::MissingProcessData {
                axis: "Y",
                node: 2,
                tpdo_cob: 0x182,
                silent_cycles: None
            }
            .to_string(),
            "axis Y (node 2): no process data (TPDO 0x182) since start"
        );
        assert_eq!(
            Alarm::SignalEscalated {
                first: Some(Signal::Int),
                latest: Some(Signal::Term)
            }
            .to_string(),
            "stopped by signal SIGINT; a second signal (SIGTERM) during the stop escalated to the fault stop"
        );
    }
}
