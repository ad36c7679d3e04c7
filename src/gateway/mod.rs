//! The gateway: start the drives up over SDO, stream the program's setpoints on SYNC from the
//! cyclic thread, watch the drives, and bring everything down in order.

pub mod control;
pub mod cyclic_bus;
pub mod io;
pub mod progress;
pub mod resume;
pub mod serve;
pub mod startup;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::{Arc, mpsc};
use std::time::Duration;

use nalgebra::Vector3;

use crate::bus::{Bus, BusError, Filter, Frame};
use crate::canopen::{AbortCode, emcy};
use crate::config::{ConfigError, Machine};
use crate::gcode::AuxPos;
use crate::interpolator::{Interpolator, OverrideRamp};
use crate::master::alarm::{Alarm, Failure, SharedBusError};
use crate::master::cyclic::{CycleRecord, CyclicMaster, Phase};
use crate::master::supervision::Supervision;
use crate::planner::{Limits, Plan, PlanError};
use crate::rt::{self, Ticker, Timing};
use io::NodeIo;

/// Everything that can stop a run, with what a person needs to act on it.
#[derive(Debug, thiserror::Error)]
pub enum GatewayError {
    /// A configuration file is wrong.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The program does not parse.
    #[error(transparent)]
    Program(#[from] crate::gcode::Error),
    /// The program cannot be planned.
    #[error("{file}: {source}")]
    Plan {
        /// Program file.
        file: String,
        /// Why.
        source: PlanError,
    },
    /// A move leaves an axis's travel.
    #[error(
        "{file}:{line}: axis {axis} would move to {target_mm:.4} mm, outside its travel [{min_mm}, {max_mm}] mm"
    )]
    OutOfTravel {
        /// Program file.
        file: String,
        /// Line of the move.
        line: usize,
        /// Axis letter.
        axis: String,
        /// Where it would go.
        target_mm: f64,
        /// Travel.
        min_mm: f64,
        /// Travel.
        max_mm: f64,
    },
    /// An axis stands outside its travel before start-up: refused before anything was written to
    /// a drive (its software limits 0x607D would make it move as soon as it is enabled).
    #[error(
        "axis {axis} (node {node}) is at {position_mm:.4} mm, outside its travel [{min_mm}, {max_mm}] mm: nothing was written to the drives and none was enabled; jog the axis into its travel first, with its software limits (0x607D) not yet applied (a jog command comes with `canmotion serve`)"
    )]
    StartOutsideTravel {
        /// Axis letter.
        axis: String,
        /// Its node.
        node: u8,
        /// Position actual (0x6064), mm.
        position_mm: f64,
        /// Travel.
        min_mm: f64,
        /// Travel.
        max_mm: f64,
    },
    /// The program moves an axis the machine does not have.
    #[error("{file}:{line}: the program moves {axis}, which machine '{machine}' does not have")]
    NoSuchAxis {
        /// Program file.
        file: String,
        /// Line.
        line: usize,
        /// Axis letter.
        axis: char,
        /// Machine name.
        machine: String,
    },
    /// The bus failed.
    #[error(transparent)]
    Bus(#[from] BusError),
    /// An SDO transfer was aborted.
    #[error("node {node}: SDO {index:04X}:{sub:02X} aborted with {code}")]
    SdoAbort {
        /// Node.
        node: u8,
        /// Object.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// Abort code and meaning.
        code: AbortCode,
    },
    /// A node did not answer an SDO request.
    #[error("node {node}: no answer to SDO {index:04X}:{sub:02X} within {} ms (abort 0x05040000 sent)", io::SDO_TIMEOUT.as_millis())]
    SdoTimeout {
        /// Node.
        node: u8,
        /// Object.
        index: u16,
        /// Sub-index.
        sub: u8,
    },
    /// The node's SDO answers broke the protocol; the gateway aborted the transfer (its own
    /// abort, not the node's).
    #[error("node {node}: SDO {index:04X}:{sub:02X}: {source}")]
    SdoClient {
        /// Node.
        node: u8,
        /// Object.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// What was wrong, and the abort code the gateway sent.
        source: crate::canopen::sdo_client::SdoError,
    },
    /// An upload whose length does not fit the data type asked for.
    #[error("node {node}: SDO {index:04X}:{sub:02X}: {len} byte(s) do not hold a {data_type:?}")]
    SdoLength {
        /// Node.
        node: u8,
        /// Object.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// The type asked for.
        data_type: canopen_rs::DataType,
        /// The bytes the node sent.
        len: usize,
    },
    /// An SDO answer that does not fit the request.
    #[error("node {node}: SDO {index:04X}:{sub:02X}: unexpected answer")]
    SdoProtocol {
        /// Node.
        node: u8,
        /// Object.
        index: u16,
        /// Sub-index.
        sub: u8,
    },
    /// Nodes that did not boot.
    #[error("no boot-up from {} within {timeout_ms} ms after NMT reset communication on bus {bus}: is the drive powered, wired, at that node id and bitrate?", missing.join(", "))]
    MissingNodes {
        /// "axis X (node 1)" …
        missing: Vec<String>,
        /// Wait.
        timeout_ms: u64,
        /// Bus name.
        bus: String,
    },
    /// A node is not the configured device.
    #[error(
        "axis {axis} (node {node}): {object} is 0x{found:08X}, the dictionary {dictionary} expects 0x{expected:08X}: wrong drive or wrong dictionary"
    )]
    WrongIdentity {
        /// Axis.
        axis: String,
        /// Node.
        node: u8,
        /// Which object, named.
        object: &'static str,
        /// Expected.
        expected: u32,
        /// Found.
        found: u32,
        /// The dictionary file.
        dictionary: String,
    },
    /// A value read back differs from what was written.
    #[error("node {node}: {index:04X}:{sub:02X} reads back {found} after writing {written}")]
    ReadBack {
        /// Node.
        node: u8,
        /// Object.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// Written.
        written: String,
        /// Read.
        found: String,
    },
    /// 0x6061 did not confirm the mode.
    #[error(
        "axis {axis} (node {node}): modes of operation display 0x6061 shows {found}, not mode {mode}, within 1 s"
    )]
    ModeNotConfirmed {
        /// Axis.
        axis: String,
        /// Node.
        node: u8,
        /// Wanted.
        mode: i8,
        /// Last read.
        found: i8,
    },
    /// Unknown node.
    #[error("node {node} is not an axis of this machine")]
    UnknownNode {
        /// Node.
        node: u8,
    },
    /// The motion stopped because of a fault.
    #[error("motion stopped: {0}")]
    Motion(Box<MotionFailure>),
    /// The control socket could not be opened.
    #[error("control socket: {source}")]
    ControlSocket {
        /// Why.
        #[from]
        source: control::ControlSocketError,
    },
    /// Writing the log failed.
    #[error("{file}: {source}")]
    Log {
        /// File.
        file: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A stop signal (SIGINT, SIGTERM) arrived before any drive was enabled: every drive was
    /// sent to Pre-operational, nothing moved.
    #[error(
        "stopped by signal {} before any motion: no drive was enabled, every drive was sent to Pre-operational",
        signal.name()
    )]
    Stopped {
        /// The first signal.
        signal: rt::signal::Signal,
    },
    /// The run ended in order, but a drive could not be told to stop consuming the gateway's
    /// heartbeat (0x1016): it will report the heartbeat's loss once the gateway exits.
    #[error(
        "the run ended in order, but axis {axis} (node {node}) could not be told to stop watching the gateway's heartbeat (0x1016:1 = 0): {source}; it will report a heartbeat loss (EMCY 0x8130, a fault with 0x6007 = 1) once the gateway has exited"
    )]
    HeartbeatStillConsumed {
        /// Axis.
        axis: String,
        /// Node.
        node: u8,
        /// The SDO error.
        source: Box<GatewayError>,
    },
    /// A resume (`run --resume`) was refused before any motion: changed program, another
    /// machine, an axis too far from the stop point, no confirmation (see [`resume`]).
    #[error("{0}")]
    Resume(String),
}

