//! Subroutines (issue 15 item 3): subroutine files found on the machine file's
//! `[program] subroutine_path`, computed O-word labels, Fanuc-style M98/M99 subprograms and
//! M99 restarting the main program. Paths come from `canmotion plan --path` on the programs of
//! `tests/programs/` and are compared with points worked out by hand (to 0.001 mm); errors are
//! matched by variant, with the file, line and column they name.

use std::path::{Path, PathBuf};
use std::process::Command;

use canmotion::config::ConfigError;
use canmotion::config::machine::Machine;
use canmotion::gcode::{CallSite, Error, ErrorKind, Interpreter, Item, ProgramEnd, Setup};
use nalgebra::Vector3;

fn programs() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/programs")
}

/// An element of the path file: source line, rapid, end, feed (mm/s; 0 for rapids).
type Record = (u64, bool, [f64; 3], f64);

fn plan_path(program: &str, extra: &[&str]) -> Vec<Record> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("path.jsonl");
    let out = Command::new(env!("CARGO_BIN_EXE_canmotion"))
        .arg("plan")
        .arg(programs().join(program))
        .arg("--path")
        .arg(&path)
        .args(extra)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let point = |v: &serde_json::Value| -> [f64; 3] {
        let a = v.as_array().unwrap();
        [0, 1, 2].map(|i| a[i].as_f64().unwrap())
    };
    let mut at = [0.0; 3];
    std::fs::read_to_string(&path)
        .unwrap()
        .lines()
        .map(|l| {
            let v: serde_json::Value = serde_json::from_str(l).unwrap();
            assert_eq!(v["kind"], "line", "{v}");
            assert_eq!(point(&v["start"]), at, "continuity: {v}");
            at = point(&v["end"]);
            (
                v["line"].as_u64().unwrap(),
                v["rapid"].as_bool().unwrap(),
                at,
                v["feed_mm_s"].as_f64().unwrap(),
            )
        })
        .collect()
}

#[track_caller]
fn check(path: &[Record], expected: &[Record]) {
    for (i, (got, want)) in path.iter().zip(expected).enumerate() {
        let close = (0..3).all(|k| (got.2[k] - want.2[k]).abs() <= 0.001)
            && (got.3 - want.3).abs() <= 0.001;
        assert!(
            got.0 == want.0 && got.1 == want.1 && close,
            "element {i}: got {got:?}, expected {want:?}"
        );
    }
    assert_eq!(path.len(), expected.len(), "number of elements: {path:?}");
}

const R: bool = true;
const F: bool = false;

#[test]
fn subroutine_files_computed_labels_and_m98_follow_the_hand_computed_path() {
    let machine = programs().join("subs.toml");
    let path = plan_path("subroutines.ngc", &["--machine", machine.to_str().unwrap()]);
    check(
        &path,
        &[
            (3, R, [10.0, 10.0, 1.0], 0.0),
            // o<square> call [5] [600]: subs/square.ngc, side 5 at 600 mm/min (10 mm/s), from
            // (10, 10); its moves carry the calling line.
            (4, F, [15.0, 10.0, 1.0], 10.0),
            (4, F, [15.0, 15.0, 1.0], 10.0),
            (4, F, [10.0, 15.0, 1.0], 10.0),
            (4, F, [10.0, 10.0, 1.0], 10.0),
            (6, R, [40.0, 10.0, 1.0], 0.0),
            // o[#5 + 2] call with #5 = 5: o7, found as subs/lib/7.ngc (the second folder). Its
            // G0 Z1 goes nowhere; the plunge to -#<_depth> = -2 at 120 mm/min = 2 mm/s.
            (7, F, [40.0, 10.0, -2.0], 2.0),
            (7, R, [40.0, 10.0, 1.0], 0.0),
            // M98 P100 L2: O100 (after M30, in the same file) twice: its own line 12.
            (12, R, [50.0, 10.0, 1.0], 0.0),
            (12, R, [60.0, 10.0, 1.0], 0.0),
            // The lines read ahead to find O100 run after the call.
            (9, R, [0.0, 0.0, 1.0], 0.0),
        ],
    );
}

