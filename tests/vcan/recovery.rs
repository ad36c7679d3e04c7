//! Recovery on vcan0, the gateway and `canmotion simdrive` in separate processes: heartbeat
//! loss on its own, a drive that resets mid-motion (IP and CSP), `run --resume` end to end on
//! the command line, and `canmotion reset`. Each checks the detection time, the message, and
//! that no healthy axis's setpoint broke its velocity or acceleration limit during the stop.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use canmotion::bus::{Bus, Filter, Port};
use canmotion::config::Machine;
use canmotion::gateway::RunOptions;
use canmotion::gateway::resume::{self, ResumeState};
use canmotion::master::alarm::{Alarm, Failure};

use super::{BIN, IFACE, ROOT, SimDrives, UML_MARGIN_S, lock, simdrive_with};
use crate::common::{self, Outcome, Recorder};

/// Three lines, so that a stop in the third has a completed line before it.
const LINES: &str =
    "G21 G90\nG1 X20 Y20 Z-1 F6000\nG1 X120 Y120 Z-3 F8485\nG1 X150 Y60 F6000\nM2\n";
/// Where LINES ends, mm.
const LINES_END_MM: [f64; 3] = [150.0, 60.0, -3.0];

fn bus() -> Bus {
    Bus::SocketCan(IFACE.into())
}

/// `program` over vcan0 by the gateway in this process, against simulated drives told to
/// misbehave, with every frame recorded.
fn run_recorded(
    m: &Machine,
    inject: &str,
    program: &str,
) -> (SimDrives, Outcome, Vec<(u64, canmotion::bus::Frame)>) {
    let drives = simdrive_with(&[1, 2, 3], None, &["--inject", inject]);
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("log.csv");
    let rec = Recorder::start(&bus());
    let out = resume::run_program(
        m,
        &bus(),
        &RunOptions {
            program_name: "recovery.ngc".into(),
            program_text: program.into(),
            log: Some(log.clone()),
            simulate: false,
            ..Default::default()
        },
    );
    let frames = rec.stop();
    let o = Outcome {
        result: out.result,
        rows: common::read_csv(&log),
        machine: m.clone(),
    };
    (drives, o, frames)
}

#[test]
fn vcan0_heartbeat_loss_alone_is_detected_within_the_consumer_time_plus_one_cycle() {
    heartbeat_loss_alone(common::machine(|t| t));
}

#[test]
fn vcan0_heartbeat_loss_alone_in_csp_too() {
    heartbeat_loss_alone(common::machine(common::csp));
}

fn heartbeat_loss_alone(m: Machine) {
    let _g = lock();
    let (_d, o, frames) = run_recorded(&m, "3:no-heartbeat@300ms", common::LONG);
    let f = common::failure(&o);
    assert!(
        matches!(
            f.alarm(),
            Alarm::HeartbeatLost {
                axis: "Z",
                node: 3,
                consumer_ms: 500,
                ..
            }
        ),
        "{f}"
    );
    let detected = f.detected_ns.unwrap();
    let (_, last_beat) =
        common::last_before(&frames, 0x703, detected).expect("heartbeats of node 3");
    // Its process data went on: only the heartbeat tells.
    let tpdos_after = frames
        .iter()
        .filter(|(t, fr)| fr.id() == 0x183 && *t > last_beat + 200_000_000)
        .count();
    assert!(
        tpdos_after > 20,
        "{tpdos_after} TPDOs of node 3 after its last heartbeat"
    );
    let d = (detected - last_beat) as f64 * 1e-9;
    let consumer = f64::from(m.heartbeat.gateway_consumer_ms) * 1e-3;
    assert!(
        d > consumer - UML_MARGIN_S && d <= consumer + m.cycle_s() + UML_MARGIN_S,
        "detected {d} s after the last heartbeat (consumer time {consumer} s)"
    );
    common::frozen_after(&o, 2, f);
    common::limits_held(&o, &[0, 1]);
}

fn reboot_stops_at_once(m: Machine) {
    let _g = lock();
    let (_d, o, frames) = run_recorded(&m, "1:reboot@600ms", LINES);
    let f = common::failure(&o);
    assert_eq!(
        f.failure,
        Failure {
            alarm: Alarm::BootUp {
                axis: "X",
                node: 1,
                completed_line: Some(2)
            },
            line: Some(3)
        }
    );
    // The stop is in the cycle that reads the boot-up: after the next SYNC, no RPDO to node 1.
    let (boot_ns, late) = common::rpdos_after_boot_up(&frames, 1, 0x201, 0x80);
    assert_eq!(late, 0, "RPDOs to node 1 after its boot-up's cycle");
    let d = (f.detected_ns.unwrap() as f64 - boot_ns as f64) * 1e-9;
    assert!(
        d <= m.cycle_s() + UML_MARGIN_S,
        "detected {d} s after the boot-up"
    );
    common::frozen_after(&o, 0, f);
    common::limits_held(&o, &[1, 2]);
}

#[test]
fn vcan0_reboot_stops_the_group_at_once_and_the_node_gets_no_further_setpoints() {
    reboot_stops_at_once(common::machine(|t| t));
}

