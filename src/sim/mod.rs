//! A simulated CiA 402 servo drive: a real CANopen peer, sans-I/O.
//!
//! It loads its object dictionary from a drive dictionary, answers SDOs with the abort codes of
//! CiA 301, enforces the PDO remap procedure, follows SYNC (synchronous RPDOs take effect at the
//! next SYNC, synchronous TPDOs are sent on it), produces and consumes heartbeats, and runs the
//! CiA 402 power state machine with interpolated position (mode 7, linear sub-mode 0) and cyclic
//! synchronous position (mode 8) over a position loop with lag and velocity/acceleration limits,
//! and homing (mode 6, [`homing`]) on simulated home and limit switches ([`SimSetup`]).
//!
//! Time is an argument (`now`, a [`Duration`] since any fixed origin): the same drive runs in
//! unit tests with a made-up clock, in-process next to the gateway, and on vcan0 as
//! `canmotion simdrive`. [`runner`] puts drives on a bus.
//!
//! Units of the motion model are the drive's: counts, counts/s, counts/s².

pub mod homing;
pub mod inject;
pub mod runner;

use std::sync::Arc;
use std::time::Duration;

use canopen_rs::Value;

use crate::bus::Frame;
use crate::canopen::dictionary::DriveDictionary;
use crate::canopen::emcy::{Emcy, code as emcy_code};
use crate::canopen::index;
use crate::canopen::od::Od;
use crate::canopen::sdo_server::{SdoServer, SdoTarget};
use crate::canopen::{AbortCode, NmtState, cob, nmt};
use crate::cia402::{PowerStateMachine, State, controlword as cw_bits, statusword as sw};
use crate::config::machine::MapEntry;
pub use homing::{HomingStatus, SimSetup};
pub use inject::{Inject, Targeted};

/// Position loop gain (1/s): the actual position approaches the demand with a ~5 ms time constant.
const KP_PER_S: f64 = 200.0;
/// Velocity feed-forward fraction: what remains gives a following error proportional to speed,
/// as on a real servo.
const K_FF: f64 = 0.95;
/// The motor's acceleration capability (counts/s²) when the dictionary has no 0x60C5.
const MOTOR_ACC_COUNTS_S2: f64 = 30_000_000.0;
/// Physics integration step.
const STEP: Duration = Duration::from_micros(250);
/// EMCY code for a parameter the drive cannot run with (CiA 301: 0x6320 "parameter error").
pub const EMCY_PARAMETER: u16 = crate::canopen::emcy::code::PARAMETER;
/// The last communication and mapping parameter of this drive's four RPDOs and TPDOs.
const RPDO_COMMUNICATION_LAST: u16 = index::RPDO_COMMUNICATION + 3;
const RPDO_MAPPING_LAST: u16 = index::RPDO_MAPPING + 3;
const TPDO_COMMUNICATION_LAST: u16 = index::TPDO_COMMUNICATION + 3;
const TPDO_MAPPING_LAST: u16 = index::TPDO_MAPPING + 3;

/// Why the drive went to Fault (what 0x603F and the EMCY say).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FaultCause {
    /// The following error exceeded 0x6065 for longer than 0x6066.
    FollowingError,
    /// The heartbeat of a consumed node (0x1016) timed out and 0x6007 says fault.
    HeartbeatLost,
    /// An injected fault ([`Inject::PersistentFault`], [`Inject::RecurringFault`]) with its
    /// EMCY code.
    Injected {
        /// EMCY code, also in 0x603F.
        code: u16,
    },
}

#[derive(Debug, Clone, Copy)]
struct Interp {
    /// Where the demand was when the current setpoint was latched.
    from: f64,
    /// The setpoint latched at the last SYNC.
    to: f64,
    /// When it was latched.
    at: Duration,
}

/// One simulated drive.
#[derive(Debug)]
pub struct SimDrive {
    node: u8,
    od: Od,
    nmt: NmtState,
    sdo: SdoServer,
    power: PowerStateMachine,
    /// Synchronous RPDO data waiting for the next SYNC, per RPDO.
    pending_rpdo: [Option<([u8; 8], usize)>; 4],
    /// SYNCs counted per TPDO for transmission types 2–240.
    tpdo_sync_count: [u32; 4],
    /// Last data sent and when, per event-driven TPDO.
    tpdo_last: [Option<(Vec<u8>, Duration)>; 4],
    last_sync: Option<Duration>,
    sync_missing_reported: bool,
    next_heartbeat: Option<Duration>,
    /// Per 0x1016 entry: last heartbeat seen, and whether its loss was reported.
    consumer: [(Option<Duration>, bool); 4],
    // motion, in counts
    pos: f64,
    vel: f64,
    demand: f64,
    interp: Option<Interp>,
    ip_active: bool,
    last_cw: u16,
    ferr_since: Option<Duration>,
    ferr_flag: bool,
    limit_flag: bool,
    fault_cause: Option<FaultCause>,
    last_physics: Option<Duration>,
    /// Frames produced inside an SDO write, sent after its response.
    deferred: Vec<Frame>,
    /// Synchronous RPDOs discarded for arriving outside the synchronous window.
    rpdo_outside_window: u64,
    /// Injected misbehaviours, and whether each has fired.
    injects: Vec<(Inject, bool)>,
    /// When the drive first followed setpoints (statusword bit 12), the origin of injections.
    motion_since: Option<Duration>,
    jammed: bool,
    silent: bool,
    /// The heartbeat producer is stopped ([`Inject::NoHeartbeat`]) until the next boot.
    heartbeat_off: bool,
    /// The EMCY code of a fault that comes back after every reset ([`Inject::RecurringFault`]).
    recurring_fault: Option<u16>,
    /// When a recurring fault comes back.
    refault_at: Option<Duration>,
    rng: u64,
    rpdo_dropped: u64,
    /// Error frames an injection produced, for the runner to send.
    bus_errors: Vec<crate::bus::ErrorFrame>,
    /// An injected warning is on (statusword bit 7), until the next boot.
    warning: bool,
    /// When the controlword first asked for Operation enabled ([`Inject::SlowEnable`]).
    enable_asked_at: Option<Duration>,
    /// The simulated axis: where its switches are.
    setup: SimSetup,
    /// Physical position (where the switches are) minus the reported position, counts: homing
    /// moves the reported frame so that the home position reads 0x607C.
    origin: f64,
    /// Homing mode's state.
    homing: homing::HomingRun,
}

fn rpdo_base(n: usize) -> u16 {
    index::RPDO_COMMUNICATION + n as u16
}
fn rpdo_map(n: usize) -> u16 {
    index::RPDO_MAPPING + n as u16
}
fn tpdo_base(n: usize) -> u16 {
    index::TPDO_COMMUNICATION + n as u16
}
fn tpdo_map(n: usize) -> u16 {
    index::TPDO_MAPPING + n as u16
}

