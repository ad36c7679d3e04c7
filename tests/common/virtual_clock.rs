//! The virtual-clock rig: the sans-I/O master ([`CyclicMaster`] and [`Supervision`], with the
//! gateway's [`CyclicBus`] for error frames and transmission) and N [`SimDrive`]s exchange
//! frames through an in-process bus on a simulated clock. No thread, no sleep: cycle `k` runs at
//! exactly `k × period`, the drives run at their own deadlines ([`SimDrive::poll_at`]) in between,
//! so every detection falls in a cycle a test can compute and assert exactly.
//!
//! Start-up is reduced to what it leaves behind: each drive's dictionary gets the writes the
//! gateway's start-up makes over SDO (heartbeats, limits, PDO remap, SYNC, mode), applied
//! directly ([`SdoTarget::sdo_write`]), then NMT start. The cyclic phase is the gateway's cyclic
//! thread, step for step: receive, supervise, supply the motion once armed, cycle, send.

use std::time::Duration;

use canmotion::bus::inproc::{InProcBus, InProcPort};
use canmotion::bus::{Filter, Frame, Port};
use canmotion::canopen::index;
use canmotion::canopen::sdo_server::SdoTarget;
use canmotion::canopen::{NmtState, cob, nmt};
use canmotion::config::machine::ip_time_period;
use canmotion::config::{AxisConfig, Machine};
use canmotion::gateway::cyclic_bus::CyclicBus;
use canmotion::interpolator::{Interpolator, OverrideRamp};
use canmotion::master::cyclic::{CycleRecord, CyclicMaster, Phase};
use canmotion::master::supervision::Supervision;
use canmotion::sim::SimDrive;
use canopen_rs::Value;

/// One frame a drive sent, and when.
#[derive(Debug, Clone, Copy)]
pub struct Sent {
    /// Virtual time.
    pub at: Duration,
    /// The frame.
    pub frame: Frame,
}

/// The rig (see the module documentation).
pub struct Rig {
    pub machine: Machine,
    pub master: CyclicMaster,
    pub sup: Supervision,
    pub drives: Vec<SimDrive>,
    /// The program, planned once the drives are armed.
    program: String,
    master_port: InProcPort,
    drive_port: InProcPort,
    cyc_bus: CyclicBus,
    /// Virtual time now.
    pub now: Duration,
    pub period: Duration,
    /// The drives' time.
    drives_at: Duration,
    /// When the drives were last polled.
    last_poll: Option<Duration>,
    next_gateway_heartbeat: Duration,
    out: Vec<Frame>,
    /// Every cycle's record.
    pub records: Vec<CycleRecord>,
    /// Every frame the drives sent (error frames not included).
    pub drive_frames: Vec<Sent>,
    /// When the drives sent the injected error frames.
    pub error_frames: Vec<Duration>,
    /// Every frame the master side sent (RPDOs, SYNC, its heartbeat).
    pub master_frames: Vec<Sent>,
    /// When the master's failure was first seen (after the poll or the cycle that raised it).
    pub failed_at: Option<Duration>,
}

fn write(d: &mut SimDrive, index: u16, sub: u8, v: Value) {
    let mut buf = [0u8; 8];
    let n = v.encode_le(&mut buf).unwrap();
    d.sdo_write(index, sub, &buf[..n])
        .unwrap_or_else(|e| panic!("node {}: {index:04X}:{sub:02X}: {e}", d.node()));
}

fn remap(d: &mut SimDrive, comm: u16, map: u16, pdo: &canmotion::config::PdoConfig) {
    let cob = u32::from(pdo.cob_id);
    write(d, comm, 1, Value::Unsigned32(cob | 0x8000_0000));
    write(d, map, 0, Value::Unsigned8(0));
    for (i, e) in pdo.mapping.iter().enumerate() {
        write(d, map, i as u8 + 1, Value::Unsigned32(e.to_u32()));
    }
    write(d, map, 0, Value::Unsigned8(pdo.mapping.len() as u8));
    write(d, comm, 2, Value::Unsigned8(pdo.transmission));
    write(d, comm, 1, Value::Unsigned32(cob));
}