impl GatewayError {
    /// The failure of an SDO transfer with `node` on `index:sub`: the node's abort as
    /// [`GatewayError::SdoAbort`], the client's own time-out or protocol error as itself.
    pub fn from_sdo(
        node: u8,
        index: u16,
        sub: u8,
        error: crate::canopen::sdo_client::SdoError,
    ) -> GatewayError {
        use crate::canopen::sdo_client::SdoError;
        match error {
            SdoError::Aborted { code } => GatewayError::SdoAbort {
                node,
                index,
                sub,
                code,
            },
            SdoError::TimedOut { .. } => GatewayError::SdoTimeout { node, index, sub },
            source @ SdoError::Protocol { .. } => GatewayError::SdoClient {
                node,
                index,
                sub,
                source,
            },
        }
    }
}

/// Why and when the motion stopped.
#[derive(Debug, Clone, PartialEq)]
pub struct MotionFailure {
    /// What happened, to which axis, and the program line in execution.
    pub failure: Failure,
    /// The cycle in which it was detected.
    pub detected_cycle: Option<u64>,
    /// The cycle in which every drive reported statusword bit 12.
    pub bit12_cycle: Option<u64>,
    /// The first cycle with a moving setpoint.
    pub first_motion_cycle: Option<u64>,
    /// The cycle period, s.
    pub period_s: f64,
    /// Wall-clock time from the cycle that saw statusword bit 12 on every drive to the one that
    /// detected the failure, s.
    pub bit12_to_failure_s: Option<f64>,
    /// When the cycle that detected the failure ran ([`rt::now_ns`], CLOCK_MONOTONIC).
    pub detected_ns: Option<u64>,
    /// Where the program's motion stopped, once it had started (the resume point's source).
    pub stop: Option<StopPoint>,
    /// The cyclic thread's timing up to the end (cycles, overruns).
    pub timing: Timing,
    /// The bus up to the end: error frames, frames not sent, SYNC period statistics.
    pub bus: cyclic_bus::BusReport,
}

impl MotionFailure {
    fn plain(alarm: Alarm, period_s: f64) -> Box<MotionFailure> {
        Box::new(MotionFailure {
            failure: Failure { alarm, line: None },
            detected_cycle: None,
            bit12_cycle: None,
            first_motion_cycle: None,
            period_s,
            bit12_to_failure_s: None,
            detected_ns: None,
            stop: None,
            timing: Timing::default(),
            bus: cyclic_bus::BusReport::default(),
        })
    }
}

/// Where a run's motion stopped: the last point of the plan streamed before the alarm (the group
/// then left the path, braking along its direction), and where the axes came to rest.
#[derive(Debug, Clone, PartialEq)]
pub struct StopPoint {
    /// Time into the plan of the last streamed sample, s (at most the plan's duration).
    pub plan_time_s: f64,
    /// The plan's point at that time (X, Y, Z), mm.
    pub path_mm: Vector3<f64>,
    /// The program line in execution.
    pub line: Option<usize>,
    /// The last program line completed.
    pub completed_line: Option<usize>,
    /// Nodes the alarm froze.
    pub frozen_nodes: Vec<u8>,
    /// Nodes that reset (boot-up) during the run.
    pub reset_nodes: Vec<u8>,
    /// Last setpoint per axis (machine order), mm: where the stop left them.
    pub rest_setpoint_mm: Vec<f64>,
    /// Last position actual per axis (machine order), counts.
    pub rest_actual_counts: Vec<i32>,
}

impl StopPoint {
    fn of(master: &CyclicMaster) -> Option<StopPoint> {
        let interp = master.motion()?;
        if interp.elapsed_s() == 0.0 {
            return None; // streaming never started
        }
        // The latest sample is the plan's point at that time (its end once finished).
        // Plan time, not wall time: an override or a hold makes them differ.
        // The jerk-limited mode's filters lag behind the plan: the plan time their output has
        // reached, so that a resume from here never skips any of the path.
        let plan_time_s = interp.reached_plan_time_s().min(interp.duration_s());
        Some(StopPoint {
            plan_time_s,
            path_mm: interp.last_mm(),
            line: master.line(),
            completed_line: master.completed_line(),
            frozen_nodes: master.frozen_nodes(),
            reset_nodes: master.reset_nodes(),
            rest_setpoint_mm: master.setpoint_mm(),
            rest_actual_counts: master.final_counts(),
        })
    }
}

impl MotionFailure {
    /// The alarm that stopped the motion.
    pub fn alarm(&self) -> &Alarm {
        &self.failure.alarm
    }
}

impl std::fmt::Display for MotionFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.failure.fmt(f)
    }
}

