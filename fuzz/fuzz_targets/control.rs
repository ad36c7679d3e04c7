//! The operator's command lines (control socket, standard input keys) on arbitrary bytes: no
//! panic, every answer `ok ...` or `error: ...`, the override within its range.

#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| canmotion::fuzzing::control::lines(data));