#[test]
fn m99_in_the_main_program_restarts_it_as_many_times_as_asked() {
    // Without the flag, the plan ends at the first M99: one pass.
    check(
        &plan_path("m99_restart.ngc", &[]),
        &[(3, R, [5.0, 0.0, 0.0], 0.0)],
    );
    check(
        &plan_path("m99_restart.ngc", &["--m99-restarts", "2"]),
        &[
            (3, R, [5.0, 0.0, 0.0], 0.0),
            (3, R, [10.0, 0.0, 0.0], 0.0),
            (3, R, [15.0, 0.0, 0.0], 0.0),
        ],
    );
    let text = "G91\nG0 X1\nM99\n";
    let mut setup = Setup::new(Vector3::zeros());
    setup.m99_restarts = 1;
    let items = run(text, setup).unwrap();
    assert_eq!(items.last(), Some(&Item::End(ProgramEnd::M99 { line: 3 })));
}

/// Runs `text` as `main.ngc` and returns its items, or the first error.
fn run(text: &str, setup: Setup) -> Result<Vec<Item>, Error> {
    Interpreter::new(text.as_bytes(), "main.ngc", setup).collect()
}

fn with_path(dirs: &[&Path]) -> Setup {
    let mut setup = Setup::new(Vector3::zeros());
    setup.subroutine_path = dirs.iter().map(|d| d.to_path_buf()).collect();
    setup
}

#[test]
fn errors_in_a_subroutine_file_name_it_and_the_calls_that_led_there() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("outer.ngc"),
        "(outer)\no<outer> sub\n  o<inner> call\no<outer> endsub\n",
    )
    .unwrap();
    std::fs::write(
        dir.path().join("inner.ngc"),
        "o<inner> sub\nG0 X1\nG0 Q1\no<inner> endsub\n",
    )
    .unwrap();
    let e = run("G21\no<outer> call\n", with_path(&[dir.path()])).unwrap_err();
    let inner = dir.path().join("inner.ngc").display().to_string();
    let outer = dir.path().join("outer.ngc").display().to_string();
    assert_eq!((e.file.as_str(), e.line, e.col), (inner.as_str(), 3, 4));
    assert_eq!(
        e.called_from.clone().map(|c| c.0),
        Some(vec![
            CallSite {
                file: outer.clone(),
                line: 3
            },
            CallSite {
                file: "main.ngc".into(),
                line: 2
            },
        ])
    );
    assert!(
        e.to_string()
            .ends_with(&format!("(called from {outer}:3, from main.ngc:2)")),
        "{e}"
    );
    // The motion of a subroutine file carries the line and column of the outermost call.
    std::fs::write(
        dir.path().join("ok.ngc"),
        "o<ok> sub\n\n\nG0 X1\no<ok> endsub\n",
    )
    .unwrap();
    let items = run("G21\n  o<ok> call\n", with_path(&[dir.path()])).unwrap();
    let Item::Motion(m) = &items[0] else {
        panic!("{items:?}")
    };
    assert_eq!((m.line, m.col), (2, 3));
}

#[test]
fn a_subroutine_that_cannot_be_found_or_read_is_an_error_at_the_call() {
    let dir = tempfile::tempdir().unwrap();
    let e = run("G21\no<probe> call\n", with_path(&[dir.path()])).unwrap_err();
    assert_eq!((e.file.as_str(), e.line, e.col), ("main.ngc", 2, 1));
    assert_eq!(e.called_from, None);
    assert_eq!(
        e.kind,
        ErrorKind::UndefinedSubroutine {
            label: "o<probe>".into(),
            file_name: "probe.ngc".into(),
            searched: vec![dir.path().display().to_string()],
        }
    );
    std::fs::write(
        dir.path().join("probe.ngc"),
        "o<other> sub\no<other> endsub\n",
    )
    .unwrap();
    let e = run("o<probe> call\n", with_path(&[dir.path()])).unwrap_err();
    assert!(
        matches!(&e.kind, ErrorKind::SubroutineFileWithoutSub { path, label }
            if path.ends_with("probe.ngc") && label == "o<probe>"),
        "{e}"
    );
    // A name that is no file name is never joined to a folder.
    let e = run("o<../probe> call\n", with_path(&[dir.path()])).unwrap_err();
    assert!(matches!(e.kind, ErrorKind::SubroutineName { .. }), "{e}");
    // The first folder that has the file wins.
    let second = tempfile::tempdir().unwrap();
    std::fs::write(
        second.path().join("probe.ngc"),
        "o<probe> sub\nG0 X7\no<probe> endsub\n",
    )
    .unwrap();
    std::fs::remove_file(dir.path().join("probe.ngc")).unwrap();
    let items = run("o<probe> call\n", with_path(&[dir.path(), second.path()])).unwrap();
    assert!(
        matches!(&items[0], Item::Motion(m) if m.end_mm.x == 7.0),
        "{items:?}"
    );
}

