//! Start-up and the orderly end, sans-I/O: one [`Sequence`] of NMT commands and SDO transfers,
//! driven by `(now, received frame)` and `poll(now)` like [`crate::sim::SimDrive`].
//!
//! Start-up runs in the order CiA 301/402 ask for: reset communication, boot-ups, identity,
//! position actual (every axis inside its travel, and the caller's check of the motion from
//! there), heartbeats, the machine file's writes, limits, PDO remap with read-back, SYNC, IP
//! period, mode (confirmed by 0x6061), NMT start. Nothing is written to a drive before every axis
//! is known to stand inside its travel: the software position limits (0x607D) written to a drive
//! outside them make it pull towards them as soon as it is enabled, uncommanded.
//!
//! The axes are configured one after another, each SDO transfer to its end before the next
//! ([`SdoClient`], expedited or segmented, [`SDO_TIMEOUT`] per answer). The steps are built as a
//! list of operations when the sequence is made ([`Sequence::start_up`],
//! [`Sequence::orderly_end`]), so the objects written and their order can be read in one place
//! ([`configure_axis`]).
//!
//! ```text
//! let mut seq = Sequence::start_up(&machine);
//! let mut step = seq.poll(now, &mut out);
//! loop {
//!     send(out.drain(..));
//!     step = match step {
//!         Step::Pending { poll_at } => match wait_for_frame(poll_at) {   // the driver's I/O
//!             Some(frame) => seq.on_frame(now, &frame, &mut out),
//!             None => seq.poll(now, &mut out),
//!         },
//!         Step::StartHeartbeat { node, period } => { start_heartbeat(node, period); seq.poll(now, &mut out) }
//!         Step::CheckPositions => seq.proceed(now, &mut out),           // or seq.refuse(&mut out)
//!         Step::Done(result) => break result,
//!     }
//! }
//! ```
//!
//! Failures are typed ([`StartupError`]): node, object and the SDO error, which tells the node's
//! abort ([`SdoError::Aborted`]) from the gateway's own time-out ([`SdoError::TimedOut`]).

use std::collections::VecDeque;
use std::time::Duration;

use canopen_rs::{DataType, Value};

use crate::bus::Frame;
use crate::canopen::sdo_client::{self, Mode, Outcome, SdoClient, SdoError};
use crate::canopen::{NmtState, cob, index, nmt};
use crate::config::machine::{DRIVE_VELOCITY_HEADROOM, ip_time_period};
use crate::config::{AxisConfig, Machine, PdoConfig};

/// The entry of the drives' consumer heartbeat time (0x1016) that start-up writes with the
/// gateway's heartbeat, and the orderly end switches off.
pub const HEARTBEAT_CONSUMER_SUB: u8 = 1;

/// How long the drives have to boot after reset communication.
pub const BOOT_TIMEOUT: Duration = Duration::from_secs(3);

/// How long a drive may take to answer one SDO request.
pub const SDO_TIMEOUT: Duration = sdo_client::DEFAULT_TIMEOUT;

/// How long modes of operation display (0x6061) has to echo the mode written to 0x6060.
pub const MODE_TIMEOUT: Duration = Duration::from_secs(1);

/// How often 0x6061 is read again while it does not echo the mode yet.
pub const MODE_RETRY: Duration = Duration::from_millis(10);

/// An axis, by letter and node (what a person looks for on the machine).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AxisNode {
    /// Axis letter.
    pub axis: String,
    /// Its drive's node id.
    pub node: u8,
}

impl std::fmt::Display for AxisNode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "axis {} (node {})", self.axis, self.node)
    }
}

