//! Subroutines on arbitrary bytes: a main program and a subroutine file on the subroutine
//! path, M98/M99 subprograms and M99 restarts; the interpreter must never panic, its elements
//! must chain, and every item must carry a line of the main program.

#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| canmotion::fuzzing::subroutines::program(data));
