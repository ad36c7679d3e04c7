//! Recovery on the in-process bus: heartbeat loss on its own, a drive that resets mid-motion
//! (IP and CSP), `run --resume` after it, and the verified fault reset of `canmotion reset`.
//! The same scenarios run on vcan0 in tests/vcan/recovery.rs. Each checks the detection time,
//! the message, and the limits of every healthy axis's setpoints during the stop.

mod common;

use std::time::{Duration, Instant};

use canmotion::bus::Bus;
use canmotion::bus::inproc::InProcBus;
use canmotion::commands::reset::{self, ResetOutcome};
use canmotion::config::Machine;
use canmotion::gateway::resume::{self, ResumePreview, ResumeState, RunOutcome};
use canmotion::gateway::{GatewayError, RunOptions};
use canmotion::master::alarm::{Alarm, Failure};
use canmotion::sim::{Inject, SimDrive, runner};
use common::*;

/// Three lines, so that a stop in the third has a completed line before it.
const LINES: &str =
    "G21 G90\nG1 X20 Y20 Z-1 F6000\nG1 X120 Y120 Z-3 F8485\nG1 X150 Y60 F6000\nM2\n";
/// Where LINES ends, in counts (X, Y at 1000/mm, Z at 2000/mm).
const LINES_END: [i32; 3] = [150_000, 60_000, -6_000];

/// Scheduling margin on a loaded machine (two cores shared with builds).
const MARGIN_S: f64 = 0.040;

struct Rig {
    bus: Bus,
    _sims: runner::SimHandle,
    dir: tempfile::TempDir,
}

fn rig(machine: &Machine, inject: &[(u8, Inject)], positions: &[i32]) -> Rig {
    let bus = Bus::InProc(InProcBus::new());
    let dict = drive_dict(|t| t);
    let drives = machine
        .axes
        .iter()
        .enumerate()
        .map(|(i, a)| {
            let d = SimDrive::new(dict.clone(), a.node)
                .with_position(positions.get(i).copied().unwrap_or(0));
            inject
                .iter()
                .filter(|(n, _)| *n == a.node)
                .fold(d, |d, (_, i)| d.with_inject(*i))
        })
        .collect();
    let sims = runner::spawn(&bus, drives).unwrap();
    Rig {
        bus,
        _sims: sims,
        dir: tempfile::tempdir().unwrap(),
    }
}

fn opts(rig: &Rig, program: &str, log: &str) -> RunOptions {
    RunOptions {
        program_name: "recovery.ngc".into(),
        program_text: program.into(),
        log: Some(rig.dir.path().join(log)),
        simulate: false,
        ..Default::default()
    }
}

fn outcome(
    machine: &Machine,
    rig: &Rig,
    out: RunOutcome,
    log: &str,
) -> (Outcome, Option<ResumeState>) {
    let path = rig.dir.path().join(log);
    let rows = if path.exists() {
        read_csv(&path)
    } else {
        Vec::new()
    };
    (
        Outcome {
            result: out.result,
            rows,
            machine: machine.clone(),
        },
        out.resume,
    )
}

// Heartbeat loss alone (process data still coming) runs on the virtual clock, detected in its
// exact cycle: tests/virtual_clock.rs. On vcan0: tests/vcan/recovery.rs.

fn reboot_stops_at_once(m: Machine) {
    let r = rig(&m, &[(1, Inject::Reboot { after: ms(600) })], &[]);
    let rec = Recorder::start(&r.bus);
    let out = resume::run_program(&m, &r.bus, &opts(&r, LINES, "reboot.csv"));
    let frames = rec.stop();
    let (o, state) = outcome(&m, &r, out, "reboot.csv");
    let f = failure(&o);
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
    let (boot_ns, late) = rpdos_after_boot_up(&frames, 1, 0x201, 0x80);
    assert_eq!(late, 0, "RPDOs to node 1 after its boot-up's cycle");
    let d = (f.detected_ns.unwrap() as f64 - boot_ns as f64) * 1e-9;
    assert!(
        d <= m.cycle_s() + MARGIN_S,
        "detected {d} s after the boot-up"
    );
    frozen_after(&o, 0, f);
    limits_held(&o, &[1, 2]);
    let st = state.expect("a resume point");
    assert_eq!(
        (st.line, st.completed_line, st.reset_nodes.as_slice()),
        (3, 2, &[1u8][..])
    );
}

