//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::Path;
use std::sync::Arc;

use canmotion::config::machine::{DEMO_DRIVE, DEMO_MACHINE};
use canmotion::config::{DriveDictionary, Machine};
use canmotion::gateway::{self, GatewayError, MotionFailure};

/// One real-time run at a time in a test binary: each run has a cyclic thread and simulated
/// drives keeping real time, and the machines this runs on have two cores. Runs in parallel
/// stall each other's cycles by several periods, and a drive that sees its demand stop for
/// 12 ms at 200 mm/s faults on its following-error window, as a real one would.
///
/// That is the lock's only reason now: a run's override, hold and progress figures are its own
/// (`RunOptions::control`, `RunOptions::progress`), and the stop-signal counts of
/// `rt::signal::STOP` are process-wide by nature but no test raises a signal in its own process.
/// The virtual-clock suite (tests/virtual_clock.rs) keeps no real time and takes no lock.
pub fn one_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());
    ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner())
}

/// The demo drive dictionary, with `edit` applied to its text.
pub fn drive_dict(edit: impl Fn(String) -> String) -> Arc<DriveDictionary> {
    Arc::new(
        DriveDictionary::parse(
            Path::new("cia402-servo.toml"),
            &edit(DEMO_DRIVE.to_string()),
        )
        .expect("dictionary"),
    )
}

/// The demo machine, with `edit` applied to its text.
pub fn machine(edit: impl Fn(String) -> String) -> Machine {
    Machine::parse(
        Path::new("demo-xyz.toml"),
        &edit(DEMO_MACHINE.to_string()),
        |rel| DriveDictionary::parse(&Path::new("dictionaries/machines").join(rel), DEMO_DRIVE),
    )
    .expect("machine")
}

/// A short program touching all three axes, ending away from the start.
pub const PROGRAM: &str =
    "G21 G90\nG0 X5 Y3 Z-1\nG1 X12.5 Y-2 F1200\nG1 Z-3.25 F300\nG0 X1 Y1\nM2\n";

/// The program's final point in counts for the demo machine (X, Y at 1000/mm, Z at 2000/mm).
pub const PROGRAM_END_COUNTS: [i32; 3] = [1000, 1000, -6500];

/// The demo machine in cyclic synchronous position mode (8): setpoint 0x607A instead of 0x60C1:01.
pub fn csp(text: String) -> String {
    text.replace("mode = \"ip\"", "mode = \"csp\"")
        .replace("0x60C10120", "0x607A0020")
}

/// A long diagonal: every axis moving steadily for over a second (X, Y at 100 mm/s).
pub const LONG: &str = "G21 G90\nG1 X150 Y150 Z-4 F8485\nM2\n";

pub struct Outcome {
    pub result: Result<gateway::Summary, GatewayError>,
    pub rows: Vec<Vec<f64>>,
    pub machine: Machine,
}

pub fn failure(o: &Outcome) -> &MotionFailure {
    match &o.result {
        Err(GatewayError::Motion(f)) => f,
        other => panic!("expected the motion to stop on a fault, got {other:?}"),
    }
}

/// Seconds from the injected fault to the gateway's detection. Injection times count from the
/// drive's motion start (its statusword bit 12), which the gateway reads one cycle later, in
/// `bit12_cycle`.
///
/// Only an upper bound is meaningful: a cycle that ran late when the gateway first saw bit 12
/// moves the origin later, so a fast detection can come out slightly negative.
pub fn detection_s(f: &MotionFailure, after_s: f64) -> f64 {
    // Measured on the gateway's monotonic clock; the drive's origin is one cycle earlier.
    f.bit12_to_failure_s
        .expect("bit 12 and the failure were both seen")
        + f.period_s
        - after_s
}

/// No setpoint of the axes in `healthy` moved faster than max_vel or accelerated harder than
/// max_acc (1 % margin), across the whole run including the stop.
pub fn limits_held(o: &Outcome, healthy: &[usize]) {
    let t = o.machine.cycle_s();
    // Columns: cycle, t_s, then cmd per axis.
    let cmd = |r: &Vec<f64>, i: usize| r[2 + i];
    let start = o
        .rows
        .iter()
        .position(|r| r[2..5].iter().any(|x| *x != 0.0))
        .unwrap_or(0)
        + 1;
    let rows = &o.rows[start..];
    for &i in healthy {
        let a = &o.machine.axes[i];
        for w in rows.windows(3) {
            let v = (cmd(&w[2], i) - cmd(&w[1], i)) / t;
            let acc = (cmd(&w[2], i) - 2.0 * cmd(&w[1], i) + cmd(&w[0], i)) / (t * t);
            assert!(
                v.abs() <= a.max_vel_mm_s * 1.01,
                "axis {} at cycle {}: {v} mm/s",
                a.name,
                w[2][0]
            );
            assert!(
                acc.abs() <= a.max_acc_mm_s2 * 1.01,
                "axis {} at cycle {}: {acc} mm/s²",
                a.name,
                w[2][0]
            );
        }
    }
}