/// The start-up's writes to one axis's drive (see `gateway::startup::configure_axis`).
fn configure(d: &mut SimDrive, m: &Machine, a: &AxisConfig) {
    let hb = &m.heartbeat;
    write(
        d,
        index::PRODUCER_HEARTBEAT_TIME,
        0,
        Value::Unsigned16(hb.drive_producer_ms),
    );
    write(
        d,
        index::CONSUMER_HEARTBEAT_TIME,
        1,
        Value::Unsigned32((u32::from(hb.gateway_node) << 16) | u32::from(hb.drive_consumer_ms)),
    );
    for w in &a.sdo {
        write(d, w.index, w.sub, w.value);
    }
    let counts = |mm: f64| a.mm_to_counts(mm);
    write(
        d,
        index::FOLLOWING_ERROR_WINDOW,
        0,
        Value::Unsigned32(counts(a.following_error_mm).unsigned_abs()),
    );
    write(
        d,
        index::FOLLOWING_ERROR_TIMEOUT,
        0,
        Value::Unsigned16(a.following_error_timeout_ms),
    );
    write(
        d,
        index::SOFTWARE_POSITION_LIMIT,
        1,
        Value::Integer32(counts(a.min_mm)),
    );
    write(
        d,
        index::SOFTWARE_POSITION_LIMIT,
        2,
        Value::Integer32(counts(a.max_mm)),
    );
    let vmax =
        (a.max_vel_mm_s * a.counts_per_mm * canmotion::config::machine::DRIVE_VELOCITY_HEADROOM)
            .ceil() as u32;
    write(d, index::MAX_PROFILE_VELOCITY, 0, Value::Unsigned32(vmax));
    let (rx, tx) = (a.setpoint_pdo.number, a.feedback_pdo.number);
    for k in 1..=4u8 {
        for (base, used) in [
            (index::RPDO_COMMUNICATION, rx),
            (index::TPDO_COMMUNICATION, tx),
        ] {
            if k != used {
                let c = base + u16::from(k - 1);
                let cob = u32::from_le_bytes(d.sdo_read(c, 1).unwrap()[..4].try_into().unwrap());
                write(d, c, 1, Value::Unsigned32(cob | 0x8000_0000));
            }
        }
    }
    remap(
        d,
        index::RPDO_COMMUNICATION + u16::from(rx - 1),
        index::RPDO_MAPPING + u16::from(rx - 1),
        &a.setpoint_pdo,
    );
    remap(
        d,
        index::TPDO_COMMUNICATION + u16::from(tx - 1),
        index::TPDO_MAPPING + u16::from(tx - 1),
        &a.feedback_pdo,
    );
    write(
        d,
        index::COB_ID_SYNC,
        0,
        Value::Unsigned32(u32::from(m.sync_cob_id)),
    );
    write(
        d,
        index::COMMUNICATION_CYCLE_PERIOD,
        0,
        Value::Unsigned32(m.cycle_us),
    );
    write(
        d,
        index::SYNC_WINDOW_LENGTH,
        0,
        Value::Unsigned32(m.sync_window_us),
    );
    let (v, idx) = ip_time_period(m.cycle_us).unwrap();
    write(d, index::IP_SUBMODE, 0, Value::Integer16(0));
    write(d, index::IP_TIME_PERIOD, 1, Value::Unsigned8(v));
    write(d, index::IP_TIME_PERIOD, 2, Value::Integer8(idx));
    write(
        d,
        index::MODES_OF_OPERATION,
        0,
        Value::Integer8(a.mode.number()),
    );
}

impl Rig {
    /// `drives` (one per axis, machine order, not yet booted) configured for `machine`, started,
    /// and the master ready for its first cycle; `program` runs once they are armed.
    pub fn new(machine: Machine, mut drives: Vec<SimDrive>, program: &str) -> Rig {
        let bus = InProcBus::new();
        let mut boot = Vec::new();
        for (d, a) in drives.iter_mut().zip(&machine.axes) {
            d.boot(Duration::ZERO, &mut boot);
            configure(d, &machine, a);
        }
        // The drives' port hears everything the master side sends.
        let drive_port = bus.port(&[Filter { id: 0, mask: 0 }]);
        let filters: Vec<Filter> = machine
            .axes
            .iter()
            .flat_map(|a| {
                let node = u16::from(a.node);
                [
                    Filter::exact(a.feedback_pdo.cob_id),
                    Filter::exact(cob::HEARTBEAT + node),
                    Filter::exact(cob::EMCY + node),
                ]
            })
            .collect();
        let mut master_port = bus.port(&filters);
        let cyc_bus = CyclicBus::new(&machine, "vcan0", &mut master_port, None).unwrap();
        let master = CyclicMaster::new(&machine);
        let sup = Supervision::new(&machine);
        let period = Duration::from_micros(u64::from(machine.cycle_us));
        let mut rig = Rig {
            master,
            sup,
            drives,
            program: program.to_string(),
            master_port,
            drive_port,
            cyc_bus,
            now: Duration::ZERO,
            period,
            drives_at: Duration::ZERO,
            last_poll: None,
            next_gateway_heartbeat: Duration::ZERO,
            out: Vec::with_capacity(machine.axes.len() + 1),
            records: Vec::new(),
            drive_frames: Vec::new(),
            error_frames: Vec::new(),
            master_frames: Vec::new(),
            failed_at: None,
            machine,
        };
        // The gateway's heartbeat, then NMT start to every node: Operational at time 0.
        rig.gateway_heartbeat();
        let start = Frame::new(cob::NMT, &[nmt::START, 0]).unwrap();
        rig.master_send(start);
        rig.deliver_to_drives();
        rig
    }

    fn master_send(&mut self, f: Frame) {
        self.master_port.send(&f).unwrap();
        self.master_frames.push(Sent {
            at: self.now,
            frame: f,
        });
    }

    fn gateway_heartbeat(&mut self) {
        let hb = self.machine.heartbeat;
        let f = Frame::new(
            cob::HEARTBEAT + u16::from(hb.gateway_node),
            &[NmtState::Operational.byte()],
        )
        .unwrap();
        self.master_send(f);
        self.next_gateway_heartbeat =
            self.now + Duration::from_millis(u64::from(hb.gateway_producer_ms));
    }