/// What a run did.
#[derive(Debug, Clone)]
pub struct Summary {
    /// Program time (streaming), s.
    pub program_s: f64,
    /// Cycles streamed.
    pub streaming_cycles: u64,
    /// All cycles of the cyclic thread.
    pub cycles: u64,
    /// Axis letters, machine order.
    pub axes: Vec<String>,
    /// The unit of each axis's positions: `mm`, or `deg` on a rotary axis.
    pub units: Vec<&'static str>,
    /// Max |following error| per axis, mm (degrees on a rotary axis).
    pub max_ferr_mm: Vec<f64>,
    /// Final position actual per axis, counts.
    pub final_counts: Vec<i32>,
    /// Final setpoint per axis, counts.
    pub target_counts: Vec<i32>,
    /// Cycle in which statusword bit 12 was seen on all axes.
    pub bit12_cycle: Option<u64>,
    /// First cycle with a moving setpoint.
    pub first_motion_cycle: Option<u64>,
    /// Loop timing.
    pub timing: Timing,
    /// Real-time set-up.
    pub rt: String,
    /// Log rows dropped because the writer fell behind.
    pub log_dropped: u64,
    /// Warnings the drives reported (EMCYs after which they kept running).
    pub warnings: Vec<Warning>,
    /// The bus as the cyclic thread saw it: error frames, frames it could not queue in time,
    /// SYNC period statistics.
    pub bus: cyclic_bus::BusReport,
}

pub use crate::master::supervision::{WARNING_CYCLES, Warning};

/// How many cycles after a late wake-up of the cyclic thread a drive's warning is taken for its
/// consequence: the drive notices the missing SYNC during the gap, and its EMCY reaches the
/// summary once a TPDO after it shows no fault bit.
pub const LATE_WAKE_WINDOW_CYCLES: u64 = 8;

/// Drive warnings tied to a late wake-up of the cyclic thread.
#[derive(Debug, Clone, PartialEq)]
pub struct LateWakeCause {
    /// The late wake-up.
    pub wake: rt::LateWake,
    /// The nodes that warned within [`LATE_WAKE_WINDOW_CYCLES`] after it, ascending.
    pub nodes: Vec<u8>,
    /// Their EMCY codes, ascending.
    pub codes: Vec<u16>,
}

impl std::fmt::Display for LateWakeCause {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let n = self.nodes.len();
        let what: Vec<String> = self
            .codes
            .iter()
            .map(|&c| match c {
                emcy::code::COMMUNICATION => "SYNC missing (EMCY 0x8100)".to_string(),
                c => format!("EMCY 0x{c:04X} {}", emcy::meaning(c)),
            })
            .collect();
        write!(
            f,
            "{n} drive{} reported {} in cycle {}: the cyclic thread woke {:.1} ms late (host not real-time; a PREEMPT_RT kernel or isolcpus helps)",
            if n == 1 { "" } else { "s" },
            what.join(", "),
            self.wake.cycle,
            self.wake.late.as_secs_f64() * 1e3
        )
    }
}

/// Ties each drive warning to a late wake-up of the cyclic thread in the
/// [`LATE_WAKE_WINDOW_CYCLES`] cycles before it, if there was one (the latest such): a drive
/// that sees a SYNC come late reports it, as a real one would. One cause per late wake-up that
/// has warnings, in cycle order.
pub fn late_wake_causes(warnings: &[Warning], late: &rt::LateWakes) -> Vec<LateWakeCause> {
    let mut causes: Vec<LateWakeCause> = Vec::new();
    for w in warnings {
        let kept = (w.count as usize).min(WARNING_CYCLES);
        for &c in &w.cycles[..kept] {
            let Some(wake) = late
                .iter()
                .filter(|l| l.cycle <= c && c - l.cycle <= LATE_WAKE_WINDOW_CYCLES)
                .last()
            else {
                continue;
            };
            let i = match causes.iter().position(|k| k.wake == *wake) {
                Some(i) => i,
                None => {
                    causes.push(LateWakeCause {
                        wake: *wake,
                        nodes: Vec::new(),
                        codes: Vec::new(),
                    });
                    causes.len() - 1
                }
            };
            let k = &mut causes[i];
            if !k.nodes.contains(&w.node) {
                k.nodes.push(w.node);
                k.nodes.sort_unstable();
            }
            if !k.codes.contains(&w.code) {
                k.codes.push(w.code);
                k.codes.sort_unstable();
            }
        }
    }
    causes.sort_by_key(|k| k.wake.cycle);
    causes
}

impl std::fmt::Display for Warning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "axis {} (node {}): EMCY 0x{:04X} {} ×{} (cycles {}–{})",
            self.axis,
            self.node,
            self.code,
            emcy::meaning(self.code),
            self.count,
            self.first_cycle,
            self.last_cycle
        )
    }
}

impl std::fmt::Display for Summary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "program time      {:.3} s", self.program_s)?;
        writeln!(
            f,
            "cycles            {} streamed, {} in all ({})",
            self.streaming_cycles,
            self.cycles,
            self.timing.overruns_text()
        )?;
        for (i, a) in self.axes.iter().enumerate() {
            writeln!(
                f,
                "axis {a}            max following error {:.4} {}, end {} counts (setpoint {})",
                self.max_ferr_mm[i],
                self.units.get(i).copied().unwrap_or("mm"),
                self.final_counts[i],
                self.target_counts[i]
            )?;
        }
        for w in &self.warnings {
            writeln!(f, "warning           {w}")?;
        }
        for c in late_wake_causes(&self.warnings, &self.timing.late_wakes) {
            writeln!(f, "cause             {c}")?;
        }
        write!(f, "{}", self.bus)?;
        if self.log_dropped > 0 {
            writeln!(
                f,
                "warning           {} log rows dropped (the log writer fell behind)",
                self.log_dropped
            )?;
        }
        write!(
            f,
            "cyclic thread     {}, latest wake-up {} µs late",
            self.rt,
            self.timing.max_wake_late.as_micros()
        )
    }
}

/// Options of a run.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// Program file name (for messages).
    pub program_name: String,
    /// Program text.
    pub program_text: String,
    /// CSV log.
    pub log: Option<PathBuf>,
    /// Start simulated drives in-process (with the in-process bus).
    pub simulate: bool,
    /// The run's feed override and hold: the operator's side (the `--control` socket, the
    /// standard input keys) holds a clone; the run resets it when it starts.
    pub control: Arc<control::Control>,
    /// The run's live figures, for whoever displays them.
    pub progress: Arc<progress::Progress>,
}

