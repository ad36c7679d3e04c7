//! The command line's files, through the binary: inputs must be regular files (a FIFO or
//! `/dev/zero` is refused at once, naming the path and what it is), outputs are written through
//! symlinks and to devices without replacing them, a directory is refused, and a standard
//! output that fails is an error, not a panic.

use std::os::unix::fs::FileTypeExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

fn canmotion() -> Command {
    Command::new(env!("CARGO_BIN_EXE_canmotion"))
}

/// Runs `cmd` with no standard input and waits for it at most `limit`: a refusal must be
/// quick, never a hang on a FIFO or a read of `/dev/zero`.
fn run_within(mut cmd: Command, limit: Duration) -> Output {
    let mut child = cmd
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = Instant::now() + limit;
    loop {
        if child.try_wait().unwrap().is_some() {
            return child.wait_with_output().unwrap();
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let out = child.wait_with_output().unwrap();
            panic!(
                "{cmd:?} still running after {limit:?}: {}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn mkfifo(path: &Path) {
    let status = Command::new("mkfifo").arg(path).status().unwrap();
    assert!(status.success());
}

fn write(dir: &Path, name: &str, text: impl AsRef<[u8]>) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// The demo machine with absolute dictionary paths, its first dictionary replaced by `dict`
/// when given.
fn machine_file(dir: &Path, dict: Option<&Path>) -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("dictionaries");
    let demo = std::fs::read_to_string(root.join("machines/demo-xyz.toml")).unwrap();
    let servo = root.join("drives/cia402-servo.toml").display().to_string();
    let mut text = demo.replace(
        "../tools/demo-tools.toml",
        &root.join("tools/demo-tools.toml").display().to_string(),
    );
    if let Some(d) = dict {
        text = text.replacen("../drives/cia402-servo.toml", &d.display().to_string(), 1);
    }
    write(
        dir,
        "machine.toml",
        text.replace("../drives/cia402-servo.toml", &servo),
    )
}

const PROGRAM: &str = "G21 G90\nG1 X10 Y5 F600\nG0 Z2\nM2\n";

#[test]
fn inputs_that_are_not_regular_files_are_refused_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("fifo");
    mkfifo(&fifo);
    let program = write(dir.path(), "p.ngc", PROGRAM);
    let out_ngc = dir.path().join("out.ngc");
    for (bad, what) in [
        (Path::new("/dev/zero"), "is a character device"),
        (fifo.as_path(), "is a FIFO"),
    ] {
        let mut cases: Vec<(&str, Command)> = Vec::new();
        let mut c = canmotion();
        c.arg("plan").arg(&program).arg("--machine").arg(bad);
        cases.push(("machine file", c));
        let machine = machine_file(dir.path(), Some(bad));
        let mut c = canmotion();
        c.arg("plan").arg(&program).arg("--machine").arg(&machine);
        cases.push(("dictionary", c));
        let mut c = canmotion();
        c.arg("optimize").arg(bad).arg("-o").arg(&out_ngc);
        cases.push(("optimize input", c));
        let mut c = canmotion();
        c.arg("plan").arg(bad);
        cases.push(("plan program", c));
        let mut c = canmotion();
        c.arg("monitor").arg("--replay").arg(bad);
        cases.push(("monitor replay", c));
        for (kind, cmd) in cases {
            let out = run_within(cmd, Duration::from_secs(20));
            let e = stderr(&out);
            assert!(!out.status.success(), "{kind} {bad:?} accepted");
            assert!(
                e.contains(&format!("{}: {what}", bad.display())),
                "{kind} {bad:?}: {e}"
            );
        }
    }
}

#[test]
fn monitor_replay_bounds_its_lines() {
    let dir = tempfile::tempdir().unwrap();
    let log = write(
        dir.path(),
        "bus.log",
        format!("(1.000000) vcan0 080#\n{}\n", "0".repeat(100_000)),
    );
    let out = run_within(
        {
            let mut c = canmotion();
            c.arg("monitor").arg("--replay").arg(&log);
            c
        },
        Duration::from_secs(20),
    );
    assert!(!out.status.success());
    let e = stderr(&out);
    assert!(
        e.contains(&format!(
            "{}:2: line longer than 65536 bytes",
            log.display()
        )),
        "{e}"
    );
}

#[test]
fn an_overlong_program_line_is_located() {
    let dir = tempfile::tempdir().unwrap();
    let program = write(
        dir.path(),
        "long.ngc",
        format!("G0 X1\nG0 X2 ({})\nM2\n", "a".repeat(70_000)),
    );
    let out = run_within(
        {
            let mut c = canmotion();
            c.arg("plan").arg(&program);
            c
        },
        Duration::from_secs(20),
    );
    assert!(!out.status.success());
    let e = stderr(&out);
    assert!(
        e.contains(&format!("{}:2:1: line longer than", program.display())),
        "{e}"
    );
}

#[test]
fn outputs_go_through_symlinks_and_to_devices_and_refuse_directories() {
    let dir = tempfile::tempdir().unwrap();
    let program = write(dir.path(), "p.ngc", PROGRAM);
    let plan = |flag: &str, target: &Path| {
        canmotion()
            .arg("plan")
            .arg(&program)
            .arg(flag)
            .arg(target)
            .output()
            .unwrap()
    };
    // A symlink: written through, and still a link.
    let target = write(dir.path(), "real.csv", "old\n");
    let link = dir.path().join("link.csv");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    let out = plan("--setpoints", &link);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(std::fs::symlink_metadata(&link).unwrap().is_symlink());
    let csv = std::fs::read_to_string(&target).unwrap();
    assert!(csv.starts_with("cycle,t_s,"), "{csv}");
    assert!(!dir.path().join("link.csv.partial").exists());
    // The same for the path and the plot.
    let target = write(dir.path(), "real.jsonl", "");
    let link = dir.path().join("link.jsonl");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    assert!(plan("--path", &link).status.success());
    assert!(std::fs::symlink_metadata(&link).unwrap().is_symlink());
    assert!(
        std::fs::read_to_string(&target)
            .unwrap()
            .contains("\"line\"")
    );
    let target = write(dir.path(), "real.svg", "");
    let link = dir.path().join("link.svg");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    let out = plan("--plot", &link);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(std::fs::symlink_metadata(&link).unwrap().is_symlink());
    assert!(std::fs::read_to_string(&target).unwrap().contains("<svg"));
    // /dev/null: written to, and still a character device.
    for flag in ["--setpoints", "--path"] {
        let out = plan(flag, Path::new("/dev/null"));
        assert!(out.status.success(), "{flag}: {}", stderr(&out));
        let meta = std::fs::symlink_metadata("/dev/null").unwrap();
        assert!(meta.file_type().is_char_device());
    }
    // A directory: refused, naming it.
    for flag in ["--setpoints", "--path"] {
        let out = plan(flag, dir.path());
        assert!(!out.status.success(), "{flag} to a directory accepted");
        let e = stderr(&out);
        assert!(
            e.contains(&format!("{}: is a directory", dir.path().display())),
            "{flag}: {e}"
        );
    }
    let out = canmotion()
        .arg("optimize")
        .arg(&program)
        .arg("-o")
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(stderr(&out).contains("is a directory"), "{}", stderr(&out));
    // optimize -o through a symlink.
    let target = write(dir.path(), "real.ngc", "");
    let link = dir.path().join("link.ngc");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    let out = canmotion()
        .arg("optimize")
        .arg(&program)
        .arg("-o")
        .arg(&link)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(std::fs::symlink_metadata(&link).unwrap().is_symlink());
    assert!(std::fs::read_to_string(&target).unwrap().contains("G1 X10"));
}

#[test]
fn a_full_standard_output_is_an_error_not_a_panic() {
    let full = std::fs::OpenOptions::new()
        .write(true)
        .open("/dev/full")
        .unwrap();
    let out = canmotion()
        .arg("plan")
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/demo.ngc"))
        .stdin(Stdio::null())
        .stdout(full)
        .stderr(Stdio::piped())
        .output()
        .unwrap();
    let e = stderr(&out);
    let code = out.status.code();
    assert!(code.is_some_and(|c| c != 0 && c != 101), "{code:?}: {e}");
    assert!(e.contains("standard output: cannot write"), "{e}");
    assert!(!e.contains("panicked"), "{e}");
}

#[test]
fn an_override_out_of_range_is_shown_as_written() {
    let dir = tempfile::tempdir().unwrap();
    let program = write(dir.path(), "p.ngc", PROGRAM);
    let out = canmotion()
        .arg("plan")
        .arg(&program)
        .arg("--override")
        .arg("201")
        .output()
        .unwrap();
    assert!(!out.status.success());
    let e = stderr(&out);
    assert!(
        e.contains("feed override 201 % must be between 1 % and 200 %"),
        "{e}"
    );
    let out = canmotion()
        .arg("plan")
        .arg(&program)
        .arg("--override")
        .arg("50.5")
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("at 50.5 % feed override"), "{text}");
}