/// Why start-up or the orderly end failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StartupError {
    /// Nodes that sent no boot-up after reset communication.
    #[error(
        "no boot-up from {} within {} ms after NMT reset communication: is the drive powered, wired, at that node id and bitrate?",
        missing.iter().map(ToString::to_string).collect::<Vec<_>>().join(", "),
        timeout.as_millis()
    )]
    MissingNodes {
        /// The axes whose drive did not boot, in machine order.
        missing: Vec<AxisNode>,
        /// The wait ([`BOOT_TIMEOUT`]).
        timeout: Duration,
    },
    /// A node is not the device its dictionary describes.
    #[error(
        "axis {axis} (node {node}): {object} is 0x{found:08X}, the dictionary {dictionary} expects 0x{expected:08X}: wrong drive or wrong dictionary"
    )]
    WrongIdentity {
        /// Axis letter.
        axis: String,
        /// Node.
        node: u8,
        /// Which object, named (`"revision 0x1018:3"`).
        object: &'static str,
        /// What the dictionary says.
        expected: u32,
        /// What the node says.
        found: u32,
        /// The dictionary file.
        dictionary: String,
    },
    /// An SDO transfer failed: the node's abort, or the gateway's own (a time-out, a broken
    /// answer).
    #[error("node {node}: SDO {index:04X}:{sub:02X}: {error}")]
    Sdo {
        /// Node.
        node: u8,
        /// Object index (one of [`index`]).
        index: u16,
        /// Sub-index.
        sub: u8,
        /// What happened, and whose abort it was.
        error: SdoError,
    },
    /// An upload whose length does not fit the object's type.
    #[error("node {node}: SDO {index:04X}:{sub:02X}: {len} byte(s) do not hold a {data_type:?}")]
    SdoLength {
        /// Node.
        node: u8,
        /// Object index.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// The type expected.
        data_type: DataType,
        /// The bytes the node sent.
        len: usize,
    },
    /// A value read back differs from what was written.
    #[error("node {node}: {index:04X}:{sub:02X} reads back {found:?} after writing {written:?}")]
    ReadBack {
        /// Node.
        node: u8,
        /// Object index.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// Written.
        written: Value,
        /// Read back.
        found: Value,
    },
    /// Modes of operation display (0x6061) did not echo the mode within [`MODE_TIMEOUT`].
    #[error(
        "axis {axis} (node {node}): modes of operation display 0x6061 shows {found}, not mode {mode}, within {} ms",
        MODE_TIMEOUT.as_millis()
    )]
    ModeNotConfirmed {
        /// Axis letter.
        axis: String,
        /// Node.
        node: u8,
        /// The mode written to 0x6060.
        mode: i8,
        /// The last 0x6061 read.
        found: i8,
    },
    /// An axis stands outside its travel: refused before anything was written to a drive, every
    /// drive sent to Pre-operational.
    #[error(
        "axis {axis} (node {node}) is at {position_mm:.4} mm, outside its travel [{min_mm}, {max_mm}] mm"
    )]
    OutsideTravel {
        /// Axis letter.
        axis: String,
        /// Node.
        node: u8,
        /// Position actual (0x6064), mm.
        position_mm: f64,
        /// Travel.
        min_mm: f64,
        /// Travel.
        max_mm: f64,
    },
    /// The caller refused the motion from position actual ([`Sequence::refuse`]): every drive
    /// was sent to Pre-operational, nothing written.
    #[error("start-up refused from position actual: every drive was sent to Pre-operational")]
    Refused,
    /// The orderly end could not switch a drive's consumption of the gateway's heartbeat off.
    #[error(
        "axis {axis} (node {node}) could not be told to stop watching the gateway's heartbeat (0x1016:{HEARTBEAT_CONSUMER_SUB} = 0): {source}"
    )]
    HeartbeatStillConsumed {
        /// Axis letter.
        axis: String,
        /// Node.
        node: u8,
        /// The SDO failure.
        source: Box<StartupError>,
    },
}

/// Where a [`Sequence`] stands after a call.
#[derive(Debug, Clone, PartialEq)]
pub enum Step {
    /// Waiting for a frame: send what was pushed, then call [`Sequence::on_frame`] with each
    /// frame received, or [`Sequence::poll`] at `poll_at` if none comes.
    Pending {
        /// When to poll at the latest.
        poll_at: Duration,
    },
    /// Every node booted: the gateway's heartbeat (`0x700 + node`, state Operational, every
    /// `period`) must run from now on, before the drives are told to consume it. Then call
    /// [`Sequence::poll`].
    StartHeartbeat {
        /// The gateway's node id.
        node: u8,
        /// Its period.
        period: Duration,
    },
    /// Position actual of every axis is read ([`Sequence::positions`]) and inside its travel;
    /// nothing is written yet. Call [`Sequence::proceed`] or [`Sequence::refuse`].
    CheckPositions,
    /// The sequence ended.
    Done(Result<(), StartupError>),
}