impl Default for RunOptions {
    /// No program, no log, no simulated drives; fresh control and progress handles.
    fn default() -> RunOptions {
        RunOptions {
            program_name: String::new(),
            program_text: String::new(),
            log: None,
            simulate: false,
            control: Arc::new(control::Control::new()),
            progress: Arc::new(progress::Progress::new()),
        }
    }
}

/// The planner's limits from the machine's axes (axes the machine lacks get none: moving them is
/// an error before planning).
pub fn limits(machine: &Machine) -> Limits {
    let mut v = Vector3::repeat(1.0);
    let mut a = Vector3::repeat(1.0);
    let mut feed: f64 = 0.0;
    for ax in &machine.axes {
        if let Some(i) = ax.xyz() {
            v[i] = ax.max_vel_mm_s;
            a[i] = ax.max_acc_mm_s2;
            feed = feed.max(ax.max_vel_mm_s);
        }
    }
    Limits {
        max_vel_mm_s: v,
        max_acc_mm_s2: a,
        max_feed_mm_s: feed,
    }
}

/// Parse and plan a program from `start_mm`, checking every move against the machine's axes and
/// travel. Nothing moves before this has succeeded for the whole program.
pub fn plan_program(
    machine: &Machine,
    name: &str,
    text: &str,
    start_mm: Vector3<f64>,
) -> Result<Plan, GatewayError> {
    plan_program_at(machine, name, text, start_mm, [0.0; 6])
}

/// [`plan_program`] with the auxiliary axes (A B C U V W) at `start_aux`.
pub fn plan_program_at(
    machine: &Machine,
    name: &str,
    text: &str,
    start_mm: Vector3<f64>,
    start_aux: AuxPos,
) -> Result<Plan, GatewayError> {
    use crate::gcode::{Error as GcodeError, ErrorKind as GcodeErrorKind, Item};
    let program = interpret_program_at(machine, name, text, start_mm, start_aux)?;
    for item in &program.items {
        match item {
            Item::Motion(e) => check_element(machine, name, e)?,
            // The cyclic loop cannot wait for an operator yet: refuse rather than run through
            // a stop the programmer asked for.
            Item::Stop(stop) => {
                return Err(GatewayError::Program(GcodeError {
                    file: name.to_string(),
                    line: stop.line,
                    col: stop.col,
                    kind: GcodeErrorKind::Unsupported {
                        what: if stop.optional { "M1" } else { "M0" }.to_string(),
                        reason: "the gateway cannot pause a running program yet",
                    },
                    called_from: None,
                }));
            }
            _ => {}
        }
    }
    crate::planner::plan_with(&program, &limits(machine), &machine.planner).map_err(|source| {
        GatewayError::Plan {
            file: name.to_string(),
            source,
        }
    })
}

/// Interprets a whole program on `machine` from `start_mm` (its tool table, work offsets, G28/G30
/// positions) and applies cutter radius compensation: the tool-centre path the planner takes.
pub fn interpret_program(
    machine: &Machine,
    name: &str,
    text: &str,
    start_mm: Vector3<f64>,
) -> Result<crate::gcode::Program, GatewayError> {
    interpret_program_at(machine, name, text, start_mm, [0.0; 6])
}

/// [`interpret_program`] with the auxiliary axes (A B C U V W) at `start_aux`.
pub fn interpret_program_at(
    machine: &Machine,
    name: &str,
    text: &str,
    start_mm: Vector3<f64>,
    start_aux: AuxPos,
) -> Result<crate::gcode::Program, GatewayError> {
    let mut setup = machine.setup(start_mm);
    setup.start_aux = start_aux;
    let program = crate::gcode::parse_program_with(text, name, setup)?;
    Ok(crate::compensation::compensate_program(
        &program,
        machine.program.compensation,
    )?)
}

/// The auxiliary axes' positions (A B C U V W, 0 for those the machine lacks) from the drives'
/// counts, in machine order.
pub fn aux_of_counts(machine: &Machine, counts: &[i32]) -> AuxPos {
    let mut aux = [0.0; 6];
    for (a, c) in machine.axes.iter().zip(counts) {
        if let Some(k) = a.aux() {
            aux[k] = a.counts_to_mm(*c);
        }
    }
    aux
}

/// Checks one element of the tool-centre path against the machine: every axis it moves exists
/// and stays within its travel (an arc over its whole extent, not only its end points).
pub fn check_element(
    machine: &Machine,
    name: &str,
    element: &crate::gcode::Element,
) -> Result<(), GatewayError> {
    // A line is checked at its end (its start was checked as the previous end); an arc can
    // leave the box of its end points, so its whole extent is checked.
    let (lo_mm, hi_mm) = match element.kind {
        crate::gcode::ElementKind::Line => (element.end_mm, element.end_mm),
        crate::gcode::ElementKind::Arc { .. } => element.bounds_mm(),
    };
    for (i, letter) in ['X', 'Y', 'Z'].into_iter().enumerate() {
        let axis = machine.axes.iter().find(|a| a.name.starts_with(letter));
        let moves = element.end_mm[i] != element.start_mm[i] || hi_mm[i] > lo_mm[i];
        match axis {
            None if moves => {
                return Err(GatewayError::NoSuchAxis {
                    file: name.to_string(),
                    line: element.line,
                    axis: letter,
                    machine: machine.name.clone(),
                });
            }
            Some(a)
                if !(a.min_mm..=a.max_mm).contains(&lo_mm[i])
                    || !(a.min_mm..=a.max_mm).contains(&hi_mm[i]) =>
            {
                let target_mm = if lo_mm[i] < a.min_mm || lo_mm[i].is_nan() {
                    lo_mm[i]
                } else {
                    hi_mm[i]
                };
                return Err(GatewayError::OutOfTravel {
                    file: name.to_string(),
                    line: element.line,
                    axis: a.name.clone(),
                    target_mm,
                    min_mm: a.min_mm,
                    max_mm: a.max_mm,
                });
            }
            _ => {}
        }
    }
    // The auxiliary axes move linearly over an element: its ends are their extremes. A
    // wrapped rotary axis has no travel limits.
    if element.aux.moves() {
        for (i, letter) in crate::gcode::AUX_LETTERS.into_iter().enumerate() {
            if element.aux.start[i] == element.aux.end[i] {
                continue;
            }
            let target_mm = element.aux.end[i];
            match machine.axes.iter().find(|a| a.aux() == Some(i)) {
                None => {
                    return Err(GatewayError::NoSuchAxis {
                        file: name.to_string(),
                        line: element.line,
                        axis: letter,
                        machine: machine.name.clone(),
                    });
                }
                Some(a) if a.has_travel() && !(a.min_mm..=a.max_mm).contains(&target_mm) => {
                    return Err(GatewayError::OutOfTravel {
                        file: name.to_string(),
                        line: element.line,
                        axis: a.name.clone(),
                        target_mm,
                        min_mm: a.min_mm,
                        max_mm: a.max_mm,
                    });
                }
                _ => {}
            }
        }
    }
    Ok(())
}