impl SimDrive {
    /// A drive with `node` id, powered on but not yet booted: call [`SimDrive::boot`].
    pub fn new(dict: Arc<DriveDictionary>, node: u8) -> SimDrive {
        let od = Od::new(dict, node);
        SimDrive {
            node,
            od,
            nmt: NmtState::BootUp,
            sdo: SdoServer::new(),
            power: PowerStateMachine::new(),
            pending_rpdo: [None; 4],
            tpdo_sync_count: [0; 4],
            tpdo_last: Default::default(),
            last_sync: None,
            sync_missing_reported: false,
            next_heartbeat: None,
            consumer: [(None, false); 4],
            pos: 0.0,
            vel: 0.0,
            demand: 0.0,
            interp: None,
            ip_active: false,
            last_cw: 0,
            ferr_since: None,
            ferr_flag: false,
            limit_flag: false,
            fault_cause: None,
            last_physics: None,
            deferred: Vec::new(),
            rpdo_outside_window: 0,
            injects: Vec::new(),
            motion_since: None,
            jammed: false,
            silent: false,
            heartbeat_off: false,
            recurring_fault: None,
            refault_at: None,
            rng: 0x9E37_79B9_7F4A_7C15 ^ u64::from(node),
            rpdo_dropped: 0,
            bus_errors: Vec::new(),
            warning: false,
            enable_asked_at: None,
            setup: SimSetup::default(),
            origin: 0.0,
            homing: homing::HomingRun::default(),
        }
    }

    /// The simulated drive of a machine file's axis: its dictionary, node and `[axis.sim]`.
    pub fn for_axis(axis: &crate::config::AxisConfig) -> SimDrive {
        SimDrive::new(axis.dictionary.clone(), axis.node).with_sim_setup(SimSetup::for_axis(axis))
    }

    /// The simulated axis's switches and start position (see [`SimSetup`]).
    pub fn with_sim_setup(mut self, setup: SimSetup) -> SimDrive {
        self.setup = setup;
        self.origin = 0.0;
        self.with_position(setup.start_counts)
    }

    /// Where homing (mode 6) stands.
    pub fn homing_status(&self) -> HomingStatus {
        self.homing.status
    }

    /// A fresh drive (a reset of the node) on the same motor: the motor does not move, and the
    /// switches stay where they are; homing is lost.
    fn reset_keeping_motor(&mut self) {
        let (pos, origin, setup) = (self.pos, self.origin, self.setup);
        *self = SimDrive::new(self.od.dictionary().clone(), self.node);
        self.pos = pos;
        self.demand = pos;
        self.origin = origin;
        self.setup = setup;
    }

    /// Start with the motor at `counts` (where the machine was left).
    pub fn with_position(mut self, counts: i32) -> SimDrive {
        self.pos = f64::from(counts);
        self.demand = self.pos;
        self.refresh();
        self
    }

    /// Add a misbehaviour to show (see [`inject`]).
    pub fn with_inject(mut self, inject: Inject) -> SimDrive {
        self.injects.push((inject, false));
        self
    }

    /// RPDOs lost to an injected drop rate.
    pub fn rpdos_dropped(&self) -> u64 {
        self.rpdo_dropped
    }

    /// Fire the injections that are due.
    fn check_injects(&mut self, now: Duration, out: &mut Vec<Frame>) {
        let Some(since) = self.motion_since else {
            return;
        };
        for k in 0..self.injects.len() {
            let (inj, fired) = self.injects[k];
            if fired {
                continue;
            }
            let Some(after) = inj.after() else {
                continue;
            };
            if now < since + after {
                continue;
            }
            self.injects[k].1 = true;
            match inj {
                Inject::FollowingError { .. } => self.jammed = true,
                Inject::Silent { .. } => self.silent = true,
                Inject::Reboot { .. } => {
                    let injects = std::mem::take(&mut self.injects);
                    self.reset_keeping_motor();
                    self.injects = injects;
                    self.boot(now, out);
                    return;
                }
                Inject::NoHeartbeat { .. } => self.heartbeat_off = true,
                Inject::PersistentFault { .. } => {
                    let code = emcy_code::TEMPERATURE;
                    self.raise_fault(FaultCause::Injected { code }, now, out, true);
                    self.power.set_fault_active(true);
                    self.refresh();
                }
                Inject::RecurringFault { .. } => {
                    let code = emcy_code::OVER_CURRENT;
                    self.recurring_fault = Some(code);
                    self.raise_fault(FaultCause::Injected { code }, now, out, true);
                    self.refresh();
                }
                Inject::Fault { .. } => {
                    let code = emcy_code::OVER_CURRENT;
                    self.raise_fault(FaultCause::Injected { code }, now, out, true);
                    self.refresh();
                }
                Inject::BusOff { .. } => self.bus_errors.push(crate::bus::ErrorFrame::bus_off()),
                Inject::ErrorPassive { .. } => self
                    .bus_errors
                    .push(crate::bus::ErrorFrame::error_passive(128, 128)),
                Inject::Warning { code, .. } => {
                    self.warning = true;
                    self.emcy(code, 0, out);
                    self.refresh();
                }
                Inject::DropRpdo { .. } | Inject::SlowEnable { .. } => {}
            }
        }
    }

    /// Error frames injected since the last call ([`Inject::BusOff`], [`Inject::ErrorPassive`]),
    /// to send with [`crate::bus::Port::send_error`].
    pub fn take_bus_errors(&mut self) -> Vec<crate::bus::ErrorFrame> {
        std::mem::take(&mut self.bus_errors)
    }

    fn next_inject_at(&self) -> Option<Duration> {
        let since = self.motion_since?;
        self.injects
            .iter()
            .filter(|(_, fired)| !fired)
            .filter_map(|(i, _)| i.after().map(|a| since + a))
            .min()
    }

