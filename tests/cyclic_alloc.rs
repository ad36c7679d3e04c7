//! The cyclic path allocates nothing (issue 13, item 4): a counting global allocator (its own
//! test binary, since `#[global_allocator]` is per binary) counts every allocation made inside
//! the cyclic master's calls on this thread, over a whole program's streaming phase and over
//! fault stops, and the count must be 0.
//!
//! The drives are reduced to what the master sees (as the `Rig` of `gateway::cyclic`'s unit
//! tests): the CiA 402 power state machine, statusword bit 12 answering controlword bit 4, and
//! a position that follows the setpoint latched at SYNC. They run outside the counted calls.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use canmotion::bus::Frame;
use canmotion::canopen::cob;
use canmotion::canopen::index;
use canmotion::cia402::{PowerStateMachine, controlword as cwb, statusword as swb};
use canmotion::config::Machine;
use canmotion::interpolator::Interpolator;
use canmotion::master::alarm::Alarm;
use canmotion::master::cyclic::{CyclicMaster, Phase};
use canmotion::master::supervision::Supervision;
use std::time::Duration;

struct Counting;

thread_local! {
    /// Whether this thread's allocations are counted (the test harness's own threads are not).
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    /// This thread's count. Per thread, so that tests running in parallel (one of them
    /// allocates on purpose, to show that the counter counts) never see each other's counts.
    static ALLOCS: Cell<u64> = const { Cell::new(0) };
}

fn note() {
    if COUNTING.with(Cell::get) {
        ALLOCS.with(|a| a.set(a.get() + 1));
    }
}

// SAFETY: every call is forwarded unchanged to the system allocator; counting only reads a
// thread-local flag and bumps a thread-local counter, neither of which allocates.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note();
        // SAFETY: forwarded with the caller's layout.
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note();
        // SAFETY: forwarded with the caller's layout.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note();
        // SAFETY: forwarded with the caller's pointer, layout and size.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded with the caller's pointer and layout.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Run `f` with this thread's allocations counted; returns its result and the count.
fn counted<T>(f: impl FnOnce() -> T) -> (T, u64) {
    let before = ALLOCS.with(Cell::get);
    COUNTING.with(|c| c.set(true));
    let r = f();
    COUNTING.with(|c| c.set(false));
    (r, ALLOCS.with(Cell::get) - before)
}

struct FakeDrive {
    psm: PowerStateMachine,
    cw: u16,
    latched: i32,
    pos: i32,
    fault: bool,
    silent: bool,
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
        }
    }
    fn statusword(&self) -> u16 {
        let mut sw = self.psm.statusword();
        if self.psm.is_operation_enabled() && self.cw & cwb::IP_ENABLE != 0 {
            sw |= swb::OP_MODE_SPECIFIC_12;
        }
        sw
    }
}

/// Where each axis's objects sit in its PDOs.
struct PdoLayout {
    rpdo_cob: u16,
    cw_off: usize,
    sp_off: usize,
    tpdo_cob: u16,
    tpdo_len: usize,
    sw_off: usize,
    pos_off: usize,
}

struct Rig {
    machine: Machine,
    master: CyclicMaster,
    drives: Vec<FakeDrive>,
    layout: Vec<PdoLayout>,
    out: Vec<Frame>,
    /// Allocations counted so far inside the master's calls.
    allocs: u64,
    /// Whether the master's calls are counted.
    count: bool,
}

impl Rig {
    fn new() -> Rig {
        let machine = Machine::demo();
        let layout = machine
            .axes
            .iter()
            .map(|a| {
                let (si, ss) = a.mode.setpoint_object();
                let off = |p: &canmotion::config::PdoConfig, i, s| p.offset_of(i, s).unwrap().0;
                PdoLayout {
                    rpdo_cob: a.setpoint_pdo.cob_id,
                    cw_off: off(&a.setpoint_pdo, index::CONTROLWORD, 0),
                    sp_off: off(&a.setpoint_pdo, si, ss),
                    tpdo_cob: a.feedback_pdo.cob_id,
                    tpdo_len: a.feedback_pdo.len_bytes(),
                    sw_off: off(&a.feedback_pdo, index::STATUSWORD, 0),
                    pos_off: off(&a.feedback_pdo, index::POSITION_ACTUAL, 0),
                }
            })
            .collect();
        let master = CyclicMaster::new(&machine);
        let drives = vec![
            FakeDrive::new(1000),
            FakeDrive::new(-2000),
            FakeDrive::new(0),
        ];
        // As the cyclic thread does: room for SYNC and one RPDO per axis, reserved once.
        let out = Vec::with_capacity(machine.axes.len() + 1);
        Rig {
            machine,
            master,
            drives,
            layout,
            out,
            allocs: 0,
            count: false,
        }
    }