/// CSV header: `cycle,t_s`, then `<axis>_cmd_mm` for each axis, then `_act_mm`, then `_ferr_mm`.
pub fn csv_header(axes: &[String]) -> String {
    let mut h = String::from("cycle,t_s");
    for suffix in ["cmd_mm", "act_mm", "ferr_mm"] {
        for a in axes {
            h.push_str(&format!(",{a}_{suffix}"));
        }
    }
    h
}

fn csv_row(r: &CycleRecord, n: usize, period_s: f64) -> String {
    let mut s = format!("{},{:.6}", r.cycle, r.cycle as f64 * period_s);
    for v in [&r.cmd_mm, &r.act_mm, &r.ferr_mm] {
        for x in v.iter().take(n) {
            s.push_str(&format!(",{x:.6}"));
        }
    }
    s
}

/// Where a run's motion comes from: checked once the drives are configured (before any is
/// enabled), then planned from the position at which the drives were armed. A program run from
/// its start is [`run`]'s; [`resume`] continues an interrupted one.
pub trait MotionSource {
    /// During start-up, before anything is written to a drive, every axis inside its travel:
    /// `start_mm` is position actual (X, Y, Z),
    /// `start_counts` per axis in machine order. An error ends the run with every drive sent to
    /// Pre-operational, nothing enabled.
    fn check(
        &mut self,
        machine: &Machine,
        start_mm: Vector3<f64>,
        start_counts: &[i32],
    ) -> Result<(), GatewayError>;
    /// The motion from `armed_mm`, where the drives were enabled and armed (position actual),
    /// the auxiliary axes at `armed_aux`.
    fn plan(
        &mut self,
        machine: &Machine,
        armed_mm: Vector3<f64>,
        armed_aux: AuxPos,
    ) -> Result<Plan, GatewayError>;
    /// The last program line completed before this motion starts (a resumed program's).
    fn completed_line(&self) -> Option<usize> {
        None
    }
}

/// The program of [`RunOptions`], from its start.
struct FromStart<'a>(&'a RunOptions);

impl MotionSource for FromStart<'_> {
    fn check(
        &mut self,
        machine: &Machine,
        start_mm: Vector3<f64>,
        start_counts: &[i32],
    ) -> Result<(), GatewayError> {
        plan_program_at(
            machine,
            &self.0.program_name,
            &self.0.program_text,
            start_mm,
            aux_of_counts(machine, start_counts),
        )
        .map(|_| ())
    }
    fn plan(
        &mut self,
        machine: &Machine,
        armed_mm: Vector3<f64>,
        armed_aux: AuxPos,
    ) -> Result<Plan, GatewayError> {
        plan_program_at(
            machine,
            &self.0.program_name,
            &self.0.program_text,
            armed_mm,
            armed_aux,
        )
    }
}

/// Run a program on a machine over `bus`: start-up, streaming, orderly stop. Returns the summary
/// when the whole program ran with every drive healthy.
pub fn run(machine: &Machine, bus: &Bus, opts: &RunOptions) -> Result<Summary, GatewayError> {
    run_with(machine, bus, opts, &mut FromStart(opts))
}

/// [`run`] with the motion from `source` (the program of `opts` is still parsed first).
pub fn run_with(
    machine: &Machine,
    bus: &Bus,
    opts: &RunOptions,
    source: &mut dyn MotionSource,
) -> Result<Summary, GatewayError> {
    // The whole program must parse and stay in travel before anything happens on the bus. The
    // start position is not known yet: interpret it from the origin (the machine's tools and
    // offsets, compensation) for its errors, and plan again from the armed position below.
    interpret_program(
        machine,
        &opts.program_name,
        &opts.program_text,
        Vector3::zeros(),
    )?;
    rt::signal::STOP.begin_run();

    let _sims = if opts.simulate {
        Some(spawn_sims(machine, bus, &[])?)
    } else {
        None
    };

    runtime().block_on(run_async(machine, bus, opts, source))
}

/// What the cyclic thread receives: every axis's feedback TPDO, its node's heartbeat (a boot-up
/// freezes its axis in the cycle that reads it) and its EMCYs.
pub(crate) fn cyclic_filters(machine: &Machine) -> Vec<Filter> {
    machine
        .axes
        .iter()
        .flat_map(|a| {
            let node = u16::from(a.node);
            [
                Filter::exact(a.feedback_pdo.cob_id),
                Filter::exact(crate::canopen::cob::HEARTBEAT + node),
                Filter::exact(crate::canopen::cob::EMCY + node),
            ]
        })
        .collect()
}

/// A tokio runtime for a gateway's non-cyclic side.
pub(crate) fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("tokio runtime")
}

/// The machine's simulated drives on `bus`, each with the injected misbehaviours aimed at it.
pub(crate) fn spawn_sims(
    machine: &Machine,
    bus: &Bus,
    injects: &[crate::sim::Targeted],
) -> Result<crate::sim::runner::SimHandle, GatewayError> {
    let drives = machine
        .axes
        .iter()
        .map(|a| {
            injects
                .iter()
                .filter(|t| t.node.is_none_or(|n| n == a.node))
                .fold(crate::sim::SimDrive::for_axis(a), |d, t| {
                    d.with_inject(t.inject)
                })
        })
        .collect();
    Ok(crate::sim::runner::spawn(bus, drives)?)
}