    /// Whether to lose this RPDO (xorshift64*, deterministic per node).
    fn drop_rpdo(&mut self) -> bool {
        let Some(p) = self.injects.iter().find_map(|(i, _)| match i {
            Inject::DropRpdo { percent } => Some(*percent),
            _ => None,
        }) else {
            return false;
        };
        self.rng ^= self.rng >> 12;
        self.rng ^= self.rng << 25;
        self.rng ^= self.rng >> 27;
        let r = (self.rng.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64;
        r * 100.0 < p
    }

    /// Node id.
    pub fn node(&self) -> u8 {
        self.node
    }
    /// NMT state.
    pub fn nmt_state(&self) -> NmtState {
        self.nmt
    }
    /// CiA 402 state.
    pub fn state(&self) -> State {
        self.power.state()
    }
    /// Position actual (0x6064).
    pub fn position_counts(&self) -> i32 {
        self.pos.round() as i32
    }
    /// Statusword (0x6041).
    pub fn statusword(&self) -> u16 {
        self.od.int(index::STATUSWORD, 0) as u16
    }
    /// Synchronous RPDOs discarded because they came outside the synchronous window (0x1007).
    pub fn rpdos_outside_window(&self) -> u64 {
        self.rpdo_outside_window
    }
    /// Why the drive faulted last, if it did.
    pub fn fault_cause(&self) -> Option<FaultCause> {
        self.fault_cause
    }
    /// The object dictionary (read access for tests and diagnostics).
    pub fn od(&self) -> &Od {
        &self.od
    }

    /// Leave initialisation: boot-up message, then Pre-operational (CiA 301 §7.3.2.2.1).
    pub fn boot(&mut self, now: Duration, out: &mut Vec<Frame>) {
        self.power.boot();
        self.nmt = NmtState::PreOperational;
        self.sdo.reset();
        self.pending_rpdo = [None; 4];
        self.tpdo_sync_count = [0; 4];
        self.tpdo_last = Default::default();
        self.last_sync = None;
        self.sync_missing_reported = false;
        self.consumer = [(None, false); 4];
        self.last_physics = Some(now);
        self.heartbeat_off = false;
        self.warning = false;
        self.enable_asked_at = None;
        out.push(Frame::new(cob::HEARTBEAT + u16::from(self.node), &[0x00]).expect("id"));
        self.schedule_heartbeat(now);
        self.refresh();
    }

    fn schedule_heartbeat(&mut self, now: Duration) {
        let ms = self.od.int(index::PRODUCER_HEARTBEAT_TIME, 0) as u64;
        self.next_heartbeat = (ms > 0).then(|| now + Duration::from_millis(ms));
    }

    fn sync_period(&self) -> Option<Duration> {
        let us = self.od.int(index::COMMUNICATION_CYCLE_PERIOD, 0) as u64;
        (us > 0).then(|| Duration::from_micros(us))
    }

    /// The IP time period from 0x60C2 (value × 10^index s).
    fn ip_period(&self) -> Option<Duration> {
        let v = self.od.int(index::IP_TIME_PERIOD, 1) as f64;
        let idx = self.od.int(index::IP_TIME_PERIOD, 2) as i32;
        let s = v * 10f64.powi(idx);
        (s > 0.0).then(|| Duration::from_secs_f64(s))
    }

    /// The identifiers this drive listens to, from its current configuration: NMT, SYNC (0x1005),
    /// its SDO channel, its valid RPDOs and every heartbeat (0x700–0x77F). A runner installs them
    /// as receive filters so the drive is not woken by other nodes' traffic.
    pub fn rx_filters(&self) -> Vec<crate::bus::Filter> {
        use crate::bus::Filter;
        let mut f = vec![
            Filter::exact(cob::NMT),
            Filter::exact((self.od.int(index::COB_ID_SYNC, 0) as u32 & 0x7FF) as u16),
            Filter::exact(cob::SDO_RX + u16::from(self.node)),
            Filter {
                id: cob::HEARTBEAT,
                mask: 0x780,
            },
        ];
        for n in 0..4 {
            let c = self.od.int(rpdo_base(n), 1) as u32;
            if c & 0x8000_0000 == 0 {
                f.push(Filter::exact((c & 0x7FF) as u16));
            }
        }
        f
    }

    /// When [`SimDrive::poll`] must run next at the latest.
    pub fn poll_at(&self, now: Duration) -> Duration {
        let mut t = now + Duration::from_millis(10);
        if let Some(h) = self.next_heartbeat {
            t = t.min(h);
        }
        if let (Some(last), Some(p), false) = (
            self.last_sync,
            self.sync_period(),
            self.sync_missing_reported,
        ) && self.nmt == NmtState::Operational
        {
            t = t.min(last + p * 3 / 2 + Duration::from_micros(1));
        }
        for (i, (seen, lost)) in self.consumer.iter().enumerate() {
            let e = self.od.int(index::CONSUMER_HEARTBEAT_TIME, i as u8 + 1) as u32;
            let ms = u64::from(e & 0xFFFF);
            if let (Some(seen), false, true) = (seen, lost, ms > 0) {
                t = t.min(*seen + Duration::from_millis(ms) + Duration::from_micros(1));
            }
        }
        if self.vel != 0.0 || self.interp.is_some() || self.power.power_enabled() {
            t = t.min(now + Duration::from_millis(1));
        }
        if let Some(i) = self.next_inject_at() {
            t = t.min(i.max(now));
        }
        if let Some(r) = self.refault_at {
            t = t.min(r.max(now));
        }
        t
    }

    /// Advance time: the motor, the heartbeat producer, the SYNC and heartbeat consumers.
    pub fn poll(&mut self, now: Duration, out: &mut Vec<Frame>) {
        if self.nmt == NmtState::BootUp || self.silent {
            return;
        }
        self.physics(now, out);
        self.check_injects(now, out);
        if self.silent {
            return;
        }
        if let (Some(at), Some(code)) = (self.refault_at, self.recurring_fault)
            && now >= at
        {
            self.refault_at = None;
            self.raise_fault(FaultCause::Injected { code }, now, out, true);
            self.refresh();
        }
        if self.heartbeat_off {
            self.next_heartbeat = None;
        }
        if let Some(h) = self.next_heartbeat
            && now >= h
        {
            out.push(
                Frame::new(cob::HEARTBEAT + u16::from(self.node), &[self.nmt.byte()]).expect("id"),
            );
            let ms = self.od.int(index::PRODUCER_HEARTBEAT_TIME, 0) as u64;
            // Keep the beat on its grid; if we fell far behind, restart from now.
            let mut next = h + Duration::from_millis(ms.max(1));
            if next <= now {
                next = now + Duration::from_millis(ms.max(1));
            }
            self.next_heartbeat = (ms > 0).then_some(next);
        }

        if self.nmt == NmtState::Operational
            && let (Some(last), Some(p)) = (self.last_sync, self.sync_period())
            && !self.sync_missing_reported
            && now > last + p * 3 / 2
        {
            self.sync_missing_reported = true;
            self.emcy(emcy_code::COMMUNICATION, 0x10, out);
        }
        for i in 0..4 {
            let e = self.od.int(index::CONSUMER_HEARTBEAT_TIME, i as u8 + 1) as u32;
            let ms = u64::from(e & 0xFFFF);
            let (seen, lost) = self.consumer[i];
            if let (Some(seen), false, true) = (seen, lost, ms > 0)
                && now > seen + Duration::from_millis(ms)
            {
                self.consumer[i].1 = true;
                self.heartbeat_lost(now, out);
            }
        }
        self.send_event_tpdos(now, out);
    }

    fn heartbeat_lost(&mut self, now: Duration, out: &mut Vec<Frame>) {
        self.emcy(emcy_code::HEARTBEAT, 0x10, out);
        // 0x6007 abort connection option: 1 fault, 2 disable voltage, 3 quick stop.
        match self.od.int(index::ABORT_CONNECTION_OPTION, 0) {
            1 => self.raise_fault(FaultCause::HeartbeatLost, now, out, false),
            2 => {
                self.power.on_controlword(cw_bits::DISABLE_VOLTAGE);
            }
            3 => {
                self.power.on_controlword(cw_bits::QUICK_STOP_CMD);
            }
            _ => {}
        }
        // 0x1029:1 communication error behaviour: 0 pre-operational, 1 no change, 2 stopped.
        match self.od.int(index::ERROR_BEHAVIOUR, 1) {
            0 if self.nmt == NmtState::Operational => self.nmt = NmtState::PreOperational,
            2 => self.nmt = NmtState::Stopped,
            _ => {}
        }
        self.refresh();
    }

    fn raise_fault(
        &mut self,
        cause: FaultCause,
        _now: Duration,
        out: &mut Vec<Frame>,
        send_emcy: bool,
    ) {
        if self.power.fault().is_some() {
            self.fault_cause = Some(cause);
            let code = match cause {
                FaultCause::FollowingError => emcy_code::FOLLOWING_ERROR,
                FaultCause::HeartbeatLost => emcy_code::HEARTBEAT,
                FaultCause::Injected { code } => code,
            };
            self.od.set_int(index::ERROR_CODE, 0, i64::from(code));
            self.ip_active = false;
            self.interp = None;
            if send_emcy {
                self.emcy(code, 0x20, out);
            }
        }
    }

    /// Send an EMCY (if 0x1014 is valid), set the error register and the error history.
    fn emcy(&mut self, code: u16, register_bits: u8, out: &mut Vec<Frame>) {
        let reg = if code == 0 {
            0
        } else {
            (self.od.int(index::ERROR_REGISTER, 0) as u8) | 0x01 | register_bits
        };
        self.od.set_int(index::ERROR_REGISTER, 0, i64::from(reg));
        if code != 0 {
            for s in (2..=8u8).rev() {
                let prev = self.od.int(index::PREDEFINED_ERROR_FIELD, s - 1);
                self.od.set_int(index::PREDEFINED_ERROR_FIELD, s, prev);
            }
            self.od
                .set_int(index::PREDEFINED_ERROR_FIELD, 1, i64::from(code));
            let n = (self.od.int(index::PREDEFINED_ERROR_FIELD, 0) + 1).min(8);
            self.od.set_int(index::PREDEFINED_ERROR_FIELD, 0, n);
        }
        let cob_id = self.od.int(index::COB_ID_EMCY, 0) as u32;
        if cob_id & 0x8000_0000 != 0 || self.nmt == NmtState::Stopped {
            return;
        }
        let e = Emcy {
            node: self.node,
            code,
            register: reg,
            vendor: [0; 5],
        };
        let f = e.to_frame();
        out.push(Frame::new((cob_id & 0x7FF) as u16, f.data()).expect("id"));
    }

    /// Handle one received frame.
    pub fn handle(&mut self, now: Duration, frame: &Frame, out: &mut Vec<Frame>) {
        if self.nmt == NmtState::BootUp || self.silent {
            return;
        }
        let id = frame.id();
        let data = frame.data();
        // Heartbeats and other nodes' traffic do not touch the motor: no need to advance it.
        if id != cob::NMT && (0x701..=0x77F).contains(&id) {
            if !frame.is_remote() {
                self.on_heartbeat(id, now);
            }
            return;
        }
        let sync_id = (self.od.int(index::COB_ID_SYNC, 0) as u32 & 0x7FF) as u16;
        let rpdo = (0..4).find(|&n| {
            let c = self.od.int(rpdo_base(n), 1) as u32;
            c & 0x8000_0000 == 0 && (c & 0x7FF) as u16 == id
        });
        let mine = id == cob::NMT
            || id == sync_id
            || id == cob::SDO_RX + u16::from(self.node)
            || rpdo.is_some();
        if !mine {
            return;
        }
        self.physics(now, out);
        if id == cob::NMT {
            if data.len() == 2 && (data[1] == 0 || data[1] == self.node) {
                self.nmt_command(data[0], now, out);
            }
            return;
        }
        if self.nmt == NmtState::Stopped {
            return;
        }
        if id == cob::SDO_RX + u16::from(self.node) {
            let mut server = std::mem::take(&mut self.sdo);
            let mut answers = Vec::new();
            server.handle(self, data, &mut answers);
            self.sdo = server;
            for r in &answers {
                out.push(Frame::new(cob::SDO_TX + u16::from(self.node), r).expect("id"));
            }
            out.append(&mut self.deferred);
            self.refresh();
            return;
        }
        if id == sync_id {
            self.on_sync(now, data, out);
            return;
        }
        if self.nmt != NmtState::Operational {
            return;
        }
        if let Some(n) = rpdo {
            self.on_rpdo(n, now, data, out);
        }
    }

    /// A heartbeat of a node we may consume (0x1016).
    fn on_heartbeat(&mut self, id: u16, now: Duration) {
        let producer = u32::from(id - cob::HEARTBEAT);
        for i in 0..4 {
            let e = self.od.int(index::CONSUMER_HEARTBEAT_TIME, i as u8 + 1) as u32;
            if e & 0xFFFF != 0 && (e >> 16) & 0x7F == producer {
                self.consumer[i] = (Some(now), false);
            }
        }
    }

    fn nmt_command(&mut self, cs: u8, now: Duration, out: &mut Vec<Frame>) {
        match cs {
            nmt::START => self.nmt = NmtState::Operational,
            nmt::STOP => {
                self.leave_operational();
                self.nmt = NmtState::Stopped;
            }
            nmt::PRE_OPERATIONAL => {
                self.leave_operational();
                self.nmt = NmtState::PreOperational;
            }
            nmt::RESET_NODE => {
                self.reset_keeping_motor();
                self.boot(now, out);
            }
            nmt::RESET_COMMUNICATION => {
                self.od.reset_range(index::COMMUNICATION_AREA);
                self.boot(now, out);
            }
            _ => {}
        }
        self.refresh();
    }

    /// Leaving Operational stops process data: the drive no longer receives setpoints, so it holds.
    fn leave_operational(&mut self) {
        self.pending_rpdo = [None; 4];
        self.last_sync = None;
        self.interp = None;
    }

    fn on_rpdo(&mut self, n: usize, now: Duration, data: &[u8], out: &mut Vec<Frame>) {
        if self.drop_rpdo() {
            self.rpdo_dropped += 1;
            return;
        }
        let map = self.mapping(rpdo_map(n));
        let len: usize = map.iter().map(|e| usize::from(e.bits / 8)).sum();
        if data.len() < len {
            self.emcy(emcy_code::PDO_LENGTH, 0x10, out);
            return;
        }
        if data.len() > len {
            self.emcy(emcy_code::PDO_TOO_LONG, 0x10, out);
        }
        let mut buf = [0u8; 8];
        buf[..data.len()].copy_from_slice(data);
        let tt = self.od.int(rpdo_base(n), 2);
        if tt <= 240 {
            // CiA 301: synchronous PDOs outside the synchronous window (0x1007) are discarded.
            let window = Duration::from_micros(self.od.int(index::SYNC_WINDOW_LENGTH, 0) as u64);
            if let Some(sync) = self.last_sync
                && !window.is_zero()
                && now > sync + window
            {
                self.rpdo_outside_window += 1;
                return;
            }
            self.pending_rpdo[n] = Some((buf, len));
        } else {
            self.apply_rpdo(n, &buf[..len], out);
        }
    }

    fn apply_rpdo(&mut self, n: usize, data: &[u8], out: &mut Vec<Frame>) {
        let map = self.mapping(rpdo_map(n));
        let mut off = 0;
        for e in map {
            let bytes = usize::from(e.bits / 8);
            if let Some(def) = self.od.def(e.index, e.sub)
                && let Ok(v) = Value::decode_le(def.data_type, &data[off..off + bytes])
            {
                self.od.set(e.index, e.sub, v);
                self.on_written(e.index, e.sub, out);
            }
            off += bytes;
        }
    }

    fn mapping(&self, map_index: u16) -> Vec<MapEntry> {
        let n = self.od.int(map_index, 0) as u8;
        (1..=n)
            .map(|s| MapEntry::from_u32(self.od.int(map_index, s) as u32))
            .collect()
    }

    fn on_sync(&mut self, now: Duration, data: &[u8], out: &mut Vec<Frame>) {
        let expect = if self.od.int(index::SYNC_COUNTER_OVERFLOW, 0) == 0 {
            0
        } else {
            1
        };
        if data.len() != expect {
            self.emcy(emcy_code::SYNC_LENGTH, 0x10, out);
        }
        if self.nmt != NmtState::Operational {
            return;
        }
        self.last_sync = Some(now);
        self.sync_missing_reported = false;
        // 1. Synchronous RPDOs received since the last SYNC take effect now.
        for n in 0..4 {
            if let Some((buf, len)) = self.pending_rpdo[n].take() {
                self.apply_rpdo(n, &buf[..len], out);
            }
        }
        // 2. The setpoint in force from this SYNC on.
        self.latch_setpoint(now);
        self.refresh();
        // 3. Synchronous TPDOs.
        for n in 0..4 {
            let c = self.od.int(tpdo_base(n), 1) as u32;
            let tt = self.od.int(tpdo_base(n), 2) as u32;
            if c & 0x8000_0000 != 0 || !(1..=240).contains(&tt) {
                continue;
            }
            self.tpdo_sync_count[n] += 1;
            if self.tpdo_sync_count[n] >= tt {
                self.tpdo_sync_count[n] = 0;
                let d = self.pack(tpdo_map(n));
                out.push(Frame::new((c & 0x7FF) as u16, &d).expect("≤ 8 bytes"));
            }
        }
    }

    fn send_event_tpdos(&mut self, now: Duration, out: &mut Vec<Frame>) {
        if self.nmt != NmtState::Operational {
            return;
        }
        for n in 0..4 {
            let c = self.od.int(tpdo_base(n), 1) as u32;
            let tt = self.od.int(tpdo_base(n), 2);
            if c & 0x8000_0000 != 0 || tt < 254 {
                continue;
            }
            let inhibit = Duration::from_micros(self.od.int(tpdo_base(n), 3) as u64 * 100);
            let timer = Duration::from_millis(self.od.int(tpdo_base(n), 5) as u64);
            let d = self.pack(tpdo_map(n));
            let due = match &self.tpdo_last[n] {
                None => true,
                Some((last, at)) => {
                    now >= *at + inhibit && (*last != d || (!timer.is_zero() && now >= *at + timer))
                }
            };
            if due {
                out.push(Frame::new((c & 0x7FF) as u16, &d).expect("≤ 8 bytes"));
                self.tpdo_last[n] = Some((d, now));
            }
        }
    }

    fn pack(&self, map_index: u16) -> Vec<u8> {
        let mut d = Vec::with_capacity(8);
        for e in self.mapping(map_index) {
            let mut b = [0u8; 8];
            let n = self
                .od
                .get(e.index, e.sub)
                .and_then(|v| v.encode_le(&mut b).ok())
                .unwrap_or(0);
            let want = usize::from(e.bits / 8);
            d.extend_from_slice(&b[..want.min(8)]);
            let _ = n;
        }
        d.truncate(8);
        d
    }

    /// The homing methods 0x60E3 lists, or all this drive runs if its dictionary has no 0x60E3.
    fn supported_homing_methods(&self) -> Vec<i8> {
        if self.od.get(index::SUPPORTED_HOMING_METHODS, 0).is_none() {
            return homing::SUPPORTED_METHODS.to_vec();
        }
        let n = self.od.int(index::SUPPORTED_HOMING_METHODS, 0) as u8;
        (1..=n)
            .map(|s| self.od.int(index::SUPPORTED_HOMING_METHODS, s) as i8)
            .filter(|m| homing::SUPPORTED_METHODS.contains(m))
            .collect()
    }

    /// The mode in force (0x6061).
    fn mode(&self) -> i8 {
        self.od.int(index::MODES_DISPLAY, 0) as i8
    }

    /// The setpoint object of the active mode becomes the interpolation target.
    fn latch_setpoint(&mut self, now: Duration) {
        let target = match self.mode() {
            7 if self.ip_active => self.od.int(index::IP_DATA_RECORD, 1),
            8 if self.power.is_operation_enabled() => self.od.int(index::TARGET_POSITION, 0),
            _ => {
                self.interp = None;
                return;
            }
        } as f64;
        // Software position limits (0x607D) bound the target itself, so neither the demand nor
        // the velocity feed-forward derived from it can carry the motor past them.
        let lo = self.od.int(index::SOFTWARE_POSITION_LIMIT, 1) as f64;
        let hi = self.od.int(index::SOFTWARE_POSITION_LIMIT, 2) as f64;
        let (lo, hi) = (lo.min(hi), hi.max(lo));
        self.limit_flag = !(lo..=hi).contains(&target);
        self.interp = Some(Interp {
            from: self.demand.clamp(lo, hi),
            to: target.clamp(lo, hi),
            at: now,
        });
    }

    /// Side effects of a write (by SDO or RPDO).
    fn on_written(&mut self, index: u16, sub: u8, out: &mut Vec<Frame>) {
        match (index, sub) {
            (index::CONTROLWORD, 0) => {
                self.on_controlword(self.od.int(index::CONTROLWORD, 0) as u16, out)
            }
            (index::MODES_OF_OPERATION, 0) => {
                // Only a different value is a mode change: masters that carry 0x6060 in their
                // cyclic RPDO (python-canopen's BaseNode402 does) rewrite the same mode every SYNC.
                let m = self.od.int(index::MODES_OF_OPERATION, 0);
                if m != self.od.int(index::MODES_DISPLAY, 0) {
                    if self.mode() == 6 {
                        // Bumpless out of homing: the IP buffer and the CSP target start where
                        // the drive holds (the master sends position actual next).
                        let hold = self.demand.round() as i64;
                        self.od.set_int(index::IP_DATA_RECORD, 1, hold);
                        self.od.set_int(index::TARGET_POSITION, 0, hold);
                    }
                    self.od.set_int(index::MODES_DISPLAY, 0, m);
                    self.ip_active = false;
                    self.interp = None;
                    self.homing.v = 0.0;
                    self.homing.stopping = false;
                    self.leave_homing_if_disabled();
                }
            }
            (index::QUICK_STOP_OPTION, 0) => {
                let _ = self
                    .power
                    .set_quick_stop_option(self.od.int(index::QUICK_STOP_OPTION, 0) as i16);
            }
            (index::PRODUCER_HEARTBEAT_TIME, 0) => {
                let now = self.last_physics.unwrap_or_default();
                self.schedule_heartbeat(now);
            }
            (index::CONSUMER_HEARTBEAT_TIME, _) => self.consumer = [(None, false); 4],
            (index::IP_DATA_CONFIG, 6) => {
                // Buffer clear: the one-deep buffer holds the actual position.
                let p = self.pos.round() as i64;
                self.od.set_int(index::IP_DATA_RECORD, 1, p);
            }
            _ => {}
        }
    }

    fn on_controlword(&mut self, cw: u16, out: &mut Vec<Frame>) {
        let was_fault = self.power.state() == State::Fault;
        let was_enabled = self.power.is_operation_enabled();
        if let Some(delay) = self.injects.iter().find_map(|(i, _)| match i {
            Inject::SlowEnable { delay } => Some(*delay),
            _ => None,
        }) && !was_enabled
        {
            let mut next = self.power.clone();
            next.on_controlword(cw);
            if next.is_operation_enabled() {
                let now = self.last_physics.unwrap_or_default();
                let asked = *self.enable_asked_at.get_or_insert(now);
                if now < asked + delay {
                    return; // still releasing the brake: Switched on
                }
            } else {
                self.enable_asked_at = None;
            }
        }
        self.power.on_controlword(cw);
        if self.power.is_operation_enabled() && !was_enabled {
            // Bumpless enable: the loop holds where the motor is.
            self.demand = self.pos;
            self.vel = 0.0;
            self.interp = None;
            self.homing.v = 0.0;
            self.homing.stopping = false;
        }
        if was_fault && self.power.state() != State::Fault {
            self.ferr_flag = false;
            self.fault_cause = None;
            self.od.set_int(index::ERROR_CODE, 0, 0);
            self.emcy(emcy_code::RESET, 0, out);
            self.od.set_int(index::ERROR_REGISTER, 0, 0);
            if self.recurring_fault.is_some() {
                let now = self.last_physics.unwrap_or_default();
                self.refault_at = Some(now + inject::RECURRING_FAULT_DELAY);
            }
        }
        // IP: bit 4 enables interpolation (rising edge), clearing it stops it.
        let bit4 = cw & cw_bits::IP_ENABLE != 0;
        let was4 = self.last_cw & cw_bits::IP_ENABLE != 0;
        self.last_cw = cw;
        if self.mode() == 7 && self.power.is_operation_enabled() {
            if bit4 && !was4 {
                match (self.ip_period(), self.sync_period()) {
                    (Some(ip), Some(sync)) if ip != sync => {
                        // 0x60C2 must equal the SYNC period: refuse to interpolate.
                        self.emcy(EMCY_PARAMETER, 0x80, out);
                    }
                    _ => {
                        self.ip_active = true;
                        self.interp = None;
                    }
                }
            } else if !bit4 {
                self.ip_active = false;
                self.interp = None;
            }
        } else {
            self.ip_active = false;
        }
        // Homing: bit 4's rising edge starts it; bit 4 cleared or halt (bit 8) interrupts it.
        let halt = cw & cw_bits::HALT != 0;
        if self.mode() == 6 && self.power.is_operation_enabled() {
            if bit4 && !was4 && !halt {
                self.start_homing();
            } else if (!bit4 || halt) && self.homing.status == HomingStatus::InProgress {
                self.homing.stop(HomingStatus::Interrupted);
            }
        }
        self.leave_homing_if_disabled();
        self.refresh();
    }

    /// Leaving Operation enabled (or mode 6) ends a homing run: the power stage stops the motor.
    fn leave_homing_if_disabled(&mut self) {
        if (!self.power.is_operation_enabled() || self.mode() != 6)
            && (self.homing.status == HomingStatus::InProgress || self.homing.stopping)
        {
            if self.homing.status == HomingStatus::InProgress {
                self.homing.status = HomingStatus::Interrupted;
            }
            self.homing.v = 0.0;
            self.homing.stopping = false;
            self.homing.goto = None;
        }
    }

    /// Start the method in 0x6098 from where the motor is.
    fn start_homing(&mut self) {
        let x = self.pos + self.origin;
        let limits = match self.setup.limit_switches_counts {
            Some([lo, hi]) => [f64::from(lo), f64::from(hi)],
            None => {
                let lo = self.od.int(index::SOFTWARE_POSITION_LIMIT, 1) as f64;
                let hi = self.od.int(index::SOFTWARE_POSITION_LIMIT, 2) as f64;
                [lo.min(hi) + self.origin, hi.max(lo) + self.origin]
            }
        };
        let switches = homing::Switches {
            home: self.setup.home_switch_counts.map(f64::from),
            limits,
        };
        let method = self.od.int(index::HOMING_METHOD, 0) as i8;
        self.homing = homing::HomingRun {
            status: HomingStatus::InProgress,
            switches,
            v: self.homing.v,
            ..Default::default()
        };
        match method {
            35 | 37 => {
                self.set_home(x);
                self.homing.status = HomingStatus::Attained;
            }
            m => match homing::legs(m, &switches, x) {
                Some(legs) => self.homing.legs = legs,
                None => self.homing.stop(HomingStatus::Error),
            },
        }
    }

    /// The physical position `edge` is the home: from now on it reads 0x607C.
    fn set_home(&mut self, edge: f64) {
        let offset = self.od.int(index::HOME_OFFSET, 0) as f64;
        let delta = offset - (edge - self.origin);
        self.pos += delta;
        self.demand += delta;
        self.origin -= delta;
        self.interp = None;
    }

    /// One physics step of homing: advance the demand the drive generates itself; its
    /// velocity (the feed-forward).
    fn homing_step(&mut self, dt: f64) -> f64 {
        let vmax = self.od.int(index::MAX_PROFILE_VELOCITY, 0).max(1) as f64;
        let acc = self.od.int(index::HOMING_ACCELERATION, 0).max(1) as f64;
        let fast = (self.od.int(index::HOMING_SPEEDS, 1).max(1) as f64).min(vmax);
        let slow = (self.od.int(index::HOMING_SPEEDS, 2).max(1) as f64).min(vmax);
        let h = &mut self.homing;
        if h.status == HomingStatus::InProgress && !h.stopping {
            if let Some(target) = h.goto {
                let (v, done) = homing::approach(self.demand, h.v, target, slow, acc, dt);
                if done {
                    self.demand = target;
                    h.v = 0.0;
                    h.goto = None;
                    h.status = HomingStatus::Attained;
                } else {
                    h.v = v;
                    self.demand += v * dt;
                }
                return h.v;
            }
            let x = self.pos + self.origin;
            let leg = h.legs[h.leg];
            let beyond = if leg.dir < 0.0 {
                homing::Switch::NegativeLimit
            } else {
                homing::Switch::PositiveLimit
            };
            if h.switches.active(leg.switch, x) == leg.until {
                if h.leg + 1 < h.legs.len() {
                    h.leg += 1;
                } else {
                    let edge = h.switches.edge(leg.switch).unwrap_or(x);
                    self.set_home(edge);
                    let offset = self.od.int(index::HOME_OFFSET, 0) as f64;
                    self.homing.goto = Some(offset);
                    return self.homing_step(dt);
                }
            } else if beyond != leg.switch && h.switches.active(beyond, x) {
                // The search reached the end of the travel: the switch is not there.
                h.stop(HomingStatus::Error);
            }
        }
        let h = &mut self.homing;
        let target = if h.status == HomingStatus::InProgress && !h.stopping {
            let leg = h.legs[h.leg];
            leg.dir * if leg.fast { fast } else { slow }
        } else {
            0.0
        };
        h.v = homing::ramp(h.v, target, acc, dt);
        if h.stopping && h.v == 0.0 {
            h.stopping = false;
        }
        self.demand += h.v * dt;
        h.v
    }

    /// Time in which the simulated world did not run (the thread that runs it was descheduled
    /// for `d`): the motor, its following-error timer and the setpoint being interpolated resume
    /// where they stopped, instead of moving through time in which nothing updated the demand.
    /// Everything else (the heartbeat producer, the SYNC and heartbeat consumers, event timers)
    /// stays on the caller's clock, as a real drive's would.
    pub fn skip(&mut self, d: Duration) {
        if let Some(t) = &mut self.last_physics {
            *t += d;
        }
        if let Some(t) = &mut self.ferr_since {
            *t += d;
        }
        if let Some(ip) = &mut self.interp {
            ip.at += d;
        }
    }

    /// Integrate the motor from the last update to `now`.
    fn physics(&mut self, now: Duration, out: &mut Vec<Frame>) {
        let Some(mut t) = self.last_physics else {
            self.last_physics = Some(now);
            return;
        };
        if t >= now {
            return;
        }
        while t < now {
            let dt = (now - t).min(STEP);
            t += dt;
            self.step(t, dt.as_secs_f64(), out);
        }
        self.last_physics = Some(now);
        self.refresh();
    }

    fn step(&mut self, t: Duration, dt: f64, out: &mut Vec<Frame>) {
        self.leave_homing_if_disabled();
        let vmax = self.od.int(index::MAX_PROFILE_VELOCITY, 0).max(1) as f64;
        // 0x60C5 limits the acceleration in every mode (0x6083 is the profile modes' ramp); a
        // dictionary without it gets the motor's own limit.
        let amax = match self.od.get(index::MAX_ACCELERATION, 0) {
            Some(_) => self.od.int(index::MAX_ACCELERATION, 0).max(1) as f64,
            None => MOTOR_ACC_COUNTS_S2,
        };
        match self.power.state() {
            State::OperationEnabled => {
                let mut v_ff = 0.0;
                let homing_mode = self.mode() == 6;
                if homing_mode {
                    v_ff = self.homing_step(dt);
                } else if let Some(ip) = self.interp {
                    let period = self
                        .ip_period()
                        .or(self.sync_period())
                        .unwrap_or(Duration::from_millis(1));
                    let p = period.as_secs_f64();
                    let frac = ((t.saturating_sub(ip.at)).as_secs_f64() / p).min(1.0);
                    self.demand = ip.from + (ip.to - ip.from) * frac;
                    if frac < 1.0 {
                        v_ff = (ip.to - ip.from) / p;
                    }
                }
                // Software position limits (0x607D) bound the demand (the target was clamped
                // when latched; a limit written since applies here).
                let lo = self.od.int(index::SOFTWARE_POSITION_LIMIT, 1) as f64;
                let hi = self.od.int(index::SOFTWARE_POSITION_LIMIT, 2) as f64;
                // A motor already beyond a limit (a homing search stops past the limit switch)
                // is not pulled back by the drive: the demand may stay where the motor is, and
                // only a setpoint brings it back in.
                let (lo, hi) = (lo.min(hi), hi.max(lo));
                let (lo, hi) = (lo.min(self.pos.round()), hi.max(self.pos.round()));
                if !homing_mode && !(lo..=hi).contains(&self.demand) {
                    self.limit_flag = true;
                    self.demand = self.demand.clamp(lo, hi);
                    v_ff = 0.0;
                }
                // A jammed motor (injected) does not move whatever it is told.
                let v_cmd = if self.jammed {
                    self.vel = 0.0;
                    0.0
                } else {
                    (K_FF * v_ff + KP_PER_S * (self.demand - self.pos)).clamp(-vmax, vmax)
                };
                let dv = (v_cmd - self.vel).clamp(-amax * dt, amax * dt);
                self.vel += dv;
                self.pos += self.vel * dt;
                // Following error: beyond 0x6065 for longer than 0x6066 ms.
                let window = self.od.int(index::FOLLOWING_ERROR_WINDOW, 0) as f64;
                let err = (self.demand - self.pos).abs();
                if err > window {
                    let since = *self.ferr_since.get_or_insert(t);
                    if t - since
                        > Duration::from_millis(
                            self.od.int(index::FOLLOWING_ERROR_TIMEOUT, 0) as u64
                        )
                    {
                        self.ferr_flag = true;
                        self.raise_fault(FaultCause::FollowingError, t, out, true);
                    }
                } else {
                    self.ferr_since = None;
                }
            }
            State::QuickStopActive | State::FaultReactionActive => {
                let dec = self.od.int(index::QUICK_STOP_DECELERATION, 0).max(1) as f64;
                let dv = self.vel.abs().min(dec * dt);
                self.vel -= dv * self.vel.signum();
                self.pos += self.vel * dt;
                self.demand = self.pos;
                if self.vel == 0.0 {
                    if self.power.state() == State::FaultReactionActive {
                        self.power.fault_reaction_done();
                    } else {
                        self.power.quick_stop_done();
                    }
                }
            }
            _ => {
                // No torque: the motor coasts to rest (friction).
                let dv = self.vel.abs().min(amax * dt);
                self.vel -= dv * self.vel.signum();
                self.pos += self.vel * dt;
                self.demand = self.pos;
            }
        }
    }

    /// Refresh the process values in the dictionary from the model.
    fn refresh(&mut self) {
        let mut s = self.power.statusword() | sw::REMOTE;
        let enabled = self.power.is_operation_enabled();
        if self.ferr_flag {
            s |= sw::OP_MODE_SPECIFIC_13;
        }
        if self.limit_flag && enabled {
            s |= sw::INTERNAL_LIMIT;
        }
        if self.warning {
            s |= sw::WARNING;
        }
        let following = match self.mode() {
            7 => enabled && self.ip_active,
            8 => enabled,
            _ => false,
        };
        if following {
            s |= sw::OP_MODE_SPECIFIC_12;
            if self.motion_since.is_none() {
                self.motion_since = self.last_physics;
            }
        }
        let window = self.od.int(index::POSITION_WINDOW, 0) as f64;
        let reached = (self.demand - self.pos).abs() <= window && self.vel.abs() < 1.0;
        if self.mode() == 6 && enabled {
            // CiA 402-2 homing statusword: bits 13/12/10.
            let standstill = reached && self.homing.v == 0.0;
            s |= match self.homing.status {
                HomingStatus::InProgress => 0,
                HomingStatus::NotStarted | HomingStatus::Interrupted => 0,
                HomingStatus::Attained => sw::HOMING_ATTAINED,
                HomingStatus::Error => sw::HOMING_ERROR,
            };
            if standstill && self.homing.status != HomingStatus::InProgress {
                s |= sw::TARGET_REACHED;
            }
        } else if reached {
            s |= sw::TARGET_REACHED;
        }
        self.od.set_int(index::STATUSWORD, 0, i64::from(s));
        self.od
            .set_int(index::POSITION_ACTUAL, 0, self.pos.round() as i64);
        self.od
            .set_int(index::POSITION_DEMAND, 0, self.demand.round() as i64);
        self.od
            .set_int(index::VELOCITY_ACTUAL, 0, self.vel.round() as i64);
        self.od.set_int(
            index::FOLLOWING_ERROR_ACTUAL,
            0,
            (self.demand - self.pos).round() as i64,
        );
    }

    /// The PDO number (0-based) and whether it is receive, for a communication or mapping index.
    fn pdo_of(index: u16) -> Option<(usize, bool, bool)> {
        match index {
            index::RPDO_COMMUNICATION..=RPDO_COMMUNICATION_LAST => {
                Some(((index - index::RPDO_COMMUNICATION) as usize, true, false))
            }
            index::RPDO_MAPPING..=RPDO_MAPPING_LAST => {
                Some(((index - index::RPDO_MAPPING) as usize, true, true))
            }
            index::TPDO_COMMUNICATION..=TPDO_COMMUNICATION_LAST => {
                Some(((index - index::TPDO_COMMUNICATION) as usize, false, false))
            }
            index::TPDO_MAPPING..=TPDO_MAPPING_LAST => {
                Some(((index - index::TPDO_MAPPING) as usize, false, true))
            }
            _ => None,
        }
    }

    fn pdo_valid(&self, n: usize, rx: bool) -> bool {
        let base = if rx { rpdo_base(n) } else { tpdo_base(n) };
        self.od.int(base, 1) as u32 & 0x8000_0000 == 0
    }

    /// CiA 301 §7.5.2.36: a mapping entry must name an existing, mappable object of that length.
    fn check_map_entry(&self, v: u32, rx: bool) -> Result<(), AbortCode> {
        if v == 0 {
            return Ok(());
        }
        let e = MapEntry::from_u32(v);
        let Some(def) = self.od.def(e.index, e.sub) else {
            return Err(if self.od.dictionary().objects.contains_key(&e.index) {
                AbortCode::NO_SUB
            } else {
                AbortCode::NO_OBJECT
            });
        };
        let ok_access = if rx {
            def.access.writable()
        } else {
            def.access.readable()
        };
        if !def.pdo || !ok_access || usize::from(e.bits) != def.data_type.size() * 8 {
            return Err(AbortCode::NOT_MAPPABLE);
        }
        Ok(())
    }

    /// Device rules on a decoded SDO write, before it is stored.
    fn check_device_rules(&self, index: u16, sub: u8, v: &Value) -> Result<(), AbortCode> {
        let x = crate::canopen::dictionary::value_as_i128(v).unwrap_or(0);
        if let Some((n, rx, is_map)) = Self::pdo_of(index) {
            let valid = self.pdo_valid(n, rx);
            if is_map {
                let map_index = index;
                // Mapping may change only while the PDO is invalid, and entries only while sub0 = 0.
                if valid {
                    return Err(AbortCode::UNSUPPORTED_ACCESS);
                }
                if sub == 0 {
                    let count = x as u8;
                    let mut bits = 0u32;
                    for s in 1..=count {
                        let e = self.od.int(map_index, s) as u32;
                        if e == 0 {
                            return Err(AbortCode::PARAM_INCOMPATIBLE);
                        }
                        self.check_map_entry(e, rx)?;
                        bits += e & 0xFF;
                    }
                    if bits > 64 {
                        return Err(AbortCode::PDO_TOO_LONG);
                    }
                } else {
                    if self.od.int(map_index, 0) != 0 {
                        return Err(AbortCode::UNSUPPORTED_ACCESS);
                    }
                    self.check_map_entry(x as u32, rx)?;
                }
            } else {
                match sub {
                    1 => {
                        let new = x as u32;
                        let old = self.od.int(index, 1) as u32;
                        if new & 0x2000_0000 != 0 {
                            return Err(AbortCode::INVALID_VALUE); // 29-bit ids not supported
                        }
                        let map_index = if rx { rpdo_map(n) } else { tpdo_map(n) };
                        if new & 0x8000_0000 == 0 {
                            if old & 0x8000_0000 == 0 && (new & 0x7FF) != (old & 0x7FF) {
                                return Err(AbortCode::INVALID_VALUE);
                            }
                            if self.od.int(map_index, 0) == 0 {
                                return Err(AbortCode::INVALID_VALUE);
                            }
                        }
                    }
                    2 if ((241..=251).contains(&x) || (rx && (252..=253).contains(&x))) => {
                        return Err(AbortCode::INVALID_VALUE);
                    }
                    _ => {}
                }
            }
            return Ok(());
        }
        match (index, sub) {
            (index::SYNC_COUNTER_OVERFLOW, 0)
                if self.od.int(index::COMMUNICATION_CYCLE_PERIOD, 0) != 0 =>
            {
                Err(AbortCode::DEVICE_STATE)
            }
            (index::SYNC_COUNTER_OVERFLOW, 0) if x == 1 => Err(AbortCode::INVALID_VALUE),
            (index::PREDEFINED_ERROR_FIELD, 0) if x != 0 => Err(AbortCode::INVALID_VALUE),
            (index::MODES_OF_OPERATION, 0) => {
                let supported = self.od.int(index::SUPPORTED_MODES, 0);
                if x != 0 && (!(1..=32).contains(&x) || supported & (1 << (x - 1)) == 0) {
                    return Err(AbortCode::INVALID_VALUE);
                }
                // Streaming setpoints (IP active, CSP) changes mode only to homing (CiA 402
                // allows a change at any time; a change between the cyclic modes mid-stream
                // would jump); a homing run in motion is not left.
                if self.power.is_operation_enabled()
                    && (self.ip_active || self.mode() == 8)
                    && x as i8 != self.mode()
                    && x != 6
                {
                    return Err(AbortCode::DEVICE_STATE);
                }
                if (self.homing.status == HomingStatus::InProgress || self.homing.stopping)
                    && x as i8 != self.mode()
                {
                    return Err(AbortCode::DEVICE_STATE);
                }
                Ok(())
            }
            (index::HOMING_METHOD, 0) => {
                if self.homing.status == HomingStatus::InProgress {
                    return Err(AbortCode::DEVICE_STATE);
                }
                if self.supported_homing_methods().contains(&(x as i8)) {
                    Ok(())
                } else {
                    Err(AbortCode::INVALID_VALUE)
                }
            }
            (index::IP_TIME_PERIOD, _) if self.ip_active => Err(AbortCode::DEVICE_STATE),
            _ => Ok(()),
        }
    }
}

impl SdoTarget for SimDrive {
    fn sdo_read(&mut self, index: u16, sub: u8) -> Result<Vec<u8>, AbortCode> {
        self.od.sdo_read(index, sub)
    }

    fn sdo_check_write(
        &mut self,
        index: u16,
        sub: u8,
        size: Option<usize>,
    ) -> Result<(), AbortCode> {
        self.od.sdo_check_write(index, sub, size)
    }

    fn sdo_write(&mut self, index: u16, sub: u8, data: &[u8]) -> Result<(), AbortCode> {
        let e = self.od.sdo_decode_write(index, sub, data)?;
        if let crate::canopen::od::Entry::Value(v) = &e {
            self.check_device_rules(index, sub, v)?;
        }
        self.od.set_entry(index, sub, e);
        if index == index::PREDEFINED_ERROR_FIELD {
            for s in 1..=8 {
                self.od.set_int(index::PREDEFINED_ERROR_FIELD, s, 0);
            }
        }
        let mut out = Vec::new();
        self.on_written(index, sub, &mut out);
        // EMCYs raised by an SDO write (e.g. a parameter error) go out with the next poll.
        self.deferred.extend(out);
        Ok(())
    }
}

#[cfg(test)]
mod tests;