    /// One cycle: the master decides (counted), the drives latch at SYNC and answer with their
    /// TPDOs, which the master takes (counted).
    fn step(&mut self) {
        self.out.clear();
        let sync = self.machine.sync_cob_id;
        let (_, n) = self.maybe_counted(|m, out| {
            m.cycle(sync, out);
        });
        self.allocs += n;
        for f in &self.out {
            let Some(i) = self.layout.iter().position(|l| l.rpdo_cob == f.id()) else {
                continue;
            };
            let (d, l, dr) = (f.data(), &self.layout[i], &mut self.drives[i]);
            dr.cw = u16::from_le_bytes([d[l.cw_off], d[l.cw_off + 1]]);
            dr.psm.on_controlword(dr.cw);
            if dr.statusword() & swb::OP_MODE_SPECIFIC_12 != 0 {
                dr.pos = dr.latched;
                dr.latched = i32::from_le_bytes(d[l.sp_off..l.sp_off + 4].try_into().unwrap());
            } else {
                dr.latched = dr.pos;
            }
        }
        let mut tpdos = Vec::new();
        for (dr, l) in self.drives.iter_mut().zip(&self.layout) {
            if dr.silent {
                continue;
            }
            if dr.fault {
                dr.psm.fault();
                dr.psm.fault_reaction_done();
            }
            let mut d = [0u8; 8];
            d[l.sw_off..l.sw_off + 2].copy_from_slice(&dr.statusword().to_le_bytes());
            d[l.pos_off..l.pos_off + 4].copy_from_slice(&dr.pos.to_le_bytes());
            tpdos.push(Frame::new(l.tpdo_cob, &d[..l.tpdo_len]).unwrap());
        }
        for f in &tpdos {
            let (_, n) = self.maybe_counted(|m, _| m.on_frame(f));
            self.allocs += n;
        }
    }