#[test]
fn a_reboot_stops_the_group_at_once_and_the_node_gets_no_further_setpoints() {
    let _one = one_at_a_time();
    reboot_stops_at_once(machine(|t| t));
}

#[test]
fn a_reboot_in_csp_too() {
    let _one = one_at_a_time();
    reboot_stops_at_once(machine(csp));
}

#[test]
fn resume_after_a_reboot_completes_the_program_after_a_confirmation() {
    let _one = one_at_a_time();
    let m = machine(|t| t);
    let r = rig(&m, &[(1, Inject::Reboot { after: ms(600) })], &[]);
    let out = resume::run_program(&m, &r.bus, &opts(&r, LINES, "first.csv"));
    let (o, state) = outcome(&m, &r, out, "first.csv");
    failure(&o);
    let st = state.expect("a resume point");
    let file = r.dir.path().join("recovery.ngc.resume");
    st.save(&file).unwrap();
    let st = ResumeState::load(&file).unwrap();
    assert_eq!(st.line, 3);

    // A changed program: refused before anything happens on the bus.
    let changed = LINES.replace("X150 Y60", "X150 Y61");
    let rec = Recorder::start(&r.bus);
    let out = resume::resume_program(&m, &r.bus, &opts(&r, &changed, "x.csv"), &st, &mut |_| {
        panic!("no confirmation is asked for a changed program")
    });
    match out.result {
        Err(GatewayError::Resume(e)) => {
            assert!(e.contains("recovery.ngc changed since the stop"), "{e}")
        }
        other => panic!("{other:?}"),
    }
    // No confirmation: nothing enabled, no SYNC, no setpoint.
    let mut shown: Option<ResumePreview> = None;
    let out = resume::resume_program(&m, &r.bus, &opts(&r, LINES, "no.csv"), &st, &mut |p| {
        shown = Some(p.clone());
        false
    });
    match out.result {
        Err(GatewayError::Resume(e)) => {
            assert_eq!(
                e,
                "resume of recovery.ngc at line 3 not confirmed: nothing moved"
            )
        }
        other => panic!("{other:?}"),
    }
    let frames = rec.stop();
    assert!(
        frames
            .iter()
            .all(|(_, f)| f.id() != 0x80 && !(0x201..=0x203).contains(&f.id())),
        "SYNC or RPDO without a confirmation"
    );
    let p = shown.expect("the operator was asked");
    assert_eq!(p.line, 3);
    assert!(p.axes[0].reset && !p.axes[1].reset);
    let text = p.to_string();
    assert!(text.contains("resume recovery.ngc at line 3"), "{text}");
    assert!(text.contains("(line 2 completed)"), "{text}");
    assert!(text.contains("axis X (node 1)  at "), "{text}");

    // Confirmed: the program completes.
    let out = resume::resume_program(
        &m,
        &r.bus,
        &opts(&r, LINES, "resumed.csv"),
        &st,
        &mut |_| true,
    );
    let (o, again) = outcome(&m, &r, out, "resumed.csv");
    let s = o.result.as_ref().expect("the resumed run completes");
    assert!(again.is_none());
    for (i, want) in LINES_END.iter().enumerate() {
        assert!((s.final_counts[i] - want).abs() <= 1, "{s}");
    }
    limits_held_all(&m, &o.rows);
    // The rows pass through the stop point, then the end of line 3's predecessor is not
    // revisited: the path continues from where it stopped.
    let stop = st.stop_point_mm;
    // (Samples fall within a period of the approach's end, at rest: within 0.05 mm.)
    let near = o
        .rows
        .iter()
        .any(|row| (0..3).all(|k| (row[2 + k] - stop[k]).abs() < 0.05));
    assert!(
        near,
        "the resumed run never reached the stop point {stop:?}"
    );
}

