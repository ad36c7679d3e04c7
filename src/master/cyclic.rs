//! The cyclic master, sans-I/O: once per SYNC period it takes the drives' feedback (TPDOs) and
//! gives the frames of the next cycle (one RPDO per axis, then SYNC).
//!
//! Its phases follow CiA 402 and the IP start sequence of the checklist:
//!
//! 1. **Enabling**: walk every drive to Operation enabled through the controlword in the RPDO,
//!    with the setpoint tracking position actual (bumpless).
//! 2. **Arming**: setpoint held at position actual; IP axes get controlword bit 4 and must
//!    answer with statusword bit 12 before any motion (CSP axes: bit 12 = following).
//! 3. **Armed**: holding, waiting for the motion (an [`Interpolator`] planned from the armed
//!    positions on another thread) to be supplied.
//! 4. **Streaming**: one setpoint per axis per cycle from the interpolator, through the axis's
//!    post-interpolation filter when it has one ([`AxisFilter`]), each checked against the
//!    axis's travel limits and its largest step (max velocity × period). The motion is over
//!    once the interpolator has given its end point and every filter has settled there.
//! 5. **Settling**: holding the final setpoint until every axis is within one count of it.
//! 6. **Disabling**: bit 4 cleared, drives walked to Switch on disabled.
//!
//! Any alarm (drive fault bit, EMCY, lost heartbeat, unexpected boot-up, missing process data)
//! freezes the axis it concerns and stops the others along their current direction within their
//! acceleration limits, then disables; the outcome is a failure naming the axis and the cause.
//! A drive that sent a boot-up message (0x700 + node, data 0x00) has reset: from that cycle on
//! it gets no RPDO at all, so it can never act on a stale setpoint, whatever NMT state it
//! reaches by itself.

use nalgebra::Vector3;

use super::alarm::{Alarm, Failure, LateAxes, LateAxis, axis_letter};
use crate::bus::Frame;
use crate::canopen::index;
use crate::cia402::{Action, Enabler, State, Target, controlword as cwb, statusword as swb};
use crate::config::machine::MAX_AXES;
use crate::config::{AxisConfig, AxisMode, Machine};
use crate::interpolator::filter::AxisFilter;
use crate::interpolator::{Interpolator, Status};

/// How long the drives may take to reach Switch on disabled at the end. (Reaching Operation
/// enabled, and answering bit 4 with bit 12, have each axis's `enable_timeout_ms`.)
const STATE_TIMEOUT_S: f64 = 2.0;
/// How long the final position may take to settle within one count.
const SETTLE_TIMEOUT_S: f64 = 3.0;
/// Feedback older than this many cycles is an alarm (a drive that stops answering SYNC is
/// caught here long before its heartbeat times out).
const STALE_CYCLES: u64 = 50;

/// What the master needs to know of one axis, resolved from the machine file.
#[derive(Debug, Clone)]
pub struct AxisIo {
    /// Axis letter.
    pub name: String,
    /// Node id.
    pub node: u8,
    /// X = 0, Y = 1, Z = 2; `None` for the other axes.
    pub xyz: Option<usize>,
    /// A = 0 … W = 5 ([`crate::gcode::AUX_LETTERS`]): the interpolator's auxiliary axes
    /// ([`Interpolator::aux`]); they hold their position until a motion says where they go.
    pub aux: Option<usize>,
    /// Mode.
    pub mode: AxisMode,
    /// The axis letter, for alarms (a `&'static str`: raising an alarm allocates nothing).
    letter: &'static str,
    rpdo_cob: u16,
    rpdo_len: usize,
    cw_off: usize,
    sp_off: usize,
    /// COB-ID of the feedback TPDO.
    pub tpdo_cob: u16,
    sw_off: usize,
    pos_off: usize,
    counts_per_mm: f64,
    min_mm: f64,
    max_mm: f64,
    /// The travel limits apply (not on a wrapped rotary axis).
    has_travel: bool,
    max_vel_mm_s: f64,
    max_acc_mm_s2: f64,
    /// `enable_timeout_ms`: to reach Operation enabled, and then to set statusword bit 12.
    enable_timeout_ms: u32,
}

impl AxisIo {
    /// Resolve one axis.
    pub fn new(a: &AxisConfig) -> AxisIo {
        let (si, ss) = a.mode.setpoint_object();
        let off = |p: &crate::config::PdoConfig, i, s| {
            p.offset_of(i, s).map(|(o, _)| o).expect("validated")
        };
        AxisIo {
            name: a.name.clone(),
            letter: axis_letter(&a.name),
            node: a.node,
            xyz: a.xyz(),
            aux: a.aux(),
            mode: a.mode,
            rpdo_cob: a.setpoint_pdo.cob_id,
            rpdo_len: a.setpoint_pdo.len_bytes(),
            cw_off: off(&a.setpoint_pdo, index::CONTROLWORD, 0),
            sp_off: off(&a.setpoint_pdo, si, ss),
            tpdo_cob: a.feedback_pdo.cob_id,
            sw_off: off(&a.feedback_pdo, index::STATUSWORD, 0),
            pos_off: off(&a.feedback_pdo, index::POSITION_ACTUAL, 0),
            counts_per_mm: a.counts_per_mm,
            min_mm: a.min_mm,
            max_mm: a.max_mm,
            has_travel: a.has_travel(),
            max_vel_mm_s: a.max_vel_mm_s,
            max_acc_mm_s2: a.max_acc_mm_s2,
            enable_timeout_ms: a.enable_timeout_ms,
        }
    }

    fn enable_timeout_s(&self) -> f64 {
        f64::from(self.enable_timeout_ms) / 1000.0
    }

    fn to_counts(&self, mm: f64) -> i32 {
        (mm * self.counts_per_mm)
            .round()
            .clamp(i32::MIN as f64, i32::MAX as f64) as i32
    }

    fn to_mm(&self, counts: i32) -> f64 {
        f64::from(counts) / self.counts_per_mm
    }

    fn rpdo(&self, cw: u16, setpoint: i32) -> Frame {
        let mut d = [0u8; 8];
        d[self.cw_off..self.cw_off + 2].copy_from_slice(&cw.to_le_bytes());
        d[self.sp_off..self.sp_off + 4].copy_from_slice(&setpoint.to_le_bytes());
        Frame::new(self.rpdo_cob, &d[..self.rpdo_len]).expect("validated PDO")
    }
}

/// The phases of a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// Walking the drives to Operation enabled.
    Enabling,
    /// Waiting for statusword bit 12.
    Arming,
    /// Holding, waiting for the motion.
    Armed,
    /// Streaming setpoints.
    Streaming,
    /// Holding the end point until the axes settle.
    Settling,
    /// Controlled stop after an alarm.
    Stopping,
    /// Walking the drives to Switch on disabled.
    Disabling,
    /// Finished (see [`CyclicMaster::failure`]).
    Done,
    /// A service master ([`CyclicMaster::service`]) with its drives disabled: SYNC and the
    /// RPDOs go on (the drives stay Operational), each setpoint tracks position actual, and the
    /// drives are held in Switch on disabled. A fault stop ends here rather than in
    /// [`Phase::Done`], with its failure kept until [`CyclicMaster::reset_alarm`].
    Disabled,
    /// A service master with some axes under the drive's own control (homing, CiA 402 mode 6;
    /// see [`AxisControl`]); the other axes hold.
    DriveControl,
}

/// Who commands an axis of a service master.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AxisControl {
    /// The master: one setpoint per cycle (IP or CSP, statusword bit 12 set).
    Cyclic,
    /// Handed over to the drive: controlword bit 4 cleared, the setpoint tracks position
    /// actual, so that the drive can change its mode of operation (0x6060) without a jump.
    Released,
    /// The drive's own operation runs (homing: controlword bit 4 = homing operation start);
    /// statusword bits 10, 12 and 13 are that mode's ([`DriveOpStatus`]), not alarms.
    DriveOp,
    /// Back to the cyclic mode: setpoint = position actual and controlword bit 4 set, waiting
    /// for statusword bit 12 (IP active / following) before the axis is [`AxisControl::Cyclic`].
    Rearming,
}

/// Where a drive's own operation ([`AxisControl::DriveOp`]: homing) stands, from statusword
/// bits 10, 12 and 13 (CiA 402-2, homing mode).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DriveOpStatus {
    /// No statusword yet that answers the start.
    InProgress,
    /// Bits 12 (homing attained) and 10 (target reached).
    Attained,
    /// Bit 13 (homing error), with the statusword.
    Error {
        /// 0x6041.
        statusword: u16,
    },
}

/// Why a service master refused a request.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum Refusal {
    /// The request needs another phase (e.g. `enable` while enabled).
    #[error("not possible while {phase:?}")]
    Phase {
        /// The phase the master is in.
        phase: Phase,
    },
    /// An alarm stands: it must be reset first.
    #[error("an alarm stands; reset it first")]
    Alarm,
    /// A drive reset or the bus was lost: the drives must be started up again.
    #[error("a drive reset or the bus was lost; the drives must be started up again")]
    NeedsStartUp,
    /// The motion does not start where the axes are.
    #[error("the motion starts {distance_mm:.6} mm away from where the axes stand")]
    StartMismatch {
        /// The distance between the two.
        distance_mm: f64,
    },
}

/// The latest feedback of one axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Feedback {
    /// 0x6041.
    pub statusword: u16,
    /// 0x6064.
    pub position: i32,
    /// Cycle it arrived in.
    pub cycle: u64,
}

