//! SIGINT and SIGTERM during `canmotion run`, sent to the real binary mid-move on the embedded
//! simulated machine: the first stops on the path within the axes' limits (the feed hold), the
//! drives are disabled, the resume point names the signal, the exit status is 128 + the signal
//! number, and the `--control` socket is gone. A second signal escalates to the fault stop, and
//! a signal before any motion leaves everything disabled.

use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use canmotion::config::Machine;

/// Long enough (about 6 s) that a signal lands mid-move.
const PROGRAM: &str =
    "G21 G90\nG1 X250 Y150 F12000\nG1 X0 Y0\nG1 X250 Y150\nG1 X0 Y0\nG1 X250 Y150\nG1 X0 Y0\nM2\n";

struct Run {
    child: Child,
    log: PathBuf,
    socket: PathBuf,
    state: PathBuf,
    _dir: tempfile::TempDir,
}

fn start() -> Run {
    let dir = tempfile::tempdir().unwrap();
    let program = dir.path().join("long.ngc");
    std::fs::write(&program, PROGRAM).unwrap();
    let (log, socket, state) = (
        dir.path().join("log.csv"),
        dir.path().join("ctl"),
        dir.path().join("long.resume"),
    );
    let child = Command::new(env!("CARGO_BIN_EXE_canmotion"))
        .arg("run")
        .arg(&program)
        .arg("--log")
        .arg(&log)
        .arg("--control")
        .arg(&socket)
        .arg("--state")
        .arg(&state)
        .arg("--no-keys")
        .env("CANMOTION_RT_PRIORITY", "0")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    Run {
        child,
        log,
        socket,
        state,
        _dir: dir,
    }
}

/// The complete rows of the log so far: (cycle, setpoint per axis, mm).
fn rows(log: &Path) -> Vec<(u64, Vec<f64>)> {
    let Ok(text) = std::fs::read_to_string(log) else {
        return Vec::new();
    };
    let mut lines: Vec<&str> = text.split_inclusive('\n').collect();
    if lines.last().is_some_and(|l| !l.ends_with('\n')) {
        lines.pop(); // still being written
    }
    let Some((header, body)) = lines.split_first() else {
        return Vec::new();
    };
    let cmd: Vec<usize> = header
        .trim_end()
        .split(',')
        .enumerate()
        .filter(|(_, h)| h.ends_with("_cmd_mm"))
        .map(|(i, _)| i)
        .collect();
    body.iter()
        .map(|l| {
            let f: Vec<&str> = l.trim_end().split(',').collect();
            (
                f[0].parse().unwrap(),
                cmd.iter().map(|&i| f[i].parse().unwrap()).collect(),
            )
        })
        .collect()
}

fn wait_for(what: &str, deadline: Duration, mut done: impl FnMut() -> bool) {
    let t0 = Instant::now();
    while !done() {
        assert!(t0.elapsed() < deadline, "not within {deadline:?}: {what}");
        std::thread::sleep(Duration::from_millis(10));
    }
}

fn signal(child: &Child, name: &str) {
    let ok = Command::new("kill")
        .arg(format!("-{name}"))
        .arg(child.id().to_string())
        .status()
        .unwrap()
        .success();
    assert!(ok, "kill -{name}");
}

/// Waits until the setpoints move fast (mid-move).
fn wait_for_motion(run: &Run) {
    wait_for("motion in the log", Duration::from_secs(30), || {
        rows(&run.log)
            .windows(2)
            .any(|w| (w[1].1[0] - w[0].1[0]).abs() > 0.2) // > 50 mm/s at 4 ms
    });
}

fn finish(run: Run) -> (Output, Run) {
    let Run {
        child,
        log,
        socket,
        state,
        _dir,
    } = run;
    let out = child.wait_with_output().unwrap();
    (
        out,
        Run {
            child: Command::new("true").spawn().unwrap(),
            log,
            socket,
            state,
            _dir,
        },
    )
}

/// Every axis's setpoints by finite differences within its velocity and acceleration limits
/// (1 % and the log's rounding), and the last rows standing still.
fn stops_within_limits(log: &Path) {
    let m = Machine::demo();
    let t = m.cycle_s();
    let r = rows(log);
    assert!(r.len() > 100, "{} rows", r.len());
    for w in r.windows(3) {
        if w[2].0 != w[0].0 + 2 {
            continue; // a dropped row
        }
        for (i, a) in m.axes.iter().enumerate() {
            let v = (w[2].1[i] - w[1].1[i]) / t;
            let acc = (w[2].1[i] - 2.0 * w[1].1[i] + w[0].1[i]) / (t * t);
            assert!(
                v.abs() <= a.max_vel_mm_s * 1.01 + 1e-3,
                "cycle {}: axis {} at {v} mm/s",
                w[2].0,
                a.name
            );
            assert!(
                acc.abs() <= a.max_acc_mm_s2 * 1.01 + 0.2,
                "cycle {}: axis {} at {acc} mm/s²",
                w[2].0,
                a.name
            );
        }
    }
    let last = &r[r.len() - 5..];
    assert!(
        last.iter().all(|row| row.1 == last[0].1),
        "still moving at the end: {last:?}"
    );
}

