//! Canned cycles on arbitrary bytes, and on programs of cycle lines built from them: the
//! interpreter must never panic, its elements must chain with finite points, no line may queue
//! more than the cycle bound, and the planner must accept the result.

#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| canmotion::fuzzing::cycles::program(data));