/// One cycle's numbers, for the log.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CycleRecord {
    /// Cycle number.
    pub cycle: u64,
    /// Phase during the cycle.
    pub phase: Phase,
    /// Program line in execution (while streaming).
    pub line: Option<usize>,
    /// Setpoint sent, per axis in machine order (mm); up to 3 axes.
    pub cmd_mm: [f64; MAX_AXES],
    /// Position actual, per axis (mm).
    pub act_mm: [f64; MAX_AXES],
    /// Following error, per axis (mm): setpoint in force at the drive minus position actual.
    pub ferr_mm: [f64; MAX_AXES],
}

/// The cyclic master.
#[derive(Debug)]
pub struct CyclicMaster {
    axes: Vec<AxisIo>,
    enablers: Vec<Enabler>,
    fb: Vec<Option<Feedback>>,
    /// Setpoint history per axis (mm): [this cycle, 1 ago, 2 ago].
    sp_mm: Vec<[f64; 3]>,
    motion: Option<Interpolator>,
    /// Per axis, its post-interpolation filter (allocated here, reset when streaming starts).
    filters: Vec<Option<AxisFilter>>,
    phase: Phase,
    phase_since: u64,
    cycle: u64,
    period_s: f64,
    line: Option<usize>,
    armed_mm: Option<Vector3<f64>>,
    /// The auxiliary axes' setpoints when armed (0 for the axes the machine lacks).
    armed_aux: crate::gcode::AuxPos,
    stop_vel: Vec<f64>,
    stop_acc: Vec<f64>,
    frozen: Vec<bool>,
    /// Axes whose drive reset (boot-up seen): no RPDO goes to them any more.
    reset: Vec<bool>,
    /// The last program line whose motion was completed.
    completed_line: Option<usize>,
    failure: Option<Failure>,
    /// The cycle in which the failure was detected.
    pub failure_cycle: Option<u64>,
    /// First cycle in which every IP axis reported statusword bit 12.
    pub bit12_cycle: Option<u64>,
    /// First cycle whose setpoint differed from the armed position.
    pub first_motion_cycle: Option<u64>,
    /// Largest |following error| per axis while streaming and settling (mm).
    pub max_ferr_mm: Vec<f64>,
    /// The latest following error computed from a fresh TPDO, per axis.
    last_ferr_mm: Vec<f64>,
    /// Cycles spent streaming.
    pub streaming_cycles: u64,
    /// The feed override and hold the operator wants (given to the motion once supplied).
    override_wanted: (f64, bool),
    /// A stop on the path was asked for ([`Self::stop_on_path`]): why, once the hold is done.
    stop_asked: Option<Alarm>,
    /// The run ended in a fault stop (see [`Self::fault_stop`]).
    fault_stop: bool,
    /// A service master: it stays up between motions (see [`Self::service`]).
    service: bool,
    /// Per axis, who commands it (always [`AxisControl::Cyclic`] outside a service master).
    control: Vec<AxisControl>,
    /// Per axis, the cycle its control last changed.
    control_since: Vec<u64>,
    /// Per axis, whether its setpoints are checked against its travel (off for an axis that
    /// is not homed: its travel limits mean nothing yet).
    check_travel: Vec<bool>,
    /// An abort (service master): hold, then drop the motion and hold position, enabled.
    aborting: bool,
}

impl CyclicMaster {
    /// A master for the machine's axes, starting in [`Phase::Enabling`].
    pub fn new(machine: &Machine) -> CyclicMaster {
        let axes: Vec<AxisIo> = machine.axes.iter().map(AxisIo::new).collect();
        let n = axes.len();
        CyclicMaster {
            enablers: vec![Enabler::new(Target::OperationEnabled); n],
            fb: vec![None; n],
            sp_mm: vec![[0.0; 3]; n],
            motion: None,
            filters: machine
                .axes
                .iter()
                .map(|a| {
                    a.filter.map(|spec| {
                        AxisFilter::new(spec, machine.cycle_s())
                            .expect("validated with the machine file")
                    })
                })
                .collect(),
            phase: Phase::Enabling,
            phase_since: 0,
            cycle: 0,
            period_s: machine.cycle_s(),
            line: None,
            armed_mm: None,
            armed_aux: [0.0; 6],
            stop_vel: vec![0.0; n],
            stop_acc: vec![0.0; n],
            frozen: vec![false; n],
            reset: vec![false; n],
            completed_line: None,
            failure: None,
            failure_cycle: None,
            bit12_cycle: None,
            first_motion_cycle: None,
            max_ferr_mm: vec![0.0; n],
            last_ferr_mm: vec![0.0; n],
            streaming_cycles: 0,
            override_wanted: (1.0, false),
            stop_asked: None,
            fault_stop: false,
            service: false,
            control: vec![AxisControl::Cyclic; n],
            control_since: vec![0; n],
            // A wrapped rotary axis has no travel limits: it keeps counting turns.
            check_travel: machine.axes.iter().map(|a| a.has_travel()).collect(),
            aborting: false,
            axes,
        }
    }

    /// A master that stays up (`canmotion serve`): it starts in [`Phase::Disabled`]
    /// ([`Self::enable`] walks the drives to Operation enabled); a motion that ends, or an
    /// [`Self::abort`], leaves the drives enabled and holding in [`Phase::Armed`] for the next
    /// one; [`Self::disable`] goes back to [`Phase::Disabled`]; a fault stop ends in
    /// [`Phase::Disabled`] with its failure, until [`Self::reset_alarm`]. Homing runs through
    /// [`Self::release`], [`Self::start_drive_op`], [`Self::end_drive_op`] and
    /// [`Self::rearm`].
    pub fn service(machine: &Machine) -> CyclicMaster {
        let mut m = CyclicMaster::new(machine);
        m.service = true;
        for e in &mut m.enablers {
            e.set_bits(0);
            e.set_target(Target::SwitchOnDisabled);
        }
        m.phase = Phase::Disabled;
        m
    }

    /// Service master: walk the drives to Operation enabled, then arm ([`Phase::Armed`]).
    pub fn enable(&mut self) -> Result<(), Refusal> {
        self.check_no_alarm()?;
        if self.phase != Phase::Disabled {
            return Err(Refusal::Phase { phase: self.phase });
        }
        for e in &mut self.enablers {
            e.set_bits(0);
            e.set_target(Target::OperationEnabled);
        }
        self.control
            .iter_mut()
            .for_each(|c| *c = AxisControl::Cyclic);
        self.motion = None;
        self.set_phase(Phase::Enabling);
        Ok(())
    }

    /// Service master, holding ([`Phase::Armed`], no motion): walk the drives to Switch on
    /// disabled ([`Phase::Disabled`]).
    pub fn disable(&mut self) -> Result<(), Refusal> {
        match self.phase {
            Phase::Armed if self.motion.is_none() => {
                self.start_disabling();
                Ok(())
            }
            Phase::Enabling | Phase::Arming => {
                self.start_disabling();
                Ok(())
            }
            Phase::Disabled | Phase::Disabling => Ok(()),
            phase => Err(Refusal::Phase { phase }),
        }
    }

    fn check_no_alarm(&self) -> Result<(), Refusal> {
        if self.any_reset() || (self.failure.is_some() && self.phase == Phase::Done) {
            return Err(Refusal::NeedsStartUp);
        }
        if self.failure.is_some() {
            return Err(Refusal::Alarm);
        }
        Ok(())
    }

    /// Service master: the standing alarm is cleared once the drives are disabled; from the
    /// next cycle the drives in Fault get a fault reset (CiA 402 transition 15) towards Switch
    /// on disabled. Refused while stopping, and when a drive reset or the bus was lost (the
    /// drives must be started up again).
    pub fn reset_alarm(&mut self) -> Result<(), Refusal> {
        if self.any_reset() || self.phase == Phase::Done {
            return Err(Refusal::NeedsStartUp);
        }
        if self.phase != Phase::Disabled {
            return Err(Refusal::Phase { phase: self.phase });
        }
        self.failure = None;
        self.failure_cycle = None;
        self.fault_stop = false;
        self.stop_asked = None;
        self.aborting = false;
        self.frozen.iter_mut().for_each(|f| *f = false);
        self.override_wanted.1 = false;
        Ok(())
    }

    /// Service master: stop the motion on the path (a feed hold with the motion's override
    /// ramp), then drop it and hold there, enabled ([`Phase::Armed`]). A motion without an
    /// override ramp stops along its direction within the axes' limits. Nothing to do when no
    /// motion runs.
    pub fn abort(&mut self) {
        if !self.service {
            return;
        }
        match self.phase {
            Phase::Streaming => {
                self.aborting = true;
                let held = self.motion.as_mut().is_some_and(|m| m.hold().is_ok());
                if !held {
                    self.begin_stopping();
                }
            }
            Phase::Armed if self.motion.is_some() => self.motion = None,
            _ => {}
        }
    }

    /// Service master, idle: start `interp`, which must start where the axes hold (within
    /// 1 nm).
    pub fn start_motion(&mut self, interp: Interpolator) -> Result<(), Refusal> {
        self.check_no_alarm()?;
        if !self.is_idle() {
            return Err(Refusal::Phase { phase: self.phase });
        }
        let here = self.armed_mm.unwrap_or_default();
        let distance_mm = (interp.last_mm() - here).norm();
        if distance_mm > 1e-6 {
            return Err(Refusal::StartMismatch { distance_mm });
        }
        self.line = None;
        self.supply_motion(interp);
        Ok(())
    }

    /// Whether an abort is under way.
    pub fn is_aborting(&self) -> bool {
        self.aborting
    }

    /// Service master: whether it holds, enabled, with no motion (ready for one).
    pub fn is_idle(&self) -> bool {
        self.phase == Phase::Armed && self.motion.is_none()
    }