#[test]
fn resume_refuses_an_axis_that_lost_its_position() {
    let _one = one_at_a_time();
    let m = machine(|t| t);
    let r = rig(&m, &[(1, Inject::Reboot { after: ms(600) })], &[]);
    let out = resume::run_program(&m, &r.bus, &opts(&r, LINES, "first.csv"));
    let st = out.resume.expect("a resume point");
    drop(r);
    // The drives come back with X at 0: an incremental encoder after a power cycle.
    let y = (st.stop_point_mm[1] * 1000.0) as i32;
    let z = (st.stop_point_mm[2] * 2000.0) as i32;
    let r = rig(&m, &[], &[0, y, z]);
    let out = resume::resume_program(&m, &r.bus, &opts(&r, LINES, "lost.csv"), &st, &mut |_| {
        panic!("not asked: the position is lost")
    });
    match out.result {
        Err(GatewayError::Resume(e)) => assert!(
            e.starts_with("not resuming: axis X (node 1) is at 0.0000 mm")
                && e.contains("its position was lost"),
            "{e}"
        ),
        other => panic!("{other:?}"),
    }
}

/// Wait until `node` reports EMCY `code` on `bus`, at most `within`.
fn wait_emcy(port: &mut dyn canmotion::bus::Port, node: u8, code: u16, within: Duration) {
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

/// Fault node 2 with `inject` in the middle of a run (checking the stop), then wait for the
/// drives to notice the gateway is gone (EMCY 0x8130), so its heartbeat loss does not fault the
/// drive again during the reset's observation.
fn faulted(inject: Inject, cause: fn(&Alarm) -> bool, bound_s: f64) -> Rig {
    let m = machine(|t| t);
    let r = rig(&m, &[(2, inject)], &[]);
    let mut watch = r.bus.open(&[canmotion::bus::Filter::exact(0x82)]).unwrap();
    let out = resume::run_program(&m, &r.bus, &opts(&r, LONG, "fault.csv"));
    let (o, _) = outcome(&m, &r, out, "fault.csv");
    let f = failure(&o);
    assert_eq!(f.alarm().node(), Some(2), "{f}");
    assert!(cause(f.alarm()), "{f}");
    let d = detection_s(f, 0.3);
    assert!(d < bound_s + MARGIN_S, "detected {d} s after the fault");
    frozen_after(&o, 1, f);
    limits_held(&o, &[0, 2]);
    wait_emcy(watch.as_mut(), 2, 0x8130, Duration::from_secs(3));
    r
}

#[test]
fn reset_clears_a_following_error_fault_and_verifies_it() {
    let _one = one_at_a_time();
    // The jam: the window (2 mm at 100 mm/s) plus 0x6066 (10 ms) and the PDO round trip.
    let r = faulted(
        Inject::FollowingError { after: ms(300) },
        |a| {
            matches!(
                a,
                Alarm::FollowingError { axis: "Y", .. } | Alarm::Emcy { code: 0x8611, .. }
            )
        },
        0.090,
    );
    let reports = reset::reset(&r.bus, &[2, 3], &reset::ResetOptions::default()).unwrap();
    let rep = &reports[0];
    assert!(matches!(rep.outcome, ResetOutcome::Cleared { .. }), "{rep}");
    assert_eq!((rep.error_before, rep.error_after), (0x8611, 0));
    let text = rep.to_string();
    assert!(
        text.starts_with("node 2: fault cleared ")
            && text.contains("was Fault (statusword 0x")
            && text.contains("0x603F = 0x8611 (following error)")
            && text.contains("now Switch on disabled"),
        "{text}"
    );
    // Node 3 faulted on the gateway's lost heartbeat: cleared as well.
    assert_eq!(reports[1].error_before, 0x8130, "{}", reports[1]);
    assert!(reports[1].ok(), "{}", reports[1]);
    // A second reset finds nothing to do.
    let again = reset::reset(&r.bus, &[2], &reset::ResetOptions::default()).unwrap();
    assert_eq!(again[0].outcome, ResetOutcome::NotFaulted, "{}", again[0]);
}

#[test]
fn reset_reports_a_fault_whose_cause_persists() {
    let _one = one_at_a_time();
    // A drive fault (statusword bit 3 or its EMCY): the cycle after it, and the PDO round trip.
    let m = machine(|t| t);
    let r = faulted(
        Inject::PersistentFault { after: ms(300) },
        |a| {
            matches!(
                a,
                Alarm::DriveFault { axis: "Y", .. } | Alarm::Emcy { code: 0x4310, .. }
            )
        },
        2.0 * m.cycle_s(),
    );
    let reports = reset::reset(&r.bus, &[2], &reset::ResetOptions::default()).unwrap();
    let rep = &reports[0];
    assert_eq!(rep.outcome, ResetOutcome::NotCleared, "{rep}");
    assert!(!rep.ok());
    let text = rep.to_string();
    assert!(
        text.starts_with("node 2: fault NOT cleared: still Fault (statusword 0x")
            && text.contains("0x603F = 0x4310 (excess drive temperature)"),
        "{text}"
    );
}

#[test]
fn reset_reports_a_fault_that_comes_back() {
    let _one = one_at_a_time();
    let m = machine(|t| t);
    let r = faulted(
        Inject::RecurringFault { after: ms(300) },
        |a| {
            matches!(
                a,
                Alarm::DriveFault { axis: "Y", .. } | Alarm::Emcy { code: 0x2310, .. }
            )
        },
        2.0 * m.cycle_s(),
    );
    let reports = reset::reset(&r.bus, &[2], &reset::ResetOptions::default()).unwrap();
    let rep = &reports[0];
    assert!(
        matches!(rep.outcome, ResetOutcome::CameBack { .. }),
        "{rep}"
    );
    let text = rep.to_string();
    assert!(
        text.starts_with("node 2: fault came back ")
            && text.contains("0x603F = 0x2310 (continuous over-current)"),
        "{text}"
    );
}

/// The EMCYs (COB-ID 0x81–0xFF, 8 bytes) arriving on `port` within `within` of now: the wait
/// ends at the first one or at the deadline.
fn first_emcy(
    port: &mut dyn canmotion::bus::Port,
    within: Duration,
) -> Option<canmotion::canopen::Emcy> {
    let end = Instant::now() + within;
    loop {
        let left = end.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return None;
        }
        if let Ok(Some(f)) = port.recv_timeout(left.min(Duration::from_millis(50)))
            && let Some(e) = canmotion::canopen::Emcy::from_frame(&f)
        {
            return Some(e);
        }
    }
}