/// The faulted axis's setpoint does not move after the detection.
pub fn frozen_after(o: &Outcome, axis: usize, f: &MotionFailure) {
    let d = f.detected_cycle.unwrap() as f64;
    let after: Vec<f64> = o
        .rows
        .iter()
        .filter(|r| r[0] >= d)
        .map(|r| r[2 + axis])
        .collect();
    assert!(
        after.windows(2).all(|w| w[0] == w[1]),
        "axis {axis} moved after its fault: {after:?}"
    );
}

/// The rows of a `--log` CSV, as numbers.
pub fn read_csv(path: &Path) -> Vec<Vec<f64>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect()
}

/// Milliseconds.
pub fn ms(n: u64) -> std::time::Duration {
    std::time::Duration::from_millis(n)
}

/// Every frame on a bus, with when it was received ([`canmotion::rt::now_ns`]), recorded by a
/// thread of its own until [`Recorder::stop`].
pub struct Recorder {
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    thread: Option<std::thread::JoinHandle<Vec<(u64, canmotion::bus::Frame)>>>,
}

impl Recorder {
    /// Start recording (the port is open when this returns).
    pub fn start(bus: &canmotion::bus::Bus) -> Recorder {
        let mut port = bus.open(&[]).expect("a port to record on");
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let s = stop.clone();
        let thread = std::thread::spawn(move || {
            let mut frames = Vec::new();
            while !s.load(std::sync::atomic::Ordering::Relaxed) {
                if let Ok(Some(f)) = port.recv_timeout(std::time::Duration::from_millis(20)) {
                    frames.push((canmotion::rt::now_ns(), f));
                }
            }
            while let Ok(Some(f)) = port.recv_timeout(std::time::Duration::ZERO) {
                frames.push((canmotion::rt::now_ns(), f));
            }
            frames
        });
        Recorder {
            stop,
            thread: Some(thread),
        }
    }

    /// Stop and hand over the frames, in bus order.
    pub fn stop(mut self) -> Vec<(u64, canmotion::bus::Frame)> {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        self.thread.take().unwrap().join().unwrap()
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The recorded frames' index and time of the last one with `id` and `data` before `before_ns`.
pub fn last_before(
    frames: &[(u64, canmotion::bus::Frame)],
    id: u16,
    before_ns: u64,
) -> Option<(usize, u64)> {
    frames
        .iter()
        .enumerate()
        .rfind(|(_, (t, f))| f.id() == id && *t <= before_ns)
        .map(|(i, (t, _))| (i, *t))
}

/// The node's RPDOs (`rpdo_cob`) after its boot-up message: only the cycle in progress when it
/// arrived may still carry one (its SYNC is the first after the boot-up); from the next SYNC on,
/// none. Returns the boot-up's time and the offending frames' count.
pub fn rpdos_after_boot_up(
    frames: &[(u64, canmotion::bus::Frame)],
    node: u8,
    rpdo_cob: u16,
    sync_cob: u16,
) -> (u64, usize) {
    // The last one: the first came after the start-up's reset communication.
    let boot = frames
        .iter()
        .rposition(|(_, f)| f.id() == 0x700 + u16::from(node) && f.data() == [0])
        .expect("a boot-up message during the run");
    let second_sync = frames[boot..]
        .iter()
        .enumerate()
        .filter(|(_, (_, f))| f.id() == sync_cob)
        .nth(1)
        .map_or(frames.len(), |(i, _)| boot + i);
    let late = frames[second_sync..]
        .iter()
        .filter(|(_, f)| f.id() == rpdo_cob)
        .count();
    (frames[boot].0, late)
}

/// The limits held by the setpoints of every axis across a whole log, from the cycle before the
/// first setpoint that differs from position actual (while enabling, the setpoint is position
/// actual: before the first feedback both are 0).
pub fn limits_held_all(machine: &Machine, rows: &[Vec<f64>]) {
    let n = machine.axes.len();
    let first = rows
        .iter()
        .position(|r| (0..n).any(|i| (r[2 + i] - r[2 + n + i]).abs() > 1e-9))
        .expect("a setpoint apart from position actual");
    assert!(
        first >= 3,
        "motion from the first rows: {:?}",
        &rows[..first + 1]
    );
    limits_held_rows(machine, &rows[first - 1..]);
}

/// Every axis's setpoints in `rows` (CSV log rows: cycle, time, then the setpoints) keep its
/// velocity and acceleration limits (1 %), by finite differences.
pub fn limits_held_rows(machine: &Machine, rows: &[Vec<f64>]) {
    let t = machine.cycle_s();
    for w in rows.windows(3) {
        for (i, a) in machine.axes.iter().enumerate() {
            let cmd = |r: &Vec<f64>| r[2 + i];
            let v = (cmd(&w[2]) - cmd(&w[1])) / t;
            let acc = (cmd(&w[2]) - 2.0 * cmd(&w[1]) + cmd(&w[0])) / (t * t);
            assert!(
                v.abs() <= a.max_vel_mm_s * 1.01,
                "axis {} at cycle {}: {v} mm/s",
                a.name,
                w[2][0]
            );
            assert!(
                acc.abs() <= a.max_acc_mm_s2 * 1.01,
                "axis {} at cycle {}: {acc} mm/s²",
                a.name,
                w[2][0]
            );
        }
    }
}
