//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::Path;
use std::sync::Arc;

use canmotion::config::machine::{DEMO_DRIVE, DEMO_MACHINE};
use canmotion::config::{DriveDictionary, Machine};

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