    /// Per axis, who commands it.
    pub fn axis_control(&self, i: usize) -> AxisControl {
        self.control[i]
    }

    /// Whether axis `i`'s setpoints are checked against its travel (default on).
    pub fn set_travel_checked(&mut self, i: usize, checked: bool) {
        if let Some(c) = self.check_travel.get_mut(i) {
            *c = checked && self.axes[i].has_travel;
        }
    }

    /// Service master, idle or under drive control: hand the axes of `mask` (bit i = axis i)
    /// to their drives ([`AxisControl::Released`]).
    pub fn release(&mut self, mask: u32) -> Result<(), Refusal> {
        self.check_no_alarm()?;
        if !(self.is_idle() || self.phase == Phase::DriveControl) {
            return Err(Refusal::Phase { phase: self.phase });
        }
        for i in self.axes_of(mask) {
            if self.control[i] == AxisControl::Cyclic {
                self.enablers[i].set_bits(0);
                self.set_control(i, AxisControl::Released);
            }
        }
        if self.control.iter().any(|c| *c != AxisControl::Cyclic) {
            self.set_phase(Phase::DriveControl);
        }
        Ok(())
    }

    /// Whether every axis of `mask` is released and has reported since with statusword bit
    /// 12 clear (its IP mode inactive): its mode of operation may change now.
    pub fn released(&self, mask: u32) -> bool {
        self.axes_of(mask).all(|i| {
            self.control[i] == AxisControl::Released
                && self.fb[i].is_some_and(|f| {
                    f.cycle > self.control_since[i] + 1
                        && (self.axes[i].mode == AxisMode::Csp
                            || f.statusword & swb::OP_MODE_SPECIFIC_12 == 0)
                })
        })
    }

    /// Start the drive's own operation on the released axes of `mask` (homing: the rising
    /// edge of controlword bit 4 once the drive is in mode 6).
    pub fn start_drive_op(&mut self, mask: u32) {
        for i in self.axes_of(mask) {
            if self.control[i] == AxisControl::Released {
                self.enablers[i].set_bits(cwb::IP_ENABLE);
                self.set_control(i, AxisControl::DriveOp);
            }
        }
    }

    /// Where the drive's operation on axis `i` stands ([`None`] unless it is one).
    pub fn drive_op_status(&self, i: usize) -> Option<DriveOpStatus> {
        if self.control.get(i) != Some(&AxisControl::DriveOp) {
            return None;
        }
        let fb = self.fb[i].filter(|f| f.cycle > self.control_since[i] + 1);
        Some(match fb {
            Some(f) if f.statusword & swb::OP_MODE_SPECIFIC_13 != 0 => DriveOpStatus::Error {
                statusword: f.statusword,
            },
            Some(f)
                if f.statusword & (swb::OP_MODE_SPECIFIC_12 | swb::TARGET_REACHED)
                    == swb::OP_MODE_SPECIFIC_12 | swb::TARGET_REACHED =>
            {
                DriveOpStatus::Attained
            }
            _ => DriveOpStatus::InProgress,
        })
    }

    /// End the drive's operation on the axes of `mask` (controlword bit 4 cleared: the axes
    /// are [`AxisControl::Released`] again, their setpoints at position actual).
    pub fn end_drive_op(&mut self, mask: u32) {
        for i in self.axes_of(mask) {
            if self.control[i] == AxisControl::DriveOp {
                self.enablers[i].set_bits(0);
                self.set_control(i, AxisControl::Released);
            }
        }
    }

    /// Back to the cyclic mode on the released axes of `mask`, once their drives are in it
    /// again (0x6061 confirmed): bumpless, from position actual; the master is
    /// [`Phase::Armed`] once every axis answered with statusword bit 12.
    pub fn rearm(&mut self, mask: u32) {
        for i in self.axes_of(mask) {
            if self.control[i] == AxisControl::Released {
                self.enablers[i].set_bits(cwb::IP_ENABLE);
                self.set_control(i, AxisControl::Rearming);
            }
        }
    }

    fn set_control(&mut self, i: usize, c: AxisControl) {
        self.control[i] = c;
        self.control_since[i] = self.cycle;
    }

    fn axes_of(&self, mask: u32) -> impl Iterator<Item = usize> + use<> {
        (0..self.axes.len()).filter(move |i| mask & (1 << i) != 0)
    }

    /// The axes.
    pub fn axes(&self) -> &[AxisIo] {
        &self.axes
    }
    /// The cycle period, s.
    pub fn period_s(&self) -> f64 {
        self.period_s
    }
    /// The phase.
    pub fn phase(&self) -> Phase {
        self.phase
    }
    /// Why the run failed, once it has.
    pub fn failure(&self) -> Option<&Failure> {
        self.failure.as_ref()
    }
    /// Whether the run stopped on a fault: a drive fault or following error (statusword bits 3,
    /// 13, a fault EMCY), missing process data, a lost heartbeat, a boot-up, the bus, or a stop
    /// signal escalated to the fault stop ([`Self::alarm`], [`Self::bus_lost`]). Not an orderly
    /// end: the program's end, a stop on the path, an enable that timed out. After a fault stop
    /// the drives keep consuming the gateway's heartbeat, so that they still stop by themselves
    /// should the gateway die next.
    pub fn fault_stop(&self) -> bool {
        self.fault_stop
    }
    /// The latest feedback (statusword, position, the cycle it arrived in) of axis `i`, machine
    /// order, once one has arrived.
    pub fn feedback(&self, i: usize) -> Option<Feedback> {
        self.fb.get(i).copied().flatten()
    }
    /// The number of the last cycle run (0 before the first).
    pub fn cycle_number(&self) -> u64 {
        self.cycle
    }
    /// The positions at which the drives were armed (the start of the motion), once armed.
    pub fn armed_mm(&self) -> Option<Vector3<f64>> {
        self.armed_mm
    }
    /// The auxiliary axes' positions at which the drives were armed (with
    /// [`armed_mm`](Self::armed_mm); 0 for the axes the machine lacks).
    pub fn armed_aux(&self) -> crate::gcode::AuxPos {
        self.armed_aux
    }
    /// The program line last executed.
    pub fn line(&self) -> Option<usize> {
        self.line
    }
    /// The motion, once supplied.
    pub fn motion(&self) -> Option<&Interpolator> {
        self.motion.as_ref()
    }
    /// The last program line whose motion was completed (the line before the one in execution,
    /// or the last line once the motion finished).
    pub fn completed_line(&self) -> Option<usize> {
        self.completed_line
    }
    /// Start with `line` as the last completed program line (a resumed program's).
    pub fn set_completed_line(&mut self, line: Option<usize>) {
        self.completed_line = line;
    }
    /// Nodes whose drive reset during the run (a boot-up message was seen).
    pub fn reset_nodes(&self) -> Vec<u8> {
        self.axes
            .iter()
            .zip(&self.reset)
            .filter(|(_, r)| **r)
            .map(|(a, _)| a.node)
            .collect()
    }
    /// Whether a drive reset during the run (without allocating, for the cyclic path).
    pub fn any_reset(&self) -> bool {
        self.reset.iter().any(|r| *r)
    }

    /// Nodes of the axes an alarm froze.
    pub fn frozen_nodes(&self) -> Vec<u8> {
        self.axes
            .iter()
            .zip(&self.frozen)
            .filter(|(_, f)| **f)
            .map(|(a, _)| a.node)
            .collect()
    }

    /// A boot-up message from `node`: its drive reset (CiA 301: boot-up, then Pre-operational,
    /// power stage off, its configuration back to defaults). The axis freezes, the group stops,
    /// and the node gets no further RPDO. Repeated boot-ups change nothing.
    pub fn node_reset(&mut self, node: u8) {
        let Some(i) = self.axes.iter().position(|a| a.node == node) else {
            return;
        };
        if self.reset[i] {
            return;
        }
        self.reset[i] = true;
        self.frozen[i] = true;
        self.fault_stop = true;
        let a = &self.axes[i];
        self.fail(Alarm::BootUp {
            axis: a.letter,
            node: a.node,
            completed_line: self.completed_line,
        });
    }

    /// Last position actual per axis (counts; 0 when none arrived).
    pub fn final_counts(&self) -> Vec<i32> {
        self.fb
            .iter()
            .map(|f| f.map_or(0, |f| f.position))
            .collect()
    }

    /// Last setpoint per axis (mm).
    pub fn setpoint_mm(&self) -> Vec<f64> {
        self.sp_mm.iter().map(|h| h[0]).collect()
    }

    /// Last setpoint per axis (counts).
    pub fn setpoint_counts(&self) -> Vec<i32> {
        self.axes
            .iter()
            .zip(&self.sp_mm)
            .map(|(a, h)| a.to_counts(h[0]))
            .collect()
    }

    /// Supply the motion once [`Phase::Armed`]: an interpolator planned from [`Self::armed_mm`].
    pub fn supply_motion(&mut self, interp: Interpolator) {
        self.motion = Some(interp);
        if self.override_wanted != (1.0, false) {
            self.apply_override();
        }
    }

    /// The operator wants the feed override `fraction` (1 = 100 %) and, with `hold`, a feed
    /// hold: the motion's override ramps there from the next cycle (on the motion supplied
    /// later, from its start). A hold keeps the drives enabled, streaming the held point. A
    /// motion without an override ramp ignores it.
    pub fn set_override(&mut self, fraction: f64, hold: bool) {
        // A stop on the path under way holds, whatever the operator asks next.
        self.override_wanted = (fraction, hold || self.stop_asked.is_some());
        self.apply_override();
    }