/// One operation of a sequence.
#[derive(Debug, Clone, PartialEq)]
pub enum Op {
    /// An NMT command to one node.
    Nmt {
        /// Command specifier ([`nmt`]).
        cs: u8,
        /// Node.
        node: u8,
    },
    /// Wait for every axis's boot-up, [`BOOT_TIMEOUT`] from now.
    AwaitBootUps,
    /// Start the gateway's heartbeat ([`Step::StartHeartbeat`]).
    StartHeartbeat,
    /// Read an UNSIGNED32 of the identity and compare it with the axis's dictionary.
    Identity {
        /// Axis (machine order).
        axis: usize,
        /// Object index.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// The object, named for the error.
        object: &'static str,
        /// What the dictionary says.
        expected: u32,
    },
    /// Read position actual (0x6064) of an axis.
    ReadPosition {
        /// Axis (machine order).
        axis: usize,
    },
    /// Every axis inside its travel, then [`Step::CheckPositions`].
    CheckTravel,
    /// SDO download.
    Write {
        /// Node.
        node: u8,
        /// Object index.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// Value.
        value: Value,
    },
    /// SDO upload, compared with what was written.
    Verify {
        /// Node.
        node: u8,
        /// Object index.
        index: u16,
        /// Sub-index.
        sub: u8,
        /// The value expected.
        value: Value,
    },
    /// Read a PDO's COB-ID (`comm`:1) and set its bit 31 (not valid) if clear.
    DisablePdo {
        /// Node.
        node: u8,
        /// The PDO's communication parameter.
        comm: u16,
    },
    /// Read 0x6061 until it echoes `mode`, within [`MODE_TIMEOUT`] of the first read.
    ConfirmMode {
        /// Axis (machine order).
        axis: usize,
        /// The mode written to 0x6060.
        mode: i8,
        /// Set at the first read.
        deadline: Option<Duration>,
    },
}

impl Op {
    fn write(node: u8, index: u16, sub: u8, value: Value) -> Op {
        Op::Write {
            node,
            index,
            sub,
            value,
        }
    }

    /// A download read back.
    fn write_checked(ops: &mut Vec<Op>, node: u8, index: u16, sub: u8, value: Value) {
        ops.push(Op::write(node, index, sub, value));
        ops.push(Op::Verify {
            node,
            index,
            sub,
            value,
        });
    }
}

/// Refuses a start with an axis outside its travel (`counts`: position actual per axis, machine
/// order).
pub fn check_in_travel(m: &Machine, counts: &[i32]) -> Result<(), StartupError> {
    for (a, &c) in m.axes.iter().zip(counts) {
        let position_mm = a.counts_to_mm(c);
        if !(a.min_mm..=a.max_mm).contains(&position_mm) {
            return Err(StartupError::OutsideTravel {
                axis: a.name.clone(),
                node: a.node,
                position_mm,
                min_mm: a.min_mm,
                max_mm: a.max_mm,
            });
        }
    }
    Ok(())
}

/// CiA 301 §7.5.2.35–38: COB-ID invalid, mapping count 0, entries, count, transmission type,
/// COB-ID valid; then everything read back.
fn remap(ops: &mut Vec<Op>, node: u8, comm: u16, map: u16, pdo: &PdoConfig) {
    let cob = u32::from(pdo.cob_id);
    let count = Value::Unsigned8(pdo.mapping.len() as u8);
    ops.push(Op::write(
        node,
        comm,
        1,
        Value::Unsigned32(cob | 0x8000_0000),
    ));
    ops.push(Op::write(node, map, 0, Value::Unsigned8(0)));
    for (i, e) in pdo.mapping.iter().enumerate() {
        ops.push(Op::write(
            node,
            map,
            i as u8 + 1,
            Value::Unsigned32(e.to_u32()),
        ));
    }
    ops.push(Op::write(node, map, 0, count));
    ops.push(Op::write(node, comm, 2, Value::Unsigned8(pdo.transmission)));
    ops.push(Op::write(node, comm, 1, Value::Unsigned32(cob)));
    let verify = |index, sub, value| Op::Verify {
        node,
        index,
        sub,
        value,
    };
    ops.push(verify(comm, 1, Value::Unsigned32(cob)));
    ops.push(verify(comm, 2, Value::Unsigned8(pdo.transmission)));
    ops.push(verify(map, 0, count));
    for (i, e) in pdo.mapping.iter().enumerate() {
        ops.push(verify(map, i as u8 + 1, Value::Unsigned32(e.to_u32())));
    }
}