#[test]
fn a_clean_run_leaves_no_drive_watching_the_gateways_heartbeat() {
    let _one = one_at_a_time();
    let m = machine(|t| t);
    let r = rig(&m, &[], &[]);
    let rec = Recorder::start(&r.bus);
    for run in 0..2 {
        let summary = canmotion::gateway::run(&m, &r.bus, &opts(&r, PROGRAM, "clean.csv"))
            .unwrap_or_else(|e| panic!("run {run}: {e}"));
        // From the end of the run on (the port sees only frames sent after it opened). EMCYs
        // share 0x080 + node with SYNC's 0x080: `first_emcy` skips SYNC.
        let mut emcys = r
            .bus
            .open(&[canmotion::bus::Filter {
                id: 0x080,
                mask: 0x780,
            }])
            .unwrap();
        // The gateway's heartbeat has stopped; the drives' consumer time is 500 ms.
        let e = first_emcy(emcys.as_mut(), Duration::from_secs(2));
        assert_eq!(e, None, "run {run}: {summary}");
    }
    // Each start-up armed the consumer again before NMT start, and each end disarmed it (read
    // back) before the gateway's heartbeat stopped.
    let frames = rec.stop();
    for a in &m.axes {
        let sdo = 0x600 + u16::from(a.node);
        let writes: Vec<(u64, u32)> = frames
            .iter()
            .filter(|(_, f)| f.id() == sdo && f.data()[..4] == [0x23, 0x16, 0x10, 0x01])
            .map(|(t, f)| (*t, u32::from_le_bytes(f.data()[4..8].try_into().unwrap())))
            .collect();
        let starts: Vec<u64> = frames
            .iter()
            .filter(|(_, f)| f.id() == 0 && f.data() == [0x01, a.node])
            .map(|(t, _)| *t)
            .collect();
        assert_eq!(writes.len(), 4, "node {}: {writes:?}", a.node);
        assert_eq!(starts.len(), 2, "node {}", a.node);
        for run in 0..2 {
            let (armed_at, armed) = writes[2 * run];
            let (_, disarmed) = writes[2 * run + 1];
            assert_eq!((armed, disarmed), (0x007F_01F4, 0), "node {}", a.node);
            assert!(
                armed_at < starts[run],
                "node {}: armed after NMT start",
                a.node
            );
        }
    }
}