#[test]
fn optimize_reads_programs_as_plan_does() {
    let dir = tempfile::tempdir().unwrap();
    // A Latin-1 comment: plan accepts it, so does optimize, and keeps its bytes.
    let latin1 = b"G21 G90 (pi\xe8ce \xe0 fraiser)\r\nG1 X10 F600000\rG1 Y10\nM2\n";
    let program = write(dir.path(), "latin1.ngc", latin1);
    let plan = canmotion().arg("plan").arg(&program).output().unwrap();
    assert!(plan.status.success(), "{}", stderr(&plan));
    let out_ngc = dir.path().join("out.ngc");
    let out = canmotion()
        .arg("optimize")
        .arg(&program)
        .arg("-o")
        .arg(&out_ngc)
        .arg("--no-trace")
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    let written = std::fs::read(&out_ngc).unwrap();
    assert!(written.starts_with(b"G21 G90 (pi\xe8ce \xe0 fraiser)\r\nG1 X10 F"));
    // Its CR line end too: the third line is a line of its own (it gets its own F).
    let text = String::from_utf8_lossy(&written);
    assert!(text.contains("\rG1 Y10 F"), "{text:?}");
    assert!(text.ends_with("\nM2\n"), "{text:?}");
    // A bad byte outside a comment: the same located error from both.
    let bad = write(dir.path(), "bad.ngc", b"G21\rG1 X10 F600\nG1 Y\xe9\nM2\n");
    let plan = canmotion().arg("plan").arg(&bad).output().unwrap();
    let out = canmotion()
        .arg("optimize")
        .arg(&bad)
        .arg("-o")
        .arg(&out_ngc)
        .output()
        .unwrap();
    assert!(!plan.status.success() && !out.status.success());
    let where_ = format!("{}:3:", bad.display());
    assert!(stderr(&plan).contains(&where_), "{}", stderr(&plan));
    assert!(stderr(&out).contains(&where_), "{}", stderr(&out));
}

