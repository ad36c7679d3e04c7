//! Subroutines on arbitrary input: subroutine files found on a subroutine path, computed
//! O-word labels, M98/M99 subprograms (read ahead of the call) and M99 restarting the main
//! program. The bytes are split at their first 0 byte: the part before it is the main program,
//! the part after it the text of the subroutine file `f.ngc` on the path (besides the
//! repository's `tests/programs/subs` folders); then the same runs on a program built from the
//! bytes out of call, definition and motion lines, so that most inputs reach the calls rather
//! than a syntax error.
//!
//! The interpreter must not panic; its elements must chain with finite points; and every item,
//! whichever file or subprogram it came from, must carry a line of the main program (the
//! planner, the feed optimiser and the resume point only know that file).

use std::path::PathBuf;
use std::sync::{Mutex, OnceLock};

use nalgebra::Vector3;

use crate::gcode::{Interpreter, Item, Setup};

/// The interpreter on `data` split into a program and a subroutine file, then on the program
/// built from it.
pub fn program(data: &[u8]) {
    let (main, file) = match data.iter().position(|b| *b == 0) {
        Some(i) => (&data[..i], &data[i + 1..]),
        None => (data, &b"o<f> sub\nG0 X1\no<f> endsub\n"[..]),
    };
    let restarts = data.first().map_or(0, |b| u32::from(b % 3));
    check(main, file, restarts);
    let (main, file) = generate(data);
    check(main.as_bytes(), file.as_bytes(), restarts);
}

/// This process's folder for `f.ngc` (one per process: fuzzing runs one input at a time).
fn folder() -> &'static PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("canmotion-fuzz-subs-{}", std::process::id()));
        let _ = std::fs::create_dir_all(&dir);
        dir
    })
}

/// A main program and a subroutine file from the bytes: per line, one of a set of lines with
/// a value from the next byte.
fn generate(data: &[u8]) -> (String, String) {
    const LINES: [&str; 22] = [
        "o<f> call [{}]",
        "o<square> call [{}] [600]",
        "o[{} + 6] call",
        "o<{}> call",
        "M98 P100 L{}",
        "M98 P{}",
        "O100",
        "O{}",
        "M99",
        "G0 X{}",
        "G1 Y{} F300",
        "G91",
        "G90",
        "M30",
        "o<g> sub",
        "o<g> endsub",
        "o<g> call",
        "o<f> sub",
        "o<f> endsub",
        "#<_depth> = {}",
        "o1 repeat [{}]",
        "o1 endrepeat",
    ];
    let mut main = String::from("G21 G90\n");
    let mut file = String::new();
    let mut bytes = data.iter().copied();
    while let Some(b) = bytes.next() {
        let v = bytes.next().unwrap_or(0);
        let line = LINES[usize::from(b) % LINES.len()].replace("{}", &(v % 8).to_string());
        let out = if b >= 128 { &mut file } else { &mut main };
        out.push_str(&line);
        out.push('\n');
    }
    (main, file)
}

/// Writes `f.ngc` when a program may call it and its text changed (writing files is what
/// takes the time of a case).
fn write_file(main: &[u8], file: &[u8]) -> bool {
    static LAST: Mutex<Option<Vec<u8>>> = Mutex::new(None);
    if !main.windows(4).any(|w| w.eq_ignore_ascii_case(b"call")) {
        return true;
    }
    let mut last = LAST.lock().unwrap_or_else(|e| e.into_inner());
    if last.as_deref() == Some(file) {
        return true;
    }
    let ok = std::fs::write(folder().join("f.ngc"), file).is_ok();
    *last = ok.then(|| file.to_vec());
    ok
}

fn check(main: &[u8], file: &[u8], m99_restarts: u32) {
    let dir = folder();
    if !write_file(main, file) {
        return;
    }
    let subs = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/programs/subs"));
    let mut setup = Setup::new(Vector3::new(1.0, -2.0, 3.0));
    setup.subroutine_path = vec![dir.clone(), subs.clone(), subs.join("lib")];
    setup.m99_restarts = m99_restarts;
    let main_lines = crate::gcode::split_lines_inclusive(main).count();
    let mut position = setup.start_mm;
    for item in Interpreter::new(main, "fuzz.ngc", setup).take(5000) {
        let item = match item {
            Ok(item) => item,
            Err(e) => {
                let _ = e.to_string();
                break;
            }
        };
        let line = match &item {
            Item::Motion(e) => {
                assert_eq!(e.start_mm, position, "elements must chain");
                assert!(e.end_mm.iter().all(|c| c.is_finite()));
                position = e.end_mm;
                e.line
            }
            Item::Dwell(d) => d.line,
            Item::Stop(s) => s.line,
            Item::Note(n) => n.line,
            Item::End(_) => 0,
        };
        assert!(
            line <= main_lines,
            "item of line {line}: the main program has {main_lines} lines"
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn generated_programs_reach_the_calls() {
        // Line 0 (o<f> call [2]) in the main program, line 17 (o<f> sub) in the file.
        let (main, file) = generate(&[0, 2, 149, 0, 141, 1, 18, 0]);
        assert_eq!(main, "G21 G90\no<f> call [2]\no<f> endsub\n");
        assert_eq!(file, "o<f> sub\nG0 X1\n");
    }
}
