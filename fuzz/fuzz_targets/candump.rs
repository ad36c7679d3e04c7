//! See `canmotion::fuzzing::candump`.

#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| canmotion::fuzzing::candump::log(data));