#[test]
fn reset_reports_an_emcy_without_the_fault_bit_as_information() {
    let _one = one_at_a_time();
    // Node 2 faults on a following error; 0x6007 = 0: a lost heartbeat is reported (EMCY
    // 0x8130) without a fault. After the fault stop the drives keep consuming the gateway's
    // heartbeat, so node 2's 0x8130 arrives some 500 ms after the run, inside a watch window
    // that starts right after it.
    let m = machine(|t| t);
    let bus = Bus::InProc(InProcBus::new());
    let dict = drive_dict(|t| {
        t.replace(
            "default = 1                  # 0 no action",
            "default = 0                  # 0 no action",
        )
    });
    let def = dict.sub(0x6007, 0).unwrap();
    assert_eq!(
        dict.default_for(def, 2),
        Some(canopen_rs::Value::Integer16(0)),
        "0x6007's default"
    );
    let drives = m
        .axes
        .iter()
        .map(|a| {
            let d = SimDrive::new(dict.clone(), a.node);
            if a.node == 2 {
                d.with_inject(Inject::FollowingError { after: ms(300) })
            } else {
                d
            }
        })
        .collect();
    let _sims = runner::spawn(&bus, drives).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let out = canmotion::gateway::run(
        &m,
        &bus,
        &RunOptions {
            program_name: "fault.ngc".into(),
            program_text: LONG.into(),
            log: Some(dir.path().join("fault.csv")),
            simulate: false,
            ..Default::default()
        },
    );
    assert!(matches!(out, Err(GatewayError::Motion(_))), "{out:?}");
    let opts = reset::ResetOptions {
        observe: Duration::from_millis(2000),
        ..Default::default()
    };
    let reports = reset::reset(&bus, &[2], &opts).unwrap();
    let rep = &reports[0];
    assert!(matches!(rep.outcome, ResetOutcome::Cleared { .. }), "{rep}");
    assert!(rep.ok(), "{rep}");
    assert_eq!(
        rep.info_emcys.iter().map(|e| e.0).collect::<Vec<_>>(),
        [0x8130],
        "{rep}"
    );
    assert!(
        rep.to_string().contains(
            "node 2: EMCY 0x8130 (life guard or heartbeat error) after the fault cleared, with no fault in the statusword"
        ),
        "{rep}"
    );
}