    fn apply_override(&mut self) {
        let (fraction, hold) = self.override_wanted;
        if let Some(m) = self.motion.as_mut() {
            let _ = m.set_override(fraction);
            let _ = if hold { m.hold() } else { m.resume() };
        }
    }

    /// Feed a received frame; TPDOs of our axes update their feedback, a boot-up message of one
    /// of our nodes is [`Self::node_reset`].
    pub fn on_frame(&mut self, f: &Frame) {
        if let Some(node) = f.id().checked_sub(crate::canopen::cob::HEARTBEAT)
            && f.data() == [crate::canopen::NmtState::BootUp.byte()]
            && !f.is_remote()
            && let Ok(node) = u8::try_from(node)
        {
            self.node_reset(node);
            return;
        }
        for (i, a) in self.axes.iter().enumerate() {
            if f.id() == a.tpdo_cob {
                let d = f.data();
                if d.len() >= a.sw_off + 2 && d.len() >= a.pos_off + 4 {
                    self.fb[i] = Some(Feedback {
                        statusword: u16::from_le_bytes([d[a.sw_off], d[a.sw_off + 1]]),
                        position: i32::from_le_bytes([
                            d[a.pos_off],
                            d[a.pos_off + 1],
                            d[a.pos_off + 2],
                            d[a.pos_off + 3],
                        ]),
                        cycle: self.cycle,
                    });
                }
            }
        }
    }

    /// Raise an alarm on an axis (by node id), from outside the cyclic data: an EMCY, a lost
    /// heartbeat, a boot-up. The axis is frozen and the group stops.
    pub fn alarm(&mut self, node: u8, alarm: Alarm) {
        self.fault_stop = true;
        if let Some(i) = self.axes.iter().position(|a| a.node == node) {
            self.frozen[i] = true;
        }
        self.fail(alarm);
    }

    /// Stop the run on the path (SIGINT, SIGTERM): while the motion streams, a feed hold with
    /// the motion's own override ramp (the path kept, every axis within its limits), then, at
    /// standstill, the drives are disabled as at the end of a program and the run fails with
    /// `alarm`, so that its resume point is where the hold stopped. Before the motion
    /// streams, or for a motion without an override ramp, it is the stop of [`Self::alarm`] (no
    /// axis frozen). While the axes settle at the program's end, or once stopping, nothing
    /// changes. A later [`Self::alarm`] escalates to the fault stop.
    pub fn stop_on_path(&mut self, alarm: Alarm) {
        match self.phase {
            Phase::Streaming => {
                let held = self.motion.as_mut().is_some_and(|m| m.hold().is_ok());
                if held {
                    self.override_wanted.1 = true;
                    self.stop_asked = Some(alarm);
                } else {
                    self.fail(alarm);
                }
            }
            Phase::Enabling | Phase::Arming | Phase::Armed | Phase::DriveControl => {
                self.fail(alarm)
            }
            Phase::Settling
            | Phase::Stopping
            | Phase::Disabling
            | Phase::Done
            | Phase::Disabled => {}
        }
    }

    /// The bus is gone (bus-off, interface down): no frame reaches the drives any more, so no
    /// controlled stop is possible. Every setpoint is held where it is, and the run ends now
    /// ([`Phase::Done`]: no more frames).
    pub fn bus_lost(&mut self, alarm: Alarm) {
        self.fault_stop = true;
        self.frozen.iter_mut().for_each(|f| *f = true);
        self.fail(alarm);
        self.set_phase(Phase::Done);
    }

    /// The run's failure, unless it has one already.
    fn fail_message(&mut self, alarm: Alarm) {
        if self.failure.is_none() {
            self.failure = Some(Failure {
                alarm,
                line: self.line,
            });
            self.failure_cycle = Some(self.cycle);
        }
    }

    fn fail(&mut self, alarm: Alarm) {
        self.fail_message(alarm);
        match self.phase {
            Phase::Streaming
            | Phase::Settling
            | Phase::Armed
            | Phase::Arming
            | Phase::DriveControl => {
                // An axis under its drive's control is stopped by the drive when it is
                // disabled; it holds its position actual meanwhile.
                for i in 0..self.axes.len() {
                    if self.control[i] != AxisControl::Cyclic {
                        self.sp_mm[i][1] = self.sp_mm[i][0];
                    }
                }
                self.begin_stopping();
            }
            Phase::Enabling => self.start_disabling(),
            Phase::Stopping | Phase::Disabling | Phase::Done | Phase::Disabled => {}
        }
    }

    /// Stop along the current direction: every axis decelerates so that all reach rest at the
    /// same time, each within its own acceleration limit.
    fn begin_stopping(&mut self) {
        let t_stop = self
            .axes
            .iter()
            .enumerate()
            .map(|(i, a)| {
                let v = (self.sp_mm[i][0] - self.sp_mm[i][1]) / self.period_s;
                v.abs() / a.max_acc_mm_s2
            })
            .fold(0.0, f64::max);
        for i in 0..self.axes.len() {
            let v = (self.sp_mm[i][0] - self.sp_mm[i][1]) / self.period_s;
            let stopped = self.frozen[i] || t_stop == 0.0;
            self.stop_vel[i] = if stopped { 0.0 } else { v };
            // v(t) = v0 (1 − t / t_stop) on every axis: the direction of motion holds.
            self.stop_acc[i] = if stopped { 0.0 } else { v.abs() / t_stop };
        }
        self.set_phase(Phase::Stopping);
    }

    /// Service master, at rest after a motion, an abort or homing: hold there, enabled.
    fn back_to_armed(&mut self) {
        self.motion = None;
        self.aborting = false;
        self.override_wanted.1 = false;
        self.arm_here();
    }

    /// Armed where the setpoints stand: the next motion starts there.
    fn arm_here(&mut self) {
        let mut p = Vector3::zeros();
        let mut aux = [0.0; 6];
        for (i, a) in self.axes.iter().enumerate() {
            if let Some(k) = a.xyz {
                p[k] = self.sp_mm[i][0];
            }
            if let Some(k) = a.aux {
                aux[k] = self.sp_mm[i][0];
            }
        }
        self.armed_mm = Some(p);
        self.armed_aux = aux;
        self.set_phase(Phase::Armed);
    }

    /// The statusword bits that are alarms for axis `i`: fault, and bit 13 (following error in
    /// IP/CSP) unless its drive runs its own operation (homing error there, not an alarm).
    /// A re-arming axis's bit 13 counts only in a statusword sent after the re-arm began (an
    /// older one is the homing mode's, where bit 13 is a homing error).
    fn alarm_bits(&self, i: usize) -> u16 {
        match self.control[i] {
            AxisControl::Cyclic => swb::FAULT | swb::OP_MODE_SPECIFIC_13,
            AxisControl::Rearming
                if self.fb[i].is_some_and(|f| f.cycle > self.control_since[i] + 1) =>
            {
                swb::FAULT | swb::OP_MODE_SPECIFIC_13
            }
            AxisControl::Rearming | AxisControl::Released | AxisControl::DriveOp => swb::FAULT,
        }
    }

    fn set_phase(&mut self, p: Phase) {
        self.phase = p;
        self.phase_since = self.cycle;
    }

    fn start_disabling(&mut self) {
        for e in &mut self.enablers {
            e.set_bits(0);
            e.set_target(Target::SwitchOnDisabled);
        }
        self.set_phase(Phase::Disabling);
    }

    fn phase_time_s(&self) -> f64 {
        (self.cycle - self.phase_since) as f64 * self.period_s
    }

