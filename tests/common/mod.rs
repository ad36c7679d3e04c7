//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::Path;
use std::sync::Arc;

use canmotion::config::machine::{DEMO_DRIVE, DEMO_MACHINE};
use canmotion::config::{DriveDictionary, Machine};
use canmotion::gateway::{self, GatewayError, MotionFailure};

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
