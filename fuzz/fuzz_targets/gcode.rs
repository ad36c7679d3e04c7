//! The G-code front end on arbitrary bytes: the interpreter (scanner, expressions, O-word flow,
//! modal state) must never panic, and whatever it yields must be usable downstream: finite
//! points, continuous elements, valid arcs, and a plan that the planner accepts.

#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| canmotion::fuzzing::gcode::program(data));