async fn run_async(
    machine: &Machine,
    bus: &Bus,
    opts: &RunOptions,
    source: &mut dyn MotionSource,
) -> Result<Summary, GatewayError> {
    // The feed override's ramp (none when the planner keeps no acceleration for it).
    let ramp = OverrideRamp::for_machine(&limits(machine), &machine.planner);
    opts.control.reset(ramp.is_ok());
    let nodes: Vec<u8> = machine.axes.iter().map(|a| a.node).collect();
    let mut io = NodeIo::start(bus, &nodes)?;
    // Check the program against the travel from where the machine is, before anything is
    // written to a drive. A refusal leaves the drives as it found them: disabled, and
    // Pre-operational. With every axis inside its travel (which start-up checks first), the
    // element checks cover the whole path: a line from a point inside to a point inside stays
    // inside, and an arc is checked over its extent. A stop signal during start-up (SDO
    // configuration, nothing enabled) ends it there.
    let started = tokio::select! {
        r = startup::start(machine, bus, &mut io, |counts| {
            let mut start_mm = Vector3::zeros();
            for (a, c) in machine.axes.iter().zip(counts) {
                if let Some(i) = a.xyz() {
                    start_mm[i] = a.counts_to_mm(*c);
                }
            }
            source.check(machine, start_mm, counts)
        }) => Ok(r),
        s = stop_signal() => Err(s),
    };
    match started {
        Ok(r) => {
            r?;
        }
        Err(signal) => return Err(pre_operational(machine, &io, signal).await),
    }
    // A signal during the check (a resume's confirmation): nothing is enabled yet.
    if let Some(signal) = rt::signal::STOP.first() {
        return Err(pre_operational(machine, &io, signal).await);
    }

    let (log_tx, log_thread) = match &opts.log {
        Some(path) => {
            let (tx, thread) = spawn_logger(path, machine)?;
            (Some(tx), Some(thread))
        }
        None => (None, None),
    };

    // The cyclic thread, with the supervision: what start-up saw of the nodes' heartbeats and
    // EMCYs is its starting point (the last lock of the health view the run takes).
    let sup = supervision_from(machine, &io.health());
    let (control, progress) = (opts.control.clone(), opts.progress.clone());
    let (plan_tx, plan_rx) = mpsc::channel::<Interpolator>();
    let (armed_tx, armed_rx) = tokio::sync::oneshot::channel::<(Vector3<f64>, AuxPos)>();
    let m = machine.clone();
    // The TPDOs, the nodes' heartbeats (a boot-up freezes its axis in the cycle that reads it)
    // and their EMCYs: the cyclic thread supervises the nodes itself.
    let mut port = bus.open(&cyclic_filters(machine))?;
    let completed = source.completed_line();
    let cyc_bus = cyclic_bus::CyclicBus::new(
        machine,
        bus.name(),
        port.as_mut(),
        bus.sync_tap(machine.sync_cob_id)?,
    )?;
    let cyc = std::thread::Builder::new()
        .name("canmotion-cyclic".into())
        .spawn(move || {
            cyclic_thread(
                &m,
                port.as_mut(),
                cyc_bus,
                sup,
                CyclicLinks {
                    plan_rx,
                    armed_tx,
                    log_tx,
                    control,
                    progress,
                },
                completed,
            )
        })
        .expect("spawn cyclic thread");

    // Plan from the armed position, on this side, and hand the motion to the cyclic thread.
    let plan_result = match armed_rx.await {
        Ok((armed_mm, armed_aux)) => {
            let r = source.plan(machine, armed_mm, armed_aux).and_then(|plan| {
                Interpolator::new(plan, machine.cycle_s())
                    .map(|i| match ramp {
                        Ok(r) => i.with_override_ramp(r),
                        Err(_) => i,
                    })
                    .map_err(|e| {
                        GatewayError::Motion(MotionFailure::plain(
                            Alarm::from(e),
                            machine.cycle_s(),
                        ))
                    })
            });
            match r {
                Ok(interp) => {
                    let _ = plan_tx.send(interp);
                    Ok(())
                }
                Err(e) => Err(e),
            }
        }
        Err(_) => Ok(()), // the cyclic thread ended before arming: its result says why
    };
    drop(plan_tx);
    let CyclicEnd {
        master,
        timing,
        rt_setup,
        port_err,
        dropped,
        warnings,
        bit12_to_failure_s,
        detected_ns,
        bus: bus_report,
    } = tokio::task::spawn_blocking(move || cyc.join().expect("cyclic thread panicked"))
        .await
        .expect("join");
    if let Some(t) = log_thread {
        t.join()
            .expect("log thread")
            .map_err(|source| GatewayError::Log {
                file: opts.log.clone().unwrap_or_default(),
                source,
            })?;
    }
    // The orderly end: the drives are disabled and Pre-operational (the cyclic thread's end);
    // before the gateway's heartbeat stops, they stop consuming it. After a fault stop they
    // keep consuming it: should the gateway die now, each drive still stops by itself.
    let disarmed = if master.fault_stop() || port_err.is_some() {
        Ok(())
    } else {
        startup::stop_consuming_heartbeat(machine, bus, &mut io).await
    };
    io.stop_heartbeat();
    plan_result?;
    // A failure of the motion first: when the bus failed during it, the failure says so, with
    // what the motion did about it.
    if let Some(f) = master.failure() {
        if let Err(e) = &disarmed {
            tracing::warn!("{e}");
        }
        return Err(GatewayError::Motion(Box::new(MotionFailure {
            failure: f.clone(),
            detected_cycle: master.failure_cycle,
            bit12_cycle: master.bit12_cycle,
            first_motion_cycle: master.first_motion_cycle,
            period_s: master.period_s(),
            bit12_to_failure_s,
            detected_ns,
            stop: StopPoint::of(&master),
            timing: timing.clone(),
            bus: bus_report.clone(),
        })));
    }
    if let Some(e) = port_err {
        // Every port error raised an alarm, so a failure returned above; should one not have,
        // the error is still the run's.
        return Err(match Arc::try_unwrap(e.0) {
            Ok(e) => GatewayError::Bus(e),
            Err(e) => GatewayError::Motion(MotionFailure::plain(
                Alarm::Bus {
                    error: SharedBusError(e),
                },
                master.period_s(),
            )),
        });
    }
    disarmed?;
    let final_counts = master.final_counts();
    Ok(Summary {
        program_s: master.motion().map_or(0.0, |m| m.duration_s()),
        streaming_cycles: master.streaming_cycles,
        cycles: timing.cycles,
        axes: machine.axes.iter().map(|a| a.name.clone()).collect(),
        units: machine
            .axes
            .iter()
            .map(|a| match a.kind {
                crate::config::AxisKind::Rotary => "deg",
                crate::config::AxisKind::Linear => "mm",
            })
            .collect(),
        max_ferr_mm: master.max_ferr_mm.clone(),
        final_counts,
        target_counts: master.setpoint_counts(),
        bit12_cycle: master.bit12_cycle,
        first_motion_cycle: master.first_motion_cycle,
        timing,
        rt: rt_setup,
        log_dropped: dropped,
        warnings,
        bus: bus_report,
    })
}

