//! The machine-file loader on arbitrary bytes: it must return an error, never panic, and a
//! machine it accepts keeps every promise of its validation (see `canmotion::fuzzing::machine`).

#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| canmotion::fuzzing::machine::machine_file(data));