/// The operations that configure axis `i` of `m` once every axis is known to be inside its
/// travel: heartbeats, the machine file's writes, limits, PDOs, SYNC, IP period, mode.
pub fn configure_axis(m: &Machine, i: usize) -> Vec<Op> {
    let a: &AxisConfig = &m.axes[i];
    let n = a.node;
    let mut ops = Vec::new();
    // Heartbeats: the drive produces, and consumes the gateway's. The consumer entry is written
    // at every start-up, before NMT start: the orderly end of the last run switched it off, and
    // a drive must watch the gateway before it moves.
    let hb = &m.heartbeat;
    let consumer = (u32::from(hb.gateway_node) << 16) | u32::from(hb.drive_consumer_ms);
    for (index, sub, value) in [
        (
            index::PRODUCER_HEARTBEAT_TIME,
            0,
            Value::Unsigned16(hb.drive_producer_ms),
        ),
        (
            index::CONSUMER_HEARTBEAT_TIME,
            HEARTBEAT_CONSUMER_SUB,
            Value::Unsigned32(consumer),
        ),
    ] {
        Op::write_checked(&mut ops, n, index, sub, value);
    }
    // The machine file's own writes.
    for w in &a.sdo {
        Op::write_checked(&mut ops, n, w.index, w.sub, w.value);
    }
    // Limits in the drive's units, and its own velocity limit with head-room for its position
    // loop to catch up (the machine file's validation keeps it within UNSIGNED32).
    let counts = |mm: f64| a.mm_to_counts(mm);
    let vmax = (a.max_vel_mm_s * a.counts_per_mm * DRIVE_VELOCITY_HEADROOM).ceil() as u32;
    for (index, sub, value) in [
        (
            index::FOLLOWING_ERROR_WINDOW,
            0,
            Value::Unsigned32(counts(a.following_error_mm).unsigned_abs()),
        ),
        (
            index::FOLLOWING_ERROR_TIMEOUT,
            0,
            Value::Unsigned16(a.following_error_timeout_ms),
        ),
        (
            index::SOFTWARE_POSITION_LIMIT,
            1,
            Value::Integer32(counts(a.min_mm)),
        ),
        (
            index::SOFTWARE_POSITION_LIMIT,
            2,
            Value::Integer32(counts(a.max_mm)),
        ),
        (index::MAX_PROFILE_VELOCITY, 0, Value::Unsigned32(vmax)),
    ] {
        Op::write_checked(&mut ops, n, index, sub, value);
    }
    // Process data: our two PDOs, every other one off.
    let rx = a.setpoint_pdo.number;
    let tx = a.feedback_pdo.number;
    for k in 1..=4u8 {
        if k != rx {
            ops.push(Op::DisablePdo {
                node: n,
                comm: index::RPDO_COMMUNICATION + u16::from(k - 1),
            });
        }
        if k != tx {
            ops.push(Op::DisablePdo {
                node: n,
                comm: index::TPDO_COMMUNICATION + u16::from(k - 1),
            });
        }
    }
    remap(
        &mut ops,
        n,
        index::RPDO_COMMUNICATION + u16::from(rx - 1),
        index::RPDO_MAPPING + u16::from(rx - 1),
        &a.setpoint_pdo,
    );
    remap(
        &mut ops,
        n,
        index::TPDO_COMMUNICATION + u16::from(tx - 1),
        index::TPDO_MAPPING + u16::from(tx - 1),
        &a.feedback_pdo,
    );
    // SYNC consumer settings (the gateway produces SYNC); interpolation: linear sub-mode,
    // period = SYNC period.
    let (v, idx) = ip_time_period(m.cycle_us).expect("validated");
    for (index, sub, value) in [
        (
            index::COB_ID_SYNC,
            0,
            Value::Unsigned32(u32::from(m.sync_cob_id)),
        ),
        (
            index::COMMUNICATION_CYCLE_PERIOD,
            0,
            Value::Unsigned32(m.cycle_us),
        ),
        (
            index::SYNC_WINDOW_LENGTH,
            0,
            Value::Unsigned32(m.sync_window_us),
        ),
        (index::IP_SUBMODE, 0, Value::Integer16(0)),
        (index::IP_TIME_PERIOD, 1, Value::Unsigned8(v)),
        (index::IP_TIME_PERIOD, 2, Value::Integer8(idx)),
    ] {
        Op::write_checked(&mut ops, n, index, sub, value);
    }
    // Mode, confirmed by 0x6061.
    let mode = a.mode.number();
    ops.push(Op::write(
        n,
        index::MODES_OF_OPERATION,
        0,
        Value::Integer8(mode),
    ));
    ops.push(Op::ConfirmMode {
        axis: i,
        mode,
        deadline: None,
    });
    ops
}