    fn maybe_counted<T>(
        &mut self,
        f: impl FnOnce(&mut CyclicMaster, &mut Vec<Frame>) -> T,
    ) -> (T, u64) {
        if self.count {
            counted(|| f(&mut self.master, &mut self.out))
        } else {
            (f(&mut self.master, &mut self.out), 0)
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

    /// Arm, supply the motion of `program` (several lines, so that a failure names one), and
    /// run until it streams; counting starts there.
    fn streaming(program: &str) -> Rig {
        let mut r = Rig::new();
        r.run_until(Phase::Armed, 40);
        let from = r.master.armed_mm().unwrap();
        let m = &r.machine;
        let prog = canmotion::gcode::parse_program(program, "t.ngc", from).unwrap();
        let plan = canmotion::planner::plan_with(&prog, &canmotion::gateway::limits(m), &m.planner)
            .unwrap();
        let interp = Interpolator::new(plan, m.cycle_s()).unwrap();
        r.master.supply_motion(interp);
        r.step();
        assert_eq!(r.master.phase(), Phase::Streaming);
        r.count = true;
        r
    }
}

const PROGRAM: &str = "G1 X20 Y10 F6000\nG2 X40 Y10 I10 J0 F4000\nG1 X60 Y30 Z-1 F6000\n";

#[test]
fn streaming_a_whole_program_allocates_nothing() {
    let mut r = Rig::streaming(PROGRAM);
    r.run_until(Phase::Done, 20_000);
    assert_eq!(r.master.failure(), None);
    assert!(
        r.master.streaming_cycles > 200,
        "{}",
        r.master.streaming_cycles
    );
    assert_eq!(
        r.allocs, 0,
        "allocations on the cyclic path while streaming"
    );
}

#[test]
fn a_drive_fault_stop_allocates_nothing() {
    let mut r = Rig::streaming(PROGRAM);
    while r.master.line() != Some(2) {
        r.step();
    }
    r.drives[2].fault = true;
    r.run_until(Phase::Done, 5_000);
    let f = r.master.failure().unwrap();
    assert!(
        matches!(f.alarm, Alarm::DriveFault { node: 3, .. }) && f.line == Some(2),
        "{f}"
    );
    assert_eq!(
        r.allocs, 0,
        "allocations on the cyclic path during a fault stop"
    );
}

#[test]
fn a_silent_drive_stop_allocates_nothing() {
    let mut r = Rig::streaming(PROGRAM);
    while r.master.line() != Some(2) {
        r.step();
    }
    r.drives[1].silent = true;
    r.run_until(Phase::Done, 5_000);
    let f = r.master.failure().unwrap();
    assert!(
        matches!(f.alarm, Alarm::MissingProcessData { node: 2, .. }),
        "{f}"
    );
    assert_eq!(
        r.allocs, 0,
        "allocations on the cyclic path during a fault stop"
    );
}

#[test]
fn a_boot_up_stop_allocates_nothing() {
    let mut r = Rig::streaming(PROGRAM);
    while r.master.line() != Some(2) {
        r.step();
    }
    let boot_up = Frame::new(0x701, &[0x00]).unwrap();
    let (_, n) = r.maybe_counted(|m, _| m.on_frame(&boot_up));
    r.allocs += n;
    r.run_until(Phase::Done, 5_000);
    let f = r.master.failure().unwrap();
    assert!(matches!(f.alarm, Alarm::BootUp { node: 1, .. }), "{f}");
    assert_eq!(
        r.allocs, 0,
        "allocations on the cyclic path during a fault stop"
    );
}

#[test]
fn an_alarm_from_the_supervision_allocates_nothing_either() {
    // As the cyclic thread raises a lost heartbeat: every cycle, until the run is done.
    let mut r = Rig::streaming(PROGRAM);
    while r.master.line() != Some(2) {
        r.step();
    }
    for _ in 0..5_000 {
        if r.master.phase() == Phase::Done {
            break;
        }
        let alarm = Alarm::HeartbeatLost {
            axis: "Z",
            node: 3,
            silent_ms: 512,
            consumer_ms: 500,
        };
        let (_, n) = r.maybe_counted(|m, _| m.alarm(3, alarm));
        r.allocs += n;
        r.step();
    }
    assert_eq!(r.master.phase(), Phase::Done);
    let f = r.master.failure().unwrap();
    assert!(
        matches!(f.alarm, Alarm::HeartbeatLost { node: 3, .. }),
        "{f}"
    );
    assert_eq!(
        r.allocs, 0,
        "allocations on the cyclic path during a fault stop"
    );
}

#[test]
fn the_supervision_counting_a_warning_and_losing_a_heartbeat_allocates_nothing() {
    // As the cyclic thread feeds it: every node's heartbeat each cycle until line 2, then node 3
    // falls silent; node 1 warns (EMCY without the fault bit) once streaming. Every call of the
    // supervision is counted, until the run is done.
    let mut r = Rig::streaming(PROGRAM);
    let mut sup = Supervision::new(&r.machine);
    let period = Duration::from_micros(u64::from(r.machine.cycle_us));
    let hb = |node: u16| Frame::new(cob::HEARTBEAT + node, &[0x05]).unwrap();
    let warning = Frame::new(cob::EMCY + 1, &[0x10, 0x42, 0x01, 0, 0, 0, 0, 0]).unwrap();
    let mut now = Duration::ZERO;
    let mut warned = false;
    for _ in 0..10_000 {
        if r.master.phase() == Phase::Done {
            break;
        }
        now += period;
        let silent = r.master.line() >= Some(2);
        let (_, n) = counted(|| {
            for node in 1..=3 {
                if node != 3 || !silent {
                    sup.on_frame(now, &hb(node), &r.master);
                }
            }
            if !warned {
                sup.on_frame(now, &warning, &r.master);
            }
            sup.poll(now, &mut r.master);
        });
        warned = true;
        r.allocs += n;
        r.step();
    }
    assert_eq!(r.master.phase(), Phase::Done);
    let f = r.master.failure().unwrap();
    assert!(
        matches!(f.alarm, Alarm::HeartbeatLost { node: 3, .. }),
        "{f}"
    );
    let w = sup.warnings();
    assert_eq!(
        (w.len(), w[0].node, w[0].code, w[0].count),
        (1, 1, 0x4210, 1)
    );
    assert_eq!(
        r.allocs, 0,
        "allocations on the cyclic path during a fault stop"
    );
}

#[test]
fn the_counter_counts() {
    // The test cannot pass by counting nothing.
    let (v, n) = counted(|| vec![1u8; 10]);
    assert_eq!(v.len(), 10);
    assert!(n >= 1);
}