    /// Whatever the master side sent, to every drive, at `now`.
    fn deliver_to_drives(&mut self) {
        let mut out = Vec::new();
        while let Ok(Some(f)) = self.drive_port.recv_timeout(Duration::ZERO) {
            for d in &mut self.drives {
                d.handle(self.now, &f, &mut out);
            }
        }
        self.drives_send(self.now, out);
    }

    fn drives_send(&mut self, at: Duration, frames: Vec<Frame>) {
        for f in frames {
            self.drive_port.send(&f).unwrap();
            self.drive_frames.push(Sent { at, frame: f });
        }
        for e in self.drives.iter_mut().flat_map(|d| d.take_bus_errors()) {
            self.drive_port.send_error(&e).unwrap();
            self.error_frames.push(at);
        }
    }

    /// The drives run at their own deadlines up to `until` (inclusive). A deadline at or before
    /// the last poll is one that poll did not clear (a stopped heartbeat producer keeps its past
    /// deadline): the next other deadline serves it.
    fn run_drives(&mut self, until: Duration) {
        loop {
            let next = self
                .drives
                .iter()
                .map(|d| d.poll_at(self.drives_at))
                .filter(|&t| self.last_poll.is_none_or(|l| t > l))
                .min();
            let Some(t) = next.map(|t| t.max(self.drives_at)) else {
                break;
            };
            if t > until {
                break;
            }
            let mut out = Vec::new();
            for d in &mut self.drives {
                d.poll(t, &mut out);
            }
            self.drives_send(t, out);
            self.last_poll = Some(t);
            self.drives_at = t;
        }
        self.drives_at = until;
    }

    /// The cycle number about to run.
    pub fn next_cycle(&self) -> u64 {
        self.master.cycle_number() + 1
    }

    /// One cycle at the next multiple of the period.
    pub fn step(&mut self) {
        self.now += self.period;
        self.run_drives(self.now);
        let cycle = self.next_cycle();
        self.cyc_bus
            .receive(
                &mut self.master_port,
                &mut self.master,
                &mut self.sup,
                self.now,
                cycle,
            )
            .unwrap();
        self.sup.poll(self.now, &mut self.master);
        if self.master.phase() == Phase::Armed && self.master.motion().is_none() {
            let interp = self.plan();
            self.master.supply_motion(interp);
        }
        self.out.clear();
        let rec = self.master.cycle(self.machine.sync_cob_id, &mut self.out);
        self.records.push(rec);
        if self.master.failure().is_some() && self.failed_at.is_none() {
            self.failed_at = Some(self.now);
        }
        let out = std::mem::take(&mut self.out);
        self.cyc_bus.send(
            &mut self.master_port,
            &out,
            u64::MAX / 4,
            &mut self.master,
            cycle,
        );
        for f in &out {
            self.master_frames.push(Sent {
                at: self.now,
                frame: *f,
            });
        }
        self.out = out;
        if self.now >= self.next_gateway_heartbeat && !self.cyc_bus.lost() {
            self.gateway_heartbeat();
        }
        self.deliver_to_drives();
    }

    fn plan(&self) -> Interpolator {
        let m = &self.machine;
        let plan = canmotion::gateway::plan_program(
            m,
            "virtual.ngc",
            &self.program,
            self.master.armed_mm().unwrap(),
        )
        .unwrap();
        let interp = Interpolator::new(plan, m.cycle_s()).unwrap();
        match OverrideRamp::for_machine(&canmotion::gateway::limits(m), &m.planner) {
            Ok(r) => interp.with_override_ramp(r),
            Err(_) => interp,
        }
    }

    /// Cycles until `done` holds (checked before each), at most `max`; panics past it.
    pub fn run_until(&mut self, max: u64, mut done: impl FnMut(&Rig) -> bool) {
        for _ in 0..max {
            if done(self) {
                return;
            }
            self.step();
        }
        panic!(
            "not reached in {max} cycles: phase {:?}, failure {:?}",
            self.master.phase(),
            self.master.failure().map(|f| f.to_string())
        );
    }

    /// Cycles until the run is over ([`Phase::Done`]).
    pub fn run_to_end(&mut self, max: u64) {
        self.run_until(max, |r| r.master.phase() == Phase::Done);
    }

    /// Time of cycle `k`.
    pub fn cycle_time(&self, k: u64) -> Duration {
        self.period * k as u32
    }

    /// The first cycle at or after `t` (the one whose receive reads a frame sent at `t`).
    pub fn cycle_at_or_after(&self, t: Duration) -> u64 {
        let p = self.period.as_nanos();
        t.as_nanos().div_ceil(p) as u64
    }

    /// The frames a node sent with COB-ID `base + node`.
    pub fn sent_by(&self, base: u16, node: u8) -> impl Iterator<Item = &Sent> {
        self.drive_frames
            .iter()
            .filter(move |s| s.frame.id() == base + u16::from(node))
    }
}