#[test]
fn vcan0_reboot_in_csp_too() {
    reboot_stops_at_once(common::machine(common::csp));
}

/// `canmotion run` on vcan0 with the demo machine, extra arguments, standard input closed.
fn canmotion_run(program: &Path, extra: &[&str]) -> Output {
    let out = Command::new(BIN)
        .current_dir(ROOT)
        .args([
            "run",
            "--bus",
            IFACE,
            "--machine",
            "dictionaries/machines/demo-xyz.toml",
        ])
        .arg(program)
        .args(extra)
        .stdin(Stdio::null())
        .output()
        .expect("run canmotion");
    eprintln!(
        "[canmotion run {extra:?}] {}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

#[test]
fn vcan0_resume_after_a_reboot_on_the_command_line() {
    let _g = lock();
    let m = common::machine(|t| t);
    let _drives = simdrive_with(&[1, 2, 3], None, &["--inject", "1:reboot@600ms"]);
    let dir = tempfile::tempdir().unwrap();
    let program: PathBuf = dir.path().join("lines.ngc");
    std::fs::write(&program, LINES).unwrap();
    let state = dir.path().join("lines.ngc.resume");
    let first_csv = dir.path().join("first.csv");

    // 1. The run stops at the reboot and records where.
    let rec = Recorder::start(&bus());
    let out = canmotion_run(&program, &["--log", first_csv.to_str().unwrap()]);
    let frames = rec.stop();
    assert!(!out.status.success());
    let err = text(&out.stderr);
    assert!(
        err.contains("motion stopped: axis X (node 1): boot-up during the run: the drive reset; no further setpoints to node 1; last completed program line 2 (last program line 3)"),
        "{err}"
    );
    assert!(
        err.contains(&format!(
            "resume point saved in {}: line 3 at X",
            state.display()
        )),
        "{err}"
    );
    let (_, late) = common::rpdos_after_boot_up(&frames, 1, 0x201, 0x80);
    assert_eq!(late, 0, "RPDOs to node 1 after its boot-up's cycle");
    let first = Outcome {
        result: Err(canmotion::gateway::GatewayError::Resume(String::new())),
        rows: common::read_csv(&first_csv),
        machine: m.clone(),
    };
    common::limits_held(&first, &[1, 2]);
    let st = ResumeState::load(&state).unwrap();
    assert_eq!(
        (st.line, st.completed_line, st.reset_nodes.clone()),
        (3, 2, vec![1])
    );
    assert_eq!(st.axis[0].mode, "ip");

    // 2. No confirmation (no terminal, no --yes): nothing moves.
    let rec = Recorder::start(&bus());
    let out = canmotion_run(&program, &["--resume"]);
    let frames = rec.stop();
    assert!(!out.status.success());
    let (o, e) = (text(&out.stdout), text(&out.stderr));
    assert!(o.contains("resume "), "{o}");
    assert!(o.contains(" at line 3\n"), "{o}");
    assert!(
        o.contains("axis X (node 1)  at ") && o.contains("its drive reset"),
        "{o}"
    );
    assert!(e.contains("nobody to confirm the resume: use --yes"), "{e}");
    assert!(e.contains("at line 3 not confirmed: nothing moved"), "{e}");
    assert!(
        frames
            .iter()
            .all(|(_, f)| f.id() != 0x80 && !(0x201..=0x203).contains(&f.id())),
        "SYNC or RPDO without a confirmation"
    );

    // 3. A changed program is refused.
    std::fs::write(&program, LINES.replace("X150 Y60", "X150 Y61")).unwrap();
    let out = canmotion_run(&program, &["--resume", "--yes"]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("changed since the stop"),
        "{}",
        text(&out.stderr)
    );
    std::fs::write(&program, LINES).unwrap();

    // 4. Confirmed: every node configured again, back to the stop point, the rest of the
    // program, and the end within one count.
    let resumed_csv = dir.path().join("resumed.csv");
    let out = canmotion_run(
        &program,
        &["--resume", "--yes", "--log", resumed_csv.to_str().unwrap()],
    );
    let o = text(&out.stdout);
    assert!(out.status.success(), "{o}\n{}", text(&out.stderr));
    assert!(o.contains("confirmed by --yes"), "{o}");
    assert!(
        o.contains("move back to the stop point in a straight line at 5 mm/s")
            || o.contains("the axes are at the stop point"),
        "{o}"
    );
    assert!(
        o.contains("resume point") && o.contains("removed (the program completed)"),
        "{o}"
    );
    assert!(!state.exists());
    let rows = common::read_csv(&resumed_csv);
    let last = rows.last().unwrap();
    let counts = [1000.0, 1000.0, 2000.0];
    for k in 0..3 {
        assert_eq!(last[2 + k], LINES_END_MM[k], "setpoint {k}");
        assert!(
            ((last[5 + k] - LINES_END_MM[k]) * counts[k]).abs() <= 1.0 + 1e-9,
            "axis {k} ends at {} mm",
            last[5 + k]
        );
    }
    common::limits_held_all(&m, &rows);
    let stop = st.stop_point_mm;
    assert!(
        rows.iter()
            .any(|r| (0..3).all(|k| (r[2 + k] - stop[k]).abs() < 0.05)),
        "the resumed run never reached the stop point {stop:?}"
    );
}

/// Wait until `node` sends EMCY `code`, at most `within`.
fn wait_emcy(port: &mut dyn Port, node: u8, code: u16, within: Duration) {
    let end = Instant::now() + within;
    while Instant::now() < end {
        if let Ok(Some(f)) = port.recv_timeout(Duration::from_millis(20))
            && f.id() == 0x80 + u16::from(node)
            && f.data().len() == 8
            && u16::from_le_bytes([f.data()[0], f.data()[1]]) == code
        {
            return;
        }
    }
    panic!("no EMCY 0x{code:04X} from node {node} within {within:?}");
}

/// Fault node 2 mid-motion with `inject` (checking the stop), then wait until the drives have
/// noticed the gateway is gone (EMCY 0x8130), and run `canmotion reset vcan0 TARGET`.
fn fault_then_reset(inject: &str, cause: fn(&Alarm) -> bool, bound_s: f64, target: &str) -> Output {
    let _g = lock();
    let m = common::machine(|t| t);
    // Only node 2's EMCYs: a port that buffered the whole run would overflow.
    let mut watch = bus().open(&[Filter::exact(0x82)]).unwrap();
    let (_drives, o, _) = run_recorded(&m, inject, common::LONG);
    let f = common::failure(&o);
    assert_eq!(f.alarm().node(), Some(2), "{f}");
    assert!(cause(f.alarm()), "{f}");
    let d = common::detection_s(f, 0.3);
    assert!(d < bound_s + UML_MARGIN_S, "detected {d} s after the fault");
    common::frozen_after(&o, 1, f);
    common::limits_held(&o, &[0, 2]);
    wait_emcy(watch.as_mut(), 2, 0x8130, Duration::from_secs(5));
    drop(watch);
    let out = Command::new(BIN)
        .args(["reset", IFACE, target])
        .stdin(Stdio::null())
        .output()
        .expect("run canmotion reset");
    eprintln!(
        "[canmotion reset {target}] {}\n{}",
        text(&out.stdout),
        text(&out.stderr)
    );
    out
}

#[test]
fn vcan0_reset_clears_a_following_error_fault_and_verifies_it() {
    // The jam: the window (2 mm at 100 mm/s) plus 0x6066 (10 ms) and a PDO round trip.
    let out = fault_then_reset(
        "2:following-error@300ms",
        |a| {
            matches!(
                a,
                Alarm::FollowingError { axis: "Y", .. } | Alarm::Emcy { code: 0x8611, .. }
            )
        },
        0.080,
        "all",
    );
    let o = text(&out.stdout);
    assert!(out.status.success(), "{o}\n{}", text(&out.stderr));
    let node2 = o
        .lines()
        .find(|l| l.starts_with("node 2: "))
        .expect("node 2");
    assert!(
        node2.starts_with("node 2: fault cleared ")
            && node2.contains("0x603F = 0x8611 (following error)")
            && node2.contains("now Switch on disabled")
            && node2.contains("0x603F = 0x0000 (no error)"),
        "{node2}"
    );
    // Nodes 1 and 3 went to Fault when the gateway's heartbeat stopped: cleared too.
    for n in [1, 3] {
        let l = o
            .lines()
            .find(|l| l.starts_with(&format!("node {n}: ")))
            .expect("node line");
        assert!(
            l.contains("fault cleared") && l.contains("0x603F = 0x8130"),
            "{l}"
        );
    }
}

#[test]
fn vcan0_reset_reports_a_fault_whose_cause_persists() {
    let m = common::machine(|t| t);
    let out = fault_then_reset(
        "2:persistent-fault@300ms",
        |a| {
            matches!(
                a,
                Alarm::DriveFault { axis: "Y", .. } | Alarm::Emcy { code: 0x4310, .. }
            )
        },
        2.0 * m.cycle_s(),
        "2",
    );
    let e = text(&out.stderr);
    assert!(!out.status.success());
    assert!(
        e.contains("canmotion: error: node 2: fault NOT cleared: still Fault (statusword 0x")
            && e.contains("0x603F = 0x4310 (excess drive temperature)"),
        "{e}"
    );
}

#[test]
fn vcan0_reset_reports_a_fault_that_comes_back() {
    let m = common::machine(|t| t);
    let out = fault_then_reset(
        "2:recurring-fault@300ms",
        |a| {
            matches!(
                a,
                Alarm::DriveFault { axis: "Y", .. } | Alarm::Emcy { code: 0x2310, .. }
            )
        },
        2.0 * m.cycle_s(),
        "2",
    );
    let e = text(&out.stderr);
    assert!(!out.status.success());
    assert!(
        e.contains("canmotion: error: node 2: fault came back ")
            && e.contains("0x603F = 0x2310 (continuous over-current)"),
        "{e}"
    );
}