    /// One cycle: read the feedback received since the last call, decide, and append the frames
    /// to send (SYNC with `sync_cob_id`, then the RPDOs) to `out`. Returns the cycle's record.
    pub fn cycle(&mut self, sync_cob_id: u16, out: &mut Vec<Frame>) -> CycleRecord {
        self.cycle += 1;
        let n = self.axes.len();
        // Alarms from the process data itself.
        for i in 0..n {
            match self.fb[i] {
                // A fault, or a following error the drive flags without faulting (CiA 402
                // leaves the reaction to the drive): either way the axis is not where it
                // should be.
                Some(fb)
                    if fb.statusword & self.alarm_bits(i) != 0
                        && matches!(
                            self.phase,
                            Phase::Arming
                                | Phase::Armed
                                | Phase::Streaming
                                | Phase::Settling
                                | Phase::Stopping
                                | Phase::DriveControl
                        )
                        || fb.statusword & swb::FAULT != 0 && self.phase == Phase::Enabling =>
                {
                    if self.frozen[i] {
                        continue;
                    }
                    self.frozen[i] = true;
                    self.fault_stop = true;
                    let (axis, node, statusword) =
                        (self.axes[i].letter, self.axes[i].node, fb.statusword);
                    self.fail(if statusword & swb::OP_MODE_SPECIFIC_13 != 0 {
                        Alarm::FollowingError {
                            axis,
                            node,
                            statusword,
                        }
                    } else {
                        Alarm::DriveFault {
                            axis,
                            node,
                            statusword,
                        }
                    });
                }
                Some(fb)
                    if self.cycle - fb.cycle > STALE_CYCLES
                        && self.phase != Phase::Done
                        && !self.frozen[i] =>
                {
                    self.frozen[i] = true;
                    self.fault_stop = true;
                    let a = &self.axes[i];
                    self.fail(Alarm::MissingProcessData {
                        axis: a.letter,
                        node: a.node,
                        tpdo_cob: a.tpdo_cob,
                        silent_cycles: Some(self.cycle - fb.cycle),
                    });
                }
                None if self.cycle > STALE_CYCLES
                    && self.phase != Phase::Done
                    && !self.frozen[i] =>
                {
                    self.frozen[i] = true;
                    self.fault_stop = true;
                    let a = &self.axes[i];
                    self.fail(Alarm::MissingProcessData {
                        axis: a.letter,
                        node: a.node,
                        tpdo_cob: a.tpdo_cob,
                        silent_cycles: None,
                    });
                }
                _ => {}
            }
        }
        // Fixed arrays, not vectors: the cyclic path allocates nothing.
        let mut states = [None::<State>; MAX_AXES];
        let mut actual_mm = [None::<f64>; MAX_AXES];
        for i in 0..n {
            states[i] = self.fb[i].and_then(|f| State::from_statusword(f.statusword));
            actual_mm[i] = self.fb[i].map(|f| self.axes[i].to_mm(f.position));
        }

        // Shift the setpoint history.
        for h in &mut self.sp_mm {
            h[2] = h[1];
            h[1] = h[0];
        }

        match self.phase {
            Phase::Enabling => {
                let mut all = true;
                for i in 0..n {
                    if let Some(p) = actual_mm[i] {
                        self.sp_mm[i] = [p; 3];
                    }
                    match states[i] {
                        Some(s) => match self.enablers[i].update(s) {
                            Action::Done => {}
                            Action::Next(_) => all = false,
                            Action::Fault => {
                                self.fault_stop = true;
                                let a = &self.axes[i];
                                self.fail(Alarm::FaultResetFailed {
                                    axis: a.letter,
                                    node: a.node,
                                });
                                all = false;
                            }
                        },
                        None => all = false,
                    }
                }
                if self.phase == Phase::Enabling {
                    if all {
                        for e in &mut self.enablers {
                            e.set_bits(cwb::IP_ENABLE);
                        }
                        // The IP buffer is preloaded with position actual (this cycle's RPDO
                        // already carries it), and bit 4 goes out from the next cycle on.
                        self.set_phase(Phase::Arming);
                    } else {
                        let t = self.phase_time_s();
                        let mut late = LateAxes::default();
                        for (a, state) in self.axes.iter().zip(states) {
                            if state != Some(State::OperationEnabled) && t > a.enable_timeout_s() {
                                late.push(LateAxis {
                                    axis: a.letter,
                                    node: a.node,
                                    state,
                                    enable_timeout_ms: a.enable_timeout_ms,
                                });
                            }
                        }
                        if !late.is_empty() {
                            self.fail(Alarm::EnableTimeout { late });
                        }
                    }
                }
            }
            Phase::Arming => {
                for e in self.enablers.iter_mut().zip(&states) {
                    if let Some(s) = e.1 {
                        let _ = e.0.update(*s);
                    }
                }
                let ready = (0..n).all(|i| {
                    self.fb[i].is_some_and(|f| {
                        f.cycle > self.phase_since && f.statusword & swb::OP_MODE_SPECIFIC_12 != 0
                    })
                });
                if ready {
                    self.bit12_cycle = Some(self.cycle);
                    self.arm_here();
                } else {
                    let t = self.phase_time_s();
                    let mut late = LateAxes::default();
                    for (i, a) in self.axes.iter().enumerate() {
                        if t > a.enable_timeout_s()
                            && self.fb[i]
                                .is_none_or(|f| f.statusword & swb::OP_MODE_SPECIFIC_12 == 0)
                        {
                            late.push(LateAxis {
                                axis: a.letter,
                                node: a.node,
                                state: states[i],
                                enable_timeout_ms: a.enable_timeout_ms,
                            });
                        }
                    }
                    if !late.is_empty() {
                        self.fail(Alarm::Bit12Timeout { late });
                    }
                }
            }
            Phase::Disabled => {
                for i in 0..n {
                    if let Some(p) = actual_mm[i] {
                        self.sp_mm[i] = [p; 3];
                    }
                    // A standing alarm keeps a faulted drive in Fault until it is reset.
                    match states[i] {
                        Some(State::Fault) if self.failure.is_some() => {}
                        Some(s) if !self.reset[i] => {
                            let _ = self.enablers[i].update(s);
                        }
                        _ => {}
                    }
                }
            }
            Phase::DriveControl => {
                for i in 0..n {
                    if let Some(s) = states[i] {
                        let _ = self.enablers[i].update(s);
                    }
                    match self.control[i] {
                        AxisControl::Cyclic => {}
                        AxisControl::Released | AxisControl::DriveOp => {
                            // The drive moves the axis: the setpoint follows it, so that the
                            // return to the cyclic mode is bumpless.
                            if let Some(p) = actual_mm[i] {
                                self.sp_mm[i] = [p; 3];
                            }
                        }
                        AxisControl::Rearming => {
                            let since = self.control_since[i];
                            let following = self.fb[i].is_some_and(|f| {
                                f.cycle > since + 1 && f.statusword & swb::OP_MODE_SPECIFIC_12 != 0
                            });
                            if following {
                                self.control[i] = AxisControl::Cyclic;
                            } else if let Some(p) = actual_mm[i] {
                                self.sp_mm[i] = [p; 3];
                                let a = &self.axes[i];
                                let t = (self.cycle - since) as f64 * self.period_s;
                                if t > a.enable_timeout_s() {
                                    let mut late = LateAxes::default();
                                    late.push(LateAxis {
                                        axis: a.letter,
                                        node: a.node,
                                        state: states[i],
                                        enable_timeout_ms: a.enable_timeout_ms,
                                    });
                                    self.fail(Alarm::Bit12Timeout { late });
                                    break;
                                }
                            }
                        }
                    }
                }
                if self.phase == Phase::DriveControl
                    && self.control.iter().all(|c| *c == AxisControl::Cyclic)
                {
                    self.back_to_armed();
                }
            }
            Phase::Armed if self.motion.is_some() => {
                for (f, h) in self.filters.iter_mut().zip(&self.sp_mm) {
                    if let Some(f) = f {
                        f.reset(h[0]);
                    }
                }
                self.set_phase(Phase::Streaming);
            }
            _ => {}
        }

        if self.phase == Phase::Streaming {
            self.streaming_cycles += 1;
            let mut p = Vector3::zeros();
            let status = self.motion.as_mut().map(|m| m.update(&mut p));
            match status {
                // A hold at standstill keeps streaming the held point: the drives stay
                // enabled, following.
                Some(Status::Working { line } | Status::Held { line }) => {
                    if let Some(prev) = self.line
                        && prev != line
                    {
                        self.completed_line = Some(prev);
                    }
                    self.line = Some(line);
                }
                Some(Status::Finished) => {
                    self.completed_line = self
                        .motion
                        .as_ref()
                        .and_then(|m| m.current_line())
                        .or(self.line);
                }
                Some(Status::Starved) => {
                    // The gateway streams settled plans only; an underrun would hold every
                    // axis in place mid-path, which is a planning failure to stop on.
                    self.fail(Alarm::PlannerUnderrun);
                }
                None => {}
            }
            for i in 0..n {
                let a = &self.axes[i];
                let aux = self.motion.as_ref().and_then(|m| m.aux());
                let target = match (a.xyz, a.aux, aux) {
                    (Some(k), ..) => p[k],
                    (None, Some(k), Some(aux)) => aux[k],
                    _ => self.sp_mm[i][1],
                };
                let target = match &mut self.filters[i] {
                    Some(f) => f.update(target),
                    None => target,
                };
                let prev = self.sp_mm[i][1];
                let step = (target - prev).abs();
                // Last line of defence; the plan is checked against these before motion starts.
                if self.check_travel[i] && !(a.min_mm..=a.max_mm).contains(&target) {
                    let alarm = Alarm::OutsideTravel {
                        axis: a.letter,
                        setpoint_mm: target,
                        min_mm: a.min_mm,
                        max_mm: a.max_mm,
                    };
                    self.fail(alarm);
                    break;
                }
                if step > a.max_vel_mm_s * self.period_s * 1.01 + 1e-9 {
                    let alarm = Alarm::StepTooLarge {
                        axis: a.letter,
                        step_mm: step,
                    };
                    self.fail(alarm);
                    break;
                }
                self.sp_mm[i][0] = target;
                if self.first_motion_cycle.is_none()
                    && self.axes[i].to_counts(target) != self.axes[i].to_counts(prev)
                {
                    self.first_motion_cycle = Some(self.cycle);
                }
            }
            let filtered = self.filters.iter().flatten().all(AxisFilter::is_settled);
            if self.phase == Phase::Streaming && status == Some(Status::Finished) && filtered {
                self.set_phase(Phase::Settling);
            }
            // An abort: once held at standstill, settle where it stopped and hold there.
            if self.phase == Phase::Streaming
                && self.aborting
                && filtered
                && self
                    .motion
                    .as_ref()
                    .is_some_and(Interpolator::is_standing_still)
            {
                self.set_phase(Phase::Settling);
            }
            // A stop on the path: once held at standstill, settle where it stopped and disable.
            if self.phase == Phase::Streaming
                && filtered
                && self
                    .motion
                    .as_ref()
                    .is_some_and(Interpolator::is_standing_still)
                && let Some(alarm) = self.stop_asked.take()
            {
                self.fail_message(alarm);
                self.set_phase(Phase::Settling);
            }
        } else if self.phase == Phase::Settling {
            let settled = (0..n).all(|i| {
                self.fb[i].is_some_and(|f| {
                    f.cycle > self.phase_since
                        && (f.position - self.axes[i].to_counts(self.sp_mm[i][0])).abs() <= 1
                })
            });
            if settled && self.service && self.stop_asked.is_none() && self.failure.is_none() {
                self.back_to_armed();
            } else if settled {
                for e in &mut self.enablers {
                    e.set_bits(0);
                }
                self.start_disabling();
            } else if self.phase_time_s() > SETTLE_TIMEOUT_S {
                self.fail(Alarm::SettleTimeout {
                    timeout_s: SETTLE_TIMEOUT_S,
                });
            }
        } else if self.phase == Phase::Stopping {
            let mut moving = false;
            for i in 0..n {
                if self.frozen[i] {
                    continue;
                }
                let a = &self.axes[i];
                let v = self.stop_vel[i];
                // Decelerate so that all axes stop together, each within its limit.
                let dv = self.stop_acc[i].min(a.max_acc_mm_s2) * self.period_s;
                let nv = if v > 0.0 {
                    (v - dv).max(0.0)
                } else {
                    (v + dv).min(0.0)
                };
                self.stop_vel[i] = nv;
                let next = (self.sp_mm[i][1] + nv * self.period_s).clamp(a.min_mm, a.max_mm);
                self.sp_mm[i][0] = next;
                moving |= nv != 0.0;
            }
            if !moving && self.service && self.aborting && self.failure.is_none() {
                self.set_phase(Phase::Settling);
            } else if !moving {
                self.start_disabling();
            }
        } else if self.phase == Phase::Disabling {
            let mut all = true;
            for ((e, st), reset) in self.enablers.iter_mut().zip(&states).zip(&self.reset) {
                if *reset {
                    continue; // it booted into Switch on disabled, and hears no RPDO of ours
                }
                match st {
                    Some(State::Fault) | None => {}
                    Some(s) => {
                        if e.update(*s) != Action::Done {
                            all = false;
                        }
                    }
                }
            }
            if all || self.phase_time_s() > STATE_TIMEOUT_S {
                if self.service {
                    self.motion = None;
                    self.aborting = false;
                    self.control
                        .iter_mut()
                        .for_each(|c| *c = AxisControl::Cyclic);
                    self.set_phase(Phase::Disabled);
                } else {
                    self.set_phase(Phase::Done);
                }
            }
        }

        // Following error: the drive interpolates towards the setpoint latched at the last SYNC,
        // and its TPDO reports the position at that SYNC, when the setpoint sent two cycles ago
        // was the demand. Only a TPDO that answered the last SYNC is compared: a stale one (the
        // drive or this thread ran late) belongs to an older demand, and comparing it with this
        // one would report the distance travelled meanwhile as following error.
        let mut rec = CycleRecord {
            cycle: self.cycle,
            phase: self.phase,
            line: self.line,
            cmd_mm: [0.0; MAX_AXES],
            act_mm: [0.0; MAX_AXES],
            ferr_mm: [0.0; MAX_AXES],
        };
        for (i, act) in actual_mm.iter().enumerate().take(n) {
            rec.cmd_mm[i] = self.sp_mm[i][0];
            if let Some(p) = *act {
                rec.act_mm[i] = p;
                let fresh = self.fb[i].is_some_and(|f| f.cycle + 1 == self.cycle);
                if !fresh {
                    rec.ferr_mm[i] = self.last_ferr_mm[i];
                    continue;
                }
                let ferr = self.sp_mm[i][2] - p;
                self.last_ferr_mm[i] = ferr;
                rec.ferr_mm[i] = ferr;
                if matches!(self.phase, Phase::Streaming | Phase::Settling) {
                    self.max_ferr_mm[i] = self.max_ferr_mm[i].max(ferr.abs());
                }
            }
        }

        if self.phase != Phase::Done {
            // SYNC first, then the RPDOs inside its synchronous window (0x1007): each drive
            // latches them at the next SYNC (CiA 301 §7.2.2.2).
            out.push(Frame::new(sync_cob_id, &[]).expect("valid SYNC id"));
            for i in 0..n {
                // No setpoint before the drive has told us where it is: a drive still enabled
                // from an earlier session (CSP) would take any other value as a target.
                if self.fb[i].is_none() || self.reset[i] {
                    continue;
                }
                let a = &self.axes[i];
                let cw = self.enablers[i].controlword();
                let cw = if a.mode == AxisMode::Csp && self.control[i] != AxisControl::DriveOp {
                    cw & !cwb::IP_ENABLE
                } else {
                    cw
                };
                out.push(a.rpdo(cw, a.to_counts(self.sp_mm[i][0])));
            }
        }
        rec
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cia402::PowerStateMachine;
    use crate::planner;

    /// A drive reduced to what the master sees: the power state machine, IP bit 12 answering
    /// bit 4, and a position that follows the setpoint latched at SYNC one cycle later.
    struct FakeDrive {
        psm: PowerStateMachine,
        cw: u16,
        latched: i32,
        pos: i32,
        fault: bool,
        silent: bool,
        /// In homing mode (6): bit 4 homes to this position (and sets bits 12 and 10), or
        /// with `None`, reports a homing error (bit 13).
        homing: Option<Option<i32>>,
    }

    impl FakeDrive {
        fn new(pos: i32) -> FakeDrive {
            let mut psm = PowerStateMachine::new();
            psm.boot();
            FakeDrive {
                psm,
                cw: 0,
                latched: pos,
                pos,
                fault: false,
                silent: false,
                homing: None,
            }
        }
        fn statusword(&self) -> u16 {
            let mut sw = self.psm.statusword();
            let bit4 = self.psm.is_operation_enabled() && self.cw & cwb::IP_ENABLE != 0;
            match self.homing {
                Some(Some(home)) if bit4 && self.pos == home => {
                    sw |= swb::OP_MODE_SPECIFIC_12 | swb::TARGET_REACHED;
                }
                Some(None) if bit4 => sw |= swb::OP_MODE_SPECIFIC_13,
                Some(_) => {}
                None if bit4 => sw |= swb::OP_MODE_SPECIFIC_12,
                None => {}
            }
            sw
        }
    }

    struct Rig {
        master: CyclicMaster,
        drives: Vec<FakeDrive>,
        frames: Vec<Frame>,
        records: Vec<CycleRecord>,
    }

    impl Rig {
        fn new() -> Rig {
            Rig::with(&Machine::demo())
        }

        fn with(m: &Machine) -> Rig {
            let master = CyclicMaster::new(m);
            let drives = vec![
                FakeDrive::new(1000),
                FakeDrive::new(-2000),
                FakeDrive::new(0),
            ];
            Rig {
                master,
                drives,
                frames: Vec::new(),
                records: Vec::new(),
            }
        }

        /// One cycle: master decides, drives latch at SYNC and answer with their TPDOs.
        fn step(&mut self) {
            self.frames.clear();
            let rec = self.master.cycle(0x80, &mut self.frames);
            self.records.push(rec);
            for f in &self.frames {
                if let Some(i) = self.master.axes.iter().position(|a| a.rpdo_cob == f.id()) {
                    let d = f.data();
                    let a = &self.master.axes[i];
                    let dr = &mut self.drives[i];
                    dr.cw = u16::from_le_bytes([d[a.cw_off], d[a.cw_off + 1]]);
                    dr.psm.on_controlword(dr.cw);
                    if let Some(home) = dr.homing {
                        // Homing: the drive moves by itself, 1 count per cycle.
                        if let Some(h) = home
                            && dr.psm.is_operation_enabled()
                            && dr.cw & cwb::IP_ENABLE != 0
                        {
                            dr.pos += (h - dr.pos).signum();
                        }
                        dr.latched = dr.pos;
                    } else if dr.statusword() & swb::OP_MODE_SPECIFIC_12 != 0 {
                        dr.pos = dr.latched;
                        dr.latched =
                            i32::from_le_bytes(d[a.sp_off..a.sp_off + 4].try_into().unwrap());
                    } else {
                        dr.latched = dr.pos;
                    }
                }
            }
            for (i, dr) in self.drives.iter_mut().enumerate() {
                if dr.silent {
                    continue;
                }
                if dr.fault {
                    dr.psm.fault();
                    dr.psm.fault_reaction_done();
                }
                let a = &self.master.axes[i];
                let mut d = [0u8; 6];
                d[a.sw_off..a.sw_off + 2].copy_from_slice(&dr.statusword().to_le_bytes());
                d[a.pos_off..a.pos_off + 4].copy_from_slice(&dr.pos.to_le_bytes());
                let f = Frame::new(a.tpdo_cob, &d).unwrap();
                self.master.on_frame(&f);
            }
        }

        fn run_until(&mut self, phase: Phase, max_cycles: usize) {
            for _ in 0..max_cycles {
                if self.master.phase() == phase {
                    return;
                }
                self.step();
            }
            panic!(
                "phase {phase:?} not reached; now {:?}, failure {:?}",
                self.master.phase(),
                self.master.failure()
            );
        }
    }

    fn motion(from: Vector3<f64>, text: &str) -> Interpolator {
        let m = Machine::demo();
        let prog = crate::gcode::parse_program(text, "t.ngc", from).unwrap();
        // As `run` plans it: the machine's look-ahead.
        let plan = planner::plan_with(&prog, &crate::gateway::limits(&m), &m.planner).unwrap();
        Interpolator::new(plan, m.cycle_s()).unwrap()
    }

    #[test]
    fn enables_arms_only_after_bit12_streams_settles_and_disables() {
        let mut r = Rig::new();
        r.run_until(Phase::Arming, 20);
        // Bumpless: while enabling, the setpoint is position actual.
        assert_eq!(r.master.setpoint_counts(), vec![1000, -2000, 0]);
        r.run_until(Phase::Armed, 10);
        let armed = r.master.armed_mm().unwrap();
        assert_eq!(armed, Vector3::new(1.0, -2.0, 0.0));
        assert!(
            r.drives
                .iter()
                .all(|d| d.statusword() & swb::OP_MODE_SPECIFIC_12 != 0)
        );
        // Holding until the motion arrives.
        for _ in 0..5 {
            r.step();
        }
        assert_eq!(r.master.phase(), Phase::Armed);
        r.master
            .supply_motion(motion(armed, "G1 X10 Y5 Z-1 F3000\n"));
        r.run_until(Phase::Done, 5000);
        assert_eq!(r.master.failure(), None);
        assert_eq!(r.master.setpoint_counts(), vec![10_000, 5_000, -2_000]);
        assert!(r.master.bit12_cycle.unwrap() < r.master.first_motion_cycle.unwrap());
        // Every step of every axis within max velocity × period.
        let m = Machine::demo();
        let moving: Vec<&CycleRecord> = r
            .records
            .iter()
            .skip_while(|r| r.phase == Phase::Enabling)
            .collect();
        for w in moving.windows(2) {
            for (i, a) in m.axes.iter().enumerate() {
                let step = (w[1].cmd_mm[i] - w[0].cmd_mm[i]).abs();
                assert!(
                    step <= a.max_vel_mm_s * m.cycle_s() * 1.0001,
                    "axis {} step {step}",
                    a.name
                );
            }
        }
        // Disabled at the end.
        assert!(
            r.drives
                .iter()
                .all(|d| d.psm.state() == State::SwitchOnDisabled)
        );
    }

    #[test]
    fn filtered_setpoints_end_exactly_at_the_program_end_and_agree_with_plan() {
        use crate::interpolator::filter::{FilterKind, FilterSpec};
        for (kind, time_s) in [
            (FilterKind::Linear, 0.024),
            (FilterKind::Exponential, 0.008),
        ] {
            let mut m = Machine::demo();
            for a in &mut m.axes {
                a.filter = Some(FilterSpec { kind, time_s });
            }
            let mut r = Rig::with(&m);
            r.run_until(Phase::Armed, 40);
            let armed = r.master.armed_mm().unwrap();
            let program = "G1 X10 Y5 Z-1 F3000\nG2 X20 Y5 I5 J0 F2400\n";
            let interp = motion(armed, program);
            let samples = interp.total_samples();
            r.master.supply_motion(interp);
            r.run_until(Phase::Done, 5000);
            assert_eq!(r.master.failure(), None);
            // The last setpoint is the program's end, bit for bit, and so is every axis's
            // position once settled.
            let streamed: Vec<[f64; MAX_AXES]> = r
                .records
                .iter()
                .skip_while(|c| c.phase != Phase::Streaming)
                .take(r.master.streaming_cycles as usize)
                .map(|c| c.cmd_mm)
                .collect();
            assert_eq!(streamed.last().unwrap()[..3], [20.0, 5.0, -1.0]);
            assert_eq!(r.master.setpoint_counts(), vec![20_000, 5_000, -2_000]);
            // The end waited for the filters: a linear filter of 6 cycles settles 5 cycles
            // after its input stops.
            if kind == FilterKind::Linear {
                assert_eq!(r.master.streaming_cycles, samples + 5);
            } else {
                assert!(r.master.streaming_cycles > samples);
            }
            // `plan --setpoints` writes the same setpoints (6 decimals), cycle for cycle.
            let dir = tempfile::tempdir().unwrap();
            let file = dir.path().join("sp.csv");
            let opts = crate::offline::PlanOptions {
                path_out: None,
                setpoints_out: Some(file.clone()),
                plot_out: None,
                feed_override: None,
                m99_restarts: 0,
            };
            crate::offline::plan_stream(&m, program.as_bytes(), "t.ngc", armed, &opts).unwrap();
            let text = std::fs::read_to_string(&file).unwrap();
            let rows: Vec<Vec<f64>> = text
                .lines()
                .skip(2) // the header and row 0, the start
                .map(|l| l.split(',').map(|f| f.parse().unwrap()).collect())
                .collect();
            assert_eq!(rows.len(), streamed.len());
            for (k, (row, cmd)) in rows.iter().zip(&streamed).enumerate() {
                for i in 0..3 {
                    assert!((row[2 + i] - cmd[i]).abs() <= 5e-7, "cycle {k} axis {i}");
                }
            }
        }
    }

    #[test]
    fn a_stop_on_the_path_holds_on_it_then_disables_and_fails_with_its_message() {
        let m = Machine::demo();
        let mut r = Rig::new();
        r.run_until(Phase::Armed, 40);
        let from = r.master.armed_mm().unwrap();
        let to = Vector3::new(150.0, 80.0, from[2]);
        let ramp =
            crate::interpolator::OverrideRamp::for_machine(&crate::gateway::limits(&m), &m.planner)
                .unwrap();
        r.master
            .supply_motion(motion(from, "G90 G1 X150 Y80 F12000\n").with_override_ramp(ramp));
        for _ in 0..80 {
            r.step();
        }
        assert_eq!(r.master.phase(), Phase::Streaming);
        let stopped_at = r.records.len();
        let sigint = Alarm::Signal {
            signal: Some(crate::master::alarm::Signal::Int),
        };
        r.master.stop_on_path(sigint.clone());
        // An operator's resume does not lift it.
        r.master.set_override(1.0, false);
        r.run_until(Phase::Done, 3000);
        assert_eq!(r.master.failure().unwrap().alarm, sigint);
        assert!(r.master.frozen_nodes().is_empty(), "no axis frozen");
        let interp = r.master.motion().unwrap();
        assert!(
            interp.plan_time_s() < interp.duration_s() * 0.9,
            "stopped before the end"
        );
        // On the path all along, within the limits, and at rest at the end.
        let t = m.cycle_s();
        let on = &r.records[stopped_at - 2..];
        for w in on.windows(3) {
            let p = Vector3::new(w[2].cmd_mm[0], w[2].cmd_mm[1], w[2].cmd_mm[2]);
            let off = (p - from).cross(&(to - from)).norm() / (to - from).norm();
            assert!(off < 1e-3, "cycle {}: {off} mm off the path", w[2].cycle);
            for (i, a) in m.axes.iter().enumerate() {
                let acc = (w[2].cmd_mm[i] - 2.0 * w[1].cmd_mm[i] + w[0].cmd_mm[i]) / (t * t);
                assert!(acc.abs() <= a.max_acc_mm_s2 * 1.01 + 1e-6, "{acc}");
            }
        }
        let last = r.records.last().unwrap();
        assert_eq!(last.cmd_mm, on[on.len() - 2].cmd_mm);
        assert!(r.records.iter().any(|c| c.phase == Phase::Settling));
    }

    #[test]
    fn a_drive_fault_stops_the_others_within_their_acceleration_and_names_the_axis() {
        let mut r = Rig::new();
        r.run_until(Phase::Armed, 40);
        let armed = r.master.armed_mm().unwrap();
        r.master
            .supply_motion(motion(armed, "G1 X200 Y150 F12000\n"));
        // Stream until moving at speed.
        for _ in 0..150 {
            r.step();
        }
        assert_eq!(r.master.phase(), Phase::Streaming);
        r.drives[2].fault = true; // Z faults
        r.run_until(Phase::Done, 2000);
        let f = r.master.failure().unwrap();
        assert!(
            matches!(
                f.alarm,
                Alarm::DriveFault {
                    axis: "Z",
                    node: 3,
                    statusword
                } if statusword & swb::FAULT != 0
            ),
            "{f}"
        );
        assert_eq!(f.line, Some(1), "{f}");
        // The stop: no axis's velocity change per cycle beyond its acceleration limit.
        let m = Machine::demo();
        let t = m.cycle_s();
        // From the start of the motion on (before it, the setpoint is position actual).
        let cmds: Vec<[f64; MAX_AXES]> = r
            .records
            .iter()
            .skip_while(|r| r.phase != Phase::Streaming)
            .map(|r| r.cmd_mm)
            .collect();
        for w in cmds.windows(3) {
            for (i, a) in m.axes.iter().enumerate().take(2) {
                let acc = (w[2][i] - 2.0 * w[1][i] + w[0][i]) / (t * t);
                assert!(
                    acc.abs() <= a.max_acc_mm_s2 * 1.0001,
                    "axis {} accel {acc}",
                    a.name
                );
            }
        }
        // Along the path: X/Y stay on the line of the move (150/200 of X).
        for c in &cmds {
            let (dx, dy) = (c[0] - armed[0], c[1] - armed[1]);
            assert!(
                (dy - dx * (150.0 - armed[1]) / (200.0 - armed[0])).abs() < 1e-6,
                "{c:?} left the path"
            );
        }
        // X and Y came to rest short of the target.
        let last = cmds.last().unwrap();
        assert!(last[0] < 200.0 && last[1] < 150.0);
    }

    #[test]
    fn a_late_tpdo_is_not_reported_as_following_error() {
        let mut r = Rig::new();
        r.run_until(Phase::Armed, 30);
        let armed = r.master.armed_mm().unwrap();
        r.master
            .supply_motion(motion(armed, "G1 X60 Y5 Z-1 F6000\n"));
        for _ in 0..60 {
            r.step();
        }
        // X's drive keeps following but its TPDOs miss five SYNCs (fewer than the alarm's
        // STALE_CYCLES): the axis moved on meanwhile, it did not lag.
        r.drives[0].silent = true;
        for _ in 0..5 {
            r.step();
        }
        r.drives[0].silent = false;
        r.run_until(Phase::Done, 5000);
        assert_eq!(r.master.failure(), None);
        // This rig's drive reports exactly the demand latched two SYNCs earlier, in counts.
        assert!(
            r.master.max_ferr_mm[0] <= 1.0 / r.master.axes[0].counts_per_mm,
            "following error {} mm from stale feedback",
            r.master.max_ferr_mm[0]
        );
    }

    #[test]
    fn a_boot_up_freezes_the_axis_at_once_and_its_node_gets_no_further_rpdo() {
        let mut r = Rig::new();
        r.run_until(Phase::Armed, 40);
        let armed = r.master.armed_mm().unwrap();
        r.master.supply_motion(motion(
            armed,
            "G1 X20 F6000\nG1 X40 Y20 F6000\nG1 X60 Y60 F6000\n",
        ));
        // Into the second line.
        while r.master.line() != Some(2) {
            r.step();
        }
        for _ in 0..20 {
            r.step();
        }
        let before = r.master.setpoint_counts()[0];
        // Node 1 resets: its boot-up arrives before the next cycle.
        r.master.on_frame(&Frame::new(0x701, &[0x00]).unwrap());
        assert_eq!(r.master.phase(), Phase::Stopping);
        let f = r.master.failure().unwrap();
        assert_eq!(
            *f,
            Failure {
                alarm: Alarm::BootUp {
                    axis: "X",
                    node: 1,
                    completed_line: Some(1)
                },
                line: Some(2)
            }
        );
        assert_eq!(r.master.reset_nodes(), vec![1]);
        let mut cycles = 0;
        while r.master.phase() != Phase::Done {
            r.step();
            cycles += 1;
            assert!(cycles < 2000, "no end: {:?}", r.master.phase());
            assert!(
                r.frames.iter().all(|f| f.id() != 0x201),
                "an RPDO went to the node that reset: {:?}",
                r.frames
            );
            assert_eq!(r.master.setpoint_counts()[0], before);
        }
        // The others still got theirs (disabled in order), and the end did not wait for node 1.
        assert!(r.drives[1].psm.state() == State::SwitchOnDisabled);
        assert!(cycles < 500, "{cycles} cycles to stop");
    }

    #[test]
    fn silence_from_a_drive_is_an_alarm() {
        let mut r = Rig::new();
        r.run_until(Phase::Armed, 40);
        // Node 2 stops answering SYNC.
        r.drives[1].silent = true;
        for _ in 0..(STALE_CYCLES as usize + 5) {
            r.step();
        }
        let f = r.master.failure().unwrap();
        assert!(
            matches!(
                f.alarm,
                Alarm::MissingProcessData {
                    axis: "Y",
                    node: 2,
                    tpdo_cob: 0x182,
                    silent_cycles: Some(n)
                } if n > STALE_CYCLES
            ),
            "{f}"
        );
    }

    fn service_rig() -> Rig {
        let m = Machine::demo();
        let mut r = Rig::with(&m);
        r.master = CyclicMaster::service(&m);
        r
    }

    fn with_ramp(i: Interpolator) -> Interpolator {
        let m = Machine::demo();
        let ramp =
            crate::interpolator::OverrideRamp::for_machine(&crate::gateway::limits(&m), &m.planner)
                .unwrap();
        i.with_override_ramp(ramp)
    }

    #[test]
    fn a_service_master_stays_enabled_between_motions_until_disabled() {
        let mut r = service_rig();
        for _ in 0..20 {
            r.step();
        }
        // Disabled: SYNC and RPDOs go on, the setpoints track position actual.
        assert_eq!(r.master.phase(), Phase::Disabled);
        assert_eq!(r.master.setpoint_counts(), vec![1000, -2000, 0]);
        assert!(r.frames.len() == 4);
        // Not before it is enabled.
        let here = Vector3::new(1.0, -2.0, 0.0);
        assert!(matches!(
            r.master.start_motion(motion(here, "G1 X10 F3000\n")),
            Err(Refusal::Phase { .. })
        ));
        r.master.enable().unwrap();
        r.run_until(Phase::Armed, 40);
        assert!(r.master.is_idle());
        // A motion from elsewhere is refused.
        assert!(matches!(
            r.master
                .start_motion(motion(Vector3::zeros(), "G1 X10 F3000\n")),
            Err(Refusal::StartMismatch { .. })
        ));
        r.master
            .start_motion(motion(here, "G1 X10 F3000\n"))
            .unwrap();
        r.step();
        assert_eq!(r.master.phase(), Phase::Streaming);
        r.run_until(Phase::Armed, 5000);
        // Holding where the motion ended, enabled, the drives following.
        assert!(r.master.is_idle());
        assert_eq!(r.master.setpoint_counts(), vec![10_000, -2000, 0]);
        assert!(r.drives.iter().all(|d| d.psm.is_operation_enabled()));
        // A second motion from there.
        let here = r.master.armed_mm().unwrap();
        assert_eq!(here, Vector3::new(10.0, -2.0, 0.0));
        r.master
            .start_motion(motion(here, "G1 Y3 F3000\n"))
            .unwrap();
        r.step();
        r.run_until(Phase::Armed, 5000);
        assert_eq!(r.master.setpoint_counts(), vec![10_000, 3000, 0]);
        assert_eq!(r.master.failure(), None);
        r.master.disable().unwrap();
        r.run_until(Phase::Disabled, 100);
        assert!(r.drives.iter().all(|d| !d.psm.is_operation_enabled()));
        // And enabled again.
        r.master.enable().unwrap();
        r.run_until(Phase::Armed, 40);
    }

    #[test]
    fn an_abort_stops_on_the_path_and_keeps_the_drives_enabled() {
        let mut r = service_rig();
        r.master.enable().unwrap();
        r.run_until(Phase::Armed, 40);
        let here = r.master.armed_mm().unwrap();
        r.master
            .start_motion(with_ramp(motion(here, "G1 X100 F6000\n")))
            .unwrap();
        for _ in 0..100 {
            r.step();
        }
        r.master.abort();
        assert!(r.master.is_aborting());
        r.run_until(Phase::Armed, 2000);
        assert_eq!(r.master.failure(), None);
        let x = r.master.setpoint_mm()[0];
        assert!(x > 1.5 && x < 100.0, "stopped at {x}");
        // On the path: Y and Z never moved.
        assert!(
            r.records
                .iter()
                .filter(|c| matches!(c.phase, Phase::Streaming | Phase::Settling))
                .all(|c| c.cmd_mm[1] == -2.0 && c.cmd_mm[2] == 0.0)
        );
        assert!(r.drives.iter().all(|d| d.psm.is_operation_enabled()));
        assert!(!r.master.is_aborting());
    }

    #[test]
    fn a_fault_leaves_a_service_master_disabled_with_its_alarm_until_reset() {
        let mut r = service_rig();
        r.master.enable().unwrap();
        r.run_until(Phase::Armed, 40);
        r.drives[1].fault = true;
        r.run_until(Phase::Disabled, 200);
        assert!(matches!(
            r.master.failure().map(|f| &f.alarm),
            Some(Alarm::DriveFault { node: 2, .. })
        ));
        // The drive stays in Fault while the alarm stands.
        r.drives[1].fault = false;
        for _ in 0..20 {
            r.step();
        }
        assert_eq!(r.drives[1].psm.state(), State::Fault);
        assert_eq!(r.master.enable(), Err(Refusal::Alarm));
        r.master.reset_alarm().unwrap();
        for _ in 0..40 {
            r.step();
        }
        assert_eq!(r.drives[1].psm.state(), State::SwitchOnDisabled);
        r.master.enable().unwrap();
        r.run_until(Phase::Armed, 40);
        assert_eq!(r.master.failure(), None);
    }

    #[test]
    fn homing_hands_an_axis_to_its_drive_and_back_without_a_jump() {
        let mut r = service_rig();
        r.master.enable().unwrap();
        r.run_until(Phase::Armed, 40);
        // Z (axis 2) homes; X and Y hold.
        r.master.release(0b100).unwrap();
        assert_eq!(r.master.phase(), Phase::DriveControl);
        for _ in 0..3 {
            r.step();
        }
        assert!(r.master.released(0b100));
        // The mode changes to homing (SDO, not modelled here), then bit 4 starts it.
        r.drives[2].homing = Some(Some(25));
        r.master.start_drive_op(0b100);
        let mut n = 0;
        while r.master.drive_op_status(2) != Some(DriveOpStatus::Attained) {
            assert_eq!(r.master.drive_op_status(2), Some(DriveOpStatus::InProgress));
            r.step();
            n += 1;
            assert!(n < 100);
            // The setpoint follows the drive's own motion.
            let sp = r.master.setpoint_counts()[2];
            assert!(
                (sp - r.drives[2].pos).abs() <= 1,
                "{sp} {}",
                r.drives[2].pos
            );
        }
        assert_eq!(r.drives[2].pos, 25);
        r.master.end_drive_op(0b100);
        r.step();
        r.drives[2].homing = None;
        r.master.rearm(0b100);
        r.run_until(Phase::Armed, 20);
        assert_eq!(r.master.setpoint_counts(), vec![1000, -2000, 25]);
        assert_eq!(r.master.armed_mm().unwrap()[2], 25.0 / 2000.0);
        assert_eq!(r.master.failure(), None);
        // A homing error is the drive's answer, not an alarm.
        r.master.release(0b001).unwrap();
        for _ in 0..3 {
            r.step();
        }
        r.drives[0].homing = Some(None);
        r.master.start_drive_op(0b001);
        for _ in 0..3 {
            r.step();
        }
        assert!(matches!(
            r.master.drive_op_status(0),
            Some(DriveOpStatus::Error { statusword }) if statusword & swb::OP_MODE_SPECIFIC_13 != 0
        ));
        assert_eq!(r.master.failure(), None);
    }
}