/// The first stop signal, once one has arrived (polled: the count is an atomic of the signal
/// thread's, see [`rt::signal`]).
async fn stop_signal() -> rt::signal::Signal {
    loop {
        if let Some(s) = rt::signal::STOP.first() {
            return s;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// Every drive to Pre-operational after a stop signal before any motion; the run's error.
async fn pre_operational(
    machine: &Machine,
    io: &NodeIo,
    signal: rt::signal::Signal,
) -> GatewayError {
    for a in &machine.axes {
        let _ = io.nmt(crate::canopen::nmt::PRE_OPERATIONAL, a.node).await;
    }
    GatewayError::Stopped { signal }
}

/// The channels between the cyclic thread and the async side.
struct CyclicLinks {
    /// The motion, once planned from the armed position.
    plan_rx: mpsc::Receiver<Interpolator>,
    /// The armed position (every drive following, setpoints = actual positions).
    armed_tx: tokio::sync::oneshot::Sender<(Vector3<f64>, AuxPos)>,
    /// One record per cycle for `--log`.
    log_tx: Option<mpsc::SyncSender<CycleRecord>>,
    /// The operator's override and hold.
    control: Arc<control::Control>,
    /// Where the live figures go.
    progress: Arc<progress::Progress>,
}

/// What the cyclic thread hands back when it ends.
struct CyclicEnd {
    master: CyclicMaster,
    timing: Timing,
    /// The real-time set-up achieved (scheduling class, memory lock).
    rt_setup: String,
    port_err: Option<SharedBusError>,
    /// Log records dropped because the log writer fell behind.
    dropped: u64,
    warnings: Vec<Warning>,
    bit12_to_failure_s: Option<f64>,
    /// When the cycle that detected the failure ran ([`rt::now_ns`]).
    detected_ns: Option<u64>,
    bus: cyclic_bus::BusReport,
}

fn cyclic_thread(
    machine: &Machine,
    port: &mut dyn crate::bus::Port,
    mut bus: cyclic_bus::CyclicBus,
    mut sup: Supervision,
    links: CyclicLinks,
    completed_line: Option<usize>,
) -> CyclicEnd {
    let CyclicLinks {
        plan_rx,
        armed_tx,
        log_tx,
        control,
        progress,
    } = links;
    let rt_setup = rt::make_realtime(rt::priority_from_env()).to_string();
    let mut master = CyclicMaster::new(machine);
    master.set_completed_line(completed_line);
    let mut ticker = Ticker::new(Duration::from_micros(u64::from(machine.cycle_us)));
    let mut out: Vec<Frame> = Vec::with_capacity(machine.axes.len() + 1);
    let mut armed_tx = Some(armed_tx);
    let mut dropped = 0u64;
    let mut port_err = None;
    let (mut bit12_ns, mut fail_ns): (Option<u64>, Option<u64>) = (None, None);
    // For the progress display: the path speed of the setpoints (the largest following error is
    // the master's own figure).
    let on_path: Vec<bool> = machine.axes.iter().map(|a| a.xyz().is_some()).collect();
    let mut prev_cmd_mm: Option<[f64; crate::config::machine::MAX_AXES]> = None;
    let mut control_seen = 0u64;
    let mut signals_seen = 0u32;
    loop {
        ticker.wait();
        // Override and hold from the operator: atomics only, applied from this cycle's sample.
        if let Some((fraction, hold)) = control.poll(&mut control_seen) {
            master.set_override(fraction, hold);
        }
        // Stop signals: one atomic load per cycle; the first stops on the path, the second
        // escalates to the fault stop.
        let signals = rt::signal::STOP.count();
        if signals != signals_seen {
            let first = rt::signal::STOP.first();
            if signals_seen == 0 {
                master.stop_on_path(Alarm::Signal { signal: first });
            }
            if signals >= 2 {
                let latest = rt::signal::STOP.latest();
                master.alarm(0, Alarm::SignalEscalated { first, latest });
            }
            signals_seen = signals;
        }
        // Feedback, heartbeats, EMCYs and error frames received since the last cycle, stamped
        // with this cycle's time.
        let now = Duration::from_nanos(rt::now_ns());
        if let Err(e) = bus.receive(port, &mut master, &mut sup, now, ticker.timing.cycles) {
            port_err.get_or_insert(SharedBusError(Arc::new(e)));
        }
        if let Some(e) = &port_err {
            // Cloning the shared error allocates nothing.
            master.alarm(0, Alarm::Bus { error: e.clone() });
        }
        // Heartbeat consumer and EMCYs: faults raised on the master, warnings counted.
        sup.poll(now, &mut master);
        if master.phase() == Phase::Armed
            && let Some(tx) = armed_tx.take()
        {
            let _ = tx.send((master.armed_mm().expect("armed"), master.armed_aux()));
        }
        if master.phase() == Phase::Armed {
            match plan_rx.try_recv() {
                Ok(m) => master.supply_motion(m),
                Err(mpsc::TryRecvError::Empty) => {}
                // Planning failed on the other side (its error is reported there): disable.
                Err(mpsc::TryRecvError::Disconnected) => master.alarm(0, Alarm::PlanningFailed),
            }
        }
        out.clear();
        let rec = master.cycle(machine.sync_cob_id, &mut out);
        let mut feed2 = 0.0;
        if let Some(prev) = &prev_cmd_mm {
            for (i, _) in on_path.iter().enumerate().filter(|(_, p)| **p) {
                feed2 += (rec.cmd_mm[i] - prev[i]).powi(2);
            }
        }
        let max_ferr_mm = master.max_ferr_mm.iter().fold(0.0f64, |m, f| m.max(*f));
        prev_cmd_mm = Some(rec.cmd_mm);
        progress.store(
            rec.cycle,
            rec.line,
            feed2.sqrt() / master.period_s(),
            max_ferr_mm,
        );
        if let Some(m) = master.motion() {
            progress.store_override(
                m.effective_override(),
                m.requested_override(),
                m.is_held(),
                m.is_standing_still(),
            );
        }
        // Wall-clock instants of arming and of a failure: cycle counts do not see the periods
        // an overrun skipped.
        if master.bit12_cycle.is_some() && bit12_ns.is_none() {
            bit12_ns = Some(rt::now_ns());
        }
        if master.failure_cycle.is_some() && fail_ns.is_none() {
            fail_ns = Some(rt::now_ns());
        }
        let deadline = ticker.this_deadline_ns();
        if let Some(e) = bus.send(port, &out, deadline, &mut master, ticker.timing.cycles) {
            port_err.get_or_insert(e);
        }
        bus.measure();
        if let Some(tx) = &log_tx
            && tx.try_send(rec).is_err()
        {
            dropped += 1;
        }
        if master.phase() == Phase::Done {
            break;
        }
    }
    // Orderly end: Pre-operational right after the last SYNC, so no drive waits for a SYNC that
    // will not come (unless the bus is gone).
    for a in machine.axes.iter().filter(|_| !bus.lost()) {
        let f = Frame::new(
            crate::canopen::cob::NMT,
            &[crate::canopen::nmt::PRE_OPERATIONAL, a.node],
        )
        .expect("NMT");
        if let Err(e) = port.send(&f) {
            port_err.get_or_insert(SharedBusError(Arc::new(e)));
        }
    }
    drop(armed_tx);
    let bit12_to_failure_s = match (bit12_ns, fail_ns) {
        (Some(a), Some(b)) => Some((b as f64 - a as f64) * 1e-9),
        _ => None,
    };
    CyclicEnd {
        master,
        timing: ticker.timing,
        rt_setup,
        port_err,
        dropped,
        warnings: sup.into_warnings(),
        bit12_to_failure_s,
        detected_ns: fail_ns,
        bus: bus.report(),
    }
}

/// The run's supervision, from what start-up saw of the nodes: their last heartbeats (on the
/// cyclic thread's clock, CLOCK_MONOTONIC) and their EMCYs, which the first cycles decide by the
/// statusword like any other.
pub(crate) fn supervision_from(machine: &Machine, health: &io::Health) -> Supervision {
    let mut sup = Supervision::new(machine);
    let now_ns = rt::now_ns();
    let g = health.lock().unwrap_or_else(|e| e.into_inner());
    for a in &machine.axes {
        let Some(h) = g.get(&a.node) else { continue };
        if let Some((_, at)) = h.last_heartbeat {
            let ago = at.elapsed().as_nanos() as u64;
            sup.seed_heartbeat(a.node, Duration::from_nanos(now_ns.saturating_sub(ago)));
        }
        for e in &h.emcys {
            sup.seed_emcy(a.node, e.code);
        }
    }
    sup
}

type LogThread = std::thread::JoinHandle<std::io::Result<()>>;

pub(crate) fn spawn_logger(
    path: &Path,
    machine: &Machine,
) -> Result<(mpsc::SyncSender<CycleRecord>, LogThread), GatewayError> {
    let file = std::fs::File::create(path).map_err(|source| GatewayError::Log {
        file: path.to_path_buf(),
        source,
    })?;
    let axes: Vec<String> = machine.axes.iter().map(|a| a.name.clone()).collect();
    let period = machine.cycle_s();
    let (tx, rx) = mpsc::sync_channel::<CycleRecord>(65_536);
    let t = std::thread::Builder::new()
        .name("canmotion-log".into())
        .spawn(move || {
            let mut w = std::io::BufWriter::new(file);
            writeln!(w, "{}", csv_header(&axes))?;
            for r in rx {
                writeln!(w, "{}", csv_row(&r, axes.len(), period))?;
            }
            w.flush()
        })
        .expect("spawn log thread");
    Ok((tx, t))
}

#[cfg(test)]
mod late_wake_tests {
    use super::*;

    fn warning(node: u8, code: u16, at: &[u64]) -> Warning {
        let mut cycles = [0; WARNING_CYCLES];
        cycles[..at.len()].copy_from_slice(at);
        Warning {
            axis: ["X", "Y", "Z"][usize::from(node) - 1],
            node,
            code,
            count: at.len() as u32,
            first_cycle: at[0],
            last_cycle: *at.last().unwrap(),
            cycles,
        }
    }

    fn wake(cycle: u64, late_us: u64) -> rt::LateWake {
        rt::LateWake {
            cycle,
            late: Duration::from_micros(late_us),
        }
    }

    #[test]
    fn warnings_after_a_late_wake_up_are_tied_to_it() {
        let mut late = rt::LateWakes::default();
        late.push(wake(40, 2500));
        late.push(wake(2523, 6800));
        // Nodes 1-3 warn 1-3 cycles after the late wake-up of cycle 2523; node 1 also in cycle
        // 900, after no late wake-up; node 2's 0x4210 long after cycle 40's (not its cause).
        let warnings = [
            warning(1, 0x8100, &[900, 2524]),
            warning(2, 0x8100, &[2526]),
            warning(3, 0x8100, &[2525]),
            warning(2, 0x4210, &[40 + LATE_WAKE_WINDOW_CYCLES + 1]),
        ];
        let causes = late_wake_causes(&warnings, &late);
        assert_eq!(
            causes,
            [LateWakeCause {
                wake: wake(2523, 6800),
                nodes: vec![1, 2, 3],
                codes: vec![0x8100],
            }]
        );
        assert_eq!(
            causes[0].to_string(),
            "3 drives reported SYNC missing (EMCY 0x8100) in cycle 2523: the cyclic thread woke 6.8 ms late (host not real-time; a PREEMPT_RT kernel or isolcpus helps)"
        );
        // No late wake-up, no cause.
        assert!(late_wake_causes(&warnings, &rt::LateWakes::default()).is_empty());
    }

    #[test]
    fn one_overrun_is_singular() {
        let mut t = Timing::default();
        assert_eq!(t.overruns_text(), "0 overruns");
        t.overruns = 1;
        assert_eq!(t.overruns_text(), "1 overrun");
        t.overruns = 7;
        assert_eq!(t.overruns_text(), "7 overruns");
    }
}