fn text(out: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

fn stopped_by(sig: &str, code: i32) {
    let run = start();
    wait_for_motion(&run);
    signal(&run.child, sig);
    let (out, run) = finish(run);
    let all = text(&out);
    assert_eq!(out.status.code(), Some(code), "{all}");
    assert!(
        all.contains(&format!("stopped by signal SIG{sig}")),
        "{all}"
    );
    assert!(!all.contains("escalated"), "{all}");
    stops_within_limits(&run.log);
    let state = std::fs::read_to_string(&run.state).expect("a resume point");
    assert!(
        state.contains(&format!("stopped by signal SIG{sig}")),
        "{state}"
    );
    assert!(all.contains("resume point saved"), "{all}");
    assert!(!run.socket.exists(), "the control socket is left behind");
    // A resume point on the path, mid-program (its --resume is tests/recovery.rs's: the
    // simulated drives of a new process start again from 0).
    let st = canmotion::gateway::resume::ResumeState::load(&run.state).unwrap();
    assert!((2..=7).contains(&st.line), "line {}", st.line);
    assert!(
        st.stop_point_mm[0] > 0.0 && st.stop_point_mm[0] < 250.0,
        "{st:?}"
    );
    assert!(
        (st.stop_point_mm[1] - st.stop_point_mm[0] * 150.0 / 250.0).abs() < 1e-6,
        "not on the path: {st:?}"
    );
}

#[test]
fn sigint_mid_move_stops_on_the_path_and_saves_the_resume_point() {
    stopped_by("INT", 130);
}

#[test]
fn sigterm_mid_move_stops_on_the_path_and_saves_the_resume_point() {
    stopped_by("TERM", 143);
}

#[test]
fn a_second_signal_escalates_to_the_fault_stop() {
    let run = start();
    wait_for_motion(&run);
    signal(&run.child, "INT");
    signal(&run.child, "TERM");
    let (out, run) = finish(run);
    let all = text(&out);
    assert_eq!(out.status.code(), Some(130), "{all}");
    assert!(
        all.contains("stopped by signal SIGINT; a second signal (SIGTERM) during the stop escalated to the fault stop"),
        "{all}"
    );
    stops_within_limits(&run.log);
    assert!(!run.socket.exists(), "the control socket is left behind");
}

#[test]
fn a_signal_before_motion_enables_nothing_and_removes_the_socket() {
    let run = start();
    wait_for("the control socket", Duration::from_secs(30), || {
        run.socket.exists()
    });
    signal(&run.child, "INT");
    let (out, run) = finish(run);
    let all = text(&out);
    assert_eq!(out.status.code(), Some(130), "{all}");
    assert!(all.contains("stopped by signal SIGINT"), "{all}");
    let r = rows(&run.log);
    assert!(
        r.iter().all(|row| row.1 == r[0].1),
        "the axes moved: {:?}",
        r.iter().find(|row| row.1 != r[0].1)
    );
    assert!(!run.state.exists(), "no resume point without motion");
    assert!(!run.socket.exists(), "the control socket is left behind");
}

#[test]
fn a_live_control_socket_is_refused_and_a_stale_one_replaced() {
    let first = start();
    wait_for("the control socket", Duration::from_secs(30), || {
        UnixStream::connect(&first.socket).is_ok()
    });
    // A second run on the same socket is refused before anything starts.
    let second = Command::new(env!("CARGO_BIN_EXE_canmotion"))
        .args(["run", "--no-keys", "--control"])
        .arg(&first.socket)
        .env("CANMOTION_RT_PRIORITY", "0")
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let all = text(&second);
    assert!(!second.status.success(), "{all}");
    assert!(all.contains("another process is listening"), "{all}");
    // The first is still served.
    let mut s = UnixStream::connect(&first.socket).unwrap();
    s.write_all(b"status\n").unwrap();
    let mut answer = String::new();
    BufReader::new(&s).read_line(&mut answer).unwrap();
    assert!(answer.starts_with("ok override"), "{answer}");
    // Killed outright (SIGKILL: no stop of its own), it leaves a stale socket file.
    signal(&first.child, "KILL");
    let (_, first) = finish(first);
    assert!(first.socket.exists());
    let third = Command::new(env!("CARGO_BIN_EXE_canmotion"))
        .args(["run", "--no-keys", "--control"])
        .arg(&first.socket)
        .env("CANMOTION_RT_PRIORITY", "0")
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let all = text(&third);
    assert!(third.status.success(), "{all}");
    assert!(!first.socket.exists(), "removed at the end");
}