#[derive(Debug)]
enum State {
    /// Between operations.
    Idle,
    /// An SDO transfer of `op` with `node` runs.
    Sdo { op: Op, node: u8, client: SdoClient },
    /// Waiting for boot-ups until `deadline`.
    BootUps { deadline: Duration },
    /// `op` runs again at `at`.
    Retry { op: Op, at: Duration },
    /// Waiting for [`Sequence::proceed`] or [`Sequence::refuse`].
    CheckPositions,
    /// Ended.
    Ended(Result<(), StartupError>),
}

/// What the sequence is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    StartUp,
    OrderlyEnd,
}

/// Start-up or the orderly end of a machine's drives (see the module documentation).
#[derive(Debug)]
pub struct Sequence<'m> {
    machine: &'m Machine,
    kind: Kind,
    ops: VecDeque<Op>,
    state: State,
    /// Per axis: a boot-up was seen since the reset.
    booted: Vec<bool>,
    /// Position actual per axis, as read.
    positions: Vec<i32>,
    sdo_out: Vec<[u8; 8]>,
}

impl<'m> Sequence<'m> {
    fn new(machine: &'m Machine, kind: Kind, ops: Vec<Op>) -> Sequence<'m> {
        Sequence {
            machine,
            kind,
            ops: ops.into(),
            state: State::Idle,
            booted: vec![false; machine.axes.len()],
            positions: Vec::with_capacity(machine.axes.len()),
            sdo_out: Vec::new(),
        }
    }

    /// Start-up of every axis of `machine`: the first frames come with the first
    /// [`Sequence::poll`].
    pub fn start_up(machine: &'m Machine) -> Sequence<'m> {
        let mut ops = Vec::new();
        let nmt_all = |ops: &mut Vec<Op>, cs| {
            ops.extend(machine.axes.iter().map(|a| Op::Nmt { cs, node: a.node }));
        };
        nmt_all(&mut ops, nmt::RESET_COMMUNICATION);
        ops.push(Op::AwaitBootUps);
        ops.push(Op::StartHeartbeat);
        for (i, a) in machine.axes.iter().enumerate() {
            let id = a.dictionary.identity;
            for (index, sub, object, expected) in [
                (index::DEVICE_TYPE, 0, "device type 0x1000", id.device_type),
                (index::IDENTITY, 1, "vendor-ID 0x1018:1", id.vendor_id),
                (index::IDENTITY, 2, "product code 0x1018:2", id.product_code),
                (index::IDENTITY, 3, "revision 0x1018:3", id.revision),
            ] {
                ops.push(Op::Identity {
                    axis: i,
                    index,
                    sub,
                    object,
                    expected,
                });
            }
            ops.push(Op::ReadPosition { axis: i });
        }
        ops.push(Op::CheckTravel);
        for i in 0..machine.axes.len() {
            ops.extend(configure_axis(machine, i));
        }
        nmt_all(&mut ops, nmt::START);
        Sequence::new(machine, Kind::StartUp, ops)
    }

    /// The orderly end, once every drive is disabled and before the gateway's heartbeat stops:
    /// every drive stops consuming it (0x1016:[`HEARTBEAT_CONSUMER_SUB`] = 0, read back).
    ///
    /// Heartbeat consumption goes on in Pre-operational (CiA 301 §7.2.8.3.2.2), so without this
    /// every drive would report a heartbeat loss (EMCY 0x8130, and Fault with 0x6007 = 1) some
    /// 0.5 s after a clean run. Not after a fault stop (the caller's choice): the drives keep
    /// watching, so that a drive still stops by itself should the gateway die next. The next
    /// start-up writes the entry again.
    pub fn orderly_end(machine: &'m Machine) -> Sequence<'m> {
        let mut ops = Vec::new();
        for a in &machine.axes {
            Op::write_checked(
                &mut ops,
                a.node,
                index::CONSUMER_HEARTBEAT_TIME,
                HEARTBEAT_CONSUMER_SUB,
                Value::Unsigned32(0),
            );
        }
        Sequence::new(machine, Kind::OrderlyEnd, ops)
    }

    /// Position actual per axis (machine order), as far as read.
    pub fn positions(&self) -> &[i32] {
        &self.positions
    }

    /// Time passes: runs what is due (the first call starts the sequence).
    pub fn poll(&mut self, now: Duration, out: &mut Vec<Frame>) -> Step {
        if let State::Sdo { client, .. } = &mut self.state {
            let mut sdo_out = std::mem::take(&mut self.sdo_out);
            let step = client.poll(now, &mut sdo_out);
            self.sdo_step(step, &mut sdo_out, now, out);
            self.sdo_out = sdo_out;
        }
        self.advance(now, out)
    }

    /// A frame from the bus (any: the sequence takes the boot-ups and SDO answers of its nodes).
    pub fn on_frame(&mut self, now: Duration, frame: &Frame, out: &mut Vec<Frame>) -> Step {
        let id = frame.id();
        match &mut self.state {
            State::BootUps { .. }
                if id > cob::HEARTBEAT
                    && id <= cob::HEARTBEAT + 0x7F
                    && frame.data().len() == 1
                    && NmtState::from_byte(frame.data()[0]) == Some(NmtState::BootUp) =>
            {
                let node = (id - cob::HEARTBEAT) as u8;
                for (seen, a) in self.booted.iter_mut().zip(&self.machine.axes) {
                    *seen |= a.node == node;
                }
            }
            State::Sdo { node, client, .. } if id == cob::SDO_TX + u16::from(*node) => {
                let mut sdo_out = std::mem::take(&mut self.sdo_out);
                let step = client.on_response(frame.data(), now, &mut sdo_out);
                self.sdo_step(step, &mut sdo_out, now, out);
                self.sdo_out = sdo_out;
            }
            _ => {}
        }
        self.advance(now, out)
    }

    /// After [`Step::CheckPositions`]: the caller accepts the motion from [`Sequence::positions`];
    /// configuration goes on.
    pub fn proceed(&mut self, now: Duration, out: &mut Vec<Frame>) -> Step {
        if matches!(self.state, State::CheckPositions) {
            self.state = State::Idle;
        }
        self.advance(now, out)
    }

    /// After [`Step::CheckPositions`]: the caller refuses the motion. Every drive is sent to
    /// Pre-operational (the NMT frames are pushed), nothing having been written; the sequence
    /// ends with [`StartupError::Refused`].
    pub fn refuse(&mut self, out: &mut Vec<Frame>) {
        if matches!(self.state, State::CheckPositions) {
            self.end_pre_operational(StartupError::Refused, out);
        }
    }

    fn end_pre_operational(&mut self, e: StartupError, out: &mut Vec<Frame>) {
        for a in &self.machine.axes {
            out.push(nmt_frame(nmt::PRE_OPERATIONAL, a.node));
        }
        self.ops.clear();
        self.state = State::Ended(Err(e));
    }

    fn axis_of(&self, node: u8) -> Option<&'m AxisConfig> {
        self.machine.axes.iter().find(|a| a.node == node)
    }

    /// Runs operations until one waits.
    fn advance(&mut self, now: Duration, out: &mut Vec<Frame>) -> Step {
        loop {
            match &self.state {
                State::Idle => {}
                State::Sdo { client, .. } => {
                    return Step::Pending {
                        poll_at: client.poll_at(),
                    };
                }
                State::BootUps { deadline } => {
                    let deadline = *deadline;
                    if self.booted.iter().all(|b| *b) {
                        self.state = State::Idle;
                    } else if now >= deadline {
                        let missing = self
                            .machine
                            .axes
                            .iter()
                            .zip(&self.booted)
                            .filter(|(_, b)| !**b)
                            .map(|(a, _)| AxisNode {
                                axis: a.name.clone(),
                                node: a.node,
                            })
                            .collect();
                        self.state = State::Ended(Err(StartupError::MissingNodes {
                            missing,
                            timeout: BOOT_TIMEOUT,
                        }));
                    } else {
                        return Step::Pending { poll_at: deadline };
                    }
                    continue;
                }
                State::Retry { at, .. } if now < *at => return Step::Pending { poll_at: *at },
                State::Retry { .. } => {
                    if let State::Retry { op, .. } = std::mem::replace(&mut self.state, State::Idle)
                    {
                        self.ops.push_front(op);
                    }
                }
                State::CheckPositions => return Step::CheckPositions,
                State::Ended(r) => return Step::Done(r.clone()),
            }
            let Some(op) = self.ops.pop_front() else {
                self.state = State::Ended(Ok(()));
                continue;
            };
            if let Some(step) = self.begin(op, now, out) {
                return step;
            }
        }
    }

    /// Starts `op`; a step to return at once, if it has one.
    fn begin(&mut self, op: Op, now: Duration, out: &mut Vec<Frame>) -> Option<Step> {
        let upload = |node, index, sub| (node, index, sub, None);
        let (node, index, sub, data) = match &op {
            Op::Nmt { cs, node } => {
                out.push(nmt_frame(*cs, *node));
                return None;
            }
            Op::AwaitBootUps => {
                self.booted.fill(false);
                self.state = State::BootUps {
                    deadline: now + BOOT_TIMEOUT,
                };
                return None;
            }
            Op::StartHeartbeat => {
                let hb = &self.machine.heartbeat;
                return Some(Step::StartHeartbeat {
                    node: hb.gateway_node,
                    period: Duration::from_millis(u64::from(hb.gateway_producer_ms)),
                });
            }
            Op::CheckTravel => {
                match check_in_travel(self.machine, &self.positions) {
                    Ok(()) => self.state = State::CheckPositions,
                    Err(e) => self.end_pre_operational(e, out),
                }
                return None;
            }
            Op::Identity {
                axis, index, sub, ..
            } => upload(self.machine.axes[*axis].node, *index, *sub),
            Op::ReadPosition { axis } => {
                upload(self.machine.axes[*axis].node, index::POSITION_ACTUAL, 0)
            }
            Op::Write {
                node,
                index,
                sub,
                value,
            } => (
                *node,
                *index,
                *sub,
                Some(crate::canopen::value_bytes(value)),
            ),
            Op::Verify {
                node, index, sub, ..
            } => upload(*node, *index, *sub),
            Op::DisablePdo { node, comm } => upload(*node, *comm, 1),
            Op::ConfirmMode { axis, .. } => {
                upload(self.machine.axes[*axis].node, index::MODES_DISPLAY, 0)
            }
        };
        let mut op = op;
        if let Op::ConfirmMode { deadline, .. } = &mut op {
            deadline.get_or_insert(now + MODE_TIMEOUT);
        }
        let mut sdo_out = std::mem::take(&mut self.sdo_out);
        let client = match data {
            Some(bytes) => {
                SdoClient::download(index, sub, bytes, Mode::Segmented, now, &mut sdo_out)
            }
            None => SdoClient::upload(index, sub, Mode::Segmented, now, &mut sdo_out),
        }
        .with_timeout(SDO_TIMEOUT, now);
        push_sdo(node, &mut sdo_out, out);
        self.sdo_out = sdo_out;
        self.state = State::Sdo { op, node, client };
        None
    }

    /// Sends what the SDO client pushed; if its transfer ended, finishes the operation.
    fn sdo_step(
        &mut self,
        step: sdo_client::Step,
        sdo_out: &mut Vec<[u8; 8]>,
        now: Duration,
        out: &mut Vec<Frame>,
    ) {
        let State::Sdo { node, .. } = &self.state else {
            return;
        };
        let node = *node;
        // The client's own abort, if it sent one, goes out before the error.
        push_sdo(node, sdo_out, out);
        let sdo_client::Step::Done(result) = step else {
            return;
        };
        let State::Sdo { op, client, .. } = std::mem::replace(&mut self.state, State::Idle) else {
            return;
        };
        let (index, sub) = client.address();
        let result = result
            .map_err(|error| StartupError::Sdo {
                node,
                index,
                sub,
                error,
            })
            .and_then(|outcome| self.finish(op, node, outcome, now));
        if let Err(e) = result {
            let e = match (self.kind, self.axis_of(node)) {
                (Kind::OrderlyEnd, Some(a)) => StartupError::HeartbeatStillConsumed {
                    axis: a.name.clone(),
                    node,
                    source: Box::new(e),
                },
                _ => e,
            };
            self.ops.clear();
            self.state = State::Ended(Err(e));
        }
    }

    /// What an operation's SDO transfer brought.
    fn finish(
        &mut self,
        op: Op,
        node: u8,
        outcome: Outcome,
        now: Duration,
    ) -> Result<(), StartupError> {
        let bytes = match outcome {
            Outcome::Uploaded(bytes) => bytes,
            Outcome::Downloaded => Vec::new(),
        };
        let decode = |index, sub, data_type| {
            Value::decode_le(data_type, &bytes).map_err(|_| StartupError::SdoLength {
                node,
                index,
                sub,
                data_type,
                len: bytes.len(),
            })
        };
        match op {
            Op::Write { .. } => Ok(()),
            Op::Identity {
                axis,
                index,
                sub,
                object,
                expected,
            } => {
                let found = match decode(index, sub, DataType::Unsigned32)? {
                    Value::Unsigned32(v) => v,
                    _ => 0,
                };
                if found == expected {
                    return Ok(());
                }
                let a = &self.machine.axes[axis];
                Err(StartupError::WrongIdentity {
                    axis: a.name.clone(),
                    node,
                    object,
                    expected,
                    found,
                    dictionary: a.dictionary.file.display().to_string(),
                })
            }
            Op::ReadPosition { .. } => {
                let counts = match decode(index::POSITION_ACTUAL, 0, DataType::Integer32)? {
                    Value::Integer32(v) => v,
                    _ => 0,
                };
                self.positions.push(counts);
                Ok(())
            }
            Op::Verify {
                index, sub, value, ..
            } => {
                let found = decode(index, sub, value.data_type())?;
                if found == value {
                    return Ok(());
                }
                Err(StartupError::ReadBack {
                    node,
                    index,
                    sub,
                    written: value,
                    found,
                })
            }
            Op::DisablePdo { comm, .. } => {
                let cob = match decode(comm, 1, DataType::Unsigned32)? {
                    Value::Unsigned32(v) => v,
                    _ => 0,
                };
                if cob & 0x8000_0000 == 0 {
                    self.ops.push_front(Op::write(
                        node,
                        comm,
                        1,
                        Value::Unsigned32(cob | 0x8000_0000),
                    ));
                }
                Ok(())
            }
            Op::ConfirmMode {
                axis,
                mode,
                deadline,
            } => {
                let found = match decode(index::MODES_DISPLAY, 0, DataType::Integer8)? {
                    Value::Integer8(v) => v,
                    _ => -1,
                };
                if found == mode {
                    return Ok(());
                }
                if deadline.is_some_and(|d| now > d) {
                    return Err(StartupError::ModeNotConfirmed {
                        axis: self.machine.axes[axis].name.clone(),
                        node,
                        mode,
                        found,
                    });
                }
                self.state = State::Retry {
                    op: Op::ConfirmMode {
                        axis,
                        mode,
                        deadline,
                    },
                    at: now + MODE_RETRY,
                };
                Ok(())
            }
            Op::Nmt { .. } | Op::AwaitBootUps | Op::StartHeartbeat | Op::CheckTravel => Ok(()),
        }
    }
}

fn nmt_frame(cs: u8, node: u8) -> Frame {
    Frame::new(cob::NMT, &[cs, node]).expect("an NMT frame")
}

fn push_sdo(node: u8, sdo_out: &mut Vec<[u8; 8]>, out: &mut Vec<Frame>) {
    let id = cob::SDO_RX + u16::from(node);
    out.extend(
        sdo_out
            .drain(..)
            .map(|d| Frame::new(id, &d).expect("an SDO request")),
    );
}