#[test]
fn a_program_that_cannot_be_read_is_named_without_a_line_or_column() {
    // A missing file: the path and the system's reason, no `:0:0`.
    for command in ["plan", "run"] {
        let out = run_within(
            {
                let mut c = canmotion();
                c.args([command, "/nonexistent.ngc"]);
                c
            },
            Duration::from_secs(30),
        );
        assert!(!out.status.success());
        let err = stderr(&out);
        assert!(
            err.contains("/nonexistent.ngc: cannot read: No such file or directory"),
            "{command}: {err}"
        );
        assert!(!err.contains(":0"), "{command}: {err}");
    }
    // A standard input that cannot be read (a directory): its name and the reason, no line.
    for command in ["plan", "run"] {
        let mut cmd = canmotion();
        cmd.args([command, "-"]);
        let mut child = cmd
            .stdin(std::fs::File::open("/").unwrap())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let deadline = Instant::now() + Duration::from_secs(30);
        while child.try_wait().unwrap().is_none() {
            if Instant::now() > deadline {
                let _ = child.kill();
                panic!("{command} - still running after 30 s");
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        let out = child.wait_with_output().unwrap();
        assert!(!out.status.success());
        let err = stderr(&out);
        assert!(err.contains("<stdin>: cannot read"), "{command}: {err}");
        assert!(err.contains("Is a directory"), "{command}: {err}");
        assert!(!err.contains("<stdin>:1"), "{command}: {err}");
    }
}