#[test]
fn computed_labels_call_and_only_call() {
    let items = run(
        "o12 sub\nG0 X#1\no12 endsub\n#3 = 4\no[#3 * 3] call [2]\n",
        Setup::new(Vector3::zeros()),
    )
    .unwrap();
    assert!(
        matches!(&items[0], Item::Motion(m) if m.end_mm.x == 2.0),
        "{items:?}"
    );
    let e = run("#1 = 1.5\no[#1] call\n", Setup::new(Vector3::zeros())).unwrap_err();
    assert_eq!((e.line, e.col), (2, 2));
    assert_eq!(e.kind, ErrorKind::ComputedLabel { value: 1.5 });
    let e = run("#1 = 1\no#1 while [1]\n", Setup::new(Vector3::zeros())).unwrap_err();
    assert_eq!((e.line, e.col), (2, 1));
    assert!(e.is_unsupported(), "{e}");
}

#[test]
fn m98_errors_name_the_call() {
    let e = run(
        "G0 X1\n  M98 P9\nM30\nO8\nM99\n",
        Setup::new(Vector3::zeros()),
    )
    .unwrap_err();
    assert_eq!((e.line, e.col), (2, 3));
    assert_eq!(e.kind, ErrorKind::SubprogramNotFound { number: 9 });
    // M99 ends M98 subprograms, not o-word subroutines.
    let e = run(
        "o1 sub\nM99\no1 endsub\no1 call\n",
        Setup::new(Vector3::zeros()),
    )
    .unwrap_err();
    assert_eq!(e.line, 2);
    assert!(matches!(e.kind, ErrorKind::ControlMismatch { .. }), "{e}");
    // M98 L0 runs nothing; M98 subprograms share #1 with the caller (LinuxCNC).
    let items = run(
        "#1 = 0\nM98 P5 L0\nM98 P5 L3\nG0 X#1\nM30\nO5\n#1 = [#1 + 1]\nM99\n",
        Setup::new(Vector3::zeros()),
    )
    .unwrap();
    assert!(
        matches!(&items[0], Item::Motion(m) if m.end_mm.x == 3.0),
        "{items:?}"
    );
}

#[test]
fn the_subroutine_path_is_relative_to_the_machine_file_and_checked() {
    let m = Machine::load(&programs().join("subs.toml")).unwrap();
    let setup = m.setup(Vector3::zeros());
    assert_eq!(
        setup.subroutine_path,
        vec![programs().join("subs"), programs().join("subs/lib")]
    );
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(programs().join("subs.toml"))
        .unwrap()
        .replace(
            "../../dictionaries",
            &format!("{}/dictionaries", env!("CARGO_MANIFEST_DIR")),
        )
        .replace(
            "subroutine_path = [\"subs\", \"subs/lib\"]",
            "subroutine_path = [\"nowhere\"]",
        );
    let file = dir.path().join("m.toml");
    std::fs::write(&file, text).unwrap();
    match Machine::load(&file).unwrap_err() {
        ConfigError::Invalid { table, key, .. } => {
            assert_eq!(
                (table.as_str(), key.as_str()),
                ("program", "subroutine_path")
            );
        }
        e => panic!("{e}"),
    }
}

#[test]
fn optimize_leaves_the_moves_of_subroutine_files_alone() {
    // Their F words are in another file: writing one on the call line would break it.
    let dir = tempfile::tempdir().unwrap();
    let program = dir.path().join("p.ngc");
    std::fs::write(
        &program,
        "G21 G90 G17\nG0 X10 Y10 Z1\no<square> call [5] [99000]\nG1 X50 F99000\nM2\n",
    )
    .unwrap();
    let out_file = dir.path().join("out.ngc");
    let out = Command::new(env!("CARGO_BIN_EXE_canmotion"))
        .arg("optimize")
        .arg(&program)
        .arg("--machine")
        .arg(programs().join("subs.toml"))
        .arg("-o")
        .arg(&out_file)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("left alone (first: line 3)"), "{stdout}");
    let text = std::fs::read_to_string(&out_file).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[2], "o<square> call [5] [99000]");
    assert!(lines[3].starts_with("G1 X50 F"), "{text}");
    assert_ne!(
        lines[3], "G1 X50 F99000",
        "the main program's own move is still lowered"
    );
}
