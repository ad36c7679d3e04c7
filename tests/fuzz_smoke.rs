//! Short seeded runs of every fuzz target (`fuzz/`, `src/fuzzing/`): a few thousand inputs
//! mutated from the repository's own files, so that a parser that panics on a malformed input
//! fails the ordinary test suite, not only a fuzzing session. The long runs are
//! `cargo fuzz run NAME` (see `fuzz/Cargo.toml`).

use canmotion::fuzzing::{self, run_seeded};
use std::path::Path;

/// Every file under `dir` (relative to the crate) whose name ends in one of `exts`.
fn seeds(dir: &str, exts: &[&str]) -> Vec<Vec<u8>> {
    let mut out = Vec::new();
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join(dir);
    let mut stack = vec![root];
    while let Some(d) = stack.pop() {
        let Ok(rd) = std::fs::read_dir(&d) else {
            continue;
        };
        let mut entries: Vec<_> = rd.flatten().map(|e| e.path()).collect();
        entries.sort();
        for p in entries {
            if p.is_dir() {
                stack.push(p);
            } else if exts.iter().any(|e| p.to_string_lossy().ends_with(e)) {
                out.push(std::fs::read(&p).expect("seed file"));
            }
        }
    }
    assert!(!out.is_empty(), "no seed files under {dir}");
    out
}

#[test]
fn gcode_programs() {
    let mut s = seeds("tests/programs", &[".ngc"]);
    s.extend(seeds("examples", &[".ngc"]));
    let s: Vec<&[u8]> = s.iter().map(Vec::as_slice).collect();
    run_seeded(&s, 1500, 1, fuzzing::gcode::program);
}

#[test]
fn machine_files() {
    let s = seeds("dictionaries/machines", &[".toml"]);
    let s: Vec<&[u8]> = s.iter().map(Vec::as_slice).collect();
    run_seeded(&s, 3000, 2, fuzzing::machine::machine_file);
}
